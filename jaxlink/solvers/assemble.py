"""Loop-closure (assembly) solve: closed-form dyads, or Newton's method with continuation.

For one design p and a sequence of inputs φ_0 … φ_{N-1} we solve Φ(q_k; φ_k, p) = 0.

**Closed form** (`method="auto"` when every block of the structure is a dyad, `"closed_form"`):
no Newton at all. At φ_0 each dyad's assembly branch is the one nearest to the guess q0
(`_dyads.solve_nearest`, dyad by dyad), and every position of every design is then solved in
closed form on those branches (`_closed_form_path`). A position is converged when its loops close
to the tolerance (a dyad at its exact toggle, h² negative by rounding, is assembled at h = 0) and
`singular` when a dyad's two links are collinear to within `singular_ratio` (toggle, dead
centre, change point).

**Newton** (`"continuation"`, `"independent"`, and `"auto"` for other structures):

- **first position**: Newton from the guess q0, with a step limit (0.5 rad for angles, 0.5 × the
  length scale for lengths) so that a rough guess does not jump to another branch;
- **continuation**: position k starts from a Lagrange extrapolation of the last (up to three)
  converged solutions, which keeps the assembly branch of the guess through the revolution and
  typically needs two or three Newton steps. After a failed position (e.g. past the reach of a
  non-Grashof linkage) the next one restarts like a first position from the last converged q. The
  sign of det of each diagonal block of Φ_q (each dyad's circuit) is tracked: a step that lands on
  another circuit without a singular or failed position in between is redone in sub-steps, and
  reported `max_steps` if that does not help — never as a converged position on another circuit;
- **Newton step**: Φ_q from forward-mode AD (`jax.jacfwd`) with the sines and cosines of the
  angles computed once per iteration and stored (`_fusion.materialize`; XLA on CPU would otherwise
  recompute them in every fused kernel), solved by forward substitution over the diagonal blocks
  (Cramer on 2×2 dyad blocks, unrolled Gaussian elimination with partial pivoting on larger ones,
  `_linalg`), so that `vmap` over designs fuses. The part of Φ that does not depend on q is
  evaluated once per position. The pivot ratio is column-scaled (invariant under the units of the
  unknowns); below `singular_ratio` (default 10 √eps) an assembled position is `singular`;
- **convergence** (`newton`): the loop stops at a √eps-level residual when the step is small
  enough that one final correction leaves an error below rtol / 100, applies that correction and
  reports the residual after it (evaluated once more, without trigonometry); at double roots
  (exact toggles, change points), where Newton converges only linearly, it takes extra steps while
  the residual keeps falling by ≈ 4 and stops at the rounding floor.

Every position returns a result code (`RESULTS`) instead of raising, and no position writes NaN
into the output: it keeps the last finite iterate, and the continuation goes on from the last
converged position. So one bad design or position never poisons a batch. A design whose
parameters give no finite tolerance (a NaN or infinite length) or whose guess is not finite is
`nonfinite` at every position.

**Exact gradients.** The whole path solve is a `jax.custom_jvp`: by the implicit function
theorem, dq_k = −Φ_q⁻¹ (Φ_p dp + Φ_φ dφ_k) at the converged solution — one linear solve per
position, independent of the Newton iterations (and zero at non-converged positions, `singular`
ones included). Reverse mode (`jax.grad`) follows by transposition of that linear map.
"""

from __future__ import annotations

import functools
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..model import structure as _structure
from ..model.mechanism import Mechanism
from ..results import RESULTS, Solution, SolveStats
from . import dyads as _dyads
from .fusion import materialize
from .linalg import solve_block_lower, solve_small


class NewtonOptions(NamedTuple):
    """Static solver settings (changing them recompiles).

    - `method`: `"auto"` (closed-form dyads when every block of the structure is a dyad, else
      Newton with continuation), `"closed_form"`, `"continuation"` or `"independent"` (every
      position by Newton from q0: only safe with a close guess).
    - `rtol`: a position is converged when max|Φ| at the returned q is ≤ rtol × length scale (the
      largest |length parameter|); `None` = 1000 × machine epsilon of the dtype (2.2e-13 in
      float64, 1.2e-4 in float32). Newton stops early: once max|Φ| ≤ max(rtol, √eps) × scale and
      the step is small enough that one more correction leaves an error below rtol / 100 (the
      error after a Newton step is ≈ |dq|² / (2 × pivot ratio)), that correction is applied and
      the residual after it is evaluated (cheaply: the sines and cosines of the corrected angles
      by angle addition) and tested against rtol; the returned q is accurate to rounding (tested
      against closed forms to 1e-15 rad) and `residual` is the residual at it.
    - `max_steps`: Newton iterations per position after the first (up to `EXTRA_STEPS` = 32 more
      while the residual falls by 2–10× per step at a small pivot ratio: linear convergence at a
      double root, e.g. an exact toggle). A position that ran out of steps returns its last
      evaluated iterate.
    - `max_steps_first`: iterations for the first position (from the file's guess), for every
      position of `"independent"`, and after a position that failed (the continuation restarts).
    - `continuation`: False is the same as `method="independent"` (kept for compatibility).
    - `predictor_order`: 0 (previous solution), 1 (secant) or 2 (quadratic) extrapolation.
    - `singular_ratio`: below this column-scaled pivot ratio of Φ_q (≈ the sine of the angle
      between its columns; for the closed form the sine of the angle between a dyad's two links)
      an assembled position is reported `singular` (dead centre, toggle, change point: the
      solution is not unique there); `None` = 10 √eps (1.5e-7 in float64, 3.5e-3 in float32).
    """

    rtol: float | None = None
    max_steps: int = 12
    max_steps_first: int = 60
    continuation: bool = True
    predictor_order: int = 2
    singular_ratio: float | None = None
    method: str = "auto"


