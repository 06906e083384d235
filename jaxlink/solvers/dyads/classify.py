"""Which blocks of a loop-closure system are dyads, and of which kind (`jaxlink.solvers.dyads`).

A block (`jaxlink.model.structure.blocks`) of one loop with two new unknowns is a dyad when every
term of its loop is, in the two unknowns, one of (c, k, m, α known expressions; θ an angle
unknown, ℓ a length unknown of the dyad):

    s (k ℓ + m) @ θ + c      (θ and/or ℓ may be absent: k = 0, or a known angle α for θ + c),
    s (k_x ℓ + m_x, k_y ℓ + m_y),

that is, at most one angle unknown, in the angle only and as θ + c, and at most one length
unknown, in the length (or the components) only and affinely. Each term is then a `Part` of the
dyad: the slot of the unknown that turns it (`turn`), the slot of the length it is affine in
(`slide`), the angle c (or α), and the nodes of k and m. The pair of unknowns and where the
length unknowns stand give the kind (see the package docstring): RRR (two angles), RRP (an angle;
a length only in terms that do not turn with it), RPR (an angle; a length only in terms that turn
with it), PP (two lengths, no angle). Anything else (an unknown inside a function, an angle
unknown twice in one angle, a length that both turns with the angle and does not) has no closed
form here: `classify` returns None and the solver uses Newton's method.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from ...files import expr as _expr
from ...model.mechanism import Mechanism
from ...model.structure import blocks


@dataclasses.dataclass(frozen=True)
class Part:
    """One term of a dyad's loop that holds one of its unknowns: `sign · (k ℓ + m) @ θ + angle`
    (polar) or `sign · (k_x ℓ + m_x, k_y ℓ + m_y)` (Cartesian, `angle` None).

    - `term`: its index in the loop; `sign`: ±1.
    - `turn`: the slot (0 or 1, in `Dyad.unknowns`) of the angle unknown θ that turns it, or None
      (then `angle` is the whole, known, angle).
    - `angle`: the node of c (θ + c), of the known angle, or None (Cartesian).
    - `slide`: the slot of the length unknown ℓ it is affine in, or None.
    - `coef`, `const`: the nodes of k and m (polar: 1-tuples; Cartesian: (x, y)); None for 0.
    """

    term: int
    sign: int
    turn: int | None
    angle: Any
    slide: int | None
    coef: tuple
    const: tuple

    @property
    def polar(self) -> bool:
        return len(self.coef) == 1


@dataclasses.dataclass(frozen=True)
class Dyad:
    """A dyad of the solve order: `kind` ("RRR" | "RRP" | "RPR" | "PP"), `loop` (index), `unknowns`
    (indices into q, in slot order: RRR the two angles, RRP and RPR the angle then the length, PP
    the two lengths), `parts` (the terms that hold an unknown, `Part`) and `rest` (the indices of
    the loop's other, known, terms)."""

    kind: str
    loop: int
    unknowns: tuple
    parts: tuple
    rest: tuple

    def slot(self, turn: int | None) -> tuple:
        """The parts turned by slot `turn`'s angle (None: the parts that do not turn)."""
        return tuple(pt for pt in self.parts if pt.turn == turn)


_ONE = _expr.Num(1.0)


def _has(node, name) -> bool:
    return node is not None and any(n.name == name for n in _expr.names_in(node))


def _is_zero(node) -> bool:
    return isinstance(node, _expr.Num) and node.value == 0.0


def _add(a, b, op="+"):
    if b is None:
        return a
    if a is None:
        return b if op == "+" else _expr.Neg(b)
    return _expr.Bin(op, a, b)


def _scale(a, op, factor, left: bool = False):
    """a op factor (or factor * a when `left`), None for a = None; 1 * x is x."""
    if a is None:
        return None
    if op == "*" and a == _ONE:
        return factor
    return _expr.Bin(op, factor, a) if left else _expr.Bin(op, a, factor)


def affine(node, name):
    """`(k, m)` with node = k · name + m, k and m free of `name` (None for 0); None where `node`
    is not affine in `name` (a product of two terms holding it, a function of it, a divisor)."""
    if node is None or not _has(node, name):
        return None, (None if node is None or _is_zero(node) else node)
    if isinstance(node, _expr.Name):
        return _ONE, None
    if isinstance(node, _expr.Neg):
        inner = affine(node.arg, name)
        if inner is None:
            return None
        return tuple(None if x is None else _expr.Neg(x) for x in inner)
    if isinstance(node, _expr.Bin):
        if node.op in "+-":
            left, right = affine(node.left, name), affine(node.right, name)
            if left is None or right is None:
                return None
            return _add(left[0], right[0], node.op), _add(left[1], right[1], node.op)
        inl, inr = _has(node.left, name), _has(node.right, name)
        if node.op == "*" and inl != inr:
            side, factor = (node.left, node.right) if inl else (node.right, node.left)
            inner = affine(side, name)
            if inner is None:
                return None
            return _scale(inner[0], "*", factor), _scale(inner[1], "*", factor)
        if node.op == "/" and inl and not inr:
            inner = affine(node.left, name)
            if inner is None:
                return None
            k = _expr.Bin("/", inner[0], node.right)
            return k, _scale(inner[1], "/", node.right)
    return None


def angle_offset(node, name):
    """If `node` is `name + c` (c free of `name`), return c's node (or Num(0)); else None."""
    if isinstance(node, _expr.Name):
        return _expr.Num(0.0) if node.name == name else None
    if isinstance(node, _expr.Bin) and node.op in "+-":
        inl, inr = _has(node.left, name), _has(node.right, name)
        if inl and not inr:
            c = angle_offset(node.left, name)
            if c is None:
                return None
            return _expr.Bin(node.op, c, node.right)
        if inr and not inl and node.op == "+":
            c = angle_offset(node.right, name)
            if c is None:
                return None
            return _expr.Bin("+", node.left, c)
    return None


def _part(term, index: int, names: tuple, kinds: tuple) -> Part | bool | None:
    """The `Part` of one term; False where it holds neither unknown; None where it has no
    closed form (see the module docstring)."""
    held = [j for j, n in enumerate(names) if any(_has(nd, n) for nd in term.nodes())]
    if not held:
        return False
    angles = [j for j in held if kinds[j] == "angle"]
    lengths = [j for j in held if kinds[j] != "angle"]
    if len(angles) > 1 or len(lengths) > 1:
        return None
    turn = angles[0] if angles else None
    slide = lengths[0] if lengths else None
    if term.polar:
        if turn is not None and _has(term.length, names[turn]):
            return None
        if slide is not None and _has(term.angle, names[slide]):
            return None
        angle = term.angle if turn is None else angle_offset(term.angle, names[turn])
        if angle is None:
            return None
        if slide is None:
            return Part(index, term.sign, turn, angle, None, (None,), (term.length,))
        km = affine(term.length, names[slide])
        if km is None or km[0] is None:
            return None
        return Part(index, term.sign, turn, angle, slide, (km[0],), (km[1],))
    if turn is not None or slide is None:
        return None
    kx, ky = affine(term.x, names[slide]), affine(term.y, names[slide])
    if kx is None or ky is None:
        return None
    return Part(index, term.sign, None, None, slide, (kx[0], ky[0]), (kx[1], ky[1]))


def _dyad(mech: Mechanism, li: int, unk: tuple) -> Dyad | None:
    terms = mech.loops[li][1]
    kinds = tuple(mech.unknown_kinds[i] for i in unk)
    # slots: angles first (RRR: both; RRP/RPR: the angle, then the length; PP: both lengths)
    order = (0, 1) if kinds[0] == "angle" or kinds[1] != "angle" else (1, 0)
    unk = tuple(unk[i] for i in order)
    kinds = tuple(kinds[i] for i in order)
    names = tuple(mech.unknown_names[i] for i in unk)
    parts: list[Part] = []
    rest: list[int] = []
    for ti, t in enumerate(terms):
        pt = _part(t, ti, names, kinds)
        if pt is None:
            return None
        if isinstance(pt, Part):
            parts.append(pt)
        else:
            rest.append(ti)
    for j in range(2):  # each unknown must be held somewhere
        if not any(pt.turn == j or pt.slide == j for pt in parts):
            return None
    n_angles = sum(k == "angle" for k in kinds)
    if n_angles == 2:
        kind = "RRR"
    elif n_angles == 1:
        turning = any(pt.slide == 1 and pt.turn == 0 for pt in parts)
        fixed = any(pt.slide == 1 and pt.turn is None for pt in parts)
        if turning and fixed:
            return None
        if fixed and not any(pt.turn == 0 for pt in parts):
            return None
        kind = "RPR" if turning else "RRP"
    else:
        kind = "PP"
    return Dyad(kind, li, unk, tuple(parts), tuple(rest))


def classify(mech: Mechanism) -> tuple | None:
    """The dyads of every block, in solve order, or None if some block has no closed form."""
    out = []
    for loops, unk in blocks(mech):
        if len(loops) != 1 or len(unk) != 2:
            return None
        d = _dyad(mech, loops[0], tuple(unk))
        if d is None:
            return None
        out.append(d)
    return tuple(out)
