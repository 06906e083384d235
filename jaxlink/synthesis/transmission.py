r"""The transmission angle of a synthesized linkage, and the least one a designer may ask for.

A revolute dyad's reach margin (`tracer`) is S = sin² γ, γ the angle between its two links at its
joint — the **transmission angle** of the pair (by the law of cosines, d² = l₁² + l₂² − 2 l₁ l₂ cos γ
gives the margin's formula); a slider's is cos² of the angle between its link and its guide, the
sine² of the slider-crank's transmission angle. So the least transmission angle of a design over its
interval is asin √(min S) over those dyads, located between samples by `assembly.certify` (a
slotted lever's margin is no angle and does not count; a point of a body has none).

**In the search** (`min_transmission` μ, degrees): the floor F = sin² μ. The screen and the rank
drop a candidate whose margin is at most F at a sample, the refinements and the float64 polish
keep every such dyad's margin above `AIM` F by their margin penalty (a little above the floor, since
they see samples only), and a scored design whose located least angle is below μ is not an answer.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from .assembly import Assembly, certify
from .topology import LEVER, Topology

#: the refinements' and the polish's aim: the margin floor times this (their penalty sees samples only)
AIM = 1.2


def floor_of(min_deg: float | None) -> float:
    """sin² μ (0 for None: no floor)."""
    return 0.0 if min_deg is None else math.sin(math.radians(float(min_deg))) ** 2


def angle_deg(margin: float) -> float:
    """The transmission angle (degrees, 0–90) of a margin sin² γ."""
    return math.degrees(math.asin(math.sqrt(min(max(float(margin), 0.0), 1.0))))


def thresholds(parents, floor, sliders: bool = False):
    """(D,) the margin each dyad must keep: `floor`, 0 for a slotted lever. JAX."""
    lever = parents[:, 1] >= LEVER if sliders else jnp.zeros(parents.shape[0], bool)
    return jnp.where(lever, 0.0, floor)


def least(topo: Topology, pose: np.ndarray, start: float, span: float) -> Assembly:
    """The least margin over [start, start + span] of the dyads whose margin is a transmission angle's
    (every one but the slotted levers), located between samples (`assembly.certify`)."""
    only = [k for k in range(len(topo.dyads)) if k not in topo.levers]
    return certify(topo, pose, start, span, only=only) if topo.levers else certify(topo, pose, start, span)
