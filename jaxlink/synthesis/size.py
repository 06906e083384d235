r"""The size of a synthesized linkage against its target, and the bound a designer may put on it.

A fit says nothing of size: the chamfer distance is the same for a four-bar whose links are as
long as the target and for one whose links are ten times longer, which no machine has room for.
The **size** of a design is measured on what does not move, so that it is exact without sampling:

.. math::  S = \max\Bigl(\max_i L_i,\ \max_j |F_j - c|\Bigr) / E,

- L_i every link's length in the target's unit: the crank, each dyad's two links (a plate's sides
  for a point carried with a body; a slider's one link; a slotted lever's joint's distance from
  the lever's pivot);
- F_j every frame pivot the linkage uses (the crank's pivot, every dyad's frame parent; not a
  slider guide's anchor, which is no joint), placed onto the target (`distance.place`);
- c the target's centre: its centroid as the distance normalises it (of the arclength resampling
  at the distance's n points; a timed target: the mean of its points), which the placement maps
  the traced curve's centroid onto;
- E the target's **extent**, the largest distance between two of its points.

So S ≤ K says: no link longer than K times the target's extent, no frame pivot further than that
from its centre (and hence every joint within (1 + the links of its chain) K E of it).

**In the search** (`max_size` K): the pose lives in the search's own coordinates, the traced curve
normalised to zero mean and unit RMS radius s_a, the target to unit RMS radius s_b; the placement
scales by s_b / s_a, so S ≤ K reads, in the pose, max(L_i, |F_j − ā|) / s_a ≤ K E / s_b
(`limit`). The screen and the rank drop a candidate over it, the refinements and the float64
polish add 100 Σ max(0, r − 0.97 lim)² over the terms r (`penalty`: a little inside the bound, since
their ā and s_a are the surrogate's), and a scored design over K is not an answer.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from . import distance as _dist
from .target import Target, arclength_resample
from .topology import CRANK, LEVER, RIGID, SLIDER, Topology

#: the refinements' and the polish's aim, a fraction of the bound (their curve normalisation is the
#: surrogate's, not the exact distance's)
AIM = 0.97
#: the weight of the size penalty in the refinements' loss (as the margin penalty's)
WEIGHT = 100.0


def extent(points) -> float:
    """The largest distance between two of `points` (N, 2) (their diameter), in their unit."""
    p = np.asarray(points, float)
    if len(p) > 3:
        try:
            from scipy.spatial import ConvexHull

            p = p[ConvexHull(p).vertices]
        except Exception:  # noqa: BLE001 (collinear or repeated points: every pair)
            pass
    d = p[:, None, :] - p[None, :, :]
    return float(np.sqrt(np.max(np.sum(d * d, axis=-1))))


def target_frame(target: Target, n_points: int = _dist.N_POINTS) -> tuple[np.ndarray, float, float]:
    """(centre c, RMS radius, extent E) of a target as the distance normalises it: of its arclength
    resampling at `n_points` (a timed target: of its points)."""
    pts = (np.asarray(target.points, float) if target.timed
           else arclength_resample(target.points, n_points, target.closed))
    _, centre, rms = _dist.normalise(pts)
    return centre, rms, extent(target.points)


def terms(topo: Topology, pose) -> tuple[np.ndarray, np.ndarray]:
    """(the link lengths (m,), the frame pivots the linkage uses (k, 2)) of a pose, in its coordinates
    (module doc)."""
    pose = np.asarray(pose, float)
    lengths = [np.hypot(*(pose[CRANK] - pose[0]))]
    used = {0}
    for k, (p1, p2) in enumerate(topo.dyads):
        j = CRANK + 1 + k
        lengths.append(np.hypot(*(pose[j] - pose[p1])))
        used |= {p1} if p1 < CRANK else set()
        if k not in topo.sliders and k not in topo.levers:
            lengths.append(np.hypot(*(pose[j] - pose[p2])))
            used |= {p2} if p2 < CRANK else set()
    return np.asarray(lengths), pose[sorted(used)]


def design_sizes(topo: Topology, pose, m: _dist.Match, centre: np.ndarray,
                 target_extent: float) -> tuple[float, float]:
    """(its longest link, its frame pivot furthest from the target's `centre`) over the target's
    extent: the two terms of S (module doc), its pose's links times the placement's scale, its frame
    pivots placed onto the target by the match `m` (`distance.place`)."""
    lengths, pivots = terms(topo, pose)
    reach = np.hypot(*(_dist.place(pivots, m) - np.asarray(centre, float)).T)
    return float(m.scale * np.max(lengths) / target_extent), float(np.max(reach) / target_extent)


def design_size(topo: Topology, pose, m: _dist.Match, centre: np.ndarray, target_extent: float) -> float:
    """S of a design (module doc): the larger of `design_sizes`."""
    lengths, pivots = terms(topo, pose)
    reach = np.hypot(*(_dist.place(pivots, m) - np.asarray(centre, float)).T)
    return float(max(m.scale * np.max(lengths), np.max(reach)) / target_extent)


def limit(max_size: float | None, target_extent: float, target_rms: float) -> float:
    """The bound in the search's normalised units: K E / s_b (module doc); inf for no bound (None)."""
    if max_size is None or not np.isfinite(max_size):
        return float(np.inf)
    return float(max_size) * target_extent / target_rms


def ratios(parents, active, pose, mean, rms, sliders: bool = False):
    """Every size term of a candidate over its curve's RMS radius `rms`, its frame pivots' distances
    from the curve's centroid `mean`: (1 + 2D + 3,), 0 for the terms it has not (an inactive dyad, a
    slider's second link, an unused pivot). JAX, pure, one candidate (`topology.as_arrays`' rows)."""
    lens = [jnp.sqrt(jnp.sum((pose[CRANK] - pose[0]) ** 2) + 1e-30)]
    used = [jnp.asarray(True), jnp.asarray(False), jnp.asarray(False)]
    for k in range(parents.shape[0]):
        j = CRANK + 1 + k
        p1, p2 = parents[k, 0], parents[k, 1]
        lever = p2 >= LEVER if sliders else jnp.asarray(False)
        p2 = jnp.where(lever, p2 - LEVER, p2)
        p2 = jnp.where(p2 >= RIGID, p2 - RIGID, p2)
        slider = (p2 >= SLIDER) | lever if sliders else jnp.asarray(False)  # one link, no frame anchor
        p2 = jnp.where(p2 >= SLIDER, p2 - SLIDER, p2)
        on = active[k]
        lens.append(jnp.where(on, jnp.sqrt(jnp.sum((pose[j] - pose[p1]) ** 2) + 1e-30), 0.0))
        lens.append(jnp.where(on & ~slider, jnp.sqrt(jnp.sum((pose[j] - pose[p2]) ** 2) + 1e-30), 0.0))
        for f in (1, 2):
            used[f] = used[f] | (on & ((p1 == f) | ((p2 == f) & ~slider)))
    reach = [jnp.where(used[f], jnp.sqrt(jnp.sum((pose[f] - mean) ** 2) + 1e-30), 0.0) for f in range(3)]
    return jnp.stack(lens + reach) / rms


def weighted_frame(curve, w):
    """(centroid, RMS radius) of a sampled curve (T, 2) with weights `w` (T,), Σ w = 1 (the
    surrogate's normalisation, `distance.soft_chamfer`, `distance.ordered_sq`). JAX."""
    mean = jnp.sum(w[:, None] * curve, axis=0)
    c = curve - mean
    return mean, jnp.sqrt(jnp.sum(w * jnp.sum(c * c, axis=1)) + 1e-30)


def penalty(parents, active, pose, mean, rms, lim, sliders: bool = False):
    """Σ max(0, r − `AIM` lim)² over the size terms r (`ratios`): 0 inside the aim. JAX."""
    r = ratios(parents, active, pose, mean, rms, sliders)
    return jnp.sum(jax.nn.relu(r - AIM * lim) ** 2)


def within(parents, active, pose, mean, rms, lim, sliders: bool = False):
    """Whether no size term is over `lim` (a NaN term passes: the other checks reject it). JAX."""
    return ~jnp.any(ratios(parents, active, pose, mean, rms, sliders) > lim)
