r"""The distance between a traced curve and a target, as the field reports it, and its smooth
surrogate for gradients.

**The distance** (`match`, NumPy, float64). Both curves are resampled to n points equally spaced
in arclength (`arclength_resample`: a closed curve along the loop, n spacings; an open one from
end to end, n − 1 spacings; n = 200 by default), then each is *normalised*: translated to zero
mean and scaled to unit RMS radius,

.. math::  \hat a_i = (a_i - \bar a) / s_a,\quad s_a = \sqrt{\tfrac1n\sum_i |a_i - \bar a|^2}.

The distance is the symmetric chamfer distance at the best rotation R(φ) of the curve,

.. math::  D = \min_\varphi\; \frac1n\sum_i \min_j |R(\varphi)\hat a_i - \hat b_j|
               + \frac1n\sum_j \min_i |R(\varphi)\hat a_i - \hat b_j| ,

the *sum* of the two mean Euclidean nearest-neighbour distances (not squared), the definition of
LInK's evaluation (Nobari et al. 2024), so the numbers compare with its published ones. No
reflection: a mirrored curve is another curve. φ is found by a grid of 120 angles (3°) and a
golden-section search on the six-degree bracket around each of the four best grid minima down to a
bracket of 1e-13 rad; the smallest value is D.

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

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .target import arclength_resample

#: points per curve in the distance
N_POINTS = 200
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


def match(curve: np.ndarray, target: np.ndarray, *, closed: bool, n: int = N_POINTS) -> Match:
    """The distance of `curve` to `target` (both (N, 2) polylines, open or both `closed`) and the
    placement of the curve onto the target (module doc)."""
    a, abar, sa = normalise(arclength_resample(curve, n, closed))
    b, bbar, sb = normalise(arclength_resample(target, n, closed))
    phi, d = best_rotation(a, b)
    k = sb / sa
    t = bbar - k * _rot(phi) @ abar
    return Match(d, phi, k, t)


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