METHODS = ("auto", "closed_form", "continuation", "independent")
EXTRA_STEPS = 32  # more Newton steps allowed while converging linearly (double roots)
REFINE_TRIES = 24  # sub-steps tried when the continuation lands on another circuit


def default_rtol(dtype) -> float:
    return float(1000 * np.finfo(dtype).eps)


def singular_threshold(opts: NewtonOptions, dtype) -> float:
    """The pivot ratio (sine) below which a position is `singular`: `opts.singular_ratio` or 10 √eps."""
    if opts.singular_ratio is not None:
        return float(opts.singular_ratio)
    return float(10 * np.sqrt(np.finfo(dtype).eps))


def _units(mech: Mechanism, scale, dtype):
    """Per unknown: 1 (angle, rad) or the length scale (length), to measure steps."""
    return jnp.stack([jnp.ones((), dtype) if k == "angle" else jnp.asarray(scale, dtype)
                      for k in mech.unknown_kinds])


def _linear_solve(mech: Mechanism, signs: bool = False):
    """`lin(a, b) -> (x, pivot_ratio)` (or `(x, pivot_ratio, det_signs)` with `signs`) for Φ_q of
    this structure; the pivot ratio is column-scaled (`_linalg.solve_small`)."""
    order = _structure.blocks(mech)
    blocks = tuple((tuple(r for li in loops for r in (2 * li, 2 * li + 1)), cols) for loops, cols in order)
    if len(blocks) == 1 and len(blocks[0][1]) > 2:
        def lin(a, b):
            x, ratio, sg = solve_small(a, b, scaling="columns", signs=True)
            return (x, ratio, sg[None]) if signs else (x, ratio)
        return lin

    def lin_blocks(a, b):
        x, ratio, sg = solve_block_lower(a, b, blocks)
        return (x, ratio, sg) if signs else (x, ratio)
    return lin_blocks


def _n_blocks(mech: Mechanism) -> int:
    order = _structure.blocks(mech)
    return 1 if len(order) == 1 and len(order[0][1]) > 2 else len(order)


@jax.custom_jvp
def _known_trig(x, c, s):
    """(cos x, sin x) given as (c, s), computed elsewhere; derivative (−s, c) dx."""
    return c, s


@_known_trig.defjvp
def _known_trig_jvp(primals, tangents):
    _, c, s = primals
    dx, dc, ds = tangents
    return (c, s), (dc - s * dx, ds + c * dx)


