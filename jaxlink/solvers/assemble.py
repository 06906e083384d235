"""Loop-closure (assembly) solve: closed-form dyads, or Newton's method with continuation.

For one design p and a sequence of inputs φ_0 … φ_{N-1} we solve Φ(q_k; φ_k, p) = 0.

**Closed form** (`method="auto"` when every block of the structure is a dyad, `"closed_form"`):
no Newton at all. At φ_0 each dyad's assembly branch is the one nearest to the guess q0
(`_dyads.solve_nearest`, dyad by dyad), and every position of every design is then solved in
closed form on those branches (`_closed_form_path`). A position is converged when its loops close
to the tolerance (a dyad at its exact toggle, h² negative by rounding, is assembled at h = 0) and
`singular` when a dyad's two links are collinear to within `singular_ratio` (toggle, dead
centre, change point). On the CPU a batch of two dyads or more is solved in chunks of about
`CHUNK_POSITIONS` positions (`lax.map` over designs), so that its intermediate arrays stay in
the cache; the answers do not depend on it, bit for bit.

**Newton** (`"continuation"`, `"independent"`, and `"auto"` for other structures):

- **first position**: Newton from the guess q0, with a step limit (0.5 rad for angles, 0.5 × the
  length scale for lengths) so that a rough guess does not jump to another branch;
- **lead-in**: with the file's guesses, from `[input] start` to the first input, by the same
  continuation; for a 2π-periodic input (`periodic_input`: a crank) reduced to at most half a
  revolution, else at most `MAX_LEAD_IN` steps (`_lead_in_inputs`): bounded, never a hang;
- **continuation**: position k starts from a Lagrange extrapolation of the last (up to three)
  converged solutions, which keeps the assembly branch of the guess through the revolution and
  typically needs two or three Newton steps. The sign of det of each diagonal block of Φ_q (each
  dyad's circuit; for a dyad, the side σ of `_dyads`) is tracked: a step that lands on another
  circuit without a singular or failed position in between is redone in sub-steps, and reported
  `max_steps` if that does not help — never as a converged position on another circuit;
- **re-assembly (the branch rule)**: at the first position, after a failed position (e.g. past the
  reach of a non-Grashof linkage) and where a continuation step fails, the position is assembled
  afresh *on the circuit kept* (that of the guess until a position converges, then of the last
  converged one): from the closed form of the dyads where every block is one, else by
  step-limited Newton from the last converged q and from the file's guess, with deflation of a
  solution found on another circuit (`_reassemble`). So every window of inputs where the linkage
  can be assembled is found, on the branch the closed form keeps;
- **Newton step**: Φ_q from forward-mode AD (`jax.jacfwd`) with the sines and cosines of the
  angles computed once per iteration and stored (`_fusion.materialize`; XLA on CPU would otherwise
  recompute them in every fused kernel), solved by forward substitution over the diagonal blocks
  (Cramer on 2×2 dyad blocks, unrolled Gaussian elimination with partial pivoting on larger ones,
  `_linalg`), so that `vmap` over designs fuses. The part of Φ that does not depend on q is
  evaluated once per position. The pivot ratio is column-scaled (invariant under the units of the
  unknowns); below `singular_ratio` (default 10 √eps) an assembled position is `singular`;
- **checked**: the residual at every returned q is evaluated afresh (with its own trigonometry,
  `_check_residual`), independently of Newton's stopping rule;
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
ones included). Reverse mode (`jax.grad`) follows by transposition of that linear map. The rule
(`_implicit_tangents`) costs no trigonometry: the forward solve also returns, stored, the sines
and cosines of the input, of the angle parameters and of the solved angles (`_Trig`; the closed
form has those of the solved angles without evaluating any), Φ_q, Φ_p, Φ_φ and the points'
derivatives are products and sums of them, and Φ_q is solved by forward substitution over its
diagonal blocks (Cramer on each dyad's 2×2 block). Per position it works on scalars only, so that
its transpose is as elementwise as the rule itself, and the forward's outputs are stored
(`materialize`), one (B, N) array per value, so that XLA does not recompute the closed form inside
the derivative's kernels and each of them reads only the values it uses: a gradient of a path
objective in all parameters costs about one forward solve (benchmarks/gradient_cost.py).
"""

from __future__ import annotations

import functools
import os
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero

