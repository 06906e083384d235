"""Structural analysis: mobility and independent loops.

From the loop equations: mobility = (unknowns + 1 input) − 2 × loops.
From `[joints]` (when the file has them), Grübler–Kutzbach for planar mechanisms:

    n = 3 (u − 1) − Σ_t t · s_t,      k = s − u + 1,

u = members including the frame (`ground`), s_t the number of joints of class t and s = Σ_t s_t.
What a joint may be, and its class, is `JOINT_CLASS` (`jaxlink/model/bodies.py`): every joint
joins two members (a pin shared by v members is written as v − 1 joints).
"""

from __future__ import annotations

from .bodies import JOINT_CLASS, Model
from .mechanism import Mechanism


def grubler(mdl: Model) -> dict:
    """Members u, joint count s, mobility n and independent loops k of a body model."""
    u = len(mdl.bodies) + 1
    s = len(mdl.joints)
    return {
        "members": u,
        "joint_count": s,
        "mobility": 3 * (u - 1) - sum(JOINT_CLASS[j.kind] for j in mdl.joints),
        "loops": s - u + 1,
    }


def structure(mech: Mechanism) -> dict:
    return {
        "unknowns": mech.n_unknowns,
        "equations": mech.n_equations,
        "loops": len(mech.loops),
        "mobility_loops": mech.mobility_from_loops(),
        "grubler": None if mech.bodies is None else grubler(mech.bodies),
    }


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
    out: list[tuple[tuple[int, ...], tuple[int, ...]]] = []
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
