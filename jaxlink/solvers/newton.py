"""Newton's method on the loop equations of one position, and the residual checks.

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
  the residual keeps falling by ≈ 4 and stops at the rounding floor. A stop that gave up (the
  residual stagnating) is assembled only where its last step, the error left, is ≤ √eps: a residual
  within tol next to a double root says little about the error.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..model import structure as _structure
from ..model.mechanism import Mechanism
from ..results import RESULTS
from .fusion import batched_like, materialize
from .linalg import solve_block_lower, solve_small
from .options import EXTRA_STEPS


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
      for 4 iterations (8 with `limit_step`), where a step of linear convergence at a small pivot
      ratio (< 0.1, the residual within max(rtol, √eps) × scale and falling by 2–10×) counts as
      progress even above that best — or, without `limit_step`, when after 4 iterations it is
      still above 1e-4 × scale: from a continuation predictor Newton converges in 2–3 steps, so
      such a position is almost surely unreachable, and under `vmap` one hopeless position would
      otherwise hold the whole batch. A give-up with max|Φ| ≤ tol is `converged` (`singular`
      below `singular_ratio`) only where its last step — the error left at q — is ≤ √eps (or not
      finite: Φ_q exactly singular); else it is `singular` if the pivot ratio is below
      `singular_ratio` and max|Φ| ≤ max(rtol, √eps) × scale, and `cannot_assemble` otherwise: a
      float32 start within rounding of a change point is thrown 0.1 rad into the double root's
      valley by a step of rounding noise over a tiny pivot, and its residual there is within tol
      long before its error is (it once gave up 0.015 rad off, as `converged`).

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
        qe, step, k, _, _, _, rn_last, _, dqa_prev, rn_best, stall, _, _, _, _, _ = st
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
        # linear convergence within tol_loop at a small pivot (the residual falling by 2–10× per
        # step) is no stall, even above the best residual so far: after a step thrown out by a
        # tiny pivot (rounding noise next to a double root), Newton comes back down the valley
        valley = (rn <= tol_loop) & (rn <= 0.5 * rn_last) & (rn >= 0.1 * rn_last) & (piv < 0.1)
        stall = jnp.where(better | valley, 0, stall + 1)
        give_up = (stall >= jnp.where(limit_step, 8, 4)) | ((~limit_step) & (k >= 3) & (rn > hopeless))
        stop = ~corr & (floor | give_up | ~finite)
        # a stop may count as assembled only where the error at qe is known to be small: at the
        # rounding floor, or where the last step (≈ the error at qe: at a double root Newton
        # converges linearly) is ≤ √eps (or undefined: Φ_q exactly singular). A give-up with a
        # large step is not: e.g. a float32 continuation that lands within rounding of a change
        # point, where the step (rounding noise over a tiny pivot) throws it 0.1 rad into the
        # double root's valley, stalls there half-way down (its best residual was the first) —
        # the residual is within tol, the error 0.015 rad
        trusted = corr | (stop & (floor | ~finite | (dqa <= sqrt_eps)))
        # step-limited Newton for a rough guess: at most 0.5 rad (0.5 × scale) per unknown
        shrink = jnp.where(limit_step, jnp.minimum(1.0, 0.5 / jnp.maximum(dqa, 1e-30)), 1.0)
        step = jnp.where(stop, 0.0, dq * shrink)
        return (q, step, k + 1, corr | stop, piv, sg, rn, rn_last, dqa, rn_best, stall, corr, stop, trusted, c, s)

    inf = jnp.asarray(jnp.inf, dtype)
    start_bad = ~jnp.isfinite(tol) | ~jnp.all(jnp.isfinite(q0))
    false = jnp.zeros((), bool)
    zeros_a = jnp.zeros((len(ang),), dtype)
    init = (q0, jnp.zeros_like(q0), jnp.zeros((), jnp.int32), start_bad, jnp.asarray(1.0, dtype),
            jnp.ones((nb,), dtype), inf, inf, inf, inf, jnp.zeros((), jnp.int32), false, false, false, zeros_a, zeros_a)
    init = batched_like(init, q0, phi, p, tol, max_steps, limit_step)
    qe, step, k, _, piv, sg, _, _, _, _, stall, corr, stop, trusted, c, s = jax.lax.while_loop(cond, body, init)
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
    conv = trusted & (rn <= tol)
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


def _newton_kw(rtol, thr, trig_p):
    return {"rtol": rtol, "singular_ratio": thr, "trig_p": trig_p}


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
