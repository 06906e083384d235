"""Simulating the sinker on a cam: one case, or a batch (`vmap`) of cases.

`simulate(params, cam, ...)` integrates eq. 4.25 from rest (`y = y' = 0` at `t = 0`, in
contact) over the cam's passage time with the hybrid integrator of `_integrate`, the contact
switch `l = y_z - y = 0` being the guard. `simulate_batch` does the same for stacked cases in
one jitted `vmap`; `product_cases` builds the cases friction x geometry x stiffness.

A *jam* ("vzpriceni", dynamic collapse) is flagged when, after the straight rise
(`t > cam.t_rise`), the sinker velocity `y'` becomes negative or the lag runs away past
`lag_limit` (20 mm); with `stop_on_jam=True` the run ends there (`RESULTS.stopped`).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .integrate import DormandPrince5, RadauIIA5, Stats, dense_eval, integrate_hybrid
from .sinker import SinkerParams, acceleration, lag, vector_field
from .track import CamTrack, cam_eval, cam_segment

SOLVERS = {"explicit": DormandPrince5(), "implicit": RadauIIA5()}

# Measured crossover (docs/methods/sinker.md, experiments/sinker_jamming.py): above this stiffness
# the implicit Radau IIA method needs fewer steps and less time than Dormand-Prince.
AUTO_IMPLICIT_ABOVE = 3e6


class SinkerSolution(NamedTuple):
    """Result of `simulate` (arrays; a batch adds leading axes).

    - `t` (s), `yz` cam lift (m), `y` sinker lift (m), `v` = y' (m/s), `a` = y'' (m/s^2),
      `lag` = y_z - y (m), `N` cam normal force (N), `contact` (1.0/0.0): each `[n_out]`.
    - `jammed` (bool), `t_jam` (s, inf if not jammed).
    - `result`: `RESULTS` code; `stats`: `Stats` (steps, rejected, fev, jev, events).
    """

    t: jnp.ndarray
    yz: jnp.ndarray
    y: jnp.ndarray
    v: jnp.ndarray
    a: jnp.ndarray
    lag: jnp.ndarray
    N: jnp.ndarray
    contact: jnp.ndarray
    jammed: jnp.ndarray
    t_jam: jnp.ndarray
    result: jnp.ndarray
    stats: Stats


def auto_method(C: float) -> str:
    """`"explicit"` below `AUTO_IMPLICIT_ABOVE` N/m, else `"implicit"`."""
    return "implicit" if float(C) > AUTO_IMPLICIT_ABOVE else "explicit"


def _simulate(params: SinkerParams, cam: CamTrack, knobs, *, n_out, method, max_steps,
              event_samples, stop_on_jam, axis_name=None) -> SinkerSolution:
    rtol, atol, max_step, lag_limit, h0 = knobs
    solver = SOLVERS[method]
    dtype = cam.t0.dtype
    ts = jnp.linspace(0.0, 1.0, n_out, dtype=dtype) * cam.t_end
    stops = cam.t0[1:]
    u0 = jnp.zeros(2, dtype=dtype)
    monitor_samples = jnp.arange(1, 9, dtype=dtype) / 8

    def vf(t, u, mode, piece):
        return vector_field(params, cam, t, u, mode, piece)

    def guard(t, u, piece):
        return lag(cam, t, u, piece)

    def piece_of(t):
        return cam_segment(cam, t)

    def monitor_update(carry, t, u, dense, h, theta_end, piece):
        jammed, t_jam = carry
        th = monitor_samples * theta_end
        tt = t + th * h
        uu = u[None, :] + jax.vmap(lambda x: dense_eval(dense, x))(th)
        ll = jax.vmap(lambda a, b: lag(cam, a, b, piece))(tt, uu)
        bad = ((tt > cam.t_rise) & (uu[:, 1] < 0)) | (ll > lag_limit)
        first = jnp.where(jnp.any(bad), tt[jnp.argmax(bad)], jnp.inf)
        return jammed | jnp.any(bad), jnp.minimum(t_jam, first)

    sol = integrate_hybrid(
        vf, guard, piece_of, stops, u0, jnp.asarray(1.0, dtype), cam.t_end, ts,
        solver=solver, rtol=rtol, atol=atol, h0=h0, max_step=max_step, max_steps=max_steps,
        event_samples=event_samples,
        monitor_init=(jnp.asarray(False), jnp.asarray(jnp.inf, dtype)),
        monitor_update=monitor_update,
        stop_when=(lambda c: c[0]) if stop_on_jam else None, axis_name=axis_name)

    def point(t, u, mode):
        k = cam_segment(cam, t)
        acc, normal = acceleration(params, cam, t, u, mode, k)
        return cam_eval(cam, t, k)[0], acc, normal

    yz, acc, normal = jax.vmap(point)(ts, sol.us, jnp.nan_to_num(sol.modes))
    jammed, t_jam = sol.monitor
    return SinkerSolution(t=ts, yz=yz, y=sol.us[:, 0], v=sol.us[:, 1], a=acc,
                          lag=yz - sol.us[:, 0], N=normal, contact=sol.modes, jammed=jammed,
                          t_jam=t_jam, result=sol.result, stats=sol.stats)


_STATIC = ("n_out", "method", "max_steps", "event_samples", "stop_on_jam")


@functools.partial(jax.jit, static_argnames=_STATIC)
def _simulate_jit(params, cam, knobs, **kw):
    return _simulate(params, cam, knobs, **kw)


@functools.partial(jax.jit, static_argnames=_STATIC)
def _simulate_vmap(params, cam, knobs, **kw):
    fn = functools.partial(_simulate, axis_name="cases", **kw)
    return jax.vmap(fn, in_axes=(0, 0, None), axis_name="cases")(params, cam, knobs)


def _kwargs(n_out=1001, method="explicit", rtol=1e-6, atol=1e-10, max_steps=10000,
            max_step=1e-4, event_samples=16, stop_on_jam=False, lag_limit=0.02, h0=1e-7):
    """Split the keyword arguments into traced knobs and static settings."""
    if method not in SOLVERS:
        raise ValueError(f"method must be one of {sorted(SOLVERS)}, not {method!r}")
    knobs = tuple(jnp.asarray(float(x)) for x in (rtol, atol, max_step, lag_limit, h0))
    return knobs, dict(n_out=int(n_out), method=method, max_steps=int(max_steps),
                       event_samples=int(event_samples), stop_on_jam=bool(stop_on_jam))


def simulate(params: SinkerParams, cam: CamTrack, **kwargs) -> SinkerSolution:
    """Integrate one case from rest over the cam passage (jitted).

    **Arguments:**

    - `params`: `SinkerParams` (scalar leaves); `cam`: `CamTrack` of one geometry.
    - `n_out`: number of equally spaced output times on `[0, T]` (default 1001).
    - `method`: `"explicit"` (Dormand-Prince 5(4)) or `"implicit"` (Radau IIA 5).
    - `rtol`, `atol`: tolerances (default 1e-6, 1e-10; state in m and m/s).
    - `max_steps` (10000; also the size of the step record), `max_step` (s, default inf),
      `event_samples` (16), `h0` (1e-7 s).
    - `stop_on_jam`: end the run when a jam is detected; `lag_limit`: runaway lag (m, 0.02).

    **Returns:** a `SinkerSolution`.
    """
    knobs, static = _kwargs(**kwargs)
    return _simulate_jit(params, cam, knobs, **static)


def simulate_batch(params: SinkerParams, cam: CamTrack, **kwargs) -> SinkerSolution:
    """`simulate` over stacked cases in one jitted `vmap`: every leaf of `params` and `cam`
    has the same leading batch axis (see `product_cases`). Same keyword arguments."""
    knobs, static = _kwargs(**kwargs)
    return _simulate_vmap(params, cam, knobs, **static)


def product_cases(params: SinkerParams, cam: CamTrack, *, f=None, C=None, k_over_m=None):
    """Stack the cases friction x geometry x stiffness for `simulate_batch`.

    **Arguments:**

    - `params`: base `SinkerParams` (scalar leaves).
    - `cam`: stacked `CamTrack` of `n_g` geometries (leading axis), see `make_cam`.
    - `f`: `[n_f]` friction coefficients (default: `params.f`).
    - `C`: `[n_C]` stiffnesses (default: `params.C`).
    - `k_over_m`: `[n_C]` damping per mass matching `C` (default: `params.k_over_m` for all).

    **Returns:** `(params_b, cam_b, shape)` with batch size `n_f * n_g * n_C` in that
    (row-major) order; reshape outputs with `shape = (n_f, n_g, n_C)`.
    """
    f = jnp.atleast_1d(jnp.asarray(params.f if f is None else f, dtype=float))
    cc = jnp.atleast_1d(jnp.asarray(params.C if C is None else C, dtype=float))
    if k_over_m is None:
        km = jnp.broadcast_to(jnp.asarray(params.k_over_m, dtype=float), cc.shape)
    else:
        km = jnp.atleast_1d(jnp.asarray(k_over_m, dtype=float))
    n_f, n_c = f.shape[0], cc.shape[0]
    n_g = cam.t0.shape[0] if cam.t0.ndim == 2 else 1
    if cam.t0.ndim == 1:
        cam = jax.tree.map(lambda x: x[None], cam)
    shape = (n_f, n_g, n_c)
    fi, gi, ci = (np.ravel(a) for a in np.meshgrid(np.arange(n_f), np.arange(n_g), np.arange(n_c), indexing="ij"))
    n = fi.size
    pb = params._replace(f=f[fi], C=cc[ci], k_over_m=km[ci])
    pb = jax.tree.map(lambda x: jnp.broadcast_to(jnp.asarray(x), (n,) + jnp.shape(x)[1:])
                      if jnp.ndim(x) == 0 else x, pb)
    cb = jax.tree.map(lambda x: x[gi], cam)
    return pb, cb, shape


class Maxima(NamedTuple):
    """Peak values of one run, per phase (as Tables 5.1-5.5 of the thesis; docs/studies/sinker.md).

    `rise_*` over the straight rise `[0, t_rise]`, `desc_*` over the straight descent
    `[t_descent, T]` (as the thesis's tables; the transition arc is in neither); accelerations
    in m/s^2, velocities in m/s, lags in m.
    `bounce_depth` (m) = max of `-(y_z - y)` in the rise (0 without a bounce) and
    `bounce_time` (s) = how long the contact is lost in the rise.
    """

    rise_a: float
    rise_v: float
    rise_lag: float
    desc_a: float
    desc_v: float
    desc_lag: float
    bounce_depth: float
    bounce_time: float


def maxima(sol: SinkerSolution, cam: CamTrack) -> Maxima:
    """Peak values of one solution on its output grid (numpy; see `Maxima`)."""
    t = np.asarray(sol.t)
    a, v, lg = np.asarray(sol.a), np.asarray(sol.v), np.asarray(sol.lag)
    rise = t <= float(cam.t_rise)
    desc = t >= float(cam.t_descent)
    dt = t[1] - t[0]

    def mx(x, m):
        x = x[m]
        x = x[np.isfinite(x)]
        return float(np.max(x)) if x.size else float("nan")

    lost = rise & (lg < 0)
    return Maxima(
        rise_a=mx(a, rise), rise_v=mx(v, rise), rise_lag=mx(lg, rise),
        desc_a=mx(a, desc), desc_v=mx(v, desc), desc_lag=mx(lg, desc),
        bounce_depth=max(0.0, mx(-lg, rise)), bounce_time=float(np.sum(lost) * dt))
