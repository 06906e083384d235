"""Grashof class and type of every four-bar loop of a mechanism.

A loop of four polar vectors — the input link (its angle the input plus a constant), two links at
unknown angles, and a frame vector of constant angle — is a four-bar loop, whatever the rest of
the mechanism. Neighbouring vectors that do not move (the coordinates of two frame joints, as a
sketch file writes them) are one frame link. With s and l the shortest and longest of the four
lengths and p, q the others (Grashof's law):

- s + l < p + q, **Grashof**: the shortest link turns fully relative to the others. Its type
  follows from where the shortest link is: the frame — **double-crank** (drag link); the input —
  **crank-rocker**; the coupler (the link opposite the frame) — **double-rocker**; the output —
  **rocker-crank** (the input rocks, the output turns);
- s + l > p + q, **non-Grashof**: no link turns fully relative to another, a **triple-rocker**;
- s + l = p + q (to 1e-12 of l): the **change-point** class: the links can come into line, where
  two assembly branches cross (`jaxlink.branch_points`).

Which unknown link is the coupler follows the loop as written around the polygon (the way the
file format teaches: A0 → A → B → B0 → A0; a sketch's derived loops are written so too): the
coupler is the input's neighbour that is not the frame. A loop whose input and frame terms are
not neighbours, or whose frame vectors are apart (summed into one frame link), gets its class but
no type.

Host-side and exact: the lengths are the design's numbers (`p`), nothing is solved.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..files import expr as _expr
from ..model.mechanism import Mechanism

TYPES = {"frame": "double-crank", "input": "crank-rocker", "coupler": "double-rocker", "output": "rocker-crank"}


@dataclasses.dataclass(frozen=True)
class FourBar:
    """A four-bar loop and its Grashof class.

    - `loop`: the loop's name; `links`: the roles `input`, `coupler`, `output`, `frame` → the
      length (SI, positive; `coupler`/`output` None when the loop is not written around the
      polygon, then `others` holds the two unknown links' lengths).
    - `s`, `longest`, `pq`: the shortest (s), the longest (l), and the sum of the other two (SI).
    - `grashof`: "Grashof", "non-Grashof" or "change point"; `type`: see `TYPES`, "triple-rocker"
      for non-Grashof, None for a change point or an unknown coupler; `shortest`: its role.
    """

    loop: str
    links: dict
    s: float
    longest: float
    pq: float
    grashof: str
    type: str | None
    shortest: str | None


def _names(node) -> set:
    return {n.name for n in _expr.names_in(node)}


def _frame_vector(mech: Mechanism, t, env) -> tuple:
    """(x, y) of a term that does not move, in numpy float64 (`Mechanism.term_vector` without
    JAX: an eager JAX operation compiles on a cold start, 0.1–0.2 s each)."""
    if t.polar:
        length = float(_expr.evaluate(t.length, env, mech.kinds, mech.units, _expr.LENGTH))
        angle = float(_expr.evaluate(t.angle, env, mech.kinds, mech.units, _expr.ANGLE))
        return t.sign * length * np.cos(angle), t.sign * length * np.sin(angle)
    return (t.sign * float(_expr.evaluate(t.x, env, mech.kinds, mech.units, _expr.LENGTH)),
            t.sign * float(_expr.evaluate(t.y, env, mech.kinds, mech.units, _expr.LENGTH)))


def four_bars(mech: Mechanism, p=None) -> list:
    """Every four-bar loop of `mech` with the design `p` (SI, default the file's), in file order."""
    p = np.asarray(mech.parameters if p is None else p, dtype=float)
    env = mech.env(None, 0.0, p)
    unknowns = set(mech.unknown_names)
    out = []
    moving = unknowns | {mech.input_name}
    for name, terms in mech.loops:
        # a run of vectors that do not move (a frame vector, or a frame joint's coordinates
        # `(x, y)` and another's) is one frame link: their sum
        const = [not any(_names(nd) & moving for nd in t.nodes()) for t in terms]
        if all(const) or not any(const):
            continue
        first = next(i for i in range(len(terms)) if const[i] and not const[i - 1])
        order = [terms[(first + k) % len(terms)] for k in range(len(terms))]
        groups: list = []
        for t in order:
            c = not any(_names(nd) & moving for nd in t.nodes())
            if c and groups and groups[-1][0] == "frame":
                groups[-1][1].append(t)
            else:
                groups.append(("frame" if c else "moving", [t]))
        together = sum(g[0] == "frame" for g in groups) == 1
        if not together:  # frame vectors apart (a loop not written around its polygon): one frame link,
            frames = [t for g in groups if g[0] == "frame" for t in g[1]]  # their sum; no coupler known
            groups = [("frame", frames)] + [g for g in groups if g[0] != "frame"]
        if len(groups) != 4:
            continue
        roles: list = []
        lengths: list = []
        for kind, ts in groups:
            if kind == "frame":
                roles.append("frame")
                x = sum(_frame_vector(mech, t, env)[0] for t in ts)
                y = sum(_frame_vector(mech, t, env)[1] for t in ts)
                lengths.append(float(np.hypot(x, y)))
                continue
            t = ts[0]
            if not t.polar:
                break
            lnames, anames = _names(t.length), _names(t.angle)
            if lnames & moving:
                break  # a length that moves: a slider, not a four-bar link
            if mech.input_name in anames and not anames & unknowns:
                roles.append("input")
            elif len(anames & unknowns) == 1 and mech.input_name not in anames:
                roles.append("unknown")
            else:
                break
            lengths.append(abs(float(_expr.evaluate(t.length, env, mech.kinds, mech.units, _expr.LENGTH))))
        if sorted(roles) != ["frame", "input", "unknown", "unknown"]:
            continue
        i_in, i_fr = roles.index("input"), roles.index("frame")
        links: dict = {"input": lengths[i_in], "frame": lengths[i_fr], "coupler": None, "output": None}
        neighbours = {(i_in - 1) % 4, (i_in + 1) % 4}
        if together and i_fr in neighbours:
            i_cp = (neighbours - {i_fr}).pop()
            i_out = ({0, 1, 2, 3} - {i_in, i_fr, i_cp}).pop()
            links["coupler"], links["output"] = lengths[i_cp], lengths[i_out]
        else:
            links["others"] = tuple(lengths[i] for i in range(4) if roles[i] == "unknown")
        ls = sorted(lengths)
        s, lo, pq = ls[0], ls[3], ls[1] + ls[2]
        if abs(s + lo - pq) <= 1e-12 * lo:
            cls, typ = "change point", None
        elif s + lo < pq:
            cls, typ = "Grashof", None
        else:
            cls, typ = "non-Grashof", "triple-rocker"
        shortest = None
        if links["coupler"] is not None:
            shortest = min(("frame", "input", "coupler", "output"), key=lambda r: float(links[r]))
            if cls == "Grashof":
                typ = TYPES[shortest]
        out.append(FourBar(name, links, s, lo, pq, cls, typ, shortest))
    return out


def describe(fb: FourBar, length_factor: float, unit: str) -> str:
    """One line: `loop 'main': Grashof, crank-rocker (s + l = 80 < p + q = 100 mm; the input is
    the shortest link)`."""
    rel = {"Grashof": "<", "non-Grashof": ">", "change point": "="}[fb.grashof]
    sums = f"s + l = {(fb.s + fb.longest) / length_factor:.6g} {rel} p + q = {fb.pq / length_factor:.6g} {unit}"
    what = fb.grashof + (f", {fb.type}" if fb.type else "")
    tail = f"; the {fb.shortest} is the shortest link" if fb.shortest else ""
    return f"loop '{fb.loop}': {what} ({sums}{tail})"