def newton(mech: Mechanism, q0, phi, p, *, tol, rtol: float, max_steps, limit_step, singular_ratio: float,
           trig_p=None):
    """Newton's method for one position. Returns `(q, rnorm, result, steps, signs)` (see `RESULTS`;
    `signs`: sign of det of every diagonal block of Φ_q at q, the circuit of each dyad).

    `tol` = rtol × length scale (traced; NaN or inf: `nonfinite` at once, no iteration).
    `max_steps` and `limit_step` (0.5 rad / 0.5 × scale per step, for a rough guess) may be traced.
    Each iteration evaluates Φ and Φ_q at q (the sines and cosines of the angles once, shared by
    both) and solves for the step dq. It stops

    - **converged** when max|Φ| ≤ max(rtol, √eps) × scale, the pivot ratio is ≥ `singular_ratio`
      and |dq|² / (2 × pivot ratio) — the error left after the step — is ≤ rtol / 100 (rad; length
      unknowns relative to the length scale): the step is applied as the final correction and the
      residual after it must be ≤ tol;
    - **at the rounding floor / a double root** when max|Φ| ≤ 4 eps × scale, or max|Φ| ≤ tol with
      a step |dq| ≤ √eps that no longer shrinks quadratically (≥ 1/4 of the previous one):
      `converged`, or `singular` if the pivot ratio is below `singular_ratio` (at a double root
      Newton converges only linearly, the error halving per step: up to `EXTRA_STEPS` more steps
      are allowed while the residual keeps halving, so it ends within ≈ √eps of the double root);
    - **giving up** (as `cannot_assemble`) when the residual stagnates — its best value not halved
      for 4 iterations (8 with `limit_step`) — or, without `limit_step`, when after 4 iterations it
      is still above 1e-4 × scale: from a continuation predictor Newton converges in 2–3 steps, so
      such a position is almost surely unreachable, and under `vmap` one hopeless position would
      otherwise hold the whole batch.

    The returned q is the corrected point where the final correction was applied, else the last
    evaluated iterate, and `rnorm` is max|Φ| there (evaluated once more after the loop, without
    trigonometry: the sines and cosines of the corrected angles by angle addition).
    """
    dtype = jnp.result_type(q0)
    eps = float(np.finfo(dtype).eps)
    sqrt_eps = float(np.sqrt(eps))
    const = mech.residual_const(phi, p)
    lin = _linear_solve(mech, signs=True)
    scale = mech.length_scale(p)
    tol = jnp.asarray(tol, dtype)
    tol_loop = tol * max(1.0, sqrt_eps / rtol)  # max(rtol, √eps) × scale (NaN stays NaN)
    acc2 = 2.0 * rtol / 100.0  # |dq|² ≤ 2 × pivot ratio × (rtol / 100)
    thr = singular_ratio
    unit = _units(mech, scale, dtype)
    ang = [i for i, k in enumerate(mech.unknown_kinds) if k == "angle"]
    names = mech.unknown_names
    tp = dict(trig_p) if trig_p else {}
    hopeless = 1e-4 * scale
    floor_tol = 4 * eps * scale
    limit_step = jnp.asarray(limit_step)
    max_steps = jnp.asarray(max_steps, jnp.int32)
    nb = _n_blocks(mech)

    def resid(qq, c, s):
        trig = dict(tp)
        trig.update({names[i]: (c[j], s[j]) for j, i in enumerate(ang)})
        return mech.residual_var(qq, phi, p, const, trig)

    def trig_of(qq):
        qa = jnp.stack([qq[i] for i in ang]) if ang else jnp.zeros((0,), dtype)
        return jnp.cos(qa), jnp.sin(qa)

    def value_and_jac(qq):
        # the sines and cosines of the angles computed once and stored (`materialize`): Φ and Φ_q
        # are polynomial in them (`_known_trig` gives their derivatives), so no fused kernel
        # recomputes trigonometry
        c, s = materialize(trig_of(qq))

        def f(x):
            xa = jnp.stack([x[i] for i in ang]) if ang else jnp.zeros((0,), dtype)
            cc, ss = _known_trig(xa, c, s)
            r = resid(x, cc, ss)
            return r, r
        jac, r = jax.jacfwd(f, has_aux=True)(qq)
        return r, jac, c, s

    def cond(st):
        k, done, piv, rn, rn_before = st[2], st[3], st[4], st[6], st[7]
        # linear convergence at a (near-)double root: the residual falls by ≈ 4 per step
        linear = (rn <= 0.5 * rn_before) & (rn >= 0.1 * rn_before) & (piv < 0.1)
        return (~done) & ((k < max_steps) | ((k < max_steps + EXTRA_STEPS) & linear))

    # state: the last evaluated iterate qe and the step still to apply to it; the iteration count;
    # done; the pivot ratio, det signs, residual (and the one before), |step| at qe; the best
    # residual and the iterations since it halved; how the loop ended; (cos, sin) at qe
    def body(st):
        qe, step, k, _, _, _, rn_last, _, dqa_prev, rn_best, stall, _, _, _, _ = st
        q = qe - step
        r, jac, c, s = value_and_jac(q)
        dq, piv, sg = lin(jac, r)
        rn = jnp.max(jnp.abs(r))
        dqa = jnp.max(jnp.abs(dq) / unit)
        finite = jnp.isfinite(rn) & jnp.isfinite(dqa)
        # one final correction leaves an error ≈ |dq|² / (2 × pivot ratio): small enough
        corr = finite & (piv >= thr) & (rn <= tol_loop) & (dqa * dqa <= acc2 * piv)
        # the residual is at the rounding floor of Φ (at a singular Φ_q the step is then rounding
        # noise amplified: stop here), or the step no longer shrinks quadratically (rounding
        # floor of the step, or a double root approached linearly)
        floor = (rn <= floor_tol) | ((rn <= tol) & (dqa <= sqrt_eps) & (dqa >= 0.25 * dqa_prev))
        better = rn < 0.5 * rn_best
        rn_best = jnp.where(better, rn, rn_best)
        stall = jnp.where(better, 0, stall + 1)
        give_up = (stall >= jnp.where(limit_step, 8, 4)) | ((~limit_step) & (k >= 3) & (rn > hopeless))
        stop = ~corr & (floor | give_up | ~finite)
        # step-limited Newton for a rough guess: at most 0.5 rad (0.5 × scale) per unknown
        shrink = jnp.where(limit_step, jnp.minimum(1.0, 0.5 / jnp.maximum(dqa, 1e-30)), 1.0)
        step = jnp.where(stop, 0.0, dq * shrink)
        return (q, step, k + 1, corr | stop, piv, sg, rn, rn_last, dqa, rn_best, stall, corr, stop, c, s)

    inf = jnp.asarray(jnp.inf, dtype)
    start_bad = ~jnp.isfinite(tol) | ~jnp.all(jnp.isfinite(q0))
    false = jnp.zeros((), bool)
    zeros_a = jnp.zeros((len(ang),), dtype)
    init = (q0, jnp.zeros_like(q0), jnp.zeros((), jnp.int32), start_bad, jnp.asarray(1.0, dtype),
            jnp.ones((nb,), dtype), inf, inf, inf, inf, jnp.zeros((), jnp.int32), false, false, zeros_a, zeros_a)
    qe, step, k, _, piv, sg, _, _, _, _, stall, corr, stop, c, s = jax.lax.while_loop(cond, body, init)
    # the returned q: the last evaluated iterate, after the final correction where `corr`; the
    # residual there, once per position, outside the loop and without trigonometry: the sines and
    # cosines of the corrected angles by angle addition from those at qe (the correction d is
    # tiny: cos d = 1 − d²/2 + d⁴/24, sin d = d − d³/6 to rounding)
    d = jnp.where(corr, step, 0.0)
    q = qe - d
    if ang:
        da = jnp.stack([d[i] for i in ang])
        d2 = da * da
        cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0))
        sd = da * (1.0 - d2 * (1.0 / 6.0))
        c, s = c * cd + s * sd, s * cd - c * sd
    rn = jnp.max(jnp.abs(resid(q, c, s)))
    conv = (corr | stop) & (rn <= tol)
    finite = jnp.isfinite(rn) & jnp.isfinite(tol) & jnp.all(jnp.isfinite(q))
    assemble_tol = max(1e-6, 10 * sqrt_eps) * scale
    result = jnp.where(
        conv & finite, jnp.where(piv >= thr, RESULTS.converged, RESULTS.singular),
        jnp.where(~finite, RESULTS.nonfinite,
                  jnp.where((piv < thr) & (rn <= tol_loop), RESULTS.singular,
                            jnp.where((rn > assemble_tol) | stop | (stall >= 3), RESULTS.cannot_assemble,
                                      RESULTS.max_steps)))).astype(jnp.int8)
    # never hand out non-finite numbers: fall back to the start value
    q = jnp.where(jnp.all(jnp.isfinite(q)), q, jnp.nan_to_num(q0))
    return q, rn, result, k, sg


