"""Jamming thresholds of the sinker: static (closed form) and dynamic (batched bisection).

- **Static self-locking**: the smallest `f` with `D(a2, f) = 0` at the descent angle `a2`
  (`static_threshold`, closed form; independent of m, C, R, F_P, k).
- **Dynamic collapse**: the smallest `f` for which the simulated sinker jams, i.e. after the
  straight rise its velocity turns negative or the lag runs away past 20 mm (see
  `_simulate`). Found per geometry by bisection on `f`; every bisection step simulates all
  geometries at once (`simulate_batch`, stopping each run at its jam), so the cost is
  about `log2(width / tol)` batched simulations.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .simulate import simulate_batch
from .sinker import SinkerParams, static_threshold
from .track import CamTrack


class Thresholds(NamedTuple):
    """Per geometry (numpy `[n_g]`): `static_f`, `dynamic_f` (midpoint of the final
    bracket), the final bracket `lo < dynamic_f <= hi` (`lo` does not jam, `hi` jams), and
    the number of batched simulations used."""

    static_f: np.ndarray
    dynamic_f: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    num_batches: int


def _stack(cam: CamTrack) -> CamTrack:
    return cam if cam.t0.ndim == 2 else jax.tree.map(lambda x: x[None], cam)


def jammed_at(params: SinkerParams, cam: CamTrack, f, **sim_kwargs) -> np.ndarray:
    """Whether each stacked geometry jams at its friction coefficient `f[i]` (`[n_g]`)."""
    cam = _stack(cam)
    n = cam.t0.shape[0]
    f = jnp.broadcast_to(jnp.asarray(f, dtype=float), (n,))
    pb = jax.tree.map(lambda x: jnp.broadcast_to(jnp.asarray(x), (n,)), params)._replace(f=f)
    sol = simulate_batch(pb, cam, stop_on_jam=True, n_out=2, **sim_kwargs)
    return np.asarray(sol.jammed)


def thresholds(params: SinkerParams, cam: CamTrack, *, tol: float = 1e-4,
               half_width: float = 0.01, progress: Callable | None = None,
               jammed: Callable | None = None, **sim_kwargs) -> Thresholds:
    """Static and dynamic jamming thresholds of stacked geometries.

    **Arguments:**

    - `params`: `SinkerParams` with scalar leaves (`f` is ignored).
    - `cam`: stacked `CamTrack` (`make_cam(list_of_geometries, v)`).
    - `tol`: bracket width at which the bisection stops (the midpoint is then within
      `tol / 2` of the threshold of the simulated model).
    - `half_width`: the first bracket is `static_f -/+ half_width`, widened until `lo` does
      not jam and `hi` does.
    - `progress`: optional `callable(n)` called after each batched simulation (a progress bar).
    - `jammed`: optional predicate `jammed(params, cam, f) -> bool [n_g]` that replaces
      `jammed_at` (another integrator or a reference solution; `sim_kwargs` are then unused).
    - `sim_kwargs`: passed to `simulate_batch` (`method`, `rtol`, `atol`, ...).

    **Returns:** `Thresholds`.
    """
    cam = _stack(cam)
    static = np.asarray(static_threshold(cam.descent_angle))
    lo = static - half_width
    hi = static + half_width
    n_batches = 0

    def run(f):
        nonlocal n_batches
        n_batches += 1
        out = (np.asarray(jammed(params, cam, f)) if jammed is not None
               else jammed_at(params, cam, f, **sim_kwargs))
        if progress is not None:
            progress(1)
        return out

    for _ in range(20):  # establish brackets
        j_lo, j_hi = run(lo), run(hi)
        if not j_lo.any() and j_hi.all():
            break
        lo = np.where(j_lo, lo - 2 * half_width, lo)
        hi = np.where(j_hi, hi, hi + 2 * half_width)
        lo = np.maximum(lo, 0.0)
    else:
        raise RuntimeError("could not bracket the dynamic jamming threshold")
    while np.max(hi - lo) > tol:
        mid = 0.5 * (lo + hi)
        j = run(mid)
        active = (hi - lo) > tol
        hi = np.where(active & j, mid, hi)
        lo = np.where(active & ~j, mid, lo)
    return Thresholds(static_f=static, dynamic_f=0.5 * (lo + hi), lo=lo, hi=hi,
                      num_batches=n_batches)


def bisection_steps(width: float, tol: float) -> int:
    """Batched simulations the bisection needs after bracketing: `ceil(log2(width/tol))`."""
    return int(np.ceil(np.log2(width / tol)))
