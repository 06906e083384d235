r"""The designs worth a designer's look: the Pareto front, and the simplest topology that fits.

A synthesis returns the best design of each topology; the least distance is not the whole story.
A design is on the **Pareto front** when no other design is at least as good on each of four
objectives and better on one:

- its distance to the target (less is better);
- its joints (fewer: a simpler, cheaper, stiffer linkage);
- its least transmission angle (more is better; an unknown one counts as 0°);
- its size in the target's extents (less is better).

The **simplest** design is the one with the fewest joints (then links, then the least distance)
whose distance is within `WITHIN` = 10 % of the best distance — among the designs that meet the
bounds in force (`bounds`) when any does. Pure functions of the designs' numbers: no search.
"""

from __future__ import annotations

import numpy as np

#: the simplest design's distance is at most (1 + WITHIN) times the best
WITHIN = 0.10


def front(distance, joints, transmission_deg, size) -> np.ndarray:
    """(n,) bool: whether each design (the n values of each objective, module doc) is on the Pareto
    front. A NaN distance or size is worst; a NaN transmission angle counts as 0°."""
    d = np.nan_to_num(np.asarray(distance, float), nan=np.inf)
    j = np.asarray(joints, float)
    mu = np.nan_to_num(np.asarray(transmission_deg, float), nan=0.0)
    s = np.nan_to_num(np.asarray(size, float), nan=np.inf)
    cost = np.stack([d, j, -mu, s], axis=1)  # every objective: less is better
    n = len(cost)
    on = np.ones(n, bool)
    for i in range(n):
        worse_eq = np.all(cost <= cost[i], axis=1) & np.any(cost < cost[i], axis=1)
        on[i] = not np.any(worse_eq)
    return on


def simplest(distance, joints, links=None, eligible=None, within: float = WITHIN) -> int | None:
    """The index of the simplest design (module doc): of the `eligible` ones (default every one; when
    none is eligible, every one), those whose distance is at most (1 + `within`) times the least,
    the fewest `joints`, then the fewest `links`, then the least distance; None for no design."""
    d = np.asarray(distance, float)
    if len(d) == 0:
        return None
    j = np.asarray(joints, float)
    lk = np.zeros(len(d)) if links is None else np.asarray(links, float)
    ok = np.ones(len(d), bool) if eligible is None else np.asarray(eligible, bool)
    if not ok.any():
        ok = np.ones(len(d), bool)
    ok = ok & np.isfinite(d)
    if not ok.any():
        return None
    best = np.min(d[ok])
    pool = [i for i in np.flatnonzero(ok) if d[i] <= (1 + within) * best]
    return int(min(pool, key=lambda i: (j[i], lk[i], d[i], i)))