def method_for(mech: Mechanism, opts: "NewtonOptions") -> str:
    """The path method `opts` resolves to for this mechanism."""
    if opts.method not in METHODS:
        raise ValueError(f"unknown method {opts.method!r}; use one of {METHODS}")
    if not opts.continuation and opts.method in ("auto", "continuation"):
        return "independent"
    if opts.method == "auto":
        return "closed_form" if _dyads.classify(mech) is not None else "continuation"
    if opts.method == "closed_form" and _dyads.classify(mech) is None:
        raise ValueError(f"{mech.name}: not every block is a dyad of known form; no closed form")
    return opts.method


def _closed_form_path(mech, p, phis, q0, tol, trig_in, trig_p, thr, phi_ref, points: bool = False):
    """Every position of one design in closed form, on the branches nearest to the guess q0 at
    the input `phi_ref` where it holds (`_dyads.solve_nearest`): no Newton, no continuation.

    A position is assembled when its loops close to `tol` (the residual of the closed form,
    exact to rounding: a dyad at its exact toggle, h² negative by rounding, is assembled at
    h = 0); it is `singular` when some dyad's links are collinear to within `thr` (the sine of
    the angle between them: dead centre, toggle, change point)."""
    dyads = _dyads.classify(mech)
    t_ref = _dyads.input_trig(mech, phi_ref)
    _, _, _, sigma = _dyads.solve_nearest(mech, dyads, q0, phi_ref, p, {**t_ref, **trig_p})
    # a guess that selects no branch (NaN), or parameters that allow no check (a NaN or infinite
    # tolerance, e.g. from a NaN length that no loop uses): nothing here can be verified
    ref_ok = jnp.all(jnp.isfinite(q0)) & jnp.isfinite(tol)
    q_ref = jnp.where(jnp.isfinite(q0), q0, 0.0)

    def one(phi, t_in):
        q, ok, rn, sine, trig = _dyads.solve_with_trig(mech, dyads, sigma, q_ref, phi, p, {**t_in, **trig_p})
        conv = (rn <= tol) & ref_ok
        code = jnp.where(conv, jnp.where(sine < thr, RESULTS.singular, RESULTS.converged),
                         jnp.where(~ref_ok | ~jnp.isfinite(rn), RESULTS.nonfinite,
                                   jnp.where(ok, RESULTS.max_steps, RESULTS.cannot_assemble)))
        q = jnp.where(jnp.all(jnp.isfinite(q)), q, q_ref)
        # every output of a position packed into one array: one fused kernel writes them all (XLA on
        # CPU would otherwise compute the solve once per output); the points from the sines and
        # cosines the solve already has (no new trigonometry)
        parts = [q, rn[None], code.astype(q.dtype)[None]]
        if points:
            parts.append(jnp.ravel(mech.point_positions(q, phi, p, trig)))
        return jnp.concatenate(parts)

    packed = jax.vmap(one)(phis, trig_in)
    n = len(mech.unknown_names)
    pts = packed[:, n + 2:].reshape(packed.shape[0], -1, 2) if points else None
    zeros = jnp.zeros(packed.shape[:1], jnp.int32)
    return packed[:, :n], packed[:, n], packed[:, n + 1].astype(jnp.int8), zeros, pts


