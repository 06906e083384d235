"""Objective registry: each objective maps the traced path of the chosen point to a number.

An objective is built from the `Problem` by a factory registered under its name
(`@OBJECTIVES.register("name", keys=(...))`); the factory returns an `Objective`:

- `order`: derivatives of the path the objective needs (0: positions; 2: + d/dφ, d²/dφ²),
- `value(path)`: the objective evaluated exactly at the sampled path (ranking, reports),
- `smooth(path)`: a smoothed version with useful gradients (the gradient search),
- `metrics(path)`: named numbers for the report (2a, 2b, centre, …);
- optionally `constraints(path) -> (f, c, value)`: a smooth objective f and constraint values
  c (K,) with c[:equalities] = 0 and c[equalities:] ≤ 0 wanted (normalized), and the exact
  `value(path)` from the same intermediates, for the constrained gradient solver
  (`gradient_solver = "al-lbfgs"`, `_search.py`);
- optionally `rank(path) -> (value, rank)`: the exact value and the value by which the
  constrained gradient search picks its starts from the presample (default: `value` for both).

`path` is a `PathData` in the file's units (lengths in `length_unit`, derivatives per radian of
input), with the solved configuration `q` and the parameters `p` (SI) for objectives that need
more than the point's path (the needle `dwell`: transmission, rod and toggle angles). A later
objective plugs in by registering a factory here.
"""

from __future__ import annotations

import math
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


class PathData(NamedTuple):
    """The traced path of the point, file length units, and the solved configuration.

    - `xy`: (N, 2) positions at the sampled inputs (a full revolution, equally spaced).
    - `dxy`, `ddxy`: (N, 2) first and second derivatives w.r.t. the input (per rad), or None.
    - `q`: (N, n) the solved unknowns at the same inputs (SI: rad, m), or None.
    - `p`: (P,) the design's parameters (SI), or None.
    """

    xy: jax.Array
    dxy: jax.Array | None = None
    ddxy: jax.Array | None = None
    q: jax.Array | None = None
    p: jax.Array | None = None


class Objective(NamedTuple):
    name: str
    order: int
    value: Callable
    smooth: Callable
    metrics: Callable
    report_order: int = 0
    constraints: Callable | None = None
    equalities: int = 0
    rank: Callable | None = None


class _Registry:
    def __init__(self):
        self._factories: dict[str, Callable] = {}
        self._keys: dict[str, tuple] = {}

    def register(self, name: str, *, keys: tuple = ()):
        """Decorator: register `factory(problem) -> Objective` under `name`; `keys` are the
        `[optimize]` keys it reads (so the parser accepts them)."""

        def deco(factory):
            self._factories[name] = factory
            self._keys[name] = tuple(keys)
            return factory

        return deco

    def __contains__(self, name) -> bool:
        return name in self._factories

    def __iter__(self):
        return iter(self._factories)

    def known_keys(self) -> set:
        return {k for ks in self._keys.values() for k in ks}

    def build(self, problem) -> Objective:
        return self._factories[problem.objective](problem)


OBJECTIVES = _Registry()


