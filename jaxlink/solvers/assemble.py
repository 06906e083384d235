"""Loop-closure (assembly) solve: closed-form dyads, or Newton's method with continuation.

For one design p and a sequence of inputs φ_0 … φ_{N-1} we solve Φ(q_k; φ_k, p) = 0.

The solve is split by concept: `options` (the static settings), `closed_form` (every block a
dyad: no Newton), `newton` (one position's Newton and the residual checks), `continuation` (the
Newton path along the inputs: first position, lead-in, continuation), `reassembly` (the branch
rule), `implicit` (the exact derivative) and `chunks` (a CPU batch in chunks of designs). This
module holds the batched solve that joins them (`_solve_batch_impl`), its `custom_jvp`, and the
public `solve` / `solve_path`.

Every position returns a result code (`RESULTS`) instead of raising, and no position writes NaN
into the output: it keeps the last finite iterate, and the continuation goes on from the last
converged position. So one bad design or position never poisons a batch. A design whose
parameters give no finite tolerance (a NaN or infinite length) or whose guess is not finite is
`nonfinite` at every position.
"""

from __future__ import annotations

import functools
import os
import warnings

import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero

from ..model.mechanism import Mechanism
from ..results import RESULTS, Solution, SolveStats
from . import dyads as _dyads
from .chunks import _design_chunk, _map_designs
from .closed_form import _closed_form_path, _closed_form_reference, _smooth_sides, method_for
from .continuation import _continuation_one, _continuation_smooth, _lead_in, reduce_angles
from .fusion import materialize
from .implicit import _float0, _implicit_tangents
from .newton import _check_residual, _newton_kw, _Trig, newton
from .options import NewtonOptions, default_rtol, singular_threshold


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


def _mask_points(pts, code):
    """Points where the position assembled (converged or singular), NaN elsewhere."""
    assembled = (code == RESULTS.converged) | (code == RESULTS.singular)
    return jnp.where(assembled[..., None, None], pts, jnp.nan)


def _batch(mech, phis, p, q0, options: NewtonOptions, points: bool, unknowns: bool = True) -> Solution:
    """The common body of `solve` and `solve_path`: shapes, dtypes, defaults, the lead-in. Without
    `unknowns` the `Solution`'s q is None (XLA then drops the angles' computation: the closed
    form's atan2s; the other outputs are the same values, bit for bit)."""
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
    # (q None only where the caller asked for the positions alone: `solve(..., unknowns=False)`)
    sol = Solution(q=q if unknowns else None,  # type: ignore[arg-type]
                   points=pts, result=code, stats=SolveStats(residual=rn, steps=k))
    return sol if batch else jax.tree_util.tree_map(lambda x: x[0], sol)


_warned_float32 = False


def _warn_if_float32(p) -> None:
    """Warn once when float64 numbers (the file's, or numpy float64) meet JAX's float32 default."""
    global _warned_float32
    if _warned_float32 or isinstance(p, jax.Array) or jax.config.read("jax_enable_x64"):
        return  # (a JAX array's dtype is the caller's choice, float64 or float32)
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


@functools.partial(jax.jit, static_argnames=("options", "points", "unknowns"))
def _solve_jit(mech, phis, p, q0, options, points, unknowns=True):
    return _batch(mech, phis, p, q0, options, points, unknowns)


