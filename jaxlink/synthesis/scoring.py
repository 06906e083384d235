"""The search's exact scoring: a refined candidate traced in float64, checked over its whole
interval (`assembly.certify`) and matched to the target (`distance.match`, or `match_ordered` for a
timed target): `score`, and the scored `Candidate`."""

from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np

from ..model.domains import joints_inside
from . import distance as _dist
from . import size as _size
from . import transmission as _tm
from .assembly import Assembly, certify
from .mechanism import placed_pose
from .target import Target
from .topology import Topology, bodies
from .tracer import trace_exact

#: a round scores a topology's refined candidates in the surrogate's order until `per_topology`
#: pass the exact check, at most this many times `per_topology` of them
SCORE_TRIES = 4


#: the threads that score a round's candidates (NumPy float64 and SciPy k-d trees, one topology a
#: task): 43 ten-bar topologies' 86+ scores took 6-18 s of a 58 s letter on an H200's host shared by
#: 5 processes, where the device's screen, rank and refinement took about 1 s
SCORE_THREADS = max(1, min(4, os.cpu_count() or 1))


class Candidate(NamedTuple):
    """A scored mechanism: its `topology`, `pose` (joint positions at input offset 0, the search's
    own coordinates), input offsets `start`, `span` (rad) of the traced interval, the exact
    `match` (distance and placement), the `assembly` check, when it was found (s), whether it
    is the result of the float64 `polish`, and its `size` (`size.design_size`: in the target's extents)."""

    topology: Topology
    pose: np.ndarray
    start: float
    span: float
    match: _dist.Match
    assembly: Assembly
    found_s: float
    polished: bool = False
    size: float = float("nan")


def interval_offsets(start: float, span: float, n: int, closed: bool) -> np.ndarray:
    """The input offsets of the scored trace: a closed curve n inputs over a turn (the last one
    before the first again), an open one n inputs from start to start + span, both ends included."""
    if closed:
        return start + 2 * np.pi * np.arange(n) / n
    return start + span * np.linspace(0.0, 1.0, n)


def score(topo: Topology, pose: np.ndarray, start: float, span: float, target: Target, *,
          n_trace: int, n_points: int) -> tuple[_dist.Match, Assembly]:
    """The exact distance and the assembly check of one candidate (float64): the phase-free distance
    (`distance.match`, at `distance.N_FINE` points whatever `n_points`, the surrogate's count) of the
    path traced at `n_trace` inputs. A timed target: the ordered distance (`distance.match_ordered`)
    of the traced point at start + (t_i − t_0) to point i, the check over that interval (a closed
    target: the whole turn). A candidate whose file would hold a value outside its domain
    (`in_domain`) does not pass the check (`asm.ok` False)."""
    m, asm = _scored(topo, pose, start, span, target, n_trace=n_trace, n_points=n_points)
    if asm.ok and np.isfinite(m.distance) and not in_domain(topo, pose, start, m, target):
        asm = asm._replace(ok=False)
    return m, asm


def in_domain(topo: Topology, pose: np.ndarray, start: float, m: _dist.Match, target: Target) -> bool:
    """Whether the candidate placed onto the target (`mechanism.placed_pose`, in the target's unit,
    as its file writes it: mm when the target names none) holds values a file can
    (`jaxlink.model.domains.joints_inside`: no link shorter than a nanometre, nothing beyond 1000 km)."""
    unit = {"m": 1.0, "mm": 1e-3, "cm": 1e-2}.get(target.unit, 1e-3)
    return joints_inside(placed_pose(topo, pose, start, m) * unit, bodies(topo))


def _scored(topo: Topology, pose: np.ndarray, start: float, span: float, target: Target, *,
            n_trace: int, n_points: int) -> tuple[_dist.Match, Assembly]:
    asm = certify(topo, pose, *certified_interval(start, span, target))
    if target.timed:
        t = np.asarray(target.inputs, float)
        pos, marg = trace_exact(topo, pose, start + (t - t[0]))
        if not np.all(marg > 0):
            return _dist.Match(np.inf, 0.0, 1.0, np.zeros(2)), asm
        return _dist.match_ordered(pos[:, topo.traced], target.points), asm
    th = interval_offsets(start, span, n_trace, target.closed)
    pos, marg = trace_exact(topo, pose, th)
    if not np.all(marg > 0):
        return _dist.Match(np.inf, 0.0, 1.0, np.zeros(2)), asm
    return _dist.match(pos[:, topo.traced], target.points, closed=target.closed), asm


def certified_interval(start: float, span: float, target: Target) -> tuple[float, float]:
    """(start, span) of the interval a candidate is certified over (`score`): a closed target's whole
    turn, a timed one's from its first input to its last (either way), an open one's sub-interval."""
    if target.timed:
        t = np.asarray(target.inputs, float)
        sp = float(t[-1] - t[0])
        return (start if sp >= 0 else start + sp), (2 * np.pi if target.closed else abs(sp))
    return start, (2 * np.pi if target.closed else span)


def keeps_transmission(topo: Topology, pose, start: float, span: float, target: Target, floor: float) -> bool:
    """Whether a candidate's least transmission angle over its interval (`transmission.least`) has a
    margin sin² of at least `floor`."""
    return bool(_tm.least(topo, pose, *certified_interval(start, span, target)).margin >= floor)


def size_of(topo: Topology, pose, m: _dist.Match, target: Target, n_points: int = _dist.N_POINTS,
            frame: tuple | None = None) -> float:
    """The size of a scored design (`size.design_size`), in the target's extents; nan without a match.
    `frame`: the target's `size.target_frame`, if known."""
    if not np.isfinite(m.distance):
        return float("nan")
    centre, _, ext = _size.target_frame(target, n_points) if frame is None else frame
    return _size.design_size(topo, pose, m, centre, ext)
