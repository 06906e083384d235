"""Where a synthesis is, as it runs (`synthesize(progress=...)`): the search's stages turned into
`Progress` records with the best design so far — its distance, joints and least transmission angle."""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import numpy as np

from . import transmission as _tm
from .scoring import Candidate, certified_interval
from .target import Target


class Progress(NamedTuple):
    """`stage`: "compiling", "round" (a round started), "scored" (a topology's candidates scored),
    "polished" (a float64 polish done) or "done"; `round` (0 while compiling), `polish` (a polishing
    round); `scored` of `topologies`: the topologies whose scoring this round is done; `distance`,
    `topology`, `joints`, `transmission_deg`: the best design so far (nan, "", 0, nan: none yet);
    `elapsed_s`: seconds since the limit's clock started; `left_s`: of the time limit (None: none)."""

    stage: str
    round: int
    polish: bool
    scored: int
    topologies: int
    distance: float
    topology: str
    joints: int
    transmission_deg: float
    elapsed_s: float
    left_s: float | None


def relay(callback: Callable[[Progress], None] | None, target: Target,
          on_best: Callable[[Candidate], None] | None = None) -> Callable[[dict], None]:
    """The search's `progress` function that calls `on_best` (if given) with the best candidate so
    far after every round and every polish where it changed, then `callback` (if given) with a
    `Progress` for each of its
    stages (the best design's transmission angle as `Design.transmission_deg` has it: its assembly
    check's least margin, a slotted lever's by `transmission.least`, once per best)."""
    angles: dict[int, float] = {}
    told: list[int] = []  # the id of the best last given to `on_best`

    def angle(c: Candidate) -> float:
        if id(c) not in angles:
            mu = (_tm.least(c.topology, c.pose, *certified_interval(c.start, c.span, target)) if c.topology.levers
                  else c.assembly)
            angles[id(c)] = _tm.angle_deg(mu.margin) if np.isfinite(mu.margin) else math.nan
        return angles[id(c)]

    def tell(event: dict) -> None:
        best = event["best"]
        ends = event["stage"] in ("polished", "done") or (
            event["stage"] == "scored" and event["scored"] == event["topologies"])
        if on_best is not None and ends and best is not None and told[-1:] != [id(best)]:
            told.append(id(best))
            on_best(best)
        if callback is None:
            return
        callback(Progress(event["stage"], int(event["round"]), bool(event["polish"]), int(event["scored"]),
                          int(event["topologies"]), float(best.match.distance) if best is not None else math.nan,
                          best.topology.name if best is not None else "",
                          best.topology.n_joints if best is not None else 0,
                          angle(best) if best is not None else math.nan, float(event["elapsed"]),
                          None if event["left"] is None else float(event["left"])))

    return tell
