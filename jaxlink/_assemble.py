"""Loop-closure (assembly) solve: Newton's method with continuation over the input.

For one design p and a sequence of inputs φ_0 … φ_{N-1} we solve Φ(q_k; φ_k, p) = 0:

- **first position**: Newton from the file's guess q0, with a step limit (0.5 rad for angles,
  0.5 × the length scale for lengths) so that a rough guess does not jump to another branch;
- **continuation**: position k starts from a Lagrange extrapolation of the last (up to three)
  converged solutions, which keeps the assembly branch of the guess through the revolution and
  typically needs two Newton steps;
- **Newton step**: Φ_q from forward-mode AD (`jax.jacfwd`), solved by unrolled Gaussian
  elimination with partial pivoting (`_linalg.solve_small`), so that `vmap` over designs fuses.
  The part of Φ that does not depend on q is evaluated once per position.

Every position returns a result code (`RESULTS`) instead of raising, and a non-converged position
never writes NaN into the output: it keeps the last finite iterate, and the continuation goes on
from the last converged position. So one bad design or position never poisons a batch.

**Exact gradients.** The whole path solve is a `jax.custom_jvp`: by the implicit function
theorem, dq_k = −Φ_q⁻¹ (Φ_p dp + Φ_φ dφ_k) at the converged solution — one linear solve per
position, independent of the Newton iterations (and zero at non-converged positions). Reverse
mode (`jax.grad`) follows by transposition of that linear map.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _dyads, _structure
from ._fusion import materialize
from ._linalg import solve_block_lower, solve_small
from ._mechanism import Mechanism
from ._sharding import design_sharding
from ._solution import RESULTS, Solution


class NewtonOptions(NamedTuple):
    """Static solver settings (changing them recompiles).

    - `method`: `"auto"` (closed-form dyads when every block of the structure is a dyad, else
      Newton with continuation), `"closed_form"`, `"continuation"` or `"independent"` (every
      position by Newton from q0: only safe with a close guess).
    - `rtol`: converged when max|Φ| ≤ rtol × length scale (the largest |length parameter|);
      `None` = 1000 × machine epsilon of the dtype (2.2e-13 in float64, 1.2e-4 in float32). Once
      the residual is below it, one more (small) Newton correction is applied, which squares the
      error: the returned q is accurate to rounding (tested against closed forms to 1e-15 rad).
    - `max_steps`: Newton iterations per position after the first.
    - `max_steps_first`: iterations for the first position (from the file's guess).
    - `continuation`: False is the same as `method="independent"` (kept for compatibility).
    - `predictor_order`: 0 (previous solution), 1 (secant) or 2 (quadratic) extrapolation.
    - `singular_ratio`: pivot ratio of Φ_q (≈ 1/condition) below which it counts as singular.
    """

    rtol: float | None = None
    max_steps: int = 12
    max_steps_first: int = 60
    continuation: bool = True
    predictor_order: int = 2
    singular_ratio: float = 1e-10
    method: str = "auto"


METHODS = ("auto", "closed_form", "continuation", "independent")


def default_rtol(dtype) -> float:
    return float(1000 * np.finfo(dtype).eps)


def _step_scales(mech: Mechanism, scale, dtype):
    return jnp.asarray(
        [0.5 if k == "angle" else 1.0 for k in mech.unknown_kinds], dtype=dtype
    ) * jnp.asarray([1.0 if k == "angle" else scale for k in mech.unknown_kinds], dtype=dtype)


def _linear_solve(mech: Mechanism):
    order = _structure.blocks(mech)
    blocks = tuple((tuple(r for li in loops for r in (2 * li, 2 * li + 1)), cols) for loops, cols in order)
    if len(blocks) == 1 and len(blocks[0][1]) > 2:
        return solve_small
    return lambda a, b: solve_block_lower(a, b, blocks)


def newton(mech: Mechanism, q0, phi, p, *, tol, max_steps: int, limit_step: bool, singular_ratio: float):
    """Newton's method for one position. Returns `(q, rnorm, result, steps)` (see `RESULTS`).

    Gives up early (as `cannot_assemble`) when after 4 iterations the residual has not fallen
    below 1e-4 × the length scale: from a continuation predictor Newton converges quadratically
    in 2–3 steps, so such a position is almost surely unreachable, and under `vmap` one hopeless
    position would otherwise hold the whole batch for `max_steps` iterations.
    """
    dtype = jnp.result_type(q0)
    const = mech.residual_const(phi, p)
    lin = _linear_solve(mech)
    scale = mech.length_scale(p)

    def value_and_jac(q):
        f = lambda qq: (mech.residual_var(qq, phi, p, const),) * 2  # noqa: E731
        jac, r = jax.jacfwd(f, has_aux=True)(q)
        return r, jac

    step_scale = _step_scales(mech, scale, dtype) if limit_step else None
    tiny_scale = 1e-3 * _step_scales(mech, scale, dtype)
    hopeless = 1e-4 * scale

    def cond(state):
        q, k, done, rn, piv = state
        return (~done) & (k < max_steps)

    def body(state):
        q, k, done, rn, piv = state
        # materialize r and Φ_q once: without the barrier XLA re-computes the trigonometry in
        # every fused kernel of the elimination (measured 3-4× slower)
        r, jac = jax.lax.optimization_barrier(value_and_jac(q))
        rn = jnp.max(jnp.abs(r))
        conv = rn <= tol
        dq, piv = lin(jac, r)
        dq = jax.lax.optimization_barrier(dq)
        if limit_step:
            ratio = jnp.max(jnp.abs(dq) / step_scale)
            dq = dq * jnp.minimum(1.0, 1.0 / jnp.maximum(ratio, 1e-30))
        q_new = q - dq
        finite = jnp.all(jnp.isfinite(q_new)) & jnp.isfinite(rn)
        # once converged, the last step is still taken when it is a small correction (it squares
        # the error for free); never at a singular point where it would be garbage
        small = jnp.max(jnp.abs(dq) / tiny_scale) <= 1.0
        q = jnp.where(finite & (~conv | small), q_new, q)
        give_up = (not limit_step) & (k >= 3) & (rn > hopeless)
        return q, k + 1, conv | ~finite | give_up, rn, piv

    init = (q0, jnp.zeros((), jnp.int32), jnp.zeros((), bool), jnp.asarray(jnp.inf, dtype),
            jnp.asarray(1.0, dtype))
    q, k, done, rn, piv = jax.lax.while_loop(cond, body, init)
    conv = rn <= tol
    result = _classify(conv, rn, q, piv, scale, dtype, singular_ratio)
    # never hand out non-finite numbers: fall back to the start value
    q = jnp.where(jnp.all(jnp.isfinite(q)), q, jnp.nan_to_num(q0))
    return q, rn, result, k


def _classify(conv, rn, q, piv, scale, dtype, singular_ratio):
    assemble_tol = max(1e-6, 10 * float(np.sqrt(np.finfo(dtype).eps))) * scale
    return jnp.where(
        conv, RESULTS.converged,
        jnp.where(~jnp.isfinite(rn) | ~jnp.all(jnp.isfinite(q)), RESULTS.nonfinite,
                  jnp.where(rn > assemble_tol, RESULTS.cannot_assemble,
                            jnp.where(piv < singular_ratio, RESULTS.singular, RESULTS.max_steps))),
    ).astype(jnp.int8)


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


def _closed_form_path(mech, p, phis, q0, tol, trig_in, trig_p):
    """Every position of one design in closed form, on the branches nearest to the guess q0 at
    the first input (`_dyads.solve_nearest`): no Newton, no continuation."""
    dyads = _dyads.classify(mech)
    t_first = jax.tree_util.tree_map(lambda x: x[0], trig_in)
    _, _, _, sigma = _dyads.solve_nearest(mech, dyads, q0, phis[0], p, {**t_first, **trig_p})
    # a guess that selects no branch (NaN), or parameters that allow no check (a NaN or infinite
    # tolerance, e.g. from a NaN length that no loop uses): nothing here can be verified
    ref_ok = jnp.all(jnp.isfinite(q0)) & jnp.isfinite(tol)
    q_ref = jnp.where(jnp.isfinite(q0), q0, 0.0)

    def one(phi, t_in):
        q, ok, rn = _dyads.solve(mech, dyads, sigma, q_ref, phi, p, {**t_in, **trig_p})
        conv = ok & (rn <= tol) & ref_ok
        code = jnp.where(conv, RESULTS.converged,
                         jnp.where(~ref_ok | ~jnp.isfinite(rn), RESULTS.nonfinite,
                                   jnp.where(ok, RESULTS.max_steps, RESULTS.cannot_assemble)))
        q = jnp.where(jnp.all(jnp.isfinite(q)), q, q_ref)
        return q, rn, code.astype(jnp.int8), jnp.zeros((), jnp.int32)

    return jax.vmap(one)(phis, trig_in)


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


def _first_positions(mech, opts, P, phi0, Q0, tol):
    """Newton from the guesses at the first input, one per design (step-limited)."""
    return jax.vmap(lambda p, q0, t, f: newton(mech, q0, f, p, tol=t, max_steps=opts.max_steps_first,
                                               limit_step=True, singular_ratio=opts.singular_ratio))(
        P, Q0, tol, phi0)


def _continuation_one(mech, opts, p, phis, q_first, ok_first, tol):
    """Newton + continuation along phis[1:] for one design, from its solved first position."""
    hist_q = (q_first, q_first, q_first)
    hist_phi = (phis[0], phis[0], phis[0])
    n_good = ok_first.astype(jnp.int32)

    def step(carry, phi):
        hist_q, hist_phi, n_good = carry
        guess = _extrapolate(hist_q, hist_phi, n_good, phi, opts.predictor_order)
        q, rn, code, k = newton(mech, guess, phi, p, tol=tol, max_steps=opts.max_steps, limit_step=False,
                                singular_ratio=opts.singular_ratio)
        good = code == RESULTS.converged
        new_q = tuple(jnp.where(good, a, b) for a, b in zip((q,) + hist_q[:2], hist_q))
        new_phi = tuple(jnp.where(good, a, b) for a, b in zip((phi,) + hist_phi[:2], hist_phi))
        return (new_q, new_phi, n_good + good.astype(jnp.int32)), (q, rn, code, k)

    return jax.lax.scan(step, (hist_q, hist_phi, n_good), phis[1:])[1]


def _solve_batch_impl(mech: Mechanism, opts: NewtonOptions, P, phis, Q0):
    """P (B, P), phis (N,) shared by all designs or (B, N), Q0 (B, n)
    -> q (B, N, n), rnorm, result, steps (B, N)."""
    dtype = jnp.result_type(Q0)
    B = P.shape[0]
    shared = phis.ndim == 1
    N = phis.shape[-1]
    ax = None if shared else 0  # vmap axis of phis over the designs
    rtol = opts.rtol if opts.rtol is not None else default_rtol(dtype)
    tol = rtol * jax.vmap(mech.length_scale)(P)
    method = method_for(mech, opts)
    if method == "closed_form":
        # every (design, input) pair is independent, on the branches (circuits) of the guess. The
        # trigonometry of the inputs (N values) and of the angle parameters (B) is computed once,
        # not inside every fused kernel.
        trig_in, trig_p = materialize((_dyads.input_trig(mech, phis), _dyads.parameter_trig(mech, P)))
        return jax.vmap(lambda p, ph, q0, t, ti, tp: _closed_form_path(mech, p, ph, q0, t, ti, tp),
                        in_axes=(0, ax, 0, 0, ax, 0))(P, phis, Q0, tol, trig_in, trig_p)
    phi0 = jnp.broadcast_to(phis[0], (B,)) if shared else phis[:, 0]
    q1, r1, c1, k1 = _first_positions(mech, opts, P, phi0, Q0, tol)

    def join(first, rest):
        return jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[:, None], b], axis=1), first, rest)

    if N == 1:
        return q1[:, None], r1[:, None], c1[:, None], k1[:, None]
    if method == "independent":
        rest = jax.vmap(lambda p, ph, q0, t: jax.vmap(
            lambda f: newton(mech, q0, f, p, tol=t, max_steps=opts.max_steps_first, limit_step=True,
                             singular_ratio=opts.singular_ratio))(ph[1:]), in_axes=(0, ax, 0, 0))(P, phis, Q0, tol)
        return join((q1, r1, c1, k1), rest)
    rest = jax.vmap(lambda p, ph, q, c, t: _continuation_one(mech, opts, p, ph, q, c == RESULTS.converged, t),
                    in_axes=(0, ax, 0, 0, 0))(P, phis, q1, c1, tol)
    return join((q1, r1, c1, k1), rest)


@functools.lru_cache(maxsize=64)
def _batch_solver(mech: Mechanism, opts: NewtonOptions):
    """The differentiable batched solve: (P (B,P), phis (N,) or (B,N), Q0 (B,n)) -> (q, rnorm, result, steps)."""

    @jax.custom_jvp
    def solve_batch(P, phis, Q0):
        return _solve_batch_impl(mech, opts, P, phis, Q0)

    @solve_batch.defjvp
    def _jvp(primals, tangents):
        P, phis, Q0 = primals
        dP, dphis, _ = tangents
        out = solve_batch(P, phis, Q0)
        q, rn, code, k = out
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
        return out, (dq, jnp.zeros_like(rn), _float0(code), _float0(k))

    return solve_batch


def _float0(x):
    return np.zeros(np.shape(x), dtype=jax.dtypes.float0)


def _solve_batch(mech, options, P, phis, Q0) -> Solution:
    q, rn, code, k = _batch_solver(mech, options)(P, phis, Q0)
    return Solution(q=q, converged=code == RESULTS.converged, residual=rn, result=code, steps=k)


def solve_path(mech: Mechanism, p, phis, q0=None, *, options: NewtonOptions = NewtonOptions()) -> Solution:
    """Solve the positions of one design along a sequence of inputs (differentiable in p, φ).

    **Arguments:**

    - `mech`: the compiled mechanism.
    - `p`: (P,) parameters, SI (`mech.parameters` for the file's design).
    - `phis`: (N,) input values, SI, in the order of the continuation.
    - `q0`: (n,) guess at `phis[0]` (default: the file's guess).
    - `options`: `NewtonOptions` (keyword-only, static).

    **Returns:** a `Solution` with leading axis N.
    """
    p = jnp.asarray(p)
    dtype = jnp.result_type(p)
    phis = jnp.asarray(phis, dtype=dtype)
    q0 = jnp.asarray(mech.guess if q0 is None else q0, dtype=dtype)
    sol = _solve_batch(mech, options, p[None], phis, q0[None])
    return jax.tree_util.tree_map(lambda x: x[0], sol)


def solve(mech: Mechanism, phis, p=None, q0=None, *, options: NewtonOptions = NewtonOptions(),
          devices=None) -> Solution:
    """Solve positions for one design or a batch of designs, jitted.

    `p` of shape (P,) gives a `Solution` with leading axis N; `p` of shape (B, P) gives leading
    axes (B, N) (designs × positions). `phis` is (N,) (shared by all designs) or (B, N); `q0` is
    (n,) or (B, n). With the default `q0` the solve starts at the file's `[input] start`, where its
    guesses hold, and continues to `phis[0]` first (a lead-in, dropped from the result).

    A batch of designs is split over `devices` (default: every device of the default backend,
    `jax.devices()`): each device solves its share of the designs, the results do not depend on
    the split. On a CPU, `XLA_FLAGS=--xla_force_host_platform_device_count=N` (set before JAX is
    imported) makes N host devices, one per core: XLA runs each compiled kernel on one thread, so
    this is how a batch uses every core (`benchmarks/scaling.py`).
    """
    p = jnp.asarray(mech.parameters if p is None else p)
    if not jnp.issubdtype(p.dtype, jnp.floating):
        p = p.astype(jnp.result_type(float))
    lead = 0
    if q0 is None and np.ndim(phis) == 1 and not isinstance(phis, jax.core.Tracer):
        # the file's guesses hold at `input_start`: continue from there to phis[0] first
        lead_in = lead_in_path(mech, float(np.asarray(phis)[0]))
        lead = len(lead_in)
        if lead:
            phis = np.concatenate([lead_in, np.asarray(phis, dtype=float)])
    phis = jnp.asarray(phis, dtype=p.dtype)
    q0 = jnp.asarray(mech.guess if q0 is None else q0, dtype=p.dtype)
    devs = tuple(jax.devices() if devices is None else devices) if p.ndim == 2 else ()
    devs = devs if len(devs) > 1 else ()
    sol = _jitted_solve(mech, options, p.ndim == 2, phis.ndim == 2, q0.ndim == 2, devs)(p, phis, q0)
    if lead:
        sol = jax.tree_util.tree_map(lambda x: x[..., lead:, :] if x.ndim == p.ndim + 1 else x[..., lead:], sol)
    return sol


def lead_in_path(mech: Mechanism, phi0: float, max_step: float = np.deg2rad(5.0)) -> np.ndarray:
    """Inputs from the file's `input_start` towards `phi0` (excluded), steps ≤ `max_step`
    (5° for an angle input; 5 % of the length scale for a length input)."""
    start = mech.input_start
    if mech.input_kind == "length":
        lengths = [abs(v) for v, k in zip(mech.parameters, mech.parameter_kinds) if k == "length"]
        max_step = 0.05 * (max(lengths) if lengths else 1.0)
    gap = phi0 - start
    if abs(gap) < 1e-12:
        return np.zeros((0,))
    n = int(np.ceil(abs(gap) / max_step))
    return start + gap * np.arange(n) / n


@functools.lru_cache(maxsize=64)
def _jitted_solve(mech, options, batch_p, batch_phi, batch_q0, devices=()):
    shard = design_sharding(devices) if devices else None

    def run(p, phis, q0):
        P = p if batch_p else p[None]
        B = P.shape[0]
        Q0 = q0 if batch_q0 else jnp.broadcast_to(q0, (B,) + q0.shape)
        if shard is not None:  # designs split over the devices (uneven splits are padded by XLA)
            P, Q0 = (jax.lax.with_sharding_constraint(x, shard) for x in (P, Q0))
            if batch_phi:
                phis = jax.lax.with_sharding_constraint(phis, shard)
        sol = _solve_batch(mech, options, P, phis, Q0)
        return sol if batch_p else jax.tree_util.tree_map(lambda x: x[0], sol)

    return jax.jit(run)
