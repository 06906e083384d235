"""Does a candidate assemble over its whole traced interval, on its branch, not only at the samples?

Each dyad's reach margin S(θ) (`tracer`) is a smooth function of the input offset θ; the dyad
closes iff S ≥ 0 and keeps its branch between two inputs iff S > 0 between them (S = 0 is where
the two branches meet). `certify` finds the smallest margin over the interval the way
`jaxlink.analysis.feasibility.certify` does over a revolution: the margins at `DENSE` equally
spaced inputs, then, around each of the `REFINE` smallest sampled local minima of every dyad, a
golden-section search on the bracket of the two neighbouring samples down to 1e-12 rad. A
candidate is accepted iff that smallest margin exceeds `MIN_MARGIN` (strictly positive: no toggle
and no change point inside the interval, so the closed form's fixed branch is the motion's).
This is a located minimum, not an interval-arithmetic bound: a dip narrower than the dense
spacing and away from every sampled local minimum could be missed.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .topology import Topology
from .tracer import trace_exact

DENSE = 4096
REFINE = 6
MIN_MARGIN = 1e-9
_GOLD = 0.6180339887498949


class Assembly(NamedTuple):
    """`margin`: the smallest reach margin found over the interval; `where`: its input offset
    (rad, from the pose); `dyad`: which dyad (index in `topology.dyads`); `ok`: margin > MIN_MARGIN."""

    margin: float
    where: float
    dyad: int
    ok: bool


def certify(topo: Topology, pose: np.ndarray, start: float, span: float, only=None) -> Assembly:
    """The smallest margin of every dyad over θ ∈ [start, start + span] (input offsets from the pose).
    The golden-section searches of all brackets (every dyad's `REFINE` smallest local minima) run
    side by side, one trace of the linkage at all their points per step; each bracket takes the
    steps it would alone (it stops once narrower than 1e-12 rad) and the smallest margin found is
    the first in the order dyad, bracket, point (the search one bracket at a time, the reference
    in `tests/test_synthesis.py`, gives the same answer bit for bit). `only`: the dyads (indices)
    whose margins count (default every one; the others read as +inf)."""
    if not topo.dyads:  # pragma: no cover - every topology has a dyad
        return Assembly(np.inf, start, -1, True)
    th = start + span * np.linspace(0.0, 1.0, DENSE + 1)
    skip = None if only is None else np.array([k not in set(only) for k in range(len(topo.dyads))])
    if skip is not None and skip.all():
        return Assembly(np.inf, start, -1, True)
    m = trace_exact(topo, pose, th)[1]
    if skip is not None:
        m = np.where(skip, np.inf, m)
    h = th[1] - th[0]
    ks, cs = [], []
    for k in range(m.shape[1]):
        if skip is not None and skip[k]:
            continue
        mk = m[:, k]
        inner = np.flatnonzero((mk[1:-1] <= mk[:-2]) & (mk[1:-1] <= mk[2:])) + 1
        sel = inner[np.argsort(mk[inner])][:REFINE]
        ks += [k] * len(sel)
        cs += list(th[sel])
    i0 = int(np.argmin(m))
    best = (float(m.flat[i0]), float(th[i0 // m.shape[1]]), int(i0 % m.shape[1]))
    if not ks:
        return Assembly(best[0], best[1], best[2], bool(best[0] > MIN_MARGIN))
    kk = np.array(ks)
    c = np.array(cs)
    lo, hi = c - h, c + h
    rows = np.arange(len(kk))

    def f(x):
        return trace_exact(topo, pose, x)[1][rows, kk]

    x1, x2 = hi - _GOLD * (hi - lo), lo + _GOLD * (hi - lo)
    f1, f2 = f(x1), f(x2)
    on = hi - lo > 1e-12
    while on.any():
        left = on & (f1 <= f2)
        right = on & ~(f1 <= f2)
        hi = np.where(left, x2, hi)
        lo = np.where(right, x1, lo)
        xn = np.where(left, hi - _GOLD * (hi - lo), lo + _GOLD * (hi - lo))
        fn = f(xn)
        x1, x2, f1, f2 = (np.where(left, xn, np.where(right, x2, x1)), np.where(right, xn, np.where(left, x1, x2)),
                          np.where(left, fn, np.where(right, f2, f1)), np.where(right, fn, np.where(left, f1, f2)))
        on = hi - lo > 1e-12
    xs = np.stack([x1, x2], axis=1).ravel()
    vs = np.stack([f1, f2], axis=1).ravel()
    j = int(np.argmin(vs))
    if vs[j] < best[0]:
        best = (float(vs[j]), float(xs[j]), int(kk[j // 2]))
    return Assembly(best[0], best[1], best[2], bool(best[0] > MIN_MARGIN))