def solve(mech: Mechanism, phis, p=None, q0=None, *, options: NewtonOptions = NewtonOptions(),
          points: bool = True, unknowns: bool = True, max_bytes: int | None = None) -> Solution:
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
    - `unknowns`: also return the unknowns (`Solution.q`). False: q is None, and the solve is
      the positions alone (with the result codes and residuals), the same values bit for bit;
      in closed form it skips every solved angle's atan2 (the Strider, one design × 360
      positions: about 0.65× the time).
    - `max_bytes`: the device memory a batch may use (default: a quarter of the device's memory,
      of the available host memory on a CPU). A larger batch is solved in chunks of designs that
      fit, identical to the unchunked solve: kept on the device where the whole result fits
      beside a chunk's working memory, else each chunk copied to the host as it is done (the
      result then numpy arrays).

    **Returns:** a `Solution` (q, points, result, stats) with leading axes (N,) or (B, N).

    One jitted function (compiled once per shape, dtype and options); the same under an outer
    `jax.jit`, `vmap` or `grad` (exact derivatives by implicit differentiation; no chunking there:
    the caller's trace decides). The dtype is that of `p` (float64 needs
    `jax.config.update("jax_enable_x64", True)`). A batch placed on several devices
    (`jax.device_put(p, NamedSharding(...))`) is solved where it lies.
    """
    _warn_if_float32(p)
    if not isinstance(unknowns, bool):
        raise TypeError(f"unknowns must be True or False, not {unknowns!r}")
    plan = _chunk_designs(mech, phis, p, points, max_bytes)
    if plan is None:
        return _solve_jit(mech, phis, p, q0, options, points, unknowns)
    return _solve_chunked(mech, phis, p, q0, options, points, *plan, unknowns=unknowns)


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


def _chunk_designs(mech, phis, p, points: bool, max_bytes) -> tuple[int, bool] | None:
    """(designs per chunk, whether the result stays on the device) when the batch needs more than
    `max_bytes`, else None (one call). The result stays on the device where twice its size (the
    chunks' results and their concatenation) leaves room for the chunks' working memory; the
    chunks are then sized to that room. Otherwise each chunk is copied to the host."""
    if p is None or np.ndim(p) != 2 or isinstance(p, jax.core.Tracer) or isinstance(phis, jax.core.Tracer):
        return None
    if max_bytes is not None and not (int(max_bytes) > 0):
        raise ValueError(f"max_bytes must be a positive number of bytes, not {max_bytes!r}")
    B, N = np.shape(p)[0], np.shape(phis)[-1] if np.ndim(phis) else 1
    values = len(mech.unknown_names) + 3 + (2 * len(mech.points) if points else 0)
    per_design = N * values * _BYTES_PER_VALUE
    budget = memory_budget() if max_bytes is None else int(max_bytes)
    if B * per_design <= budget:
        return None

    def largest(room):  # the largest power of two designs whose working memory fits in `room`
        chunk = 1
        while 2 * chunk * per_design <= room and 2 * chunk < B:
            chunk *= 2
        return chunk

    room = budget - 2 * B * N * values * 8  # the result (8 bytes a value at most), twice
    if room >= per_design:
        return largest(room), True
    return largest(budget), False


def _solve_chunked(mech, phis, p, q0, options, points, chunk: int, on_device: bool = False, *,
                   unknowns: bool = True) -> Solution:
    """`_solve_jit` over chunks of `chunk` designs (the last one padded by repeating its first
    design, so one compiled shape serves them all). `on_device`: the chunks are sliced, solved and
    concatenated on the device (the result jax arrays); else each is copied to the host when done
    (the result numpy arrays). The values are the same either way."""
    xp = jnp if on_device else np
    P = xp.asarray(p)
    B = P.shape[0]
    PH = xp.asarray(phis) if np.ndim(phis) == 2 else None
    Q0 = xp.asarray(q0) if q0 is not None and np.ndim(q0) == 2 else None
    parts = []
    for lo in range(0, B, chunk):
        n = min(chunk, B - lo)
        take = slice(lo, lo + n) if n == chunk else np.concatenate([np.arange(lo, lo + n), np.full(chunk - n, lo)])
        sol = _solve_jit(mech, phis if PH is None else PH[take], P[take], q0 if Q0 is None else Q0[take],
                         options, points, unknowns)
        if on_device:
            parts.append(sol if n == chunk else jax.tree_util.tree_map(lambda x, n=n: x[:n], sol))
        else:
            parts.append(jax.tree_util.tree_map(lambda x, n=n: np.asarray(x)[:n], jax.device_get(sol)))
    return jax.tree_util.tree_map(lambda *xs: xp.concatenate(xs, axis=0), *parts)


def solve_path(mech: Mechanism, phis, p=None, q0=None, *, options: NewtonOptions = NewtonOptions(),
               points: bool = False) -> Solution:
    """`solve` for one design, not wrapped in its own `jit`: for use inside the caller's traced
    functions (`vmap` over designs, `grad`), as the design search does. Same arguments and
    defaults as `solve` (`p` (P,), `phis` (N,), `q0` (n,)), but `points=False` by default."""
    return _batch(mech, phis, p, q0, options, points)
