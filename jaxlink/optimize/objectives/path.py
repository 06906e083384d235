"""Generic path objectives: `points` (distance of target points to the traced path) and
`ellipse` (fit of the path to an axis-aligned ellipse), and the shape figures of a closed path.

They read nothing but the path of the `[optimize]` point and their own `[optimize]` keys; a
value that only makes sense for one mechanism (target axes, an input speed) is set in that
mechanism's file (e.g. `jaxlink/scenes/sewing-feed-opt.toml`). Registered by
`register_objectives`, which the registry (`jaxlink/optimize/objectives/__init__.py`) calls.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from .base import Objective, number


def register_objectives(register) -> None:
    """Register `points` and `ellipse` with `register(name, factory, keys=...)`."""
    register("points", points_objective, keys=("targets", "smoothing"))
    register("ellipse", ellipse_objective, keys=("axes", "tilt_weight", "part", "rpm"))


# ----------------------------------------------------------------------------- points


def _offsets(ap, ab):
    """Offsets of points from segments: `ap` (…, 2) from each segment's start to the point, `ab`
    (…, 2) the segment; the point minus its projection clipped to the segment (a zero-length
    segment: its start)."""
    ab2 = jnp.sum(ab * ab, axis=-1)
    safe = ab2 > 0
    t = jnp.sum(ap * ab, axis=-1) / jnp.where(safe, ab2, 1.0)
    t = jnp.clip(jnp.where(safe, t, 0.0), 0.0, 1.0)
    return ap - t[..., None] * ab


def _all_offsets(xy, targets, closed: bool = True):
    """(T, N, 2) offsets of every target (T, 2) from every segment of the closed polyline through
    `xy` (N, 2); segment k runs from xy[k] to xy[k+1] (and N-1 to 0). An open polyline (`closed`
    False: a length input's path from its first to its last input) has no closing segment: the
    last one is the point xy[N-1]."""
    nxt = jnp.roll(xy, -1, axis=0) if closed else jnp.concatenate([xy[1:], xy[-1:]])
    return _offsets(targets[:, None, :] - xy[None, :, :], (nxt - xy)[None])


def segment_distances2(xy, targets, closed: bool = True):
    """Squared distance of every target (T, 2) to every segment of the closed (or open: `closed`
    False) polyline through `xy` (N, 2): shape (T, N); segment k runs from xy[k] to xy[k+1] (and
    N-1 to 0 when closed)."""
    d = _all_offsets(xy, targets, closed)
    return jnp.sum(d * d, axis=-1)


WINDOW = 3  # segments on each side of the nearest path point in the smoothed `points` objective


def _window_distances2(xy, targets, idx, closed: bool = True):
    """Squared distance of every target (T, 2) to the segments `idx` (T, K) of the closed
    polyline through `xy` (N, 2) (segment k from xy[k] to xy[k+1 mod N]; open: to xy[min(k+1,
    N−1)]): shape (T, K)."""
    a = xy[idx]  # (T, K, 2)
    n = xy.shape[0]
    d = _offsets(targets[:, None, :] - a, xy[(idx + 1) % n if closed else jnp.minimum(idx + 1, n - 1)] - a)
    return jnp.sum(d * d, axis=-1)


def nearest_offsets(xy, targets, closed: bool = True):
    """(T, 2) offsets of every target from its nearest point of the closed (or open) polyline
    through `xy` (N, 2): Σ |offset|² is the `points` objective's exact value (`segment_distances2`)."""
    d = _all_offsets(xy, targets, closed)  # (T, N, 2)
    k = jnp.argmin(jnp.sum(d * d, axis=-1), axis=1)
    return jnp.take_along_axis(d, k[:, None, None], axis=1)[:, 0]


def points_objective(problem) -> Objective:
    """Untimed path error: SSE = Σ_t min_{s} |T_t − P(s)|², the squared distance of each target
    point to the nearest point of the traced path.

    Exact value: the path is the closed polyline through the sampled positions (for a length
    input, whose samples run from `start` to `stop`, the open one; the distance to
    each segment by projection), so the error of the true curve is O(h²·curvature) — the report
    re-solves with `report_samples` (default 7200) positions. Residuals (for the gradient
    search's least-squares polish): the offsets of the targets from their nearest path points
    (`nearest_offsets`), whose squares sum to the exact value. Smooth value: the min over segments
    replaced by a soft-min with temperature τ = (smoothing · D)², D the targets' bounding-box
    diagonal (smoothing default 1e-5), over the 2W + 1 segments around each target's nearest
    path point (W = `WINDOW` = 3; the others weigh less than exp(−30) unless they nearly tie):
    SSE_τ = Σ_t −τ log Σ_k exp(−d²_tk/τ) (shifted by the min, so it never overflows);
    SSE_τ → SSE as τ → 0 and SSE − T·τ·log(2W + 1) ≤ SSE_τ ≤ SSE. The window makes its
    gradient cost T × 7 distances instead of T × N (the search's value-and-gradient call of 45
    four-bar designs at 360 samples: 205 → 65 ms for the 140 targets of ullah, 44 → 10 ms for
    the 25 of mkh3, same values and gradients).
    """
    raw = problem.option("targets")
    try:
        targets = np.asarray(raw, dtype=float)
    except (TypeError, ValueError):
        targets = None
    if targets is None or targets.ndim != 2 or targets.shape[1] != 2 or len(targets) < 1 or not np.all(
            np.isfinite(targets)):
        raise problem.error("'targets' must be a list of [x, y] points (file length units)", "targets")
    diag = float(np.hypot(*(targets.max(0) - targets.min(0)))) or 1.0
    tau = (number(problem, "smoothing", 1e-5, positive=True) * diag) ** 2
    tg = jnp.asarray(targets)
    closed = getattr(problem, "periodic", True)  # a length input's stroke is an open path

    def value(path):
        return jnp.sum(jnp.min(segment_distances2(path.xy, tg, closed), axis=1))

    def smooth(path):
        # the soft-min over the segments next to each target's nearest path point: with τ this
        # small the others weigh less than exp(−30) unless they tie with them; the nearest point
        # is found without derivative (|q|² − 2 t·q, a matrix product), so the derivative costs
        # T × (2W + 1) distances, not T × N
        xy = path.xy
        n = xy.shape[0]
        q = jax.lax.stop_gradient(xy)
        k = jnp.argmin(jnp.sum(q * q, axis=-1)[None] - 2.0 * tg @ q.T, axis=1)  # (T,)
        w = min(WINDOW, (n - 1) // 2)
        idx = (k[:, None] + jnp.arange(-w, w + 1)[None]) % n  # (T, 2w + 1)
        d2 = _window_distances2(xy, tg, idx, closed)
        m = jax.lax.stop_gradient(jnp.min(d2, axis=1, keepdims=True))
        soft = m[:, 0] - tau * jnp.log(jnp.sum(jnp.exp(-(d2 - m) / tau), axis=1))
        return jnp.sum(soft)

    def metrics(path):
        d2 = jnp.min(segment_distances2(path.xy, tg, closed), axis=1)
        return {"sse": jnp.sum(d2), "rms": jnp.sqrt(jnp.mean(d2)), "max_distance": jnp.sqrt(jnp.max(d2))}

    def residuals(path):
        return nearest_offsets(path.xy, tg, closed).reshape(-1)

    return Objective("points", 0, value, smooth, metrics, residuals=residuals)


# ----------------------------------------------------------------------------- shape of a closed path


def shape_metrics(path, *, omega=None, length_factor=1e-3):
    """Shape figures of a closed path (file units):

    - `two_a`, `two_b`: x and y extent (xmax − xmin, ymax − ymin);
    - `sx`, `sy`: centre of the bounding box;
    - `dx`: tilt Δx = x(y_max) − x(y_min) at the samples;
    - upper part: the points with y ≥ ȳ (the mean height);
    - `sag`: max distance of the upper part from its total-least-squares line;
    - `flatness`: RMS of the upper part's heights about their mean — its deviation from a
      horizontal straight line (0 for a flat top);
    - `peak_acceleration_m_s2`, `peak_acceleration_y_m_s2`: max |d²P/dt²| and max |d²y/dt²|
      over the revolution at input speed `omega` (rad/s; `length_factor`: file length unit in m),
      if `omega` is given and the path has second derivatives.
    """
    x, y = path.xy[:, 0], path.xy[:, 1]
    out = {
        "two_a": jnp.max(x) - jnp.min(x),
        "two_b": jnp.max(y) - jnp.min(y),
        "sx": 0.5 * (jnp.max(x) + jnp.min(x)),
        "sy": 0.5 * (jnp.max(y) + jnp.min(y)),
        "dx": x[jnp.argmax(y)] - x[jnp.argmin(y)],
    }
    w = (y >= jnp.mean(y)).astype(x.dtype)
    out["sag"] = line_deviation(x, y, w, hard=True)
    out["flatness"] = flatness(y, w)
    if path.ddxy is not None and omega is not None:
        acc = jnp.sqrt(jnp.sum(path.ddxy**2, axis=-1)) * omega**2 * length_factor
        out["peak_acceleration_m_s2"] = jnp.max(acc)
        out["peak_acceleration_y_m_s2"] = jnp.max(jnp.abs(path.ddxy[:, 1])) * omega**2 * length_factor
    return out


def flatness(y, w):
    """Weighted RMS of y about its weighted mean: how far the weighted points are from a
    horizontal straight line."""
    sw = jnp.maximum(jnp.sum(w), 1e-12)
    m = jnp.sum(w * y) / sw
    return jnp.sqrt(jnp.sum(w * (y - m) ** 2) / sw)


def line_deviation(x, y, w, *, hard: bool):
    """Distance of the weighted points from their weighted total-least-squares line: max (hard)
    or weighted RMS."""
    sw = jnp.maximum(jnp.sum(w), 1e-12)
    mx, my = jnp.sum(w * x) / sw, jnp.sum(w * y) / sw
    dx, dy = x - mx, y - my
    sxx, syy, sxy = jnp.sum(w * dx * dx) / sw, jnp.sum(w * dy * dy) / sw, jnp.sum(w * dx * dy) / sw
    # smallest eigenvalue of the 2×2 covariance = mean squared normal distance; its eigenvector
    # is the line normal
    tr, det = sxx + syy, sxx * syy - sxy * sxy
    disc = jnp.sqrt(jnp.maximum(0.25 * tr * tr - det, 1e-300))
    lam = 0.5 * tr - disc
    nx, ny = sxy, lam - sxx  # (Σ - λI) n = 0  →  n ∝ (sxy, λ - sxx) (or (λ - syy, sxy))
    alt = jnp.abs(nx) + jnp.abs(ny) < 1e-300
    nx, ny = jnp.where(alt, 0.0, nx), jnp.where(alt, 1.0, ny)
    nn = jnp.sqrt(nx * nx + ny * ny)
    dist = (dx * nx + dy * ny) / nn
    if hard:
        return jnp.max(jnp.where(w > 0, jnp.abs(dist), 0.0))
    return jnp.sqrt(jnp.maximum(lam, 0.0))


def input_speed(problem, default: float | None = None) -> float | None:
    """The input speed ω (rad/s) from the `[optimize]` key `rpm` (revolutions per minute), or
    from `default` rpm; None when neither is set."""
    if problem.option("rpm", default) is None:
        return None
    return number(problem, "rpm", default, positive=True) * 2 * math.pi / 60.0


# ----------------------------------------------------------------------------- ellipse


def ellipse_objective(problem) -> Objective:
    """Fit of the path to an axis-aligned ellipse. With the path points (x_k, y_k),
    k = 0…N−1 (equally spaced inputs over a revolution, file units), the target semi-axes a, b
    (`axes` = [a, b], required, file length units) and the centre (m, n) taken as the centroid
    of the points (for a harmonically traced ellipse the centroid is its centre):

        f_k = (x_k − m)²/a² + (y_k − n)²/b² − 1,
        J   = Σ_k w_k f_k² / Σ_k w_k  +  tilt_weight · (Δx / a)²,

    w_k = 1 (`part = "full"`, default) or, for `part = "working"`, w_k = 1 where y_k ≥ n (the
    upper half of the path; smoothed as a logistic of width 0.05 b for gradients).
    Δx = x(y_max) − x(y_min) (soft arg-max with width 0.02 b in the smooth version);
    `tilt_weight` default 0 (an axis-aligned ellipse fit already penalizes tilt).

    Metrics: `shape_metrics` (with the peak accelerations when the file sets the input speed
    `rpm`) and the centroid (`centroid_x`, `centroid_y`). docs/methods/optimize.md.
    """
    axes = problem.option("axes")
    if (not isinstance(axes, (list, tuple)) or len(axes) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 for v in axes)):
        raise problem.error(f"'axes' must be [a, b], two positive semi-axes in file length units, got {axes!r}",
                            "axes")
    a, b = float(axes[0]), float(axes[1])
    tilt = number(problem, "tilt_weight", 0.0)
    part = problem.option("part", "full")
    if part not in ("full", "working"):
        raise problem.error(f"'part' must be \"full\" or \"working\", got {part!r}", "part")
    omega = input_speed(problem)
    lf = problem.mech.units.length

    def j(path, soft: bool):
        x, y = path.xy[:, 0], path.xy[:, 1]
        m, n = jnp.mean(x), jnp.mean(y)
        f = (x - m) ** 2 / a**2 + (y - n) ** 2 / b**2 - 1.0
        if part == "full":
            w = jnp.ones_like(f)
        elif soft:
            w = jax.nn.sigmoid((y - n) / (0.05 * b))
        else:
            w = (y >= n).astype(f.dtype)
        val = jnp.sum(w * f * f) / jnp.sum(w)
        if tilt:
            if soft:
                wmax = jax.nn.softmax(y / (0.02 * b))
                wmin = jax.nn.softmax(-y / (0.02 * b))
                dx = jnp.sum(wmax * x) - jnp.sum(wmin * x)
            else:
                dx = x[jnp.argmax(y)] - x[jnp.argmin(y)]
            val = val + tilt * (dx / a) ** 2
        return val

    def metrics(path):
        out = shape_metrics(path, omega=omega, length_factor=lf)
        out["centroid_x"] = jnp.mean(path.xy[:, 0])
        out["centroid_y"] = jnp.mean(path.xy[:, 1])
        return out

    return Objective("ellipse", 0, lambda p: j(p, False), lambda p: j(p, True), metrics,
                     report_order=2 if omega is not None else 0)