def _extrapolate(hist_q, hist_phi, n_good, phi, order: int):
    """Lagrange extrapolation through the last `min(n_good, order+1)` converged solutions."""
    q1, q2, q3 = hist_q
    f1, f2, f3 = hist_phi
    if order == 0:
        return q1
    eps = 1e-12
    # linear
    d12 = f1 - f2
    ok12 = jnp.abs(d12) > eps
    lin = q1 + (q1 - q2) * jnp.where(ok12, (phi - f1) / jnp.where(ok12, d12, 1.0), 0.0)
    if order == 1:
        return jnp.where(n_good >= 2, lin, q1)
    d13, d23 = f1 - f3, f2 - f3
    ok = ok12 & (jnp.abs(d13) > eps) & (jnp.abs(d23) > eps)
    s13 = jnp.where(ok, d13, 1.0)
    s23 = jnp.where(ok, d23, 1.0)
    s12 = jnp.where(ok, d12, 1.0)
    w1 = (phi - f2) * (phi - f3) / (s12 * s13)
    w2 = (phi - f1) * (phi - f3) / (-s12 * s23)
    w3 = (phi - f1) * (phi - f2) / (s13 * s23)
    quad = w1 * q1 + w2 * q2 + w3 * q3
    return jnp.where((n_good >= 3) & ok, quad, jnp.where(n_good >= 2, lin, q1))


def _push(hist, value, cond):
    """History (newest first) with `value` pushed in where `cond`."""
    return tuple(jnp.where(cond, a, b) for a, b in zip((value,) + hist[:-1], hist))


def _newton_kw(rtol, thr, trig_p):
    return {"rtol": rtol, "singular_ratio": thr, "trig_p": trig_p}


def _first_positions(mech, opts, P, phi0, Q0, tol, rtol, thr, trig_p):
    """Newton from the guesses at the first input, one per design (step-limited)."""
    return jax.vmap(lambda p, q0, t, f, tp: newton(mech, q0, f, p, tol=t, max_steps=opts.max_steps_first,
                                                   limit_step=True, **_newton_kw(rtol, thr, tp)))(
        P, Q0, tol, phi0, trig_p)


def _continuation_one(mech, opts, p, phis, first, tol, kw):
    """Newton + continuation along phis[1:] for one design, from its solved first position.

    Position k starts from the extrapolation of the last converged positions. After a position
    that failed (not converged, not singular) it restarts like a first position (step-limited
    Newton from the last converged q, `max_steps_first`) instead of extrapolating across the gap.
    The sign of det of each diagonal block of Φ_q (each dyad's circuit) is compared with the last
    converged position: a change without a singular or failed position in between means the step
    jumped to another circuit, and the position is re-solved in sub-steps from the last converged
    position (half the step, halved again after every failure, each sub-step required to converge
    on the same circuit; at most `REFINE_TRIES` Newton solves, else the position is reported
    `max_steps`: refine the input step). The attempts are one `while_loop` around the single
    Newton solve, whose trip count is 1 where nothing flipped: under `vmap` the sub-steps cost
    nothing unless some lane needs them (`lax.cond` would evaluate both branches)."""
    q_first, _, code_first, _, signs_first = first
    hist_q = (q_first, q_first, q_first)
    hist_phi = (phis[0], phis[0], phis[0])
    n_good = (code_first == RESULTS.converged).astype(jnp.int32)
    zero = jnp.zeros((), jnp.int32)

    def step(carry, phi):
        hist_q, hist_phi, n_good, sign_ref, last = carry
        restart = (last != RESULTS.converged) & (last != RESULTS.singular)
        check = last == RESULTS.converged

        def cond(st):
            return (~st[6]) & (st[5] <= REFINE_TRIES)

        def body(st):
            hq, hph, ng, phi_cur, h, tries, done, out, ksum = st
            first_try = tries == 0
            last_sub = jnp.abs(phi - phi_cur) <= 1.000001 * jnp.abs(h)
            phi_try = jnp.where(first_try | last_sub, phi, phi_cur + h)
            rs = first_try & restart
            guess = jnp.where(rs, hq[0], _extrapolate(hq, hph, ng, phi_try, opts.predictor_order))
            res = newton(mech, guess, phi_try, p, tol=tol, limit_step=rs,
                         max_steps=jnp.where(rs, opts.max_steps_first, opts.max_steps), **kw)
            q, rn, code, k, sg = res
            ksum = ksum + k
            conv = code == RESULTS.converged
            same = jnp.all(sg == sign_ref)
            # first try: done unless it converged on another circuit; sub-steps: accepted when
            # converged on the circuit, done when the last one is
            flipped = first_try & conv & check & ~same
            ok = ~first_try & conv & same
            fin = (first_try & ~flipped) | (ok & last_sub)
            # (where the sub-steps fail: the first try's position, on the other circuit, `max_steps`)
            code = jnp.where(flipped, jnp.asarray(RESULTS.max_steps, code.dtype), code)
            out = jax.tree_util.tree_map(lambda a, b: jnp.where(fin | flipped, a, b), (q, rn, code, ksum, sg), out)
            out = out[:3] + (ksum,) + out[4:]
            h = jnp.where(first_try, 0.5 * (phi - hph[0]), jnp.where(ok, h, 0.5 * h))
            return (_push(hq, q, ok), _push(hph, phi_try, ok), ng + ok.astype(jnp.int32),
                    jnp.where(first_try, hph[0], jnp.where(ok, phi_try, phi_cur)), h, tries + 1, fin, out, ksum)

        dtype = jnp.result_type(phi)
        out0 = (hist_q[0], jnp.asarray(jnp.inf, dtype), jnp.asarray(RESULTS.max_steps, jnp.int8), zero, sign_ref)
        init = (hist_q, hist_phi, n_good, hist_phi[0], jnp.zeros((), dtype), zero, jnp.zeros((), bool), out0, zero)
        q, rn, code, k, sg = jax.lax.while_loop(cond, body, init)[7]
        good = code == RESULTS.converged
        carry = (_push(hist_q, q, good), _push(hist_phi, phi, good), n_good + good.astype(jnp.int32),
                 jnp.where(good, sg, sign_ref), code)
        return carry, (q, rn, code, k)

    init = (hist_q, hist_phi, n_good, signs_first, code_first)
    return jax.lax.scan(step, init, phis[1:])[1]