def _number(problem, key, default, *, positive=False):
    v = problem.option(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (positive and v <= 0):
        raise problem.error(f"'{key}' must be a {'positive ' if positive else ''}finite number, got {v!r}", key)
    return float(v)


# ----------------------------------------------------------------------------- points


def segment_distances2(xy, targets):
    """Squared distance of every target (T, 2) to every segment of the closed polyline through
    `xy` (N, 2): shape (T, N); segment k runs from xy[k] to xy[k+1] (and N-1 to 0)."""
    a = xy
    b = jnp.roll(xy, -1, axis=0)
    ab = b - a  # (N, 2)
    ab2 = jnp.sum(ab * ab, axis=-1)
    safe = ab2 > 0
    ap = targets[:, None, :] - a[None, :, :]  # (T, N, 2)
    t = jnp.sum(ap * ab[None], axis=-1) / jnp.where(safe, ab2, 1.0)[None]
    t = jnp.clip(jnp.where(safe[None], t, 0.0), 0.0, 1.0)
    d = ap - t[..., None] * ab[None]
    return jnp.sum(d * d, axis=-1)


@OBJECTIVES.register("points", keys=("targets", "smoothing"))
def points_objective(problem) -> Objective:
    """Untimed path error: SSE = Σ_t min_{s} |T_t − P(s)|², the squared distance of each target
    point to the nearest point of the traced path.

    Exact value: the path is the closed polyline through the sampled positions (the distance to
    each segment by projection), so the error of the true curve is O(h²·curvature) — the report
    re-solves with `report_samples` (default 7200) positions. Smooth value: the min over segments
    replaced by a soft-min with temperature τ = (smoothing · D)², D the targets' bounding-box
    diagonal (smoothing default 1e-5): SSE_τ = Σ_t −τ log Σ_k exp(−d²_tk/τ) (shifted by the min,
    so it never overflows); SSE_τ → SSE as τ → 0 and SSE − T·τ·log N ≤ SSE_τ ≤ SSE.
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
    tau = (_number(problem, "smoothing", 1e-5, positive=True) * diag) ** 2
    tg = jnp.asarray(targets)

    def value(path):
        return jnp.sum(jnp.min(segment_distances2(path.xy, tg), axis=1))

    def smooth(path):
        d2 = segment_distances2(path.xy, tg)
        m = jax.lax.stop_gradient(jnp.min(d2, axis=1, keepdims=True))
        soft = m[:, 0] - tau * jnp.log(jnp.sum(jnp.exp(-(d2 - m) / tau), axis=1))
        return jnp.sum(soft)

    def metrics(path):
        d2 = jnp.min(segment_distances2(path.xy, tg), axis=1)
        return {"sse": jnp.sum(d2), "rms": jnp.sqrt(jnp.mean(d2)), "max_distance": jnp.sqrt(jnp.max(d2))}

    return Objective("points", 0, value, smooth, metrics)


# ----------------------------------------------------------------------------- feed path (seed 000)


def feed_metrics(path, *, omega=None, length_factor=1e-3):
    """Shape figures of a feed path (file units), as the seed reports them, and more:

    - `two_a`, `two_b`: x and y extent (xmax − xmin, ymax − ymin), the seed's 2a, 2b;
    - `sx`, `sy`: centre of the bounding box (the seed's s_x, s_y);
    - `dx`: tilt Δx = x(y_max) − x(y_min) at the samples (the seed's `os`);
    - working part: the points with y ≥ ȳ (the mean height; above the needle plate, the half of
      the path that feeds the cloth);
    - `sag`: max distance of the working part from its total-least-squares line;
    - `flatness`: RMS of the working part's heights about their mean — its deviation from a
      horizontal straight line (0 for a flat top moving parallel to the plate);
    - `peak_acceleration_m_s2`: max |d²P/dt²| over the revolution at input speed `omega` (rad/s),
      if the path has second derivatives.
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
    out["sag"] = _line_deviation(x, y, w, hard=True)
    out["flatness"] = _flatness(y, w)
    if path.ddxy is not None and omega is not None:
        acc = jnp.sqrt(jnp.sum(path.ddxy**2, axis=-1)) * omega**2 * length_factor
        out["peak_acceleration_m_s2"] = jnp.max(acc)
        out["peak_acceleration_y_m_s2"] = jnp.max(jnp.abs(path.ddxy[:, 1])) * omega**2 * length_factor
    return out


def _flatness(y, w):
    """Weighted RMS of y about its weighted mean: how far the working part is from a horizontal
    (parallel to the needle plate) straight line."""
    sw = jnp.maximum(jnp.sum(w), 1e-12)
    m = jnp.sum(w * y) / sw
    return jnp.sqrt(jnp.sum(w * (y - m) ** 2) / sw)


def _line_deviation(x, y, w, *, hard: bool):
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


def _omega(problem):
    rpm = _number(problem, "rpm", 5490.0, positive=True)
    return rpm * 2 * math.pi / 60.0


@OBJECTIVES.register("ellipse", keys=("axes", "tilt_weight", "part", "rpm"))
def ellipse_objective(problem) -> Objective:
    """The seed-000 feed objective. With the path points (x_k, y_k), k = 0…N−1 (equally spaced
    crank angles over a revolution, file units), the target semi-axes a, b (`axes`, default
    [2.5, 1.0] mm: stroke 2a = 5 mm, lift 2b = 2 mm) and the centre (m, n) taken as the centroid
    of the points (the seed leaves m, n "free"; for a harmonically traced ellipse the centroid is
    its centre):

        f_k = (x_k − m)²/a² + (y_k − n)²/b² − 1,
        J   = Σ_k w_k f_k² / Σ_k w_k  +  tilt_weight · (Δx / a)²,

    w_k = 1 (`part = "full"`, default: the seed's programs used all points) or, for
    `part = "working"`, w_k = 1 where y_k ≥ n (the half above the needle plate; smoothed as a
    logistic of width 0.05 b for gradients). Δx = x(y_max) − x(y_min) (soft arg-max with width
    0.02 b in the smooth version); `tilt_weight` default 0 (an axis-aligned ellipse fit already
    penalizes tilt). The seed did not minimize J itself: its programs stepped l2, l22, γ until
    the bounds 2a ≥ 5 mm, 2b ≥ 2 mm and |Δx| ≤ 0.3 mm held (see docs/optimize.md).
    """
    axes = problem.option("axes", [2.5, 1.0])
    if (not isinstance(axes, (list, tuple)) or len(axes) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 for v in axes)):
        raise problem.error(f"'axes' must be [a, b], two positive semi-axes in file length units, got {axes!r}",
                            "axes")
    a, b = float(axes[0]), float(axes[1])
    tilt = _number(problem, "tilt_weight", 0.0)
    part = problem.option("part", "full")
    if part not in ("full", "working"):
        raise problem.error(f"'part' must be \"full\" or \"working\", got {part!r}", "part")
    omega = _omega(problem)
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
        out = feed_metrics(path, omega=omega, length_factor=lf)
        out["centroid_x"] = jnp.mean(path.xy[:, 0])
        out["centroid_y"] = jnp.mean(path.xy[:, 1])
        return out

    return Objective("ellipse", 0, lambda p: j(p, False), lambda p: j(p, True), metrics, report_order=2)


@OBJECTIVES.register("feed", keys=("stroke", "lift", "acceleration_weight", "acceleration_ref", "rpm", "penalty"))
def feed_objective(problem) -> Objective:
    """Beyond the seed: a straight working part and a low peak acceleration at a given stroke.

    With the working part W = {k : y_k ≥ ȳ} (ȳ the mean height: the half of the path above the
    needle plate; logistic weights of width 0.025·lift in the smooth version), s_W the RMS of its
    heights about their mean (`flatness`, mm: the deviation from a straight line parallel to the
    plate — a tilted or degenerate back-and-forth path scores badly), the stroke
    2a = max x − min x and lift 2b = max y − min y at the samples, A_k = |d²P/dt²| at `rpm`
    (default 5490 rpm = 575 rad/s) and A_p its peak ((mean_k A_k^8)^{1/8} in the smooth version):

        J = s_W² / (lift/2)² + acceleration_weight · (A_p / acceleration_ref)²
            + penalty · [((stroke − 2a)₊ / stroke)² + ((lift − 2b)₊ / lift)²]

    (`stroke` default 5 mm, `lift` 2 mm, `acceleration_weight` 1, `acceleration_ref` 1000 m/s²,
    `penalty` 10⁴): stroke and lift are lower bounds, enforced by quadratic penalties.
    """
    stroke = _number(problem, "stroke", 5.0, positive=True)
    lift = _number(problem, "lift", 2.0, positive=True)
    wacc = _number(problem, "acceleration_weight", 1.0)
    aref = _number(problem, "acceleration_ref", 1000.0, positive=True)
    pen = _number(problem, "penalty", 1e4, positive=True)
    omega = _omega(problem)
    lf = problem.mech.units.length

    def j(path, soft: bool):
        x, y = path.xy[:, 0], path.xy[:, 1]
        n = jnp.mean(y)
        w = jax.nn.sigmoid((y - n) / (0.025 * lift)) if soft else (y >= n).astype(x.dtype)
        sag = _flatness(y, w)
        acc = jnp.sqrt(jnp.sum(path.ddxy**2, axis=-1) + 1e-30) * omega**2 * lf
        peak = jnp.mean(acc**8) ** (1 / 8) if soft else jnp.max(acc)
        two_a, two_b = jnp.max(x) - jnp.min(x), jnp.max(y) - jnp.min(y)
        return ((sag / (0.5 * lift)) ** 2 + wacc * (peak / aref) ** 2
                + pen * (jnp.maximum(stroke - two_a, 0.0) / stroke) ** 2
                + pen * (jnp.maximum(lift - two_b, 0.0) / lift) ** 2)

    def metrics(path):
        return feed_metrics(path, omega=omega, length_factor=lf)

    return Objective("feed", 2, lambda p: j(p, False), lambda p: j(p, True), metrics, report_order=2)


def to_python(tree) -> Any:
    """Arrays → floats (JSON-ready); non-finite → None."""
    def conv(v):
        v = float(np.asarray(v))
        return v if math.isfinite(v) else None

    return {k: conv(v) for k, v in tree.items()}


from ..analysis import dwell as _dwell  # noqa: E402, F401  (registers the needle objective "dwell", jaxlink/_dwell.py)
