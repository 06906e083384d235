"""The loops of a sketch (`jaxlink/files/sketch.py`), found dyad by dyad.

The sketch is a graph: the joints (and the origin) are its nodes, its edges the vectors between
them — a frame joint's coordinates from the origin, every pair of joints on a body (the body's
angle), a slider's travel along its line, an actuator. An edge's `vars` are the unknowns (and the
input) its vectors use. From the joints already placed (whose position is a chain of vectors from
the origin), the shortest chain of edges through joints not yet placed that closes on placed
joints with exactly two new unknowns is one loop (an Assur group of class II): its vectors, from
the origin to the chain's start, along it, and back from its end, with every vector that meets its
opposite cancelled: the polygon of the linkage, each vector from the joint where the one before
it ends (the origin, the frame joints, the moving joints in the order the chain passes them;
`jaxlink.analysis.grashof` and `jaxlink.analysis.stroke` read which links are neighbours, as in a
loop written by hand). Its unknowns are then known, the joints they place are placed, and the search
goes on. What cannot be split so (a group of higher class) is closed by the fundamental cycles of
a spanning tree over the joints left (each plate a star from its first joint), solved together by
Newton.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

ORIGIN = "@origin"


@dataclasses.dataclass(frozen=True)
class Edge:
    """The vector from joint `u` to joint `v`: `terms` (sign, text), or `("lazy", body)` for two
    joints of a body (made by the caller when used); `vars` the unknowns its terms use."""

    u: str
    v: str
    terms: tuple
    vars: frozenset
    body: str


def neg(terms):
    """The opposite vectors."""
    return tuple((-s, t) for s, t in terms)


def text(sign: int, term: str) -> str:
    """A term as the loop form writes it: `-` in front of a negative one."""
    return term if sign > 0 else f"-{term}"


def close_loops(edges, input_name: str, unknowns: set, terms_of: Callable, err) -> tuple[dict, dict]:
    """`(loops, positions)`: the loops (name -> list of term texts) that determine `unknowns`, and
    every joint's position as its chain of `(sign, text)` vectors from the origin. `terms_of(edge,
    forward)` gives an edge's vectors."""
    adj: dict[str, list] = {}
    for e in edges:
        adj.setdefault(e.u, []).append((e, True))
        adj.setdefault(e.v, []).append((e, False))
    pos: dict[str, tuple] = {ORIGIN: ()}
    known_vars = {input_name}
    loops: dict[str, list[str]] = {}

    def propagate():
        grew = True
        while grew:
            grew = False
            for u in sorted(pos, key=lambda n: len(pos[n])):
                for e, fwd in adj.get(u, ()):
                    w = e.v if fwd else e.u
                    if w not in pos and e.vars <= known_vars:
                        pos[w] = pos[u] + terms_of(e, fwd)
                        grew = True

    def close(u: str, path: list, v: str) -> list[str]:
        ts = list(pos[u])
        for e, fwd in path:
            ts.extend(terms_of(e, fwd))
        ts.extend(neg(pos[v][::-1]))  # back to the origin the way it came: each vector joins the
        out: list = []                 # joints it lies between, the loop is the linkage's polygon
        for s, t in ts:  # cancel a vector and its opposite (a shared chain from the origin)
            if (-s, t) in out:
                out.remove((-s, t))
            else:
                out.append((s, t))
        return [text(s, t) for s, t in out]

    def best_dyad():
        best = None
        for u in sorted(pos):
            stack = [(u, [], frozenset(), (u,))]
            while stack:
                x, path, new, seen = stack.pop()
                for e, fwd in adj.get(x, ()):
                    w = e.v if fwd else e.u
                    if any(e is pe for pe, _ in path):
                        continue
                    nv = new | (e.vars - known_vars)
                    if len(nv) > 2:
                        continue
                    p2 = [*path, (e, fwd)]
                    if w in pos:
                        if len(nv) == 2:
                            score = (len(p2), u, w)
                            if best is None or score < best[0]:
                                best = (score, u, p2, w, nv)
                        continue
                    if w in seen or len(p2) >= 4:
                        continue
                    stack.append((w, p2, nv, (*seen, w)))
        return best

    propagate()
    while not unknowns <= known_vars:
        found = best_dyad()
        if found is None:
            break
        _, u, path, v, nv = found
        name = "_".join(dict.fromkeys([u, *[(e.v if f else e.u) for e, f in path]])).replace(ORIGIN, "O")
        loops[_unique(f"loop_{name}", loops)] = close(u, path, v)
        known_vars |= nv
        propagate()
    if not unknowns <= known_vars:
        # a group of higher class: the fundamental cycles of what is left (solved by Newton)
        _cycles(edges, pos, known_vars, unknowns, loops, close, err)
        known_vars |= unknowns
        propagate()
    return loops, pos


def _cycles(edges, pos, known_vars, all_vars, loops, close, err) -> None:
    """Close the unknowns left by a spanning tree over the joints not yet placed (the placed
    ones are its root): one loop per edge outside the tree."""
    # a plate's joints as a star from its first joint (the other pairs are not independent)
    first: dict[str, str] = {}
    for e in edges:
        if e.terms and e.terms[0] == "lazy":
            first.setdefault(e.body, e.u)
    rest = [e for e in edges if not e.vars <= known_vars
            and not (e.terms and e.terms[0] == "lazy" and first[e.body] not in (e.u, e.v))]
    tree: dict[str, tuple] = {}
    chords = []
    frontier = [n for n in pos]
    placed = set(pos)
    used: set = set()
    while frontier:
        x = frontier.pop(0)
        for e in rest:
            if id(e) in used or x not in (e.u, e.v):
                continue
            w, fwd = (e.v, True) if e.u == x else (e.u, False)
            used.add(id(e))
            if w in placed:
                chords.append((x, e, fwd, w))
            else:
                placed.add(w)
                tree[w] = (x, e, fwd)
                frontier.append(w)
    chords.extend((e.u, e, True, e.v) for e in rest if id(e) not in used)
    need = len(all_vars - known_vars)
    if 2 * len(chords) != need:
        raise err(f"{len(chords)} loop(s) for {need} unknown(s) left: the sketch cannot be closed into loops "
                  "(check the links and sliders)", "sketch")

    def path_to(n: str) -> tuple:
        out = []
        while n in tree:
            x, e, fwd = tree[n]
            out.append((e, fwd))
            n = x
        return n, out[::-1]

    for x, e, fwd, w in chords:
        root_x, px = path_to(x)
        root_w, pw = path_to(w)
        path = [*px, (e, fwd), *[(pe, not pf) for pe, pf in reversed(pw)]]
        loops[_unique(f"loop_{x}_{w}", loops)] = close(root_x, path, root_w)


def _unique(name: str, taken) -> str:
    k, out = 2, name
    while out in taken:
        out, k = f"{name}_{k}", k + 1
    return out


