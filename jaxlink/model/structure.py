"""Structural analysis (seed 002; seed 000 ch. 4): mobility and independent loops.

From the loop equations: mobility = (unknowns + 1 input) − 2 × loops.
From `[joints]` (when the file has them), Grübler–Kutzbach for planar mechanisms:

    n = 3 (u − 1) − Σ_t t · s_t,      s_t = Σ_v s_tv (v − 1),      k = s − u + 1,

u = members including the frame (`ground`), t = 2 for revolute/prismatic joints and 1 for a higher
pair (cam contact), a joint connecting v members counting v − 1 times.
"""

from __future__ import annotations

from ..errors import MechanismError
from .mechanism import Mechanism

JOINT_CLASS = {"revolute": 2, "prismatic": 2, "higher": 1, "cam": 1}


def grubler(joints: dict, *, file: str | None = None) -> dict:
    """Mobility from a `{name: {"bodies": [...], "kind": ...}}` table of joints."""
    members = {"ground"}
    s = {1: 0, 2: 0}
    for jname, j in joints.items():
        if not isinstance(j, dict):
            raise MechanismError(f"joint '{jname}' must be a table", file=file, key=f"joints.{jname}")
        bodies = j.get("bodies")
        if not isinstance(bodies, list) or len(bodies) < 2:
            raise MechanismError("'bodies' must list at least two bodies (use \"ground\" for the frame)",
                                 file=file, key=f"joints.{jname}.bodies")
        kind = j.get("kind", "revolute")
        if kind not in JOINT_CLASS:
            raise MechanismError(f"unknown joint kind '{kind}'; use one of {', '.join(JOINT_CLASS)}",
                                 file=file, key=f"joints.{jname}.kind")
        members.update(str(b) for b in bodies)
        s[JOINT_CLASS[kind]] += len(bodies) - 1
    u = len(members)
    joint_count = s[1] + s[2]
    return {
        "members": u,
        "joint_count": joint_count,
        "mobility": 3 * (u - 1) - 2 * s[2] - 1 * s[1],
        "loops": joint_count - u + 1,
    }


def structure(mech: Mechanism) -> dict:
    info = {
        "unknowns": mech.n_unknowns,
        "equations": mech.n_equations,
        "loops": len(mech.loops),
        "mobility_loops": mech.mobility_from_loops(),
        "grubler": None,
    }
    joints = mech.tables.get("joints")
    if isinstance(joints, dict) and joints:
        info["grubler"] = grubler(joints, file=mech.file)
    return info


# ----------------------------------------------------------------------------- solve order


def _unknowns_of(mech: Mechanism, terms) -> set:
    from ..files import expr as _expr

    names = set(mech.unknown_names)
    return {nm.name for t in terms for nd in t.nodes() for nm in _expr.names_in(nd) if nm.name in names}


def blocks(mech: Mechanism) -> tuple:
    """A block-triangular solve order of the loop equations.

    Returns a tuple of `(loop_indices, unknown_indices)`: each block's loops determine exactly its
    unknowns once the unknowns of the earlier blocks are known (a dyad — Assur group of class II —
    is one loop with two new unknowns). Loops that cannot be ordered so (class III groups and
    higher) form one final block. In this order Φ_q is block lower-triangular, so Newton's linear
    solve is a forward substitution with small diagonal blocks, and blocks of known form have
    closed-form solutions (`_dyads`).
    """
    index = {n: i for i, n in enumerate(mech.unknown_names)}
    remaining = list(range(len(mech.loops)))
    uses = {i: _unknowns_of(mech, mech.loops[i][1]) for i in remaining}
    known: set = set()
    out = []
    progress = True
    while remaining and progress:
        progress = False
        for i in remaining:
            new = uses[i] - known
            if len(new) == 2:
                out.append(((i,), tuple(sorted(index[n] for n in new))))
                known |= new
                remaining.remove(i)
                progress = True
                break
            if len(new) == 0:
                break
    if remaining:
        rest = set().union(*(uses[i] for i in remaining)) - known
        out.append((tuple(remaining), tuple(sorted(index[n] for n in rest))))
    return tuple(out)
