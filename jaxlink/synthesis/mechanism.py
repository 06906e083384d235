"""A found candidate as a mechanism file: the joints-and-links sketch (`jaxlink.Sketch`,
docs/reference/file-format.md §16), placed onto the target in the target's length unit."""

from __future__ import annotations

import math

import numpy as np

from ..model.sketch import Sketch
from . import distance as _dist
from .topology import CRANK, N_FRAME, Topology, bodies
from .tracer import trace_exact

LENGTH_UNITS = ("m", "mm", "cm")


def joint_names(topo: Topology) -> dict[int, str]:
    """Joint index → name: frame joints `F0`…, the crank joint `C`, the traced joint `P`, others `J4`…."""
    names = {i: f"F{i}" for i in topo.used_frame()}
    names[CRANK] = "C"
    for k in range(len(topo.dyads)):
        j = CRANK + 1 + k
        names[j] = "P" if j == topo.traced else f"J{j}"
    if topo.traced == CRANK:
        names[CRANK] = "P"
    return names


def placed_pose(topo: Topology, pose: np.ndarray, start: float, m: _dist.Match) -> np.ndarray:
    """Every joint at input offset `start`, placed onto the target (k R(φ) x + t)."""
    at = trace_exact(topo, pose, np.array([start]))[0][0]
    return _dist.place(at, m)


def crank_angle(placed: np.ndarray) -> float:
    """The crank's angle from +x in the placed pose (rad): the file's input there."""
    v = placed[CRANK] - placed[0]
    return math.atan2(v[1], v[0])


def to_sketch(topo: Topology, placed: np.ndarray, *, name: str = "synthesized", unit: str = "mm",
              description: str = "") -> Sketch:
    """The sketch of a topology in a placed pose (joint positions in `unit`), angles in degrees; a
    slider dyad's joint slides on the frame's line through it towards its guide's anchor (the
    anchor itself no joint of the file); a slotted lever's block pin slides on the lever's line
    through its pivot."""
    names = joint_names(topo)
    sk = Sketch(name, length_unit=unit if unit in LENGTH_UNITS else "mm", angle_unit="deg",
                description=description)
    for i, n in names.items():
        x, y = float(placed[i, 0]), float(placed[i, 1])
        if i < N_FRAME:
            sk.frame(n, x, y)
        else:
            sk.joint(n, x, y)
    link_of = {}
    for k, b in enumerate(bodies(topo)):
        link_of[b] = "crank" if k == 0 else f"link{k}"
        sk.link(link_of[b], *(names[j] for j in b))
    for k in topo.levers:
        pivot, pin, j = topo.dyads[k][0], topo.dyads[k][1], CRANK + 1 + k
        lever = next(b for b in link_of if pivot in b and j in b)  # the lever and the points on it
        sk.slider(names[pin], on=link_of[lever], through=names[pivot])
    for k in topo.sliders:
        j, anchor = CRANK + 1 + k, topo.dyads[k][1]
        g = placed[j] - placed[anchor]
        sk.slider(names[j], on="frame", along=(float(g[0]), float(g[1])))
    return sk.crank("crank", name="theta").points(names[topo.traced])
