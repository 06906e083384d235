"""Adaptive integrators for hybrid (mode-switching) ODEs, in JAX.

Two one-step methods, each an `(init, step)` pair with embedded error estimate and dense
output, share one driver (`integrate_hybrid`) written with `lax.while_loop`, so everything
jits and `vmap`s:

- `DormandPrince5`: explicit Runge-Kutta 5(4), FSAL, 4th-order dense output (the tableau of
  Dormand & Prince 1980 and the interpolant of Shampine 1986, as in scipy's RK45).
- `RadauIIA5`: implicit 3-stage Radau IIA of order 5 (L-stable), Newton on the full
  `3n x 3n` stage system with stage Jacobians from `jax.jacfwd`, Hairer & Wanner's embedded
  3rd-order error estimate filtered by `(mu/h - J)^-1`, and the collocation polynomial as
  dense output (as in scipy's Radau).

**Hybrid systems.** The state `u` evolves by `vector_field(t, u, mode, piece)` where `mode`
is 0.0 or 1.0 and `piece` indexes smooth pieces of a time-dependent input (the cam). The
driver

- never steps across a *stop* (the piece boundaries): a step that would is shortened to end on
  it, so every step's right-hand side is smooth;
- checks the *guard* `g(t, u)` on the step's dense output at `event_samples` points; in mode
  1 it must stay `>= 0`, in mode 0 `<= 0`. At the first sample on the wrong side it bisects
  the interpolant to machine precision, ends the step there and flips the mode. Sampling the
  interpolant (not only the step's ends) is what finds a contact lost *and* regained inside
  one step; `max_step` caps the step for extra safety.

Failures are not raised: `Solution.result` holds a code from `RESULTS`.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from ..results import RESULTS

# ----------------------------------------------------------------------------------------
# Dormand-Prince 5(4)
_S6 = math.sqrt(6.0)

_DP_C = (0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0)
_DP_A = (
    (),
    (1 / 5,),
    (3 / 40, 9 / 40),
    (44 / 45, -56 / 15, 32 / 9),
    (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
    (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656),
)
_DP_B = (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84)
_DP_E = (-71 / 57600, 0.0, 71 / 16695, -71 / 1920, 17253 / 339200, -22 / 525, 1 / 40)
_DP_P = (
    (1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432),
    (0.0, 0.0, 0.0, 0.0),
    (0.0, 131558114200 / 32700410799, -68118460800 / 10900136933,
     87487479700 / 32700410799),
    (0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072),
    (0.0, 127303824393 / 49829197408, -318862633887 / 49829197408,
     701980252875 / 199316789632),
    (0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844),
    (0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423),
)


class StepResult(NamedTuple):
    """One attempted step: new state, its derivative, error vector, dense coefficients
    `Q` (`u(t + theta h) = u + Q @ [theta, theta^2, theta^3, theta^4]`), counters, success."""

    u_new: jnp.ndarray
    f_new: jnp.ndarray
    err: jnp.ndarray
    dense: jnp.ndarray
    nfev: jnp.ndarray
    njev: jnp.ndarray
    ok: jnp.ndarray


class DormandPrince5(NamedTuple):
    """Explicit adaptive Runge-Kutta 5(4) (Dormand-Prince), FSAL, 4th-order dense output."""

    order: int = 5
    error_order: int = 4
    fsal: bool = True

    def init(self, fn, t, u):
        del t, u  # unused
        return None

    def step(self, fn, t, u, f0, h, rtol, atol):
        del rtol, atol  # unused
        ks = [f0]
        for c, a in zip(_DP_C[1:], _DP_A[1:]):
            du = sum(ai * ki for ai, ki in zip(a, ks) if ai != 0.0)
            ks.append(fn(t + c * h, u + h * du))
        u_new = u + h * sum(b * k for b, k in zip(_DP_B, ks) if b != 0.0)
        f_new = fn(t + h, u_new)
        ks.append(f_new)
        k = jnp.stack(ks)  # (7, n)
        err = h * jnp.asarray(_DP_E, dtype=u.dtype) @ k
        dense = h * (k.T @ jnp.asarray(_DP_P, dtype=u.dtype))  # (n, 4)
        return StepResult(u_new, f_new, err, dense, jnp.asarray(6), jnp.asarray(0),
                          jnp.asarray(True))


# ----------------------------------------------------------------------------------------
# Radau IIA, order 5
_RA_C = ((4 - _S6) / 10, (4 + _S6) / 10, 1.0)
_RA_A = (
    ((88 - 7 * _S6) / 360, (296 - 169 * _S6) / 1800, (-2 + 3 * _S6) / 225),
    ((296 + 169 * _S6) / 1800, (88 + 7 * _S6) / 360, (-2 - 3 * _S6) / 225),
    ((16 - _S6) / 36, (16 + _S6) / 36, 1 / 9),
)
_RA_E = ((-13 - 7 * _S6) / 3, (-13 + 7 * _S6) / 3, -1 / 3)
_RA_MU_REAL = 3 + 3 ** (2 / 3) - 3 ** (1 / 3)
_RA_P = (
    (13 / 3 + 7 * _S6 / 3, -23 / 3 - 22 * _S6 / 3, 10 / 3 + 5 * _S6, 0.0),
    (13 / 3 - 7 * _S6 / 3, -23 / 3 + 22 * _S6 / 3, 10 / 3 - 5 * _S6, 0.0),
    (1 / 3, -8 / 3, 10 / 3, 0.0),
)


class RadauIIA5(NamedTuple):
    """Implicit Radau IIA, order 5, L-stable; Newton on the stage system.

    The stage Jacobians are evaluated once per step at the stage times (at the step's start
    state), so for right-hand sides affine in `u` (as the sinker's, in each mode) Newton is
    exact and converges in one iteration; a second confirms it.
    """

    order: int = 5
    error_order: int = 3
    fsal: bool = True  # f(t + h, u_new) is computed and reused as the next step's f0
    newton_maxiter: int = 6

    def init(self, fn, t, u):
        del fn, t, u  # unused
        return None

    def step(self, fn, t, u, f0, h, rtol, atol):
        n = u.shape[0]
        dtype = u.dtype
        a = jnp.asarray(_RA_A, dtype=dtype)
        cs = jnp.asarray(_RA_C, dtype=dtype)
        jac = jax.jacfwd(fn, argnums=1)
        j_stage = jnp.stack([jac(t + c * h, u) for c in _RA_C])  # (3, n, n)
        j0 = jac(t, u)
        # Newton matrix  I - h (A (x) I) blockdiag(J_i): block (i, j) = -h a_ij J_j
        big = jnp.eye(3 * n, dtype=dtype) - h * jnp.einsum("ij,jab->iajb", a, j_stage).reshape(
            3 * n, 3 * n)
        scale = atol + rtol * jnp.abs(u)
        newton_tol = jnp.maximum(10 * jnp.finfo(dtype).eps / rtol,
                                 jnp.minimum(0.03, jnp.sqrt(rtol)))

        def stage_f(z):
            return jax.vmap(lambda c, zi: fn(t + c * h, u + zi))(cs, z)

        def residual(z):
            return z - h * a @ stage_f(z)

        def cond(c):
            z, it, dz_norm, rate, done = c
            return (~done) & (it < self.newton_maxiter)

        def body(c):
            z, it, dz_norm_old, rate_old, _ = c
            dz = jnp.linalg.solve(big, -residual(z).reshape(-1)).reshape(3, n)
            z = z + dz
            dz_norm = jnp.sqrt(jnp.mean((dz / scale) ** 2))
            rate = jnp.where(it > 0, dz_norm / jnp.maximum(dz_norm_old, 1e-300), 1.0)
            done = (dz_norm < newton_tol) | ((it > 0) & (rate < 1)
                                               & (rate / (1 - rate) * dz_norm < newton_tol))
            done = done | (dz_norm == 0)
            return z, it + 1, dz_norm, rate, done

        z0 = jnp.zeros((3, n), dtype=dtype)
        init = (z0, jnp.asarray(0), jnp.asarray(jnp.inf, dtype), jnp.asarray(1.0, dtype),
                jnp.asarray(False))
        z, iters, _, _, converged = lax.while_loop(cond, body, init)
        u_new = u + z[-1]
        f_new = fn(t + h, u_new)
        ze = jnp.asarray(_RA_E, dtype=dtype) @ z / h
        lu_mat = _RA_MU_REAL / h * jnp.eye(n, dtype=dtype) - j0
        err = jnp.linalg.solve(lu_mat, f0 + ze)
        # Hairer & Wanner IV.8: a second filtering when the first estimate is large
        sc = atol + rtol * jnp.maximum(jnp.abs(u), jnp.abs(u_new))
        big_err = jnp.sqrt(jnp.mean((err / sc) ** 2)) > 1
        err2 = jnp.linalg.solve(lu_mat, fn(t, u + err) + ze)
        err = jnp.where(big_err, err2, err)
        dense = z.T @ jnp.asarray(_RA_P, dtype=dtype)  # (n, 4)
        nfev = 3 * iters + 2 + jnp.where(big_err, 1, 0)
        return StepResult(u_new, f_new, err, dense, nfev, jnp.asarray(4), converged)


# ----------------------------------------------------------------------------------------
class Stats(NamedTuple):
    """Counters of one integration."""

    num_steps: jnp.ndarray  # accepted steps
    num_rejected: jnp.ndarray
    num_fev: jnp.ndarray  # right-hand side evaluations (logical; FSAL reuse not counted)
    num_jev: jnp.ndarray  # Jacobian evaluations (implicit method only)
    num_events: jnp.ndarray  # mode switches


class Solution(NamedTuple):
    """Output of `integrate_hybrid` (all arrays; `vmap` adds leading axes).

    - `ts`: output times `[n_out]`; `us`: states there `[n_out, n]` (NaN after an early stop);
      `modes`: the mode there `[n_out]`.
    - `t_final`, `u_final`: where the integration ended.
    - `result`: a code from `RESULTS`; `stats`: `Stats`.
    - `monitor`: the `stop_when` monitor's carry (e.g. jamming flag and time).
    """

    ts: jnp.ndarray
    us: jnp.ndarray
    modes: jnp.ndarray
    t_final: jnp.ndarray
    u_final: jnp.ndarray
    result: jnp.ndarray
    stats: Stats
    monitor: tuple


class _State(NamedTuple):
    t: jnp.ndarray
    u: jnp.ndarray
    f: jnp.ndarray
    f_valid: jnp.ndarray
    h: jnp.ndarray
    mode: jnp.ndarray
    done: jnp.ndarray
    result: jnp.ndarray
    stats: Stats
    monitor: tuple


class _Record(NamedTuple):
    """Accepted steps (for dense output after the loop); row `size` is a dump slot."""

    t: jnp.ndarray  # [size + 1] step start (inf = unused)
    h: jnp.ndarray
    theta_end: jnp.ndarray
    u: jnp.ndarray  # [size + 1, n]
    dense: jnp.ndarray  # [size + 1, n, 4]
    mode: jnp.ndarray


def dense_eval(dense, theta):
    """Increment `u(t + theta h) - u(t)` from a step's dense coefficients."""
    return dense @ jnp.stack([theta, theta**2, theta**3, theta**4])


def integrate_hybrid(
    vector_field: Callable,
    guard: Callable,
    piece_of: Callable,
    stops,
    u0,
    mode0,
    t_end,
    ts,
    *,
    solver=DormandPrince5(),
    rtol: float = 1e-6,
    atol: float = 1e-10,
    h0: float = 1e-7,
    max_step: float = math.inf,
    max_steps: int = 10000,
    event_samples: int = 16,
    monitor_init: tuple = (),
    monitor_update: Callable | None = None,
    stop_when: Callable | None = None,
    axis_name=None,
) -> Solution:
    """Integrate a hybrid ODE from `t = 0` to `t_end`, saving the state at times `ts`.

    **Arguments:**

    - `vector_field(t, u, mode, piece) -> du/dt`, smooth in `t, u` for fixed `mode, piece`.
    - `guard(t, u, piece) -> g`: mode 1 requires `g >= 0`, mode 0 requires `g <= 0`.
    - `piece_of(t) -> piece`: the piece of the input containing `t`.
    - `stops`: `[n_stops]` times the steps must land on (piece starts; `inf` = padding).
    - `u0`, `mode0`: initial state and mode (0.0 or 1.0); `t_end`: final time; `ts`: `[n_out]`
      output times in `[0, t_end]` (evaluated after the loop from the recorded steps' dense
      output; `n_out <= 2` records no steps).
    - `solver`: `DormandPrince5()` or `RadauIIA5()` (static).
    - `rtol`, `atol`: error tolerances (RMS norm); may be traced.
    - `h0`: first trial step; `max_step`: step cap (s); `max_steps`: attempted-step budget
      (static; also the size of the step record).
    - `event_samples`: points of the dense output where the guard is checked per step.
    - `monitor_init`, `monitor_update(carry, t, u, dense, h, theta_end, piece) -> carry`: a
      running quantity over each accepted step `u(t + theta h) = u + dense @ [theta..theta^4]`,
      `0 < theta <= theta_end` (e.g. jamming); `stop_when(carry) -> bool` ends the run early
      with `RESULTS.stopped`.
    - `axis_name`: when called under `jax.vmap(..., axis_name=...)`, pass that name: the loop
      then runs while *any* batch member is unfinished (a `psum`), finished members idle, and
      the step record is updated in place instead of being copied by the batched loop's
      `select` on every iteration (which makes large batches many times faster).

    **Returns:** a `Solution`.
    """
    u0 = jnp.asarray(u0)
    dtype = u0.dtype
    n = u0.shape[0]
    ts = jnp.asarray(ts, dtype=dtype)
    t_end = jnp.asarray(t_end, dtype=dtype)
    stops = jnp.asarray(stops, dtype=dtype)
    expo = -1.0 / (solver.error_order + 1)
    thetas = jnp.arange(1, event_samples + 1, dtype=dtype) / event_samples
    size = max_steps if ts.shape[0] > 2 else 1
    rec = _Record(t=jnp.full((size + 1,), jnp.inf, dtype), h=jnp.ones((size + 1,), dtype),
                  theta_end=jnp.ones((size + 1,), dtype), u=jnp.zeros((size + 1, n), dtype),
                  dense=jnp.zeros((size + 1, n, 4), dtype), mode=jnp.zeros((size + 1,), dtype))
    zero = jnp.asarray(0)
    state = _State(
        t=jnp.asarray(0.0, dtype), u=u0, f=jnp.zeros_like(u0), f_valid=jnp.asarray(False),
        h=jnp.asarray(h0, dtype), mode=jnp.asarray(mode0, dtype), done=jnp.asarray(False),
        result=jnp.asarray(RESULTS.converged), stats=Stats(zero, zero, zero, zero, zero),
        monitor=monitor_init)

    def cond(carry):
        s, _ = carry
        if axis_name is None:
            return ~s.done
        return lax.psum(jnp.where(s.done, 0, 1), axis_name) > 0

    def body(carry):
        s, rec = carry
        t, u, mode = s.t, s.u, s.mode
        later = jnp.where(stops > t * (1 + 4 * jnp.finfo(dtype).eps) + 1e-300, stops, jnp.inf)
        next_stop = jnp.minimum(jnp.min(later), t_end)
        room = next_stop - t
        h_try = jnp.minimum(jnp.minimum(s.h, max_step), room)
        clamped = h_try >= room
        piece = piece_of(t)

        def fn(tt, uu):
            return vector_field(tt, uu, mode, piece)

        f0 = jnp.where(s.f_valid, s.f, fn(t, u))
        nfev0 = jnp.where(s.f_valid, 0, 1)
        r = solver.step(fn, t, u, f0, h_try, rtol, atol)
        scale = atol + rtol * jnp.maximum(jnp.abs(u), jnp.abs(r.u_new))
        err_norm = jnp.sqrt(jnp.mean((r.err / scale) ** 2))
        finite = jnp.all(jnp.isfinite(r.u_new)) & jnp.isfinite(err_norm)
        accept = r.ok & finite & (err_norm <= 1.0)

        # --- events: the guard on the step's dense output
        sign = jnp.where(mode > 0.5, 1.0, -1.0)

        def g_at(theta):
            return sign * guard(t + theta * h_try, u + dense_eval(r.dense, theta), piece)

        bad = jax.vmap(g_at)(thetas) < 0
        any_bad = jnp.any(bad)
        j = jnp.argmax(bad)
        lo0 = jnp.where(j > 0, thetas[jnp.maximum(j - 1, 0)], 0.0)
        hi0 = thetas[j]

        def bisect(_, lohi):
            lo, hi = lohi
            mid = 0.5 * (lo + hi)
            mb = g_at(mid) < 0
            return jnp.where(mb, lo, mid), jnp.where(mb, mid, hi)

        # the bisection runs only in a step with a sample on the wrong side (events are rare);
        # under `vmap` with `axis_name`, when any batch member has one (a batched predicate would
        # turn the `cond` into a select that always runs it)
        some_bad = any_bad if axis_name is None else lax.psum(any_bad.astype(jnp.int32), axis_name) > 0
        theta_ev = lax.cond(some_bad, lambda: lax.fori_loop(0, 60, bisect, (lo0, hi0))[1],
                            lambda: jnp.ones((), dtype))
        event = accept & any_bad
        theta_end = jnp.where(event, theta_ev, 1.0)
        t_new = jnp.where(event, t + theta_ev * h_try,
                          jnp.where(clamped, next_stop, t + h_try))
        u_new = jnp.where(event, u + dense_eval(r.dense, theta_ev), r.u_new)

        # --- record the accepted step (in place; idle or rejected -> dump slot)
        live = accept & ~s.done
        i = jnp.where(live, s.stats.num_steps, size)
        rec = _Record(t=rec.t.at[i].set(jnp.where(live, t, jnp.inf)), h=rec.h.at[i].set(h_try),
                      theta_end=rec.theta_end.at[i].set(theta_end), u=rec.u.at[i].set(u),
                      dense=rec.dense.at[i].set(r.dense), mode=rec.mode.at[i].set(mode))

        # --- step size
        fac = jnp.where(err_norm == 0, 10.0, 0.9 * err_norm**expo)
        fac = jnp.where(accept, jnp.clip(fac, 0.2, 10.0), jnp.clip(fac, 0.2, 0.9))
        fac = jnp.where(r.ok, fac, 0.5)
        fac = jnp.where(finite, fac, 0.25)
        h_next = h_try * fac
        h_next = jnp.where(accept & clamped & ~event, jnp.maximum(h_next, s.h), h_next)

        monitor = s.monitor
        if monitor_update is not None:
            new_mon = monitor_update(s.monitor, t, u, r.dense, h_try, theta_end, piece)
            monitor = jax.tree.map(lambda a, b: jnp.where(accept, a, b), new_mon, s.monitor)

        mode_new = jnp.where(event, 1.0 - mode, mode)
        st = s.stats
        stats = Stats(
            num_steps=st.num_steps + accept,
            num_rejected=st.num_rejected + (~accept),
            num_fev=st.num_fev + nfev0 + r.nfev,
            num_jev=st.num_jev + r.njev,
            num_events=st.num_events + event,
        )
        t_acc = jnp.where(accept, t_new, t)
        finished = accept & (t_acc >= t_end)
        stopped = jnp.asarray(False)
        if stop_when is not None:
            stopped = accept & stop_when(monitor)
        too_many = (stats.num_steps + stats.num_rejected) >= max_steps
        too_small = h_next < 1e-14 * jnp.maximum(t_end, 1e-300)
        result = jnp.where(finished, RESULTS.converged,
                           jnp.where(stopped, RESULTS.stopped,
                                     jnp.where(too_small, RESULTS.step_size_too_small,
                                               jnp.where(too_many, RESULTS.max_steps,
                                                         RESULTS.converged))))
        done = finished | stopped | too_many | too_small
        new = _State(
            t=t_acc,
            u=jnp.where(accept, u_new, u),
            f=r.f_new,
            f_valid=accept & solver.fsal & ~event & ~clamped,
            h=h_next,
            mode=jnp.where(accept, mode_new, mode),
            done=done, result=result, stats=stats, monitor=monitor)
        # a finished member of a batch idles (only reachable with axis_name)
        new = jax.tree.map(lambda old, nw: jnp.where(s.done, old, nw), s, new)
        return new, rec

    final, rec = lax.while_loop(cond, body, (state, rec))

    # --- dense output at ts from the record
    if size > 1:
        k = jnp.clip(jnp.searchsorted(rec.t[:size], ts, side="right") - 1, 0, size - 1)
        theta = jnp.clip((ts - rec.t[k]) / rec.h[k], 0.0, rec.theta_end[k])
        us = rec.u[k] + jax.vmap(dense_eval)(rec.dense[k], theta)
        modes = rec.mode[k]
    else:
        us = jnp.where((ts >= t_end)[:, None], final.u[None, :], u0[None, :])
        modes = jnp.full(ts.shape, jnp.nan, dtype)
    beyond = ts > final.t
    us = jnp.where(beyond[:, None], jnp.nan, us)
    us = jnp.where((ts == final.t)[:, None], final.u[None, :], us)
    modes = jnp.where(beyond, jnp.nan, jnp.where(ts == final.t, final.mode, modes))
    if size <= 1:
        modes = jnp.where(ts == 0, jnp.asarray(mode0, dtype), modes)
    return Solution(ts=ts, us=us, modes=modes, t_final=final.t, u_final=final.u,
                    result=final.result, stats=final.stats, monitor=final.monitor)