def _lead_in(mech: Mechanism, opts: NewtonOptions, p, phi_a, phi_b, q0, tol, kw):
    """The configuration at `phi_b` of one design, from the guess `q0` that holds at `phi_a`: Newton
    along `phi_a + k h`, k = 0 … n−1 (h = (phi_b − phi_a)/n, |h| ≤ 5° for an angle input, ≤ 5 % of
    the length scale for a length input), each from the secant extrapolation of the last two
    converged positions (step-limited from `q0` at k = 0 and after a failed position). Returns the
    last converged q (q0 if none): the guess for `phi_b`. A `while_loop` with a traced trip count,
    so the same under `jit` as eagerly; zero trips when phi_b = phi_a."""
    dtype = jnp.result_type(q0)
    if mech.input_kind == "length":
        max_step = 0.05 * mech.length_scale(p)
    else:
        max_step = jnp.asarray(np.deg2rad(5.0), dtype)
    gap = phi_b - phi_a
    steps = jnp.ceil(jnp.abs(gap) / max_step)
    n = jnp.where(jnp.isfinite(steps), jnp.minimum(steps, 2**30), 0).astype(jnp.int32)
    h = gap / jnp.maximum(n, 1).astype(dtype)

    def body(st):
        k, q1, q2, f1, f2, ng, failed = st
        phi = phi_a + k.astype(dtype) * h
        restart = (k == 0) | failed
        d = f1 - f2
        lin = q1 + (q1 - q2) * jnp.where(jnp.abs(d) > 0, (phi - f1) / jnp.where(jnp.abs(d) > 0, d, 1.0), 0.0)
        guess = jnp.where(restart, jnp.where(ng > 0, q1, q0), jnp.where(ng >= 2, lin, q1))
        q, _, code, _, _ = newton(mech, guess, phi, p, tol=tol, limit_step=restart,
                                  max_steps=jnp.where(restart, opts.max_steps_first, opts.max_steps), **kw)
        good = (code == RESULTS.converged) | (code == RESULTS.singular)
        return (k + 1, jnp.where(good, q, q1), jnp.where(good, q1, q2), jnp.where(good, phi, f1),
                jnp.where(good, f1, f2), ng + good.astype(jnp.int32), ~good)

    zero = jnp.zeros((), jnp.int32)
    init = (zero, q0, q0, phi_a, phi_a, zero, jnp.zeros((), bool))
    out = jax.lax.while_loop(lambda st: st[0] < n, body, init)
    return out[1]


def _solve_batch_impl(mech: Mechanism, opts: NewtonOptions, points: bool, P, phis, Q0, phi_ref):
    """P (B, P), phis (N,) shared by all designs or (B, N), Q0 (B, n) holding at the inputs
    `phi_ref` (B,) (None: at the first input) -> q (B, N, n), rnorm, result, steps (B, N), and the
    points (B, N, n_points, 2) if `points` (else None)."""
    dtype = jnp.result_type(Q0)
    B = P.shape[0]
    shared = phis.ndim == 1
    N = phis.shape[-1]
    ax = None if shared else 0  # vmap axis of phis over the designs
    rtol = opts.rtol if opts.rtol is not None else default_rtol(dtype)
    tol = rtol * jax.vmap(mech.length_scale)(P)
    thr = singular_threshold(opts, dtype)
    method = method_for(mech, opts)
    phi0 = jnp.broadcast_to(phis[0], (B,)) if shared else phis[:, 0]
    if method == "closed_form":
        # every (design, input) pair is independent, on the branches (circuits) of the guess at the
        # reference input. The trigonometry of the inputs (N values) and of the angle parameters
        # (B) is computed once, not inside every fused kernel.
        ref = phi0 if phi_ref is None else phi_ref
        trig_in, trig_p = materialize((_dyads.input_trig(mech, phis), _dyads.parameter_trig(mech, P)))
        return jax.vmap(
            lambda p, ph, q0, t, ti, tp, r: _closed_form_path(mech, p, ph, q0, t, ti, tp, thr, r, points),
            in_axes=(0, ax, 0, 0, ax, 0, 0))(P, phis, Q0, tol, trig_in, trig_p, ref)
    # Newton: a design whose tolerance is not finite (a NaN or infinite length, even one that only
    # a point uses) or whose guess is not finite (it selects no branch) is `nonfinite` at every
    # position, without iterating (a NaN tolerance makes `newton` stop at once)
    bad = ~jnp.isfinite(tol) | ~jnp.all(jnp.isfinite(Q0), axis=1)
    tol = jnp.where(bad, jnp.nan, tol)
    trig_p = materialize(_dyads.parameter_trig(mech, P))
    if phi_ref is not None:  # continue from where the guesses hold to the first input
        Q0 = jax.vmap(lambda p, a, b, q0, t, tp: _lead_in(mech, opts, p, a, b, q0, t, _newton_kw(rtol, thr, tp)))(
            P, phi_ref, phi0, Q0, tol, trig_p)
    first = _first_positions(mech, opts, P, phi0, Q0, tol, rtol, thr, trig_p)
    q1, r1, c1, k1, _ = first
    out = _newton_path(mech, opts, P, phis, Q0, tol, rtol, thr, trig_p, first, N, method)
    if not points:
        return out + (None,)
    # the points, with the sines and cosines of the angle parameters known
    pts = jax.vmap(jax.vmap(lambda q, phi, p, tp: mech.point_positions(q, phi, p, tp), in_axes=(0, 0, None, None)),
                   in_axes=(0, ax, 0, 0))(out[0], phis, P, trig_p)
    return out + (pts,)