from ..files import expr as _expr
from ..model import structure as _structure
from ..model.mechanism import Mechanism
from ..results import RESULTS, Solution, SolveStats
from . import branch_points as _branch_points
from . import dyads as _dyads
from .fusion import batched_like, materialize
from .linalg import solve_block_lower, solve_block_lower_scalars, solve_small


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
      position of `"independent"`, and for each try of a re-assembly after a position that failed.
    - `continuation`: False is the same as `method="independent"` (kept for compatibility).
    - `predictor_order`: 0 (previous solution), 1 (secant) or 2 (quadratic) extrapolation.
    - `singular_ratio`: below this column-scaled pivot ratio of Φ_q (≈ the sine of the angle
      between its columns; for the closed form the sine of the angle between a dyad's two links)
      an assembled position is reported `singular` (dead centre, toggle, change point: the
      solution is not unique there); `None` = 10 √eps (1.5e-7 in float64, 3.5e-3 in float32).
    - `change_points`: what the path does at a change point of a dyad (two branches crossing, e.g.
      a Peaucellier cell's flat rhombus, a Grashof four-bar with s + l = p + q folding flat)
      located between two samples (`branch_points`): `"keep"` (default) keeps each dyad's side σ
      (the circuit), so the path goes on along the other branch (its velocity jumps there);
      `"smooth"` flips σ at each located change point, the branch whose velocity is continuous.
      Closed form and `"continuation"` (where every block is a dyad); `"independent"` keeps.
    """

    rtol: float | None = None
    max_steps: int = 12
    max_steps_first: int = 60
    continuation: bool = True
    predictor_order: int = 2
    singular_ratio: float | None = None
    method: str = "auto"
    change_points: str = "keep"


METHODS = ("auto", "closed_form", "continuation", "independent")
CHANGE_POINTS = ("keep", "smooth")
EXTRA_STEPS = 32  # more Newton steps allowed while converging linearly (double roots)
REFINE_TRIES = 24  # sub-steps tried when the continuation lands on another circuit
MAX_LEAD_IN = 4096  # lead-in positions at most (a longer way takes longer steps)
#: store the closed form's result codes once (`_closed_form_path`); False only for the differential
#: test (the same answers either way, bit for bit)
MATERIALIZE_CODES = True


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
    """(cos x, sin x) given as (c, s), computed elsewhere; derivative (−s, c) dx.

    The tangents of c and s are not added: they are those of cos x and sin x, the same −s dx and
    c dx again (adding them counted a second derivative twice: a Hessian 24 % off). They still
    enter a second derivative through the rule itself (d(−s dx) = −ds dx − s d(dx))."""
    return c, s


@_known_trig.defjvp
def _known_trig_jvp(primals, tangents):
    _, c, s = primals
    dx, _, _ = tangents
    return (c, s), (-s * dx, c * dx)


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
    init = batched_like(init, q0, phi, p, tol, max_steps, limit_step)
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
    if opts.change_points not in CHANGE_POINTS:
        raise ValueError(f"unknown change_points {opts.change_points!r}; use one of {CHANGE_POINTS}")
    if not opts.continuation and opts.method in ("auto", "continuation"):
        return "independent"
    if opts.method == "auto":
        return "closed_form" if _dyads.classify(mech) is not None else "continuation"
    if opts.method == "closed_form" and _dyads.classify(mech) is None:
        raise ValueError(f"{mech.name}: not every block is a dyad of known form; no closed form")
    return opts.method


def _closed_form_reference(mech, p, q0, tol, trig_p, phi_ref):
    """What one design's closed-form path needs besides its inputs: the branches σ of its dyads
    nearest to the guess q0 at the input `phi_ref` where it holds (`_dyads.solve_nearest`), the
    guess made finite, and whether anything can be verified (`ok`: False for a guess that selects
    no branch (NaN), or parameters that allow no check (a NaN or infinite tolerance, e.g. from a
    NaN length that no loop uses)). Computed once per design and stored with the trigonometry
    (`_solve_batch_impl`): fused into the per-position kernels, its sines and cosines were
    evaluated at every position."""
    dyads = _dyads.classify(mech)
    t_ref = _dyads.input_trig(mech, phi_ref, arith=False)
    _, _, _, sigma = _dyads.solve_nearest(mech, dyads, q0, phi_ref, p, {**t_ref, **trig_p})
    ok = jnp.all(jnp.isfinite(q0)) & jnp.isfinite(tol)
    return sigma, jnp.where(jnp.isfinite(q0), q0, 0.0), ok


def _closed_form_path(mech, p, phis, tol, trig_in, trig_p, thr, reference, points: bool = False,
                      trig_out: bool = False):
    """Every position of one design in closed form, on the branches `reference` selects
    (`_closed_form_reference`): no Newton, no continuation.

    A position is assembled when its loops close to `tol` (the residual of the closed form,
    exact to rounding: a dyad at its exact toggle, h² negative by rounding, is assembled at
    h = 0); it is `singular` when some dyad's links are collinear to within `thr` (the sine of
    the angle between them: dead centre, toggle, change point). Returns the packed array
    (`_unpack_closed_form`); with `trig_out`, for the derivative, separate values instead:
    `(result, rnorm, q columns, points or None, (cos, sin))`, (N,) each, the (cos, sin) of each
    solved angle as the closed form has them (no new trigonometry; (1, 0) where a position has no
    finite solution)."""
    dyads = _dyads.classify(mech)
    sigma_all, q_ref, ref_ok = reference
    per_position = sigma_all.ndim == 2  # (N, D): the sides of each position (`change_points="smooth"`)

    def one(phi, t_in, sigma):
        q, ok, rn, sine, trig = _dyads.solve_with_trig(mech, dyads, sigma, q_ref, phi, p, {**t_in, **trig_p})
        conv = (rn <= tol) & ref_ok
        code = jnp.where(conv, jnp.where(sine < thr, RESULTS.singular, RESULTS.converged),
                         jnp.where(~ref_ok | ~jnp.isfinite(rn), RESULTS.nonfinite,
                                   jnp.where(ok, RESULTS.max_steps, RESULTS.cannot_assemble)))
        q = jnp.where(jnp.all(jnp.isfinite(q)), q, q_ref)
        if trig_out:
            # for the derivative: one value per leaf, so that each is stored as its own (B, N)
            # array and every kernel of the derivative reads only the values it uses
            pts = mech.point_positions(q, phi, p, trig) if points else None
            cs = tuple(tuple(jnp.where(jnp.isfinite(trig[n][j]), trig[n][j], float(1 - j)) for n in ang)
                       for j in (0, 1))
            return code.astype(jnp.int8), rn, tuple(jnp.unstack(q)), pts, cs
        # every output of a position packed into one array: measured faster than separate outputs
        # for the forward (feed, 1e4 designs: 1.4e7 against 1.1e7 positions/s); the points from
        # the sines and cosines the solve already has (no new trigonometry)
        parts = [q, rn[None], code.astype(q.dtype)[None]]
        if points:
            parts.append(jnp.ravel(mech.point_positions(q, phi, p, trig)))
        return jnp.concatenate(parts)

    ang = [n for n, k in zip(mech.unknown_names, mech.unknown_kinds) if k == "angle"]
    packed = jax.vmap(one, in_axes=(0, 0, 0 if per_position else None))(phis, trig_in, sigma_all)
    if trig_out:
        return packed
    q, rn, code, steps, pts = _unpack_closed_form(mech, packed, points)
    if MATERIALIZE_CODES:
        # the result codes computed once and stored: every element of the points' and the unknowns'
        # outputs (the masks of `_batch`) reads them. Fused, XLA recomputed each position's residual
        # and transmission sines for each of them (the Strider, 4 dyads and 7 points: 1000 designs ×
        # 360 positions 1.2× faster, one design 1.1×; benchmarks/strider_vs_pylinkage.py)
        code = materialize(code)
    return q, rn, code, steps, pts


def _unpack_closed_form(mech, packed, points: bool):
    """The outputs of `_closed_form_path` from its packed array (…, N, m): `(q, rnorm, result,
    steps, points or None)`."""
    n = len(mech.unknown_names)
    lead = packed.shape[:-1]
    pts = packed[..., n + 2:].reshape(lead + (-1, 2)) if points else None
    return (packed[..., :n], packed[..., n], packed[..., n + 1].astype(jnp.int8), jnp.zeros(lead, jnp.int32), pts)


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


def _coefficient(node, name):
    """The integer k when `node` is k·name + (terms free of name), else None."""
    if not any(n.name == name for n in _expr.names_in(node)):
        return 0
    if isinstance(node, _expr.Name):
        return 1
    if isinstance(node, _expr.Neg):
        k = _coefficient(node.arg, name)
        return None if k is None else -k
    if isinstance(node, _expr.Bin) and node.op in "+-":
        a, b = _coefficient(node.left, name), _coefficient(node.right, name)
        if a is None or b is None:
            return None
        return a + b if node.op == "+" else a - b
    if isinstance(node, _expr.Bin) and node.op == "*":
        for num, other in ((node.left, node.right), (node.right, node.left)):
            if isinstance(num, _expr.Num) and float(num.value).is_integer():
                k = _coefficient(other, name)
                return None if k is None else int(num.value) * k
    return None


def _periodic_node(node, name) -> bool:
    """Whether `node` is a 2π-periodic function of `name` (free of it, or built from sin/cos/tan of
    integer multiples of it)."""
    if not any(n.name == name for n in _expr.names_in(node)):
        return True
    if isinstance(node, _expr.Call):
        if node.func in ("sin", "cos", "tan"):
            return _coefficient(node.args[0], name) is not None or _periodic_node(node.args[0], name)
        return all(_periodic_node(a, name) for a in node.args)
    if isinstance(node, _expr.Neg):
        return _periodic_node(node.arg, name)
    if isinstance(node, _expr.Bin):
        return _periodic_node(node.left, name) and _periodic_node(node.right, name)
    return False


def periodic_input(mech: Mechanism) -> bool:
    """Whether the loop equations are 2π-periodic in the input: an angle input that appears only as
    k·input + c (k an integer) in the angle of a polar vector, or inside sin/cos/tan of such (a
    revolute crank). A length input (a slider) never is."""
    if mech.input_kind != "angle":
        return False
    name = mech.input_name
    for _, terms in mech.loops:
        for t in terms:
            for node in t.nodes():
                if t.polar and node is t.angle and _coefficient(node, name) is not None:
                    continue
                if not _periodic_node(node, name):
                    return False
    return True


def reduce_angles(mech: Mechanism, q, bound: float):
    """`q` with every angle unknown larger than `bound` in magnitude reduced to (−π, π] (exactly:
    `remainder` is exact in floating point). Adding whole turns to an angle of magnitude A costs
    ≈ eps·A of accuracy, so a guess far beyond `bound` could not be reproduced to the tolerance."""
    two_pi = 2 * np.pi
    ang = np.array([k == "angle" for k in mech.unknown_kinds])
    if not ang.any():
        return q
    r = jnp.remainder(q, two_pi)
    r = jnp.where(r > np.pi, r - two_pi, r)
    return jnp.where(jnp.asarray(ang) & (jnp.abs(q) > bound), r, q)


class _Track(NamedTuple):
    """The continuation state of one design: the last (up to three) converged positions, newest
    first (`hq`, `hph`, `ng` of them valid), the circuit to keep (`sign_ref`: sign of det of each
    diagonal block of Φ_q; 0 = not known yet, any circuit), the code of the last position, and the
    guess of the file (`q_file`, a candidate of every re-assembly)."""

    hq: tuple
    hph: tuple
    ng: jax.Array
    sign_ref: jax.Array
    last: jax.Array
    q_file: jax.Array


def _circuit(mech: Mechanism, q, phi, p):
    """Sign of det of each diagonal block of Φ_q at (q, φ): the circuit (assembly branch) of q."""
    jac = jax.jacfwd(mech.residual)(q, phi, p)
    return _linear_solve(mech, signs=True)(jac, jnp.zeros_like(q))[2]


def _track_start(mech: Mechanism, q0, phi, p) -> _Track:
    """The state before the first position: nothing converged, the guess `q0` (holding at `phi`)
    selects the circuit: the sign of det of each block of Φ_q at the guess, or, when every block is
    a dyad, at the closed form on the branches nearest to the guess (`_dyads.solve_nearest`, as the
    closed-form path chooses them); 0 (any circuit) where that is singular."""
    dyads = _dyads.classify(mech)
    q_sel = q0 if dyads is None else _dyads.solve_nearest(mech, dyads, q0, phi, p)[0]
    sg = _circuit(mech, q_sel, phi, p)
    sg = jnp.where(jnp.isfinite(sg), sg, 0.0)
    return _Track((q0, q0, q0), (phi, phi, phi), jnp.zeros((), jnp.int32), sg,
                  jnp.asarray(RESULTS.cannot_assemble, jnp.int8), q0)


def _same_circuit(sg, sign_ref):
    return jnp.all((sg == sign_ref) | (sign_ref == 0))


def _deflated_newton(mech: Mechanism, q, phi, p, roots, active, unit, scale, max_steps):
    """Newton on the deflated residual M(q) = Φ(q) Π_i (1 / |(q − r_i) / unit|² + 1) over the
    `active` roots r_i (Farrell, Birkisson & Funke's deflation: M has the zeros of Φ except the
    r_i, so Newton from a guess near a known root finds another one), step-limited (0.5 rad, 0.5 ×
    the length scale). Zero iterations when no root is active. Returns q (not polished)."""
    dtype = jnp.result_type(q)
    n_active = jnp.sum(active.astype(jnp.int32))

    def m(x):
        d2 = jnp.sum(((x[None, :] - roots) / unit) ** 2, axis=1)
        fac = jnp.prod(jnp.where(active, 1.0 / jnp.maximum(d2, 1e-300) + 1.0, 1.0))
        return mech.residual(x, phi, p) * fac

    def body(st):
        k, x, _ = st
        val = m(x)
        jac = jax.jacfwd(m)(x)
        dx, _ = solve_small(jac, val)
        dqa = jnp.max(jnp.abs(dx) / unit)
        ok = jnp.all(jnp.isfinite(dx))
        dx = jnp.where(ok, dx * jnp.minimum(1.0, 0.5 / jnp.maximum(dqa, 1e-30)), 0.0)
        rn = jnp.max(jnp.abs(mech.residual(x - dx, phi, p)))
        return k + 1, x - dx, ~ok | (rn <= 1e-6 * scale)

    init = batched_like((jnp.zeros((), jnp.int32), q, n_active == 0), q, phi, p, roots, active, max_steps)
    out = jax.lax.while_loop(lambda st: (~st[2]) & (st[0] < max_steps), body, init)
    return out[1].astype(dtype)


def _reassemble(mech, opts, p, phi, st: _Track, tol, kw, active):
    """A position after one that did not assemble: a fresh assembly instead of an extrapolation
    across the gap, on the circuit `st.sign_ref` (each block's sign of det Φ_q: for a dyad, the
    side of its known vector that its first link lies on, the branch σ of `_dyads`).

    When every block is a dyad: the closed form on the branches of the last converged position,
    polished by step-limited Newton. Otherwise the candidates are the last converged q and the
    file's guess, each by step-limited Newton; a candidate that converges on another circuit is
    deflated (`_deflated_newton`) and the search goes on from the candidates with the roots found
    so far removed, up to twice the number of candidates in all. Returns `(q, rnorm, result,
    steps, signs)`; `max_steps` where only another circuit was found (the branch is kept, never
    switched). No iteration where not `active`."""
    dyads = _dyads.classify(mech)
    if dyads is not None:
        # every block a dyad: the closed form on the branches of the last converged position is
        # the position on its circuit (or there is none), so one Newton polish from it decides —
        # no search, no deflation (half the code of a continuation solve was this loop)
        _, _, _, sigma = _dyads.solve_nearest(mech, dyads, st.hq[0], st.hph[0], p)
        q_cf, _, _, _ = _dyads.solve(mech, dyads, sigma, st.hq[0], phi, p)
        q, rn, code, k, sg = newton(mech, q_cf, phi, p, tol=jnp.where(active, tol, jnp.nan), limit_step=True,
                                    max_steps=opts.max_steps_first, **kw)
        conv = code == RESULTS.converged
        other = conv & ~_same_circuit(sg, st.sign_ref)
        return q, rn, jnp.where(other, jnp.asarray(RESULTS.max_steps, jnp.int8), code), k, sg
    dtype = jnp.result_type(st.hq[0])
    scale = mech.length_scale(p)
    unit = _units(mech, scale, dtype)
    cands = [st.hq[0], st.q_file]
    C = jnp.stack(cands)
    nc = len(cands)
    T = 2 * nc
    n = C.shape[1]

    def cond(s):
        t, done, nroots = s[0], s[1], s[4]
        return (~done) & ((t < nc) | ((nroots > 0) & (t < T)))

    def body(s):
        t, _, out, roots, nroots, ksum = s
        live = jnp.arange(T) < nroots
        i = t % nc
        guess = C[i]
        plain = nroots == 0
        # a plain try from the same guess as the first one would only repeat it
        skip = plain & (i > 0) & jnp.all(guess == C[0])
        qd = _deflated_newton(mech, guess, phi, p, roots, live, unit, scale, opts.max_steps_first)
        q, rn, code, k, sg = newton(mech, qd, phi, p, tol=jnp.where(skip, jnp.nan, tol), limit_step=plain,
                                    max_steps=jnp.where(plain, opts.max_steps_first, opts.max_steps), **kw)
        ksum = ksum + k
        conv = code == RESULTS.converged
        ok = (code == RESULTS.singular) | (conv & _same_circuit(sg, st.sign_ref))
        other = conv & ~ok
        # what to report if nothing better is found: a position on another circuit (`max_steps`)
        # over a failure
        better = ~skip & (ok | (other & (out[2] != RESULTS.max_steps)) | (t == 0))
        rep = (q, rn, jnp.where(other, jnp.asarray(RESULTS.max_steps, jnp.int8), code), ksum, sg)
        out = jax.tree_util.tree_map(lambda a, b: jnp.where(better, a, b), rep, out)
        out = out[:3] + (ksum,) + out[4:]
        roots = jnp.where((jnp.arange(T)[:, None] == nroots) & other, q[None, :], roots)
        nroots = nroots + other.astype(jnp.int32)
        return t + 1, ok, out, roots, nroots, ksum

    zero = jnp.zeros((), jnp.int32)
    out0 = (st.hq[0], jnp.asarray(jnp.inf, dtype), jnp.asarray(RESULTS.cannot_assemble, jnp.int8), zero,
            st.sign_ref)
    init = batched_like((zero, ~jnp.asarray(active), out0, jnp.zeros((T, n), dtype), zero, zero), st, phi, p, tol,
                        active)
    return jax.lax.while_loop(cond, body, init)[2]


def _advance(mech, opts, p, tol, kw, st: _Track, phi):
    """One position of the continuation: `(state, (q, rnorm, result, steps))`.

    After a converged or singular position: Newton from the Lagrange extrapolation of the last
    converged positions. The sign of det of each diagonal block of Φ_q (each dyad's circuit) is
    compared with the last converged position: a change without a singular or failed position in
    between means the step jumped to another circuit, and the position is re-solved in sub-steps
    from the last converged position (half the step, halved again after every failure, each
    sub-step required to converge on the same circuit; at most `REFINE_TRIES` Newton solves, else
    the position is reported `max_steps`: refine the input step). The attempts are one
    `while_loop` around the single Newton solve, whose trip count is 1 where nothing flipped: under
    `vmap` the sub-steps cost nothing unless some lane needs them (`lax.cond` would evaluate both
    branches).

    After a position that did not assemble (and at the first position), or where this
    continuation step failed (next to a toggle the predictor may be far off): a re-assembly on the
    circuit kept (`_reassemble`), so that every assemblable window of the input is found on the
    branch of the guess, as the closed form finds it. The history restarts there."""
    hist_q, hist_phi, n_good, sign_ref, last = st.hq, st.hph, st.ng, st.sign_ref, st.last
    restart = (last != RESULTS.converged) & (last != RESULTS.singular)
    check = last == RESULTS.converged
    zero = jnp.zeros((), jnp.int32)
    dtype = jnp.result_type(phi)

    def cond(s):
        return (~s[6]) & (s[5] <= REFINE_TRIES)

    def body(s):
        hq, hph, ng, phi_cur, h, tries, done, out, ksum = s
        first_try = tries == 0
        last_sub = jnp.abs(phi - phi_cur) <= 1.000001 * jnp.abs(h)
        phi_try = jnp.where(first_try | last_sub, phi, phi_cur + h)
        guess = _extrapolate(hq, hph, ng, phi_try, opts.predictor_order)
        q, rn, code, k, sg = newton(mech, guess, phi_try, p, tol=tol, limit_step=False,
                                    max_steps=opts.max_steps, **kw)
        ksum = ksum + k
        conv = code == RESULTS.converged
        same = _same_circuit(sg, sign_ref)
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

    out0 = (hist_q[0], jnp.asarray(jnp.inf, dtype), jnp.asarray(RESULTS.max_steps, jnp.int8), zero, sign_ref)
    init = batched_like((hist_q, hist_phi, n_good, hist_phi[0], jnp.zeros((), dtype), zero, restart, out0, zero),
                        st, phi, p, tol)
    cont = jax.lax.while_loop(cond, body, init)[7]
    # where the continuation failed (next to a toggle the predictor can be far off) or after a
    # failed position: re-assemble
    failed = ~restart & (cont[2] != RESULTS.converged) & (cont[2] != RESULTS.singular)
    re = _reassemble(mech, opts, p, phi, st, tol, kw, restart | failed)
    use = restart | (failed & ((re[2] == RESULTS.converged) | (re[2] == RESULTS.singular)))
    q, rn, code, k, sg = jax.tree_util.tree_map(lambda a, b: jnp.where(use, a, b), re, cont)
    k = jnp.where(failed, re[3] + cont[3], k)
    good = code == RESULTS.converged
    # a re-assembled position starts a new history (no extrapolation across the gap)
    hq = tuple(jnp.where(use & good, q, h) for h in hist_q)
    hph = tuple(jnp.where(use & good, phi, h) for h in hist_phi)
    ng = jnp.where(use & good, 0, n_good)
    new = _Track(_push(hq, q, good), _push(hph, phi, good), ng + good.astype(jnp.int32),
                 jnp.where(good, sg, sign_ref), code, st.q_file)
    return new, (q, rn, code, k)


def _lead_in_inputs(mech: Mechanism, p, phi_ref, phi0):
    """The inputs of the lead-in from `phi_ref` (where the guesses hold) to `phi0`: `(start, h, n)`,
    positions start + k h, k = 0 … n−1. For an input the loops are 2π-periodic in
    (`periodic_input`), the way is reduced to at most half a revolution: `start` ≡ `phi_ref` (mod
    2π) lies within π of `phi0`. |h| ≤ 5° for an angle, ≤ 5 % of the length scale for a length, and
    n ≤ `MAX_LEAD_IN` (a longer way takes longer steps, which may fail: never a hang). A
    non-finite way has no steps."""
    dtype = jnp.result_type(phi0)
    gap = phi0 - phi_ref
    if periodic_input(mech):
        two_pi = 2 * np.pi
        r = jnp.remainder(gap, two_pi)  # exact
        gap = jnp.where(r > np.pi, r - two_pi, r)
        max_step = jnp.asarray(np.deg2rad(5.0), dtype)
    elif mech.input_kind == "length":
        max_step = 0.05 * mech.length_scale(p)
    else:
        max_step = jnp.asarray(np.deg2rad(5.0), dtype)
    steps = jnp.ceil(jnp.abs(gap) / max_step)
    n = jnp.where(jnp.isfinite(steps), jnp.minimum(steps, MAX_LEAD_IN), 0).astype(jnp.int32)
    h = jnp.where(n > 0, gap / jnp.maximum(n, 1).astype(dtype), 0.0)
    return phi0 - gap, h, n


def _smooth_sides(mech: Mechanism, reference, p, phis, phi_ref, tol, thr):
    """(N, D) the sides of one design's dyads at every position of the smooth continuation from
    the closed form's branches `reference` (`_closed_form_reference`) at `phi_ref`, where the guess
    selected them: flipped at each change point located between two inputs
    (`branch_points.smooth_sides`)."""
    dyads = _dyads.classify(mech)
    sigma, q_ref, _ = reference
    return _branch_points.smooth_sides(mech, dyads, sigma, q_ref, phis, phi_ref, p, tol, thr)


def _continuation_smooth(mech: Mechanism, opts: NewtonOptions, P, phis, Q0, phi_ref, phi0, tol, thr, ax):
    """With `change_points="smooth"` (every block a dyad): `(flips, q_start)`; else None.
    `flips` (B, N, blocks) ±1 is −1 where the circuit to keep flips between positions k − 1 and k
    (a change point of that dyad lies between them: the sides of the closed form's smooth
    continuation from where the guess holds, `_smooth_sides`, differ); `q_start` (B, n) the closed
    form at the first input on those sides, the continuation's start (instead of a lead-in, which
    would keep the circuit of the guess through a change point before the first input)."""
    if opts.change_points != "smooth" or _dyads.classify(mech) is None:
        return None
    dyads = _dyads.classify(mech)
    ref = phi0 if phi_ref is None else phi_ref
    trig_p = _dyads.parameter_trig(mech, P)
    reference = jax.vmap(lambda p, q0, t, tp, r: _closed_form_reference(mech, p, q0, t, tp, r))(
        P, Q0, tol, trig_p, ref)
    sides = jax.vmap(lambda p, ph, ref_, r, t: _smooth_sides(mech, ref_, p, ph, r, t, thr),
                     in_axes=(0, ax, 0, 0, 0))(P, phis, reference, ref, tol)
    q_start = jax.vmap(lambda p, sg, q0, f: _dyads.solve(mech, dyads, sg, q0, f, p)[0])(P, sides[:, 0], Q0, phi0)
    flips = jnp.concatenate([jnp.ones_like(sides[:, :1]), sides[:, 1:] * sides[:, :-1]], axis=1)
    return flips, jnp.where(jnp.all(jnp.isfinite(q_start), axis=1, keepdims=True), q_start, Q0)


def _continuation_one(mech, opts, p, phis, q0, phi_ref, tol, kw, flips=None):
    """Newton with continuation along `phis` for one design from its guess `q0` (holding at
    `phi_ref`, or at phis[0] when `phi_ref` is None): the lead-in (`_lead_in_inputs`) and then
    every position, each by `_advance`. Returns `(q, rnorm, result, steps)` of the positions.
    `flips` (N, blocks) ±1: the circuit kept is multiplied by it before position k (the smooth
    continuation through a change point between k − 1 and k, `_continuation_smooth`).

    The lead-in and the positions are one loop over n + N inputs (the first n of the lead-in,
    their results not kept), so that `_advance` — four nested loops — is traced and compiled
    once: two copies doubled the time to compile a continuation solve."""
    def flipped(track, i):
        if flips is None:
            return track
        return track._replace(sign_ref=track.sign_ref * flips[i].astype(track.sign_ref.dtype))

    if phi_ref is None:
        st = batched_like(_track_start(mech, q0, phis[0], p), q0, p, tol, phis)
        idx = jnp.arange(phis.shape[0])
        return jax.lax.scan(lambda s, x: _advance(mech, opts, p, tol, kw, flipped(s, x[1]), x[0]), st, (phis, idx))[1]
    start, h, n = _lead_in_inputs(mech, p, phi_ref, phis[0])
    dtype = jnp.result_type(phis)
    N = phis.shape[0]
    st = _track_start(mech, q0, start, p)
    bufs = (jnp.zeros((N,) + q0.shape, q0.dtype), jnp.zeros((N,), dtype), jnp.zeros((N,), jnp.int8),
            jnp.zeros((N,), jnp.int32))

    def body(s):
        k, track, bufs = s
        lead = k < n
        i = jnp.clip(k - n, 0, N - 1)
        phi = jnp.where(lead, start + k.astype(dtype) * h, phis[i])
        if flips is not None:
            track = track._replace(sign_ref=jnp.where(lead, track.sign_ref, flipped(track, i).sign_ref))
        track, out = _advance(mech, opts, p, tol, kw, track, phi)
        bufs = tuple(b.at[i].set(jnp.where(lead, b[i], o.astype(b.dtype))) for b, o in zip(bufs, out))
        return k + 1, track, bufs

    init = batched_like((jnp.zeros((), jnp.int32), st, bufs), q0, p, tol, h, start, phis)
    return jax.lax.while_loop(lambda s: s[0] < n + N, body, init)[2]


def _lead_in(mech: Mechanism, opts: NewtonOptions, p, phi_a, phi_b, q0, tol, kw):
    """The configuration at `phi_b` of one design from the guess `q0` holding at `phi_a` (for
    `"independent"`): the continuation of the lead-in (`_lead_in_inputs`). Returns the last
    converged q (q0 if none)."""
    start, h, n = _lead_in_inputs(mech, p, phi_a, phi_b)
    dtype = jnp.result_type(q0)

    def lead(s):
        k, track = s
        return k + 1, _advance(mech, opts, p, tol, kw, track, start + k.astype(dtype) * h)[0]

    init = (jnp.zeros((), jnp.int32), _track_start(mech, q0, start, p))
    st = jax.lax.while_loop(lambda s: s[0] < n, lead, batched_like(init, init, p, tol, h, start))[1]
    return st.hq[0]


def _solve_batch_impl(mech: Mechanism, opts: NewtonOptions, points: bool, P, phis, Q0, phi_ref,
                      trig: bool = False):
    """P (B, P), phis (N,) shared by all designs or (B, N), Q0 (B, n) holding at the inputs
    `phi_ref` (B,) (None: at the first input) -> q (B, N, n), rnorm, result, steps (B, N), and the
    points (B, N, n_points, 2) if `points` (else None). With `trig`, also the (cos, sin) the
    derivative needs (`_Trig`), computed once and stored."""
    dtype = jnp.result_type(Q0)
    B = P.shape[0]
    shared = phis.ndim == 1
    ax = None if shared else 0  # vmap axis of phis over the designs
    rtol = opts.rtol if opts.rtol is not None else default_rtol(dtype)
    tol = rtol * jax.vmap(mech.length_scale)(P)
    thr = singular_threshold(opts, dtype)
    method = method_for(mech, opts)
    phi0 = jnp.broadcast_to(phis[0], (B,)) if shared else phis[:, 0]
    # a guess angle so large that adding whole turns to it loses the tolerance is reduced first
    Q0 = reduce_angles(mech, Q0, rtol / (4 * float(np.finfo(dtype).eps)))
    ref_finite = jnp.ones((B,), bool) if phi_ref is None else jnp.isfinite(phi_ref)
    if method == "closed_form":
        # every (design, input) pair is independent, on the branches (circuits) of the guess at the
        # reference input. The trigonometry of the inputs (N values, `angles.sincos`), of the angle
        # parameters (B) and each design's branches are computed once and stored, not inside every
        # fused kernel (for one design XLA fused the branch selection's sines and cosines into
        # every per-position kernel: one design × 360 positions took 90 µs, now ≈ 50)
        ref = phi0 if phi_ref is None else jnp.where(ref_finite, phi_ref, 0.0)
        tol = jnp.where(ref_finite, tol, jnp.nan)
        # the inputs' trigonometry of the whole batch at once (`sincos` chooses its method from the
        # largest |φ| of the array it is given)
        trig_in = materialize(_dyads.input_trig(mech, phis))

        def designs(P, phis, Q0, tol, ref, trig_in):
            trig_p = _dyads.parameter_trig(mech, P)
            reference = jax.vmap(lambda p, q0, t, tp, r: _closed_form_reference(mech, p, q0, t, tp, r))(
                P, Q0, tol, trig_p, ref)
            if opts.change_points == "smooth":  # the sides of every position, flipped at change points
                sides = jax.vmap(lambda p, ph, ref_, r, t: _smooth_sides(mech, ref_, p, ph, r, t, thr),
                                 in_axes=(0, ax, 0, 0, 0))(P, phis, reference, ref, tol)
                reference = (sides,) + tuple(reference[1:])
            trig_p, reference = materialize((trig_p, reference))
            out = jax.vmap(
                lambda p, ph, t, ti, tp, r: _closed_form_path(mech, p, ph, t, ti, tp, thr, r, points, trig),
                in_axes=(0, ax, 0, ax, 0, 0))(P, phis, tol, trig_in, trig_p, reference)
            if trig:
                return out, trig_p
            q, rn, code, _, pts = out
            code, pts = _finalize(points, code, pts)
            return q, rn, code, pts

        if not trig:
            # a batch on the CPU in chunks of designs (`_design_chunk`): each chunk's intermediate
            # arrays (every value XLA stores for several kernels: the divisions of each atan2,
            # the square roots, …) stay in the cache, where the whole batch's went to memory and
            # back (the Strider, 1000 designs × 360 positions, 97 -> 45 ms; the feed 2×); the
            # same kernels, the same answers bit for bit (tests/test_strider.py)
            args = (P, phis, Q0, tol, ref, trig_in)
            axes = (0, ax, 0, 0, 0, ax)
            chunk = _design_chunk(B, phis.shape[-1], len(_dyads.classify(mech) or ()))
            q, rn, code, pts = _map_designs(designs, args, axes, chunk)
            return q, rn, code, jnp.zeros(code.shape, jnp.int32), pts
        out, trig_p = designs(P, phis, Q0, tol, ref, trig_in)
        # for the derivative: every output stored (`materialize`) as one (B, N) array per value,
        # so that no kernel of the derivative recomputes the closed form and each reads only the
        # values it uses, contiguous (a packed (B, N, m) array is read whole by every kernel)
        code, rn, cols, pts, cs = materialize(out)
        q = jnp.stack(cols, -1)
        return (q, rn, code, jnp.zeros(code.shape, jnp.int32), pts, _Trig(trig_in, trig_p, cs))
    # Newton: a design whose tolerance is not finite (a NaN or infinite length, even one that only
    # a point uses), whose guess is not finite (it selects no branch) or whose guess holds at a
    # non-finite input is `nonfinite` at every position, without iterating (a NaN tolerance makes
    # `newton` stop at once)
    bad = ~jnp.isfinite(tol) | ~jnp.all(jnp.isfinite(Q0), axis=1) | ~ref_finite
    tol = jnp.where(bad, jnp.nan, tol)
    Q0 = jnp.where(bad[:, None], 0.0, Q0)
    phi_ref = None if phi_ref is None else jnp.where(ref_finite, phi_ref, phi0)
    trig_p = materialize(_dyads.parameter_trig(mech, P))
    kw_of = lambda tp: _newton_kw(rtol, thr, tp)  # noqa: E731
    if method == "independent":
        if phi_ref is not None:  # continue from where the guesses hold to the first input
            Q0 = jax.vmap(lambda p, a, b, q0, t, tp: _lead_in(mech, opts, p, a, b, q0, t, kw_of(tp)))(
                P, phi_ref, phi0, Q0, tol, trig_p)
        out = jax.vmap(lambda p, ph, q0, t, tp: jax.vmap(
            lambda f: newton(mech, q0, f, p, tol=t, max_steps=opts.max_steps_first, limit_step=True,
                             **kw_of(tp))[:4])(ph),
            in_axes=(0, ax, 0, 0, 0))(P, phis, Q0, tol, trig_p)
    else:
        smooth = _continuation_smooth(mech, opts, P, phis, Q0, phi_ref, phi0, tol, thr, ax)
        flips = None
        if smooth is not None:  # from the smooth continuation's closed form at the first input
            flips, Q0 = smooth
            phi_ref = None
        if phi_ref is None:
            out = jax.vmap(lambda p, ph, q0, t, tp, fl: _continuation_one(mech, opts, p, ph, q0, None, t, kw_of(tp),
                                                                          fl),
                           in_axes=(0, ax, 0, 0, 0, 0))(P, phis, Q0, tol, trig_p, flips)
        else:
            out = jax.vmap(lambda p, ph, q0, r, t, tp, fl: _continuation_one(mech, opts, p, ph, q0, r, t,
                                                                             kw_of(tp), fl),
                           in_axes=(0, ax, 0, 0, 0, 0, 0))(P, phis, Q0, phi_ref, tol, trig_p, flips)
    out = _check_residual(mech, P, phis, out, tol, rtol, dtype)
    if points:
        # the points, with the sines and cosines of the angle parameters known
        pts = jax.vmap(jax.vmap(lambda q, phi, p, tp: mech.point_positions(q, phi, p, tp),
                                in_axes=(0, 0, None, None)), in_axes=(0, ax, 0, 0))(out[0], phis, P, trig_p)
    out = out + ((pts,) if points else (None,))
    if not trig:
        q, rn, code, k, pts = out
        code, pts = _finalize(points, code, pts)
        return q, rn, code, k, pts
    qa = [out[0][..., i] for i, k in enumerate(mech.unknown_kinds) if k == "angle"]
    trig_in, trig_q = materialize((_dyads.input_trig(mech, phis), (tuple(jnp.cos(a) for a in qa),
                                                                   tuple(jnp.sin(a) for a in qa))))
    return out + (_Trig(trig_in, trig_p, trig_q),)


#: positions per chunk of a closed-form batch on the CPU (`_design_chunk`): its intermediate arrays
#: (≈ 70 of 8 bytes per position for the Strider) stay within the cache (measured on the Strider:
#: 8192 to 32768 alike). 0: never chunk
CHUNK_POSITIONS = 8192


def _design_chunk(B: int, N: int, n_dyads: int = 2) -> int:
    """Designs per chunk of a closed-form batch of B designs × N positions, or 0 for one piece:
    about `CHUNK_POSITIONS` positions, a divisor of B where one is near (no padding), at least 2
    designs (XLA fuses a batch of one design differently: other kernels, other roundings). Only
    for two dyads or more (one dyad's few intermediate arrays cost less than the loop: the
    four-bar's batch 8 % slower in chunks), and on a single CPU device (a GPU wants the whole
    batch, and a batch sharded over several devices is split by them)."""
    if (not CHUNK_POSITIONS or n_dyads < 2 or jax.default_backend() != "cpu"
            or jax.device_count() != 1):
        return 0
    target = max(2, CHUNK_POSITIONS // max(N, 1))
    if B < 2 * target:
        return 0
    for c in range(target, max(2, target // 2) - 1, -1):
        if B % c == 0:
            return c
    return target


def _map_designs(fn, args, axes, chunk: int):
    """`fn(*args)` over the leading (design) axis of the `args` (pytrees) whose axis is 0 (the
    others are shared), `chunk` designs at a time (`lax.map`; 0: all at once). The last chunk is
    padded by repeating the last design, and the results cut back to the batch."""
    if not chunk:
        return fn(*args)
    B = jax.tree_util.tree_leaves([a for a, x in zip(args, axes) if x == 0])[0].shape[0]
    n = -(-B // chunk)
    pad = n * chunk - B

    def split(a):
        if pad:
            a = jnp.concatenate([a, jnp.broadcast_to(a[-1:], (pad,) + a.shape[1:])])
        return a.reshape((n, chunk) + a.shape[1:])

    batched = [jax.tree_util.tree_map(split, a) for a, x in zip(args, axes) if x == 0]

    def one(xs):
        # the chunk's inputs copied first: read through the loop's slice instead, every kernel of
        # the chunk indexes them afresh, which XLA does not vectorize (and fuses differently: the
        # four-bar's points changed in the last bit, and took 2.5× as long)
        xs = materialize(xs)
        it = iter(xs)
        return fn(*(next(it) if x == 0 else a for a, x in zip(args, axes)))

    out = jax.lax.map(one, batched)
    return jax.tree_util.tree_map(lambda o: o.reshape((n * chunk,) + o.shape[2:])[:B], out)


def _finalize(points: bool, code, pts):
    """Finiteness is part of convergence: a position whose points are not finite (an expression
    like asin(2) in [points]) is `nonfinite`, never converged with NaN points; the points are NaN
    where the position did not assemble (`_mask_points`)."""
    if not points:
        return code, pts
    bad = ~jnp.all(jnp.isfinite(pts), axis=(-2, -1))
    code = jnp.where(bad & ((code == RESULTS.converged) | (code == RESULTS.singular)),
                     jnp.int8(RESULTS.nonfinite), code)
    return code, _mask_points(pts, code)


def _check_residual(mech, P, phis, out, tol, rtol, dtype):
    """The residual at the returned q, evaluated afresh (with its own sines and cosines),
    independently of Newton's stopping rule: an assembled position whose loops do not close there
    to twice its tolerance (rtol × scale; max(rtol, √eps) × scale for `singular`) is `max_steps`
    (`nonfinite` if not finite), with that residual."""
    q, rn, code, k = out
    ax = None if phis.ndim == 1 else 0
    r = jax.vmap(jax.vmap(lambda qq, ph, p: jnp.max(jnp.abs(mech.residual(qq, ph, p))), in_axes=(0, 0, None)),
                 in_axes=(0, ax, 0))(q, phis, P)
    loose = max(1.0, float(np.sqrt(np.finfo(dtype).eps)) / rtol)
    conv, sing = code == RESULTS.converged, code == RESULTS.singular
    limit = 2.0 * tol[:, None] * jnp.where(sing, loose, 1.0)
    bad = (conv | sing) & ~(r <= limit)
    code = jnp.where(bad, jnp.where(jnp.isfinite(r), RESULTS.max_steps, RESULTS.nonfinite).astype(code.dtype), code)
    return q, jnp.where(bad, r, rn), code, k


class _Trig(NamedTuple):
    """The (cos, sin) pairs the derivative of a batched solve needs, as the forward computed them:
    of the input (`inputs`, keyed by its name, shaped as the inputs; empty for a length input), of
    the angle parameters (`params`, keyed by name, (B,)) and of the solved angle unknowns
    (`unknowns`: (cos tuple, sin tuple), one (B, N) array per angle unknown, in the order of
    `mech.unknown_names`)."""

    inputs: dict
    params: dict
    unknowns: tuple


def _env_known(mech: Mechanism, q, phi, p, t_in, t_p, t_q):
    """`(env, trig)` for `term_vector`: the values of the names (the unknowns `q` and the
    parameters `p` tuples of scalars) and their (cos, sin), given (no trigonometry evaluated) and
    differentiable in q, φ, p through `_known_trig` (derivative (−sin, cos) d(angle))."""
    env = dict(zip(mech.parameter_names, p))
    env.update(zip(mech.unknown_names, q))
    env[mech.input_name] = phi
    trig = {n: _known_trig(phi, c, s) for n, (c, s) in t_in.items()}
    trig.update({n: _known_trig(env[n], c, s) for n, (c, s) in t_p.items()})
    ang = [n for n, k in zip(mech.unknown_names, mech.unknown_kinds) if k == "angle"]
    trig.update({n: _known_trig(env[n], t_q[0][j], t_q[1][j]) for j, n in enumerate(ang)})
    return env, trig


def _sum_terms(mech: Mechanism, terms, env, trig, dtype):
    """(x, y) of a sum of terms (a loop, a point), as two scalars."""
    sx, sy = 0.0, 0.0
    for term in terms:
        x, y = mech.term_vector(term, env, trig)
        sx, sy = sx + x, sy + y
    return tuple(jnp.broadcast_to(jnp.asarray(v, dtype), ()) for v in (sx, sy))


def _residual_known(mech: Mechanism, env, trig, dtype):
    """Φ (every term, as `mech.residual`) from `_env_known`, as a tuple of scalars."""
    return tuple(v for _, terms in mech.loops for v in _sum_terms(mech, terms, env, trig, dtype))


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1, 2))
def _solve_batch(structure, opts: NewtonOptions, points: bool, P, phis, Q0, phi_ref):
    """The differentiable batched solve: (P (B,P), phis (N,) or (B,N), Q0 (B,n), phi_ref (B,) or
    None) -> (q, rnorm, result, steps, points or None), the points checked and masked
    (`_finalize`). `structure`, `opts`, `points` are static."""
    return _solve_batch_impl(structure, opts, points, P, phis, Q0, phi_ref)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1, 2))
def _solve_batch_trig(structure, opts: NewtonOptions, points: bool, P, phis, Q0, phi_ref):
    """`_solve_batch` (its points not yet checked nor masked: its JVP rule does it) and the
    (cos, sin) of its angles (`_Trig`): the primal of its derivative."""
    return _solve_batch_impl(structure, opts, points, P, phis, Q0, phi_ref, trig=True)


def _implicit_tangents(mech: Mechanism, points: bool, primals, tangents, out):
    """Implicit differentiation at every converged position (zero elsewhere):

        Φ_q dq = −(Φ_p dp + Φ_φ dφ),      d(point) = P_q dq + P_p dp + P_φ dφ,

    with Φ_q, the right-hand side and the points' derivatives evaluated from the (cos, sin) the
    forward solve stored (`_Trig`: no trigonometry here, only products and sums), and Φ_q solved
    by forward substitution over its diagonal blocks (Cramer on the 2×2 block of each dyad,
    `_linalg.solve_block_lower_scalars`). Per position everything is a scalar (the unknowns, the
    parameters, the columns of Φ_q): no array is assembled or indexed there, so that the transpose
    (reverse mode) is as elementwise as the tangent. The guesses and the reference input select a
    branch and carry no derivative."""
    P, phis, _, _ = primals
    dP, dphis = (None if isinstance(t, SymbolicZero) else t for t in tangents[:2])
    q, _, code, _, _, tr = out
    ax = None if phis.ndim == 1 else 0
    B, N, n = q.shape
    dtype = q.dtype
    order = _structure.blocks(mech)
    blocks = tuple((tuple(r for li in loops for r in (2 * li, 2 * li + 1)), cols) for loops, cols in order)
    if len(blocks) == 1 and len(blocks[0][1]) > 2:
        blocks = ((tuple(range(2 * len(mech.loops))), tuple(range(n))),)
    # the parameters as separate scalars, each tangent broadcast to the positions on its own: the
    # transpose is then one reduction over the positions per parameter, fused with the kernel that
    # computes it (a (B, N, P) broadcast would make it write a stack of every position's
    # cotangents and sum that: 0.5 -> 0.23 s of a gradient at 1e5 designs)
    Ps = tuple(P[:, i] for i in range(P.shape[1]))
    dPN = None if dP is None else tuple(jnp.broadcast_to(dP[:, i, None], (B, N)) for i in range(P.shape[1]))
    dphiN = None if dphis is None else jnp.broadcast_to(dphis, (B, N))
    Qs = tuple(jnp.unstack(q, axis=-1))

    def one(p, dp, qk, phik, dphik, ok, t_in, t_p, t_q):

        def res(qq, pp, ph):
            return _residual_known(mech, *_env_known(mech, qq, ph, pp, t_in, t_p, t_q), dtype)

        # the columns of Φ_q, one forward derivative per unknown (only the entries that depend on it)
        one_ = jnp.ones((), dtype)
        cols = [jax.jvp(lambda x, j=j: res(qk[:j] + (x,) + qk[j + 1:], p, phik), (qk[j],), (one_,))[1]
                for j in range(n)]
        if dp is None and dphik is None:
            rhs = tuple(jnp.zeros((), dtype) for _ in range(2 * len(mech.loops)))
        elif dphik is None:
            rhs = jax.jvp(lambda pp: res(qk, pp, phik), (p,), (dp,))[1]
        elif dp is None:
            rhs = jax.jvp(lambda ph: res(qk, p, ph), (phik,), (dphik,))[1]
        else:
            rhs = jax.jvp(lambda pp, ph: res(qk, pp, ph), (p, phik), (dp, dphik))[1]
        # where not converged the sensitivity is undefined: the result is zeroed, and the diagonal
        # blocks are made regular there (`ok`), so that neither the JVP nor its transpose (grad)
        # produces NaN
        dq = solve_block_lower_scalars(lambda r, c: cols[c][r], rhs, blocks, ok)
        dq = tuple(jnp.where(ok, -v, 0.0) for v in dq)
        if not points:
            return jnp.stack(dq), None

        def pts(qq, pp, ph):
            env, trig = _env_known(mech, qq, ph, pp, t_in, t_p, t_q)
            return tuple(_sum_terms(mech, terms, env, trig, dtype) for _, terms in mech.points)
        prim = (qk, p) + (() if dphik is None else (phik,))
        dpp = dp if dp is not None else tuple(jnp.zeros((), dtype) for _ in p)
        tang = (dq, dpp) + (() if dphik is None else (dphik,))
        dxy = jax.jvp(lambda qq, pp, *ph: pts(qq, pp, ph[0] if ph else phik), prim, tang)[1]
        dpts = jnp.stack([jnp.stack(v) for v in dxy]) if dxy else jnp.zeros((0, 2), dtype)
        return jnp.stack(dq), dpts

    per_pos = jax.vmap(one, in_axes=(None, 0, 0, 0, 0, 0, 0, None, 0))
    return jax.vmap(per_pos, in_axes=(0, 0, 0, ax, 0, 0, ax, 0, 0))(
        Ps, dPN, Qs, phis, dphiN, code == RESULTS.converged, tr.inputs, tr.params, tr.unknowns)


def _solve_batch_jvp(structure, opts, points, primals, tangents):
    out = _solve_batch_trig(structure, opts, points, *primals)
    dq, dpts = _implicit_tangents(structure, points, primals, tangents, out)
    q, rn, code, k, pts, _ = out
    code, pts = _finalize(points, code, pts)
    if points:  # the points' mask (`_finalize`) on their tangent too
        dpts = jnp.where(((code == RESULTS.converged) | (code == RESULTS.singular))[..., None, None], dpts, 0.0)
    return (q, rn, code, k, pts), (dq, jnp.zeros_like(rn), _float0(code), _float0(k), dpts)


def _solve_batch_trig_jvp(structure, opts, points, primals, tangents):
    out = _solve_batch_trig(structure, opts, points, *primals)
    dq, dpts = _implicit_tangents(structure, points, primals, tangents, out)
    q, rn, code, k, _, tr = out
    mech = structure
    dP, dphis = (jnp.zeros_like(x) if isinstance(t, SymbolicZero) else t for x, t in zip(primals[:2], tangents[:2]))

    def rot(cs, dx):
        c, s = cs
        return -s * dx, c * dx

    ang = [i for i, kd in enumerate(mech.unknown_kinds) if kd == "angle"]
    dtr = _Trig({n: rot(cs, dphis) for n, cs in tr.inputs.items()},
                {n: rot(cs, dP[:, mech.parameter_names.index(n)]) for n, cs in tr.params.items()},
                tuple(zip(*(rot((c, s), dq[..., i]) for c, s, i in zip(*tr.unknowns, ang)))) if ang
                else ((), ()))
    return out, (dq, jnp.zeros_like(rn), _float0(code), _float0(k), dpts, dtr)


_solve_batch.defjvp(_solve_batch_jvp, symbolic_zeros=True)
_solve_batch_trig.defjvp(_solve_batch_trig_jvp, symbolic_zeros=True)


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
    # (the points' mask and their finiteness check are part of `_solve_batch`: `_finalize`)
    q, rn, code, k, pts = _solve_batch(structure, options, points, P, phis, Q0, phi_ref)
    sol = Solution(q=q, points=pts, result=code, stats=SolveStats(residual=rn, steps=k))
    return sol if batch else jax.tree_util.tree_map(lambda x: x[0], sol)


_warned_float32 = False


def _warn_if_float32(p) -> None:
    """Warn once when float64 numbers (the file's, or numpy float64) meet JAX's float32 default."""
    global _warned_float32
    if _warned_float32 or jax.config.read("jax_enable_x64"):
        return
    # a traced `p` has a dtype; only a Python or numpy value is converted to read it (never a tracer)
    dtype = getattr(p, "dtype", None)
    if p is None or np.result_type(np.asarray(p).dtype if dtype is None else dtype) == np.float64:
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
          points: bool = True, max_bytes: int | None = None) -> Solution:
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
    - `max_bytes`: the device memory a batch may use (default: a quarter of the device's memory,
      of the available host memory on a CPU). A larger batch is solved in chunks of designs that
      fit, each copied to the host as it is done: the result is then numpy arrays, identical to
      the unchunked solve.

    **Returns:** a `Solution` (q, points, result, stats) with leading axes (N,) or (B, N).

    One jitted function (compiled once per shape, dtype and options); the same under an outer
    `jax.jit`, `vmap` or `grad` (exact derivatives by implicit differentiation; no chunking there:
    the caller's trace decides). The dtype is that of `p` (float64 needs
    `jax.config.update("jax_enable_x64", True)`). A batch placed on several devices
    (`jax.device_put(p, NamedSharding(...))`) is solved where it lies.
    """
    _warn_if_float32(p)
    chunk = _chunk_designs(mech, phis, p, points, max_bytes)
    if chunk is None:
        return _solve_jit(mech, phis, p, q0, options, points)
    return _solve_chunked(mech, phis, p, q0, options, points, chunk)


# device memory of one solved position, per value it returns (q, points, residual, code, steps):
# the measured peak of a closed-form batch is ≈ 11 float64 values per returned value (the feed
# six-bar: 88 bytes per position for 8 values); 16 leaves a margin
_BYTES_PER_VALUE = 16 * 8


def memory_budget() -> int:
    """Bytes a solve may use: a quarter of the default device's memory limit, or on a CPU a
    quarter of the available host memory (at least 64 MiB)."""
    dev = jax.local_devices()[0]
    try:
        return int(dev.memory_stats()["bytes_limit"]) // 4
    except Exception:  # noqa: BLE001 (no memory statistics: the CPU)
        pass
    try:
        avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        avail = 8 << 30
    return max(64 << 20, int(avail) // 4)


def _chunk_designs(mech, phis, p, points: bool, max_bytes) -> int | None:
    """Designs per chunk when the batch needs more than `max_bytes`, else None (one call)."""
    if p is None or isinstance(p, jax.core.Tracer) or isinstance(phis, jax.core.Tracer) or np.ndim(p) != 2:
        return None
    if max_bytes is not None and not (int(max_bytes) > 0):
        raise ValueError(f"max_bytes must be a positive number of bytes, not {max_bytes!r}")
    B, N = np.shape(p)[0], np.shape(phis)[-1] if np.ndim(phis) else 1
    values = len(mech.unknown_names) + 3 + (2 * len(mech.points) if points else 0)
    per_design = N * values * _BYTES_PER_VALUE
    budget = memory_budget() if max_bytes is None else int(max_bytes)
    if B * per_design <= budget:
        return None
    chunk = 1
    while 2 * chunk * per_design <= budget and 2 * chunk < B:
        chunk *= 2
    return chunk


def _solve_chunked(mech, phis, p, q0, options, points, chunk: int) -> Solution:
    """`_solve_jit` over chunks of `chunk` designs (the last one padded by repeating its first
    design, so one compiled shape serves them all), each copied to the host when done."""
    P = np.asarray(p)
    B = P.shape[0]
    per_design_phis = np.ndim(phis) == 2
    per_design_q0 = q0 is not None and np.ndim(q0) == 2
    parts = []
    for lo in range(0, B, chunk):
        idx = np.arange(lo, min(lo + chunk, B))
        take = np.concatenate([idx, np.full(chunk - len(idx), idx[0])])
        sol = _solve_jit(mech, np.asarray(phis)[take] if per_design_phis else phis, P[take],
                         np.asarray(q0)[take] if per_design_q0 else q0, options, points)
        parts.append(jax.tree_util.tree_map(lambda x, n=len(idx): np.asarray(x)[:n], jax.device_get(sol)))
    return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs, axis=0), *parts)


def solve_path(mech: Mechanism, phis, p=None, q0=None, *, options: NewtonOptions = NewtonOptions(),
               points: bool = False) -> Solution:
    """`solve` for one design, not wrapped in its own `jit`: for use inside the caller's traced
    functions (`vmap` over designs, `grad`), as the design search does. Same arguments and
    defaults as `solve` (`p` (P,), `phis` (N,), `q0` (n,)), but `points=False` by default."""
    return _batch(mech, phis, p, q0, options, points)
