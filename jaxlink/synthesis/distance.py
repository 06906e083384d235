r"""The distance between a traced curve and a target, as the field reports it, and its smooth
surrogate for gradients.

**The distance** (`match`, NumPy, float64) does not depend on where either curve's samples start.
Both curves are resampled to n points equally spaced in arclength (`arclength_resample`: a closed
curve along the loop, n spacings; an open one from end to end, n − 1 spacings; n = `N_FINE` =
2000), then each is *normalised*: translated to zero mean and scaled to unit RMS radius,

.. math::  \hat a_i = (a_i - \bar a) / s_a,\quad s_a = \sqrt{\tfrac1n\sum_i |a_i - \bar a|^2}.

The distance is the symmetric chamfer of each curve's points to the other's *polyline* (the
segments through its points; closed: with the closing one) at the best rotation R(φ) of the curve,

.. math::  D = \min_\varphi\; \frac1n\sum_i d(R(\varphi)\hat a_i, \hat B)
               + \frac1n\sum_j d(\hat b_j, R(\varphi)\hat A) ,

d(p, P) the Euclidean distance of p to the nearest point of polyline P (exact: `_Polyline`). A
point's distance to the other's *points* (`match_points`, below) depends on where it falls between
them — up to half a spacing along the curve — so that chamfer depends on where each curve's
samples start: the search chooses the crank's start, and on a closed target it could align its
samples with the target's (one planted four-bar's curve scored 0.00017–0.024 at 200 points
depending on its start alone; this distance 0.000166–0.000167). To a polyline the tangential part
vanishes; what remains of the start is the mean's quadrature, < 1 % at 2000 points
(`tests/test_synthesis_metric.py`). φ: the point chamfer of every tenth point (about 200 of each
curve, `_SUB`) at 120 angles (3°), golden sections on the four best brackets (those points to every
point of the other) to 1e-4 rad, then Brent's method (scipy) on the whole distance within
± 2e-3 rad of the best to 1e-9 rad (and the best bracket's grid angle: a curve against itself is
at 0 there exactly).

**LInK's metric** (`link_chamfer`, `match_points`): the *point* chamfer, each nearest-neighbour
distance to the other curve's resampled points, of both curves resampled to n = `LINK_N` = 2000
points and normalised,

.. math::  D_L = \min_\varphi\; \frac1n\sum_i \min_j |R(\varphi)\hat a_i - \hat b_j|
               + \frac1n\sum_j \min_i |R(\varphi)\hat a_i - \hat b_j| ,

the *sum* of the two mean Euclidean nearest-neighbour distances (not squared), the evaluation of
LInK (Nobari et al. 2024) at 2000 points, reported beside D so that the numbers compare with
others'. It moves with the samples' start by up to about (perimeter of the normalised curve) /
(2n) (≤ 0.002 at n = 2000; 0.02 at n = 200). φ: the coarse stage as above, then around each
coarse minimum within 0.01 of the best the whole chamfer at 41 angles across ± 0.01 rad (it has
local minima about 2e-3 rad apart where the samples slide past each other) and a golden section
from the least to 1e-10 rad. `best_rotation` (grid of 120 angles and golden sections on the four
best, to 1e-13 rad) is `match_points`' search at any n. No reflection in either: a mirrored curve
is another curve.

**The placement** maps the mechanism's coordinates onto the target's: x ↦ k R(φ) x + t with
k = s_b / s_a and t = b̄ − k R(φ) ā; the placed curve's normalised form is R(φ)â, so its distance
to the target is D at φ = 0.

**The ordered distance** (`ordered_distance`, for a timed target: points at given input angles):
the same normalisation without resampling (point i of the curve against point i of the target),
the rotation in closed form (2-D Kabsch, φ = atan2(Σ â×b̂, Σ â·b̂), the least-squares rotation),
and the RMS of |R â_i − b̂_i|. `match_ordered` adds the placement (the same k, t as above): the
distance of a timed target's match.

**The surrogate** (`soft_chamfer`, JAX, differentiable): the curve's samples weighted by their
share of arclength (trapezoid), normalised with those weights, and each nearest-neighbour minimum
replaced by a soft minimum −τ log Σ exp(−d/τ) (τ small), distances smoothed as √(d² + ε²).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .target import arclength_resample

#: points per curve in the point chamfer (`match_points`) and of the target in the surrogate
N_POINTS = 200
#: points per curve in the phase-free distance (`match`)
N_FINE = 2000
#: points per curve in LInK's metric (`link_chamfer`)
LINK_N = 2000
#: the rotation search's coarse stage takes every k-th point, k = n // `_SUB` (at least 1): about 200
_SUB = 200
#: the half-width (rad) of the fine stage's bracket around the coarse minimum
_FINE_W = 2e-3
#: the coarse stage's golden sections stop at brackets of this width (rad)
_COARSE_TOL = 1e-4
#: LInK's metric: the coarse minima within this of the best are refined, each over ± `_LINK_W` rad
#: at `_LINK_SCAN` angles, then by golden section
_LINK_MARGIN = 0.01
_LINK_W = 1e-2
_LINK_SCAN = 41
_GRID = 120
_REFINE = 4
_GOLD = 0.6180339887498949


class Match(NamedTuple):
    """A curve matched to a target.

    - `distance`: D (dimensionless: in units of the target's RMS radius);
    - `rotation`: φ (rad), `scale`: k, `translation`: t (2,), in the target's unit: the placement
      x ↦ k R(φ) x + t of the curve onto the target (module doc).
    """

    distance: float
    rotation: float
    scale: float
    translation: np.ndarray


def normalise(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(normalised points, mean, RMS radius): zero mean, unit RMS radius."""
    pts = np.asarray(points, float)
    mean = pts.mean(axis=0)
    c = pts - mean
    s = float(np.sqrt(np.mean(np.sum(c * c, axis=1))))
    return c / s, mean, s


def chamfer(a: np.ndarray, b: np.ndarray) -> float:
    """Mean nearest-neighbour distance a → b plus b → a (Euclidean, not squared)."""
    return float(_chamfer_rotated(a, b, [0.0])[0])


def _rot(phi):
    c, s = np.cos(phi), np.sin(phi)
    return np.array([[c, -s], [s, c]])


def _chamfer_rotated(a, b, phis, trees=None):
    """The chamfer of R(φ)a against b for each φ: R(φ)a queried in b's k-d tree, R(−φ)b in a's (the
    same distances), so that both trees are built once. All the angles in one query of each tree
    (a Python loop of one query per angle took most of a search's scoring time); each point's
    distance and each angle's mean are the ones a query per angle gives, bit for bit."""
    from scipy.spatial import cKDTree

    ta, tb = trees if trees is not None else (cKDTree(a), cKDTree(b))
    phis = np.asarray(phis, float)
    if phis.size == 0:
        return np.empty(0)
    rs = [_rot(phi) for phi in phis]
    da = tb.query(np.concatenate([a @ r.T for r in rs]))[0].reshape(len(phis), len(a))
    db = ta.query(np.concatenate([b @ r for r in rs]))[0].reshape(len(phis), len(b))
    return np.array([x.mean() for x in da]) + np.array([y.mean() for y in db])


def best_rotation(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(φ, D): the rotation of the normalised curve `a` nearest to `b` (module doc) and the chamfer there."""
    from scipy.spatial import cKDTree

    trees = (cKDTree(a), cKDTree(b))
    grid = 2 * np.pi * np.arange(_GRID) / _GRID
    f = _chamfer_rotated(a, b, grid, trees)
    local = np.flatnonzero((f <= np.roll(f, 1)) & (f <= np.roll(f, -1)))
    starts = local[np.argsort(f[local])][:_REFINE]
    h = grid[1]
    lo, hi = grid[starts] - h, grid[starts] + h  # every bracket at once
    x1, x2 = hi - _GOLD * (hi - lo), lo + _GOLD * (hi - lo)
    f1, f2 = _chamfer_rotated(a, b, x1, trees), _chamfer_rotated(a, b, x2, trees)
    while np.max(hi - lo) > 1e-13:
        left = f1 <= f2  # the minimum lies in [lo, x2]
        lo, hi = np.where(left, lo, x1), np.where(left, x2, hi)
        xn = np.where(left, hi - _GOLD * (hi - lo), lo + _GOLD * (hi - lo))
        fn = _chamfer_rotated(a, b, xn, trees)
        x1, x2, f1, f2 = (np.where(left, xn, x2), np.where(left, x1, xn),
                          np.where(left, fn, f2), np.where(left, f1, fn))
    xs, fs = np.concatenate([grid[starts], x1, x2]), np.concatenate([f[starts], f1, f2])
    k = int(np.argmin(fs))
    best_phi, best = float(xs[k]), float(fs[k])
    return float(np.mod(best_phi, 2 * np.pi)), best


def match_points(curve: np.ndarray, target: np.ndarray, *, closed: bool, n: int = N_POINTS) -> Match:
    """The point chamfer of `curve` to `target` at the best rotation (both resampled to n points,
    module doc: **LInK's metric** at n = `LINK_N`) and the placement it gives. It depends on where
    each curve's samples start (`match` does not)."""
    a, abar, sa = normalise(arclength_resample(curve, n, closed))
    b, bbar, sb = normalise(arclength_resample(target, n, closed))
    phi, d = best_rotation(a, b)
    k = sb / sa
    t = bbar - k * _rot(phi) @ abar
    return Match(d, phi, k, t)


def link_chamfer(curve: np.ndarray, target: np.ndarray, *, closed: bool, n: int = LINK_N) -> float:
    """LInK's metric: the point chamfer at the best rotation of both curves resampled to n = 2000
    points by arclength and normalised (module doc). The rotation: about 200 points' (`_SUB`) chamfer at
    120 angles, golden section on the four best brackets (those points against every point of the
    other) to `_COARSE_TOL`; then, around each bracket's minimum within `_LINK_MARGIN` of the best,
    the whole chamfer at `_LINK_SCAN` angles across ± `_LINK_W` (it has local minima about 2e-3 rad
    apart: the samples slide past each other) and a golden section from the least to 1e-10 rad."""
    from scipy.spatial import cKDTree

    a = normalise(arclength_resample(curve, n, closed))[0]
    b = normalise(arclength_resample(target, n, closed))[0]
    ta, tb = cKDTree(a), cKDTree(b)
    sa, sb = a[::max(1, n // _SUB)], b[::max(1, n // _SUB)]
    grid = 2 * np.pi * np.arange(_GRID) / _GRID
    f = _chamfer_rotated(sa, sb, grid)
    local = np.flatnonzero((f <= np.roll(f, 1)) & (f <= np.roll(f, -1)))
    starts = grid[local[np.argsort(f[local])][:_REFINE]]
    xs, fs = _golden(lambda phis: _vertex_chamfer(sa, ta, sb, tb, phis), starts - grid[1], starts + grid[1],
                     _COARSE_TOL)
    best = np.inf
    done: list[float] = []
    for phi in xs[np.argsort(fs)][np.sort(fs) <= np.min(fs) + _LINK_MARGIN]:
        if any(abs((phi - x + np.pi) % (2 * np.pi) - np.pi) < _LINK_W / 2 for x in done):
            continue  # the same bracket's other end
        done.append(phi)
        near_a, near_b = _NearPoints(a, b, tb, phi, _LINK_W), _NearPoints(b, a, ta, -phi, _LINK_W)

        def full(phis, near_a=near_a, near_b=near_b):
            return np.array([near_a.distance(x).mean() + near_b.distance(-x).mean() for x in phis])

        scan = phi + np.linspace(-_LINK_W, _LINK_W, _LINK_SCAN)
        fscan = full(scan)
        step = scan[1] - scan[0]
        x0 = scan[int(np.argmin(fscan))]
        _, fg = _golden(full, np.array([x0 - step]), np.array([x0 + step]), 1e-10)
        best = min(best, float(np.min(fscan)), float(np.min(fg)))
    return best


class _NearPoints:
    """The nearest-point distances of the points `pts` rotated by any φ within `w` of `phi` to the
    points `other` (k-d tree `tree`): each point's `k` nearest at `phi` gathered once, kept where
    exact (a point at radius r moves by at most r w: its nearest at φ, at most d away, is within
    d + r w of it at `phi`), the others queried again."""

    def __init__(self, pts, other, tree, phi: float, w: float, k: int = 12):
        self.pts, self.tree = pts, tree
        dk, ik = tree.query(pts @ _rot(phi).T, min(k, len(other)))
        self.cand = other[ik]
        self.reach = (dk[:, -1] if k < len(other) else np.full(len(pts), np.inf)) - \
            np.sqrt(np.sum(pts * pts, axis=1)) * w

    def distance(self, phi: float) -> np.ndarray:
        q = self.pts @ _rot(phi).T
        dx, dy = q[:, 0:1] - self.cand[..., 0], q[:, 1:2] - self.cand[..., 1]
        d = np.sqrt(np.min(dx * dx + dy * dy, axis=1))
        bad = np.flatnonzero(self.reach <= d)
        if bad.size:
            d[bad] = self.tree.query(q[bad])[0]
        return d


# ------------------------------------------------------------------- the phase-free distance
class _Polyline:
    """A polyline (closed: with the segment from the last point to the first) for exact distances
    from points to it: its segments and a k-d tree of its vertices."""

    def __init__(self, pts: np.ndarray, closed: bool):
        from scipy.spatial import cKDTree

        n = len(pts)
        self.pts = pts
        self.start = pts if closed else pts[:-1]
        self.vec = (np.roll(pts, -1, axis=0) if closed else pts[1:]) - self.start
        self.vv = np.sum(self.vec * self.vec, axis=1)
        m = len(self.start)
        i = np.arange(n)
        # the segments that end at each vertex (an open end's one twice)
        self.adj = (np.stack([(i - 1) % m, i], 1) if closed
                    else np.stack([np.maximum(i - 1, 0), np.minimum(i, m - 1)], 1))
        self.h2 = float(self.vv.max()) / 4.0  # (half the longest segment)²
        self.tree = cKDTree(pts)

    def segments(self, q: np.ndarray, k: int):
        """The segments of the k vertices nearest to each point of q: (their (Q, 2k) indices, the
        k-th vertex's distance (Q,))."""
        k = min(k, len(self.pts))
        dk, ik = self.tree.query(q, k)
        if k == 1:
            dk, ik = dk[:, None], ik[:, None]
        return self.adj[ik].reshape(len(q), -1), (dk[:, -1] if k < len(self.pts) else np.full(len(q), np.inf))

    def distance(self, q: np.ndarray, k: int = 3) -> np.ndarray:
        """The exact distance of each point of q (Q, 2) to the polyline. The nearest point lies on a
        segment whose nearer end is within √(d² + h²/4) of q (d: the least distance found, h: the
        longest segment); each point whose k-th nearest vertex is not further than that is done
        again with 4k vertices (all of them at most: every segment)."""
        seg, dk = self.segments(q, k)
        d = _to_segments(q, self.start[seg], self.vec[seg], self.vv[seg])
        bad = np.flatnonzero(dk * dk <= d * d + self.h2)
        if bad.size:
            d[bad] = self.distance(q[bad], 4 * k)
        return d


def _to_segments(q, start, vec, vv) -> np.ndarray:
    """The least distance of each point q (Q, 2) to its segments start + t vec, t ∈ [0, 1] (Q, K, 2)."""
    ax, ay = q[:, 0:1] - start[..., 0], q[:, 1:2] - start[..., 1]
    vx, vy = vec[..., 0], vec[..., 1]
    t = np.clip((ax * vx + ay * vy) / np.where(vv > 0, vv, 1.0), 0.0, 1.0)
    rx, ry = ax - t * vx, ay - t * vy
    return np.sqrt(np.min(rx * rx + ry * ry, axis=1))


class _Near:
    """The distances of the points `pts` (unrotated) rotated by any φ within `w` of `phi` to a
    polyline: each point's candidate segments gathered once (its `k` nearest vertices at `phi`),
    kept where exact (a rotation by at most w moves a point at radius r by at most r w: the
    nearest point's segment has an end within √(d² + h²/4) + r w of the point at `phi`), the
    others measured again (`_Polyline.distance`)."""

    def __init__(self, pts, poly: _Polyline, phi: float, w: float, k: int = 8):
        self.pts, self.poly = pts, poly
        seg, dk = poly.segments(pts @ _rot(phi).T, k)
        self.start, self.vec, self.vv = poly.start[seg], poly.vec[seg], poly.vv[seg]
        self.reach = dk - np.sqrt(np.sum(pts * pts, axis=1)) * w

    def distance(self, phi: float) -> np.ndarray:
        q = self.pts @ _rot(phi).T
        d = _to_segments(q, self.start, self.vec, self.vv)
        bad = np.flatnonzero((self.reach <= 0) | (self.reach * self.reach <= d * d + self.poly.h2))
        if bad.size:
            d[bad] = self.poly.distance(q[bad])
        return d


class _Curve(NamedTuple):
    """A curve resampled to n points by arclength and normalised (`normalise`): the polyline through
    them, its mean and RMS radius (of the resampled points)."""

    poly: _Polyline
    mean: np.ndarray
    rms: float


def _curve(points: np.ndarray, n: int, closed: bool) -> _Curve:
    pts, mean, s = normalise(arclength_resample(points, n, closed))
    return _Curve(_Polyline(pts, closed), mean, s)


@functools.lru_cache(maxsize=8)
def _target_curve(data: bytes, shape: tuple, n: int, closed: bool) -> _Curve:
    """`_curve` of a target, kept (a search matches every candidate to the same target)."""
    return _curve(np.frombuffer(data, float).reshape(shape), n, closed)


def _vertex_chamfer(a, ta, b, tb, phis) -> np.ndarray:
    """For each φ: the mean distance of R(φ)a to the vertices of tree `tb` plus that of R(−φ)b to
    `ta`'s (the rotation search's coarse stage: a, b about 200 points of each curve, `_SUB`)."""
    rs = [_rot(phi) for phi in phis]
    da = tb.query(np.concatenate([a @ r.T for r in rs]))[0].reshape(len(phis), len(a))
    db = ta.query(np.concatenate([b @ r for r in rs]))[0].reshape(len(phis), len(b))
    return da.mean(axis=1) + db.mean(axis=1)


def _golden(f, lo, hi, tol: float):
    """Golden-section searches on the brackets [lo, hi] (arrays) at once, `f` of an array of angles;
    (angles, values) of the last points of every bracket."""
    x1, x2 = hi - _GOLD * (hi - lo), lo + _GOLD * (hi - lo)
    f1, f2 = f(x1), f(x2)
    while np.max(hi - lo) > tol:
        left = f1 <= f2  # the minimum lies in [lo, x2]
        lo, hi = np.where(left, lo, x1), np.where(left, x2, hi)
        xn = np.where(left, hi - _GOLD * (hi - lo), lo + _GOLD * (hi - lo))
        fn = f(xn)
        x1, x2, f1, f2 = (np.where(left, xn, x2), np.where(left, x1, xn),
                          np.where(left, fn, f2), np.where(left, f1, fn))
    return np.concatenate([x1, x2]), np.concatenate([f1, f2])


def phase_free(a: _Curve, b: _Curve) -> tuple[float, float]:
    """(φ, D): the best rotation of curve `a` onto `b` and the phase-free distance there (module doc).
    Coarse: about 200 points' (`_SUB`) distance to the other's at 120 angles, then on
    the four best brackets to every vertex of the other, golden section to `_COARSE_TOL` rad; fine:
    every point's distance to the other's polyline, Brent's method (scipy) on the coarse minimum ±
    `_FINE_W` to 1e-9 rad (the bracket moved while the minimum is at its edge)."""
    from scipy.optimize import minimize_scalar

    pa, pb = a.poly, b.poly
    sa, sb = pa.pts[::max(1, len(pa.pts) // _SUB)], pb.pts[::max(1, len(pb.pts) // _SUB)]
    grid = 2 * np.pi * np.arange(_GRID) / _GRID
    f = _chamfer_rotated(sa, sb, grid)
    local = np.flatnonzero((f <= np.roll(f, 1)) & (f <= np.roll(f, -1)))
    starts = grid[local[np.argsort(f[local])][:_REFINE]]
    xs, fs = _golden(lambda phis: _vertex_chamfer(sa, pa.tree, sb, pb.tree, phis), starts - grid[1],
                     starts + grid[1], _COARSE_TOL)
    k = int(np.argmin(fs))
    phi, seen = float(xs[k]), float(starts[k % len(starts)])  # and the grid angle of its bracket
    for _ in range(8):
        near_a, near_b = _Near(pa.pts, pb, phi, _FINE_W), _Near(pb.pts, pa, -phi, _FINE_W)

        def fine(x, near_a=near_a, near_b=near_b) -> float:
            return float(near_a.distance(x).mean() + near_b.distance(-x).mean())

        r = minimize_scalar(fine, bounds=(phi - _FINE_W, phi + _FINE_W), method="bounded", options={"xatol": 1e-9})
        edge = abs(float(r.x) - phi) > 0.99 * _FINE_W
        phi, d = float(r.x), float(r.fun)
        if abs(seen - phi) <= _FINE_W and (f0 := fine(seen)) <= d:
            phi, d = seen, f0  # a grid angle can be the exact minimum (a curve against itself: at 0)
        if not edge:
            break
    return float(np.mod(phi, 2 * np.pi)), d


def match(curve: np.ndarray, target: np.ndarray, *, closed: bool, n: int = N_FINE) -> Match:
    """The phase-free distance of `curve` to `target` (both (N, 2) polylines, open or both `closed`)
    and the placement of the curve onto the target (module doc)."""
    tgt = np.ascontiguousarray(target, float)
    b = _target_curve(tgt.tobytes(), tgt.shape, int(n), bool(closed))
    a = _curve(curve, n, closed)
    phi, d = phase_free(a, b)
    k = b.rms / a.rms
    return Match(d, phi, k, b.mean - k * _rot(phi) @ a.mean)


def match_ordered(curve: np.ndarray, target: np.ndarray) -> Match:
    """The ordered distance of `curve` point i to `target` point i (module doc) and the placement of
    the curve onto the target: a timed target's match."""
    d, phi = ordered_distance(curve, target)
    _, abar, sa = normalise(curve)
    _, bbar, sb = normalise(target)
    k = sb / sa
    return Match(d, float(np.mod(phi, 2 * np.pi)), k, bbar - k * _rot(phi) @ abar)


def place(points: np.ndarray, m: Match) -> np.ndarray:
    """Points (…, 2) in the mechanism's coordinates placed onto the target: k R(φ) x + t."""
    return m.scale * np.asarray(points, float) @ _rot(m.rotation).T + m.translation


def ordered_distance(curve: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """(RMS distance, φ) between curve point i and target point i after normalising both and the
    least-squares rotation (module doc); the curves have the same number of points."""
    a, _, _ = normalise(curve)
    b, _, _ = normalise(target)
    phi = float(np.arctan2(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]), np.sum(a * b)))
    r = a @ _rot(phi).T - b
    return float(np.sqrt(np.mean(np.sum(r * r, axis=1)))), phi


# ---------------------------------------------------------------------------------- surrogate
def _safe_norm(v, eps):
    return jnp.sqrt(jnp.sum(v * v, axis=-1) + eps * eps)


def arclength_weights(curve, closed, eps: float = 1e-9):
    """Each sample's share of the polyline's arclength (trapezoid; sums to 1). `closed`: a bool or
    a traced 0/1 (the closing segment counts or not)."""
    nxt = jnp.roll(curve, -1, axis=0)
    seg = _safe_norm(nxt - curve, eps)  # seg[i]: i → i+1 (the last one closes the loop)
    seg = seg.at[-1].multiply(jnp.asarray(closed, seg.dtype))
    w = 0.5 * (seg + jnp.roll(seg, 1))
    return w / jnp.sum(w)


def ordered_sq(curve, target, w, eps: float = 1e-12):
    """The square of the ordered distance (`ordered_distance`) between `curve` (T, 2) and the
    target (T, 2), both weighted by `w` (T,), Σ w = 1 (0: a padding point): the target normalised
    with those weights beforehand, the curve here, the rotation the least-squares one in closed form,
    min_φ Σ w |R ĉ − b̂|² = 2 − 2 |Σ w (ĉ·b̂, ĉ×b̂)|. Smooth (`eps` under the root); JAX, pure."""
    mean = jnp.sum(w[:, None] * curve, axis=0)
    c = curve - mean
    c = c / jnp.sqrt(jnp.sum(w * jnp.sum(c * c, axis=1)) + 1e-30)
    dot = jnp.sum(w * (c[:, 0] * target[:, 0] + c[:, 1] * target[:, 1]))
    cross = jnp.sum(w * (c[:, 0] * target[:, 1] - c[:, 1] * target[:, 0]))
    return 2.0 - 2.0 * jnp.sqrt(dot * dot + cross * cross + eps)


def soft_chamfer(curve, target, closed, tau: float = 0.01, eps: float = 1e-6):
    """The smooth surrogate of the chamfer distance between `curve` (T, 2), a sampled trace, and
    the normalised target (M, 2) (module doc). `closed` as in `arclength_weights`; `tau`, `eps`
    static. Pure; `vmap` it."""
    w = arclength_weights(curve, closed)
    mean = jnp.sum(w[:, None] * curve, axis=0)
    c = curve - mean
    s = jnp.sqrt(jnp.sum(w * jnp.sum(c * c, axis=1)) + 1e-30)
    c = c / s
    d = _safe_norm(c[:, None, :] - target[None, :, :], eps)
    fwd = -tau * jax.nn.logsumexp(-d / tau, axis=1)
    bwd = -tau * jax.nn.logsumexp(-d / tau + jnp.log(w)[:, None] + jnp.log(d.shape[0]), axis=0)
    return jnp.sum(w * fwd) + jnp.mean(bwd)