def _newton_path(mech, opts, P, phis, Q0, tol, rtol, thr, trig_p, first, N, method):
    """The positions after the first by Newton (continuation or independent)."""
    ax = None if phis.ndim == 1 else 0
    q1, r1, c1, k1, _ = first

    def join(first, rest):
        return jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[:, None], b], axis=1), first, rest)

    if N == 1:
        return q1[:, None], r1[:, None], c1[:, None], k1[:, None]
    if method == "independent":
        rest = jax.vmap(lambda p, ph, q0, t, tp: jax.vmap(
            lambda f: newton(mech, q0, f, p, tol=t, max_steps=opts.max_steps_first, limit_step=True,
                             **_newton_kw(rtol, thr, tp))[:4])(ph[1:]),
            in_axes=(0, ax, 0, 0, 0))(P, phis, Q0, tol, trig_p)
        return join((q1, r1, c1, k1), rest)
    rest = jax.vmap(lambda p, ph, f, t, tp: _continuation_one(mech, opts, p, ph, f, t, _newton_kw(rtol, thr, tp)),
                    in_axes=(0, ax, 0, 0, 0))(P, phis, first, tol, trig_p)
    return join((q1, r1, c1, k1), rest)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1, 2))
def _solve_batch(structure, opts: NewtonOptions, points: bool, P, phis, Q0, phi_ref):
    """The differentiable batched solve: (P (B,P), phis (N,) or (B,N), Q0 (B,n), phi_ref (B,) or
    None) -> (q, rnorm, result, steps, points or None). `structure`, `opts`, `points` are static."""
    return _solve_batch_impl(structure, opts, points, P, phis, Q0, phi_ref)


@_solve_batch.defjvp
def _solve_batch_jvp(structure, opts, points, primals, tangents):
    """Implicit differentiation: dq = −Φ_q⁻¹ (Φ_p dp + Φ_φ dφ) at every converged position (zero
    elsewhere); the guesses and the reference input select a branch and carry no derivative."""
    P, phis, Q0, phi_ref = primals
    dP, dphis = tangents[0], tangents[1]
    mech = structure
    out = _solve_batch(structure, opts, points, P, phis, Q0, phi_ref)
    q, rn, code, k, _ = out
    lin = _linear_solve(mech)

    def one(p, dp, qk, phik, dphik, ok):
        rhs = jax.jvp(lambda pp, ph: mech.residual(qk, ph, pp), (p, phik), (dp, dphik))[1]
        jac = jax.jacfwd(mech.residual)(qk, phik, p)
        # where not converged the sensitivity is undefined: solve a harmless identity system
        # instead (and zero the result), so that neither the JVP nor its transpose (grad)
        # produces NaN
        eye = jnp.eye(jac.shape[0], dtype=jac.dtype)
        dq, _ = lin(jnp.where(ok, jac, eye), jnp.where(ok, rhs, 0.0))
        return jnp.where(ok, -dq, 0.0)

    per_pos = jax.vmap(one, in_axes=(None, None, 0, 0, 0, 0))
    ax = None if phis.ndim == 1 else 0
    dq = jax.vmap(per_pos, in_axes=(0, 0, 0, ax, ax, 0))(P, dP, q, phis, dphis, code == RESULTS.converged)
    dpts = None
    if points:
        def dpoint(p, dp, qk, dqk, phik, dphik):
            return jax.jvp(lambda qq, ph, pp: mech.point_positions(qq, ph, pp), (qk, phik, p), (dqk, dphik, dp))[1]

        dpts = jax.vmap(jax.vmap(dpoint, in_axes=(None, None, 0, 0, 0, 0)), in_axes=(0, 0, 0, 0, ax, ax))(
            P, dP, q, dq, phis, dphis)
    return out, (dq, jnp.zeros_like(rn), _float0(code), _float0(k), dpts)


def _float0(x):
    return np.zeros(np.shape(x), dtype=jax.dtypes.float0)


