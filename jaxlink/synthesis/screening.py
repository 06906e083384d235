"""The search's screen: random poses of every topology traced over a turn, each sub-interval
described by its sorted radii (a rotation invariant) and compared with the target's descriptor
(`_screen`); a timed target's screen by the ordered distance at its inputs (`_screen_timed`)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import distance as _dist
from . import size as _size
from . import transmission as _tm
from .sortnet import sort_first
from .target import Target, arclength_resample
from .topology import CRANK
from .tracer import trace

SCREEN_T = 64


DESC_N = 32


_STARTS = 16


#: a timed target's points in the screen (subsampled or padded to it, `timed_samples`); the refinement
#: takes `REFINE_T`
TIMED_SCREEN_T = 32


_SPANS = (0.25, 0.5, 0.75, 1.0)


_DT = jnp.float32


def _radii(curve, closed: bool, frame: bool = False):
    """The descriptor before sorting: distances from the centroid of the arclength-resampled,
    normalised curve (`_screen` sorts them, `sortnet.sort_first`). `frame`: also that centroid and
    the RMS radius (`size`)."""
    seg = jnp.sqrt(jnp.sum(jnp.diff(curve, axis=0) ** 2, axis=-1) + 1e-12)
    s = jnp.concatenate([jnp.zeros(1, curve.dtype), jnp.cumsum(seg)])
    q = s[-1] * (jnp.arange(DESC_N) / (DESC_N if closed else DESC_N - 1))
    c = jnp.stack([jnp.interp(q, s, curve[:, 0]), jnp.interp(q, s, curve[:, 1])], axis=-1)
    mean = c.mean(0)
    c = c - mean
    r = jnp.sqrt(jnp.sum(c * c, axis=-1) + 1e-12)
    rms = jnp.sqrt(jnp.mean(r * r))
    return (r / rms, mean, rms) if frame else r / rms


def _desc(points: np.ndarray, closed: bool) -> np.ndarray:
    """The sorted `_radii` in NumPy (the target's descriptor)."""
    c = arclength_resample(points, DESC_N, closed)
    c = c - c.mean(0)
    r = np.sqrt(np.sum(c * c, axis=-1) + 1e-12)
    return np.sort(r / np.sqrt(np.mean(r * r))).astype(np.float32)


def _subarcs(closed: bool):
    if closed:
        return np.array([[0.0, 2 * np.pi]], np.float32)
    return np.array([[2 * np.pi * i / _STARTS, 2 * np.pi * f] for i in range(_STARTS) for f in _SPANS], np.float32)


def _subarc_slices(closed: bool) -> list[tuple[int, int, int]]:
    """Each sub-arc of `_subarcs` as a strided slice (start, step, count) of the screen's curve at half
    samples (`_half_samples`): its starts are whole samples and its points, 33 evenly spaced over the
    span (a closed target: the whole turn's `SCREEN_T` + 1 samples), fall on whole and half samples."""
    out = []
    for start, span in _subarcs(closed).astype(np.float64):
        k = SCREEN_T + 1 if closed else 33
        x2 = 2 * SCREEN_T * (start + span * np.linspace(0.0, 1.0, k)) / (2 * np.pi)
        idx = np.rint(x2).astype(int)
        step = int(idx[1] - idx[0])
        if not (np.allclose(x2, idx, atol=1e-6) and np.all(np.diff(idx) == step)):
            raise AssertionError("a sub-arc's points are not on the half samples")  # a change of the constants
        out.append((int(idx[0]), step, k))
    return out


def _half_samples(curve, ok, reach: int):
    """The curve (T + 1 samples over a turn, the last = the first) and its dyads' closing (T + 1,) at
    every half sample, the midpoints linear (closing where both ends close), extended periodically
    to `reach` + 1 points."""
    mid = 0.5 * (curve[:-1] + curve[1:])
    c2 = jnp.stack([curve[:-1], mid], 1).reshape(2 * SCREEN_T, 2)
    o2 = jnp.stack([ok[:-1], ok[:-1] & ok[1:]], 1).reshape(2 * SCREEN_T)
    reps = reach // (2 * SCREEN_T) + 1
    return jnp.concatenate([c2] * reps + [c2[:1]]), jnp.concatenate([o2] * reps + [o2[:1]])


@functools.partial(jax.jit, static_argnames=("closed", "sliders", "bounded"))
def _screen(key, parents, active, traced, target_desc, bounds=(np.inf, 0.0), *, closed: bool, sliders: bool = False,
            bounded: bool = False):
    """Descriptor distances (B, S) of random poses (B, J, 2) over the sub-arcs; inf where a dyad does
    not close at a sample of the sub-arc (or, `bounded`, where the design is larger than `bounds`:
    `size`). Each sub-arc's points are a static strided slice of the curve at half samples
    (`_subarc_slices`: no gathers)."""
    b = parents.shape[0]
    poses = jax.random.uniform(key, (b, CRANK + 1 + parents.shape[1], 2), _DT, -1.0, 1.0)
    th = jnp.asarray(2 * np.pi * np.arange(SCREEN_T + 1) / SCREEN_T, _DT)
    pos, marg = jax.vmap(functools.partial(trace, sliders=sliders), in_axes=(0, 0, 0, None))(parents, active, poses, th)
    curves = pos[jnp.arange(b), :, traced]                    # (B, T+1, 2), the last = the first
    if bounded:  # every dyad's margin above its floor (`transmission`: 0 without one)
        thr = jax.vmap(lambda par: _tm.thresholds(par, bounds[1], sliders))(parents)
        ok = jnp.min(marg - thr[:, None, :], axis=-1) > 0
    else:
        ok = jnp.min(marg, axis=-1) > 0                        # (B, T+1)
    slices = _subarc_slices(closed)
    reach = max(st + step * (k - 1) for st, step, k in slices)

    def per_candidate(curve, okk, par, act, pose):
        c2, o2 = _half_samples(curve, okk, reach)
        pts = jnp.stack([jax.lax.slice(c2, (st, 0), (st + step * (k - 1) + 1, 2), (step, 1))
                         for st, step, k in slices])
        valid = jnp.stack([jnp.all(jax.lax.slice(o2, (st,), (st + step * (k - 1) + 1,), (step,)))
                           for st, step, k in slices])
        if not bounded:
            return jax.vmap(lambda p: _radii(p, closed))(pts), valid
        r, mean, rms = jax.vmap(lambda p: _radii(p, closed, frame=True))(pts)
        fits = jax.vmap(lambda m, s: _size.within(par, act, pose, m, s, bounds[0], sliders))(mean, rms)
        return r, valid & fits

    r, valid = jax.vmap(per_candidate)(curves, ok, parents, active, poses)  # (B, S, DESC_N), (B, S)
    desc = sort_first(jnp.moveaxis(r, -1, 0))                # sorted along the leading axis: no gathers
    d = jnp.mean(jnp.abs(desc - target_desc[:, None, None]), axis=0)
    return poses, jnp.where(valid, d, jnp.inf)


def timed_samples(target: Target, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A timed target as `n` samples: (points (n, 2) normalised with the weights, weights (n,) summing
    to 1 — 0 on padding —, input fractions u (n,) of the span, the span S = t_last − t_0, signed):
    the point i at the input offset start + S u_i. More than `n` points: `n` of them evenly by index
    (the first and last kept); fewer: all, then padding (u = 0, weight 0)."""
    t = np.asarray(target.inputs, float)
    pts = np.asarray(target.points, float)
    idx = np.arange(len(t)) if len(t) <= n else np.unique(np.rint(np.linspace(0, len(t) - 1, n)).astype(int))
    m = len(idx)
    span = float(t[-1] - t[0])
    w = np.zeros(n)
    w[:m] = 1.0 / m
    u = np.zeros(n)
    u[:m] = (t[idx] - t[0]) / span
    p = np.zeros((n, 2))
    p[:m] = _dist.normalise(pts[idx])[0]
    return p, w, u, span


@functools.partial(jax.jit, static_argnames=("sliders", "bounded"))
def _screen_timed(key, parents, active, traced, target, w, u, span, bounds=(np.inf, 0.0), *, sliders: bool = False,
                  bounded: bool = False):
    """A timed target's screen: random poses (B, J, 2), each traced from `_STARTS` starts over a turn
    at the target's inputs (start + span u), and the square of the ordered distance at each start
    (`distance.ordered_sq`: the target's own measure, no descriptor) (B, `_STARTS`); inf where a
    dyad does not close at a sample."""
    b = parents.shape[0]
    poses = jax.random.uniform(key, (b, CRANK + 1 + parents.shape[1], 2), _DT, -1.0, 1.0)
    starts = jnp.asarray(2 * np.pi * np.arange(_STARTS) / _STARTS, _DT)
    th = (starts[:, None] + span * u[None, :]).reshape(-1)

    def one(par, act, tr, pose):
        pos, marg = trace(par, act, pose, th, sliders)
        c = pos[:, tr].reshape(_STARTS, -1, 2)
        thr = _tm.thresholds(par, bounds[1], sliders) if bounded else 0.0
        ok = jnp.all((jnp.min(marg - thr, axis=-1) > 0).reshape(_STARTS, -1) | (w[None, :] == 0), axis=1)
        if bounded:  # within the size (`size`) at each start
            ok = ok & jax.vmap(lambda cc: _size.within(par, act, pose, *_size.weighted_frame(cc, w), bounds[0],
                                                       sliders))(c)
        d = jax.vmap(lambda cc: _dist.ordered_sq(cc, target, w))(c)
        return jnp.where(ok, d, jnp.inf)

    return poses, jax.vmap(one)(parents, active, traced, poses)
