"""The body model of a mechanism: bodies, joints, loads and gravity, for kinetostatics
(`jaxlink/analysis/kinetostatics.py`). The file sections `[bodies.*]`, `[joints.*]`, `[loads.*]` and
`[environment]` are read and checked into a `Model` when the file is loaded
(`jaxlink/files/bodies.py`, where the format is described); a `Mechanism` carries it as `bodies`.

A spring's tension is T = preload + stiffness·(L − length) (it pulls its two ends together when
T > 0); its potential energy is preload·(L − length) + ½ stiffness (L − length)².
The input drives the body named by `[input] body` with the unknown torque (an angle input), or with
the unknown force along `[input] axis` at `[input] at` (a length input: a cylinder, a driven slider).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

from ..errors import MechanismError

if TYPE_CHECKING:
    from .mechanism import Mechanism

GROUND = "ground"

JOINT_CLASS = {"revolute": 2, "prismatic": 2}
"""What a joint may be: its kind, and its class t, the number of relative planar motions it removes
(n = 3 (u − 1) − Σ_t t·s_t, `jaxlink/model/structure.py`). A joint joins exactly two members, the
frame being `ground` (a pin shared by v members is v − 1 joints). Kinetostatics gives each joint t
unknowns: revolute Fx, Fy; prismatic the normal force and the moment."""


@dataclasses.dataclass(frozen=True)
class Body:
    """A moving body. `angle` is an expression node (or None), `centroid` a tuple of `Term`s (or
    None); `mass` kg, `inertia` kg·m² about the centroid."""

    name: str
    angle: object
    mass: float
    inertia: float
    centroid: tuple | None


@dataclasses.dataclass(frozen=True)
class Joint:
    """A joint between bodies `a` and `b` (indices into `Model.bodies`, −1 = ground). Its unknowns
    are the force on `b` from `a` (revolute: Fx, Fy; prismatic: normal force N along the left
    normal of `axis`, and moment M)."""

    name: str
    kind: str  # a key of JOINT_CLASS
    a: int
    b: int
    at: tuple
    axis: object  # expression node (prismatic) or None


@dataclasses.dataclass(frozen=True)
class Force:
    name: str
    body: int
    at: tuple
    force: tuple  # (Fx, Fy) N


@dataclasses.dataclass(frozen=True)
class Torque:
    name: str
    body: int
    torque: float  # N·m, counter-clockwise


@dataclasses.dataclass(frozen=True)
class Spring:
    name: str
    a: int
    b: int
    start: tuple  # terms, point on body a
    end: tuple  # terms, point on body b
    stiffness: float  # N/m
    length: float  # m
    preload: float  # N


@dataclasses.dataclass(frozen=True, eq=False)
class Model:
    """The static description of a mechanism's bodies, joints and loads (hashable by identity).

    **Fields:**

    - `bodies`: moving bodies, in file order (the ground is not listed).
    - `joints`: in file order; unknowns of joint j are columns 2j, 2j+1 of the kinetostatic system.
    - `forces`, `torques`, `springs`: the loads.
    - `gravity`: (gx, gy) m/s².
    - `input_body`: index of the body the drive acts on: the drive torque (an angle input), or the
      drive force (a length input).
    - `input_at`, `input_axis`: a length input's drive force acts on `input_body` at the point
      `input_at` (terms) along the direction `input_axis` (an angle expression node): F > 0 pushes
      the body along (cos axis, sin axis), the direction in which the input grows; None for an
      angle input.
    - `input_base`: the body that takes the drive force's reaction (−F at the same point; −1 =
      the ground): a cylinder's barrel, the frame.
    """

    bodies: tuple
    joints: tuple
    forces: tuple
    torques: tuple
    springs: tuple
    gravity: tuple
    input_body: int
    input_at: tuple | None = None
    input_axis: object = None
    input_base: int = -1

    @property
    def drive_force(self) -> bool:
        """Whether the drive is a force (a length input) rather than a torque."""
        return self.input_at is not None

    @property
    def body_names(self) -> tuple:
        return tuple(b.name for b in self.bodies)

    @property
    def joint_names(self) -> tuple:
        return tuple(j.name for j in self.joints)

    @property
    def n_unknowns(self) -> int:
        return 2 * len(self.joints) + 1

    @property
    def n_equations(self) -> int:
        return 3 * len(self.bodies)


def model(mech: "Mechanism") -> Model:
    """The body model of `mech`, for kinetostatics (checked when the file was read).

    Raises `MechanismError` when the file declares no bodies or joints.
    """
    if mech.bodies is None:
        raise MechanismError(
            "reactions need [bodies.NAME] tables (angle, mass, centroid, inertia) and [joints.NAME] tables "
            "(bodies, kind, at); this file has no bodies", file=mech.file, key="bodies")
    return mech.bodies