def _mask_points(pts, code):
    """Points where the position assembled (converged or singular), NaN elsewhere."""
    assembled = (code == RESULTS.converged) | (code == RESULTS.singular)
    return jnp.where(assembled[..., None, None], pts, jnp.nan)


def _batch(mech, phis, p, q0, options: NewtonOptions, points: bool) -> Solution:
    """The common body of `solve` and `solve_path`: shapes, dtypes, defaults, the lead-in."""
    p = jnp.asarray(mech.parameters if p is None else p)
    if not jnp.issubdtype(p.dtype, jnp.floating):
        p = p.astype(jnp.result_type(float))
    dtype = p.dtype
    batch = p.ndim == 2
    P = p if batch else p[None]
    B = P.shape[0]
    phis = jnp.asarray(phis, dtype=dtype)
    if phis.ndim == 0:
        phis = phis[None]
    if not batch and phis.ndim == 2:
        raise ValueError(f"phis of shape {phis.shape} needs a batch of designs p (B, P); p is {p.shape}")
    # the guesses hold at `[input] start`: continue from there to the first input (a lead-in)
    from_start = q0 is None
    q0 = jnp.asarray(mech.guess if q0 is None else q0, dtype=dtype)
    Q0 = q0 if q0.ndim == 2 else jnp.broadcast_to(q0, (B,) + q0.shape)
    phi_ref = jnp.full((B,), mech.input_start, dtype) if from_start else None
    structure = mech.structure if isinstance(mech, Mechanism) else mech
    q, rn, code, k, pts = _solve_batch(structure, options, points, P, phis, Q0, phi_ref)
    if points:
        # finiteness is part of convergence: a position whose points are not finite (an
        # expression like asin(2) in [points]) is `nonfinite`, never converged with NaN points
        bad = ~jnp.all(jnp.isfinite(pts), axis=(-2, -1))
        code = jnp.where(bad & ((code == RESULTS.converged) | (code == RESULTS.singular)),
                         jnp.int8(RESULTS.nonfinite), code)
        pts = _mask_points(pts, code)
    sol = Solution(q=q, points=pts, result=code, stats=SolveStats(residual=rn, steps=k))
    return sol if batch else jax.tree_util.tree_map(lambda x: x[0], sol)


_warned_float32 = False


def _warn_if_float32(p) -> None:
    """Warn once when float64 numbers (the file's, or numpy float64) meet JAX's float32 default."""
    global _warned_float32
    if _warned_float32 or jax.config.read("jax_enable_x64"):
        return
    if p is None or np.result_type(getattr(p, "dtype", np.asarray(p).dtype)) == np.float64:
        _warned_float32 = True
        warnings.warn(
            "jaxlink: JAX computes in float32 here (jax_enable_x64 is off), so positions are accurate to "
            "about 1e-7 of the link lengths and the result is float32. For float64 call "
            "jax.config.update(\"jax_enable_x64\", True) before solving; to keep float32, pass float32 "
            "parameters (p=np.float32(mech.parameters)) and this warning goes away.",
            stacklevel=3)


@functools.partial(jax.jit, static_argnames=("options", "points"))
def _solve_jit(mech, phis, p, q0, options, points):
    return _batch(mech, phis, p, q0, options, points)


def solve(mech: Mechanism, phis, p=None, q0=None, *, options: NewtonOptions = NewtonOptions(),
          points: bool = True) -> Solution:
    """Solve the positions of one design or a batch of designs along a sequence of inputs.

    **Arguments:**

    - `mech`: the mechanism (`jaxlink.load`).
    - `phis`: (N,) input values, SI (rad, or m for a length input), in the order of the
      continuation; (B, N) gives each design its own inputs.
    - `p`: (P,) parameters, SI, ordered as `mech.parameter_names` (default `mech.parameters`),
      or (B, P) for a batch of designs.
    - `q0`: (n,) or (B, n) guess that holds at `phis[0]`. Default: the file's guesses, which hold
      at `[input] start`; the solve continues from there to `phis[0]` first (a lead-in).
    - `options`: `NewtonOptions` (static: another value compiles anew).
    - `points`: also compute the points of interest (`Solution.points`).

    **Returns:** a `Solution` (q, points, result, stats) with leading axes (N,) or (B, N).

    One jitted function (compiled once per shape, dtype and options); the same under an outer
    `jax.jit`, `vmap` or `grad` (exact derivatives by implicit differentiation). The dtype is that
    of `p` (float64 needs `jax.config.update("jax_enable_x64", True)`). A batch placed on several
    devices (`jax.device_put(p, NamedSharding(...))`) is solved where it lies.
    """
    _warn_if_float32(p)
    return _solve_jit(mech, phis, p, q0, options, points)


def solve_path(mech: Mechanism, phis, p=None, q0=None, *, options: NewtonOptions = NewtonOptions(),
               points: bool = False) -> Solution:
    """`solve` for one design, not wrapped in its own `jit`: for use inside the caller's traced
    functions (`vmap` over designs, `grad`), as the design search does. Same arguments and
    defaults as `solve` (`p` (P,), `phis` (N,), `q0` (n,)), but `points=False` by default."""
    return _batch(mech, phis, p, q0, options, points)
