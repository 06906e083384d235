"""Arithmetic expressions and vector terms of mechanism files.

Grammar (parsed by recursive descent, never `eval`ed; bounded: at most `MAX_TOKENS` tokens and
`MAX_NESTING` levels of parentheses, function calls and signs, so that a hostile expression is
refused with its limit instead of exhausting the stack; a long sum or product, such as a sum of
thousands of names, is built as a balanced tree)::

    term    := expr '@' expr            # LENGTH @ ANGLE: LENGTH * (cos ANGLE, sin ANGLE)
             | ['+'|'-'] '(' expr ',' expr ')'   # a constant vector (X, Y)
    expr    := mul (('+'|'-') mul)*
    mul     := unary (('*'|'/') unary)*
    unary   := ('+'|'-') unary | primary
    primary := NUMBER | NAME | NAME '(' expr [',' expr] ')' | '(' expr ')'

A leading sign of a `LENGTH @ ANGLE` term belongs to LENGTH, which is the same vector.
Functions: `sin cos tan` (argument an angle, in the file's angle unit when it is a bare
number), `sqrt`, `asin acos atan` (result an angle) and `atan2(y, x)`.

**Units.** Every name has a *kind* — length, angle or a pure number — inferred from where it
is used (`kind_constraints`) or declared. Values of names are SI (m, rad) inside jaxlink.
A bare number has no unit of its own: it takes the file unit of whatever it is added to or
compared with (`phi3 + 90` in a degree file means 90°; `2 * a` is twice `a`). So every
expression is evaluated exactly in SI, with the file's unit factors applied to bare numbers
at trace time.
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction
from typing import Callable, Mapping, Union

import jax.numpy as jnp
import numpy as np

from .keys import suggest  # noqa: F401  (the did-you-mean of every file error: `_expr.suggest`)

# ----------------------------------------------------------------------------- limits

#: most tokens (numbers, names, operators) in one expression or term
MAX_TOKENS = 20000
#: most levels of parentheses, function calls and leading signs inside one another
MAX_NESTING = 100
#: most levels of the expression tree (a balanced sum of n terms counts log2 n)
MAX_DEPTH = 250
#: largest magnitude of a number written in an expression
MAX_LITERAL = 1e15
# a sum or product of more terms than this is built as a balanced tree (shorter ones are folded
# left to right, as written, so that their rounding is that of the text)
_BALANCE_ABOVE = 32

# ----------------------------------------------------------------------------- tokens


@dataclasses.dataclass(frozen=True)
class Token:
    kind: str  # "num", "name", "op", "end"
    text: str
    col: int  # 0-based column in the expression text


def tokenize(text: str) -> list[Token]:
    tokens: list[Token] = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c.isspace():
            i += 1
            continue
        if c.isdigit() or (c == "." and i + 1 < n and text[i + 1].isdigit()):
            j = i
            while j < n and (text[j].isdigit() or text[j] == "."):
                j += 1
            if j < n and text[j] in "eE":
                k = j + 1
                if k < n and text[k] in "+-":
                    k += 1
                if k < n and text[k].isdigit():
                    j = k
                    while j < n and text[j].isdigit():
                        j += 1
            lit = text[i:j]
            try:
                value = float(lit)
            except ValueError:
                raise _SyntaxError(f"malformed number '{lit}'", i) from None
            if not abs(value) <= MAX_LITERAL:
                raise _SyntaxError(f"number '{_short(lit)}' is out of range (|x| ≤ {MAX_LITERAL:g})", i)
            tokens.append(Token("num", lit, i))
            i = j
            continue
        if c.isalpha() or c == "_":
            j = i
            while j < n and (text[j].isalnum() or text[j] == "_"):
                j += 1
            tokens.append(Token("name", text[i:j], i))
            i = j
            continue
        if c in "+-*/(),@":
            tokens.append(Token("op", c, i))
            i += 1
            continue
        raise _SyntaxError(f"unexpected character '{c}'", i)
        if len(tokens) > MAX_TOKENS:
            raise _SyntaxError(f"the expression is too long: more than {MAX_TOKENS} tokens", i)
    tokens.append(Token("end", "", n))
    return tokens


def _short(text: str, n: int = 24) -> str:
    return text if len(text) <= n else f"{text[:n // 2]}…{text[-n // 2:]} ({len(text)} characters)"


class _SyntaxError(Exception):
    def __init__(self, message: str, col: int):
        super().__init__(message)
        self.message = message
        self.col = col


# ----------------------------------------------------------------------------- AST


@dataclasses.dataclass(frozen=True)
class Num:
    value: float


@dataclasses.dataclass(frozen=True)
class Name:
    name: str
    col: int


@dataclasses.dataclass(frozen=True)
class Neg:
    arg: "Node"


@dataclasses.dataclass(frozen=True)
class Bin:
    op: str  # + - * /
    left: "Node"
    right: "Node"


@dataclasses.dataclass(frozen=True)
class Call:
    func: str
    args: tuple


@dataclasses.dataclass(frozen=True)
class Vec:
    x: "Node"
    y: "Node"


Node = Union[Num, Name, Neg, Bin, Call, Vec]

FUNCTIONS = {"sin": 1, "cos": 1, "tan": 1, "sqrt": 1, "asin": 1, "acos": 1, "atan": 1, "atan2": 2}
# named constants: `pi` is the angle π rad (180°) in any file, whatever its angle unit
CONSTANTS = {"pi": math.pi}


@dataclasses.dataclass(frozen=True)
class Term:
    """One vector of a loop or point sum: `LENGTH @ ANGLE` or `(X, Y)` (with `sign` ±1)."""

    sign: int
    length: Node | None  # polar form
    angle: Node | None
    x: Node | None  # Cartesian form
    y: Node | None
    text: str

    @property
    def polar(self) -> bool:
        return self.length is not None

    def nodes(self) -> tuple:
        return (self.length, self.angle) if self.polar else (self.x, self.y)


class _Parser:
    def __init__(self, text: str):
        self.text = text
        self.tokens = tokenize(text)
        self.pos = 0
        self.depth = 0

    def enter(self, tok: Token) -> None:
        self.depth += 1
        if self.depth > MAX_NESTING:
            raise _SyntaxError(f"nested too deeply: more than {MAX_NESTING} levels of parentheses, "
                               "functions or signs", tok.col)

    def peek(self) -> Token:
        return self.tokens[self.pos]

    def take(self) -> Token:
        tok = self.tokens[self.pos]
        self.pos += 1
        return tok

    def expect(self, text: str) -> Token:
        tok = self.take()
        if tok.text != text:
            found = f"'{tok.text}'" if tok.kind != "end" else "the end"
            raise _SyntaxError(f"expected '{text}' but found {found}", tok.col)
        return tok

    def expr(self) -> Node:
        items: list = [("+", self.mul())]
        while self.peek().text in ("+", "-") and self.peek().kind == "op":
            op = self.take().text
            items.append((op, self.mul()))
        return _chain(items, "+", "-")

    def mul(self) -> Node:
        items: list = [("*", self.unary())]
        while self.peek().text in ("*", "/") and self.peek().kind == "op":
            op = self.take()
            arg = self.unary()
            if op.text == "/" and isinstance(arg, Num) and arg.value == 0:
                raise _SyntaxError("division by zero", op.col)
            items.append((op.text, arg))
        return _chain(items, "*", "/")

    def unary(self) -> Node:
        tok = self.peek()
        if tok.kind == "op" and tok.text in "+-":
            self.take()
            self.enter(tok)
            arg = self.unary()
            self.depth -= 1
            return Neg(arg) if tok.text == "-" else arg
        return self.primary()

    def primary(self) -> Node:
        tok = self.take()
        if tok.kind == "num":
            return Num(float(tok.text))
        if tok.kind == "name":
            if self.peek().text == "(":
                if tok.text not in FUNCTIONS:
                    raise _SyntaxError(
                        f"unknown function '{tok.text}' (known: {', '.join(FUNCTIONS)})", tok.col
                    )
                self.take()
                self.enter(tok)
                args = [self.expr()]
                while self.peek().text == ",":
                    self.take()
                    args.append(self.expr())
                self.expect(")")
                self.depth -= 1
                if len(args) != FUNCTIONS[tok.text]:
                    raise _SyntaxError(
                        f"{tok.text}() takes {FUNCTIONS[tok.text]} argument(s), got {len(args)}",
                        tok.col,
                    )
                return Call(tok.text, tuple(args))
            if tok.text in FUNCTIONS:
                raise _SyntaxError(f"function '{tok.text}' needs parentheses", tok.col)
            return Name(tok.text, tok.col)
        if tok.text == "(":
            self.enter(tok)
            first = self.expr()
            if self.peek().text == ",":
                self.take()
                second = self.expr()
                self.expect(")")
                self.depth -= 1
                return Vec(first, second)
            self.expect(")")
            self.depth -= 1
            return first
        if tok.kind == "end":
            raise _SyntaxError("the expression ends too early", tok.col)
        raise _SyntaxError(f"unexpected '{tok.text}'", tok.col)


def _chain(items: list, unit: str, inverse: str) -> Node:
    """`t0 op1 t1 op2 t2 …` (items `[(unit, t0), (op1, t1), …]`) as a tree of `Bin`: folded left to
    right when short; balanced when long (`a − b + c − d` = `(a − b) − (c − d)`: the right half's
    operators flip when it is joined by the inverse operator), so that its depth is log2 of its
    length."""
    if len(items) <= _BALANCE_ABOVE:
        node = items[0][1]
        for op, arg in items[1:]:
            node = Bin(op, node, arg)
        return node

    def build(part: list) -> Node:
        if len(part) == 1:
            return part[0][1]
        mid = len(part) // 2
        op = part[mid][0]
        right = part[mid:]
        if op == inverse:  # a − (b ∓ c …): the operators after b flip
            right = [(unit, right[0][1])] + [(unit if o == inverse else inverse, t) for o, t in right[1:]]
        else:
            right = [(unit, right[0][1])] + right[1:]
        return Bin(op, build(part[:mid]), build(right))

    return build(items)


def depth(node: Node) -> int:
    """Levels of the expression tree (1 for a number or a name), without recursion."""
    best, stack = 0, [(node, 1)]
    while stack:
        nd, d = stack.pop()
        best = max(best, d)
        if isinstance(nd, Neg):
            stack.append((nd.arg, d + 1))
        elif isinstance(nd, Bin):
            stack += [(nd.left, d + 1), (nd.right, d + 1)]
        elif isinstance(nd, Call):
            stack += [(a, d + 1) for a in nd.args]
        elif isinstance(nd, Vec):
            stack += [(nd.x, d + 1), (nd.y, d + 1)]
    return best


def _bounded(node: Node) -> Node:
    d = depth(node)
    if d > MAX_DEPTH:
        raise _SyntaxError(f"the expression is nested too deeply: {d} levels, at most {MAX_DEPTH}", 0)
    return node


def _contains_vec(node: Node) -> bool:
    if isinstance(node, Vec):
        return True
    if isinstance(node, Neg):
        return _contains_vec(node.arg)
    if isinstance(node, Bin):
        return _contains_vec(node.left) or _contains_vec(node.right)
    if isinstance(node, Call):
        return any(_contains_vec(a) for a in node.args)
    return False


def parse_expr(text: str) -> Node:
    """Parse a scalar expression; raises `ExprSyntaxError` with the column."""
    try:
        p = _Parser(text)
        node = _bounded(p.expr())
        if p.peek().kind != "end":
            tok = p.peek()
            raise _SyntaxError(f"unexpected '{tok.text}' after the expression", tok.col)
        if _contains_vec(node):
            raise _SyntaxError("a vector (X, Y) is not allowed inside a scalar expression", 0)
        return node
    except _SyntaxError as exc:
        raise ExprSyntaxError(exc.message, text, exc.col) from None


def parse_term(text: str) -> Term:
    """Parse one vector term `[+|-] LENGTH @ ANGLE` or `[+|-] (X, Y)`."""
    if not isinstance(text, str):
        raise ExprSyntaxError(f"a term must be a string, got {text!r}", str(text), 0)
    try:
        p = _Parser(text)
        if p.peek().kind == "end":
            raise _SyntaxError("empty term", 0)
        left = _bounded(p.expr())
        if p.peek().text == "@":
            at = p.take()
            if _contains_vec(left):
                raise _SyntaxError("'(X, Y) @ ...' mixes the two term forms", at.col)
            right = _bounded(p.expr())
            if p.peek().kind != "end":
                tok = p.peek()
                raise _SyntaxError(f"unexpected '{tok.text}' after the angle", tok.col)
            if _contains_vec(right):
                raise _SyntaxError("the angle must be a scalar expression", at.col + 1)
            sign = 1
            while isinstance(left, Neg):  # "-c @ phi": the sign belongs to the vector
                sign, left = -sign, left.arg
            return Term(sign, left, right, None, None, text)
        if p.peek().kind != "end":
            tok = p.peek()
            raise _SyntaxError(f"unexpected '{tok.text}'", tok.col)
        sign = 1
        node = left
        while isinstance(node, Neg):
            sign, node = -sign, node.arg
        if isinstance(node, Vec):
            return Term(sign, None, None, node.x, node.y, text)
        raise _SyntaxError("a term is 'LENGTH @ ANGLE' or '(X, Y)'; no '@' found", len(text))
    except _SyntaxError as exc:
        raise ExprSyntaxError(exc.message, text, exc.col) from None


class ExprSyntaxError(Exception):
    """A syntax error with the column (1-based in the message) and a caret line."""

    def __init__(self, message: str, text: str, col: int):
        self.message = message
        self.text = text
        self.col = col
        shown, at = text, col
        if len(text) > 80:  # a window of the text around the column
            lo = max(0, min(col - 40, len(text) - 80))
            shown = ("…" if lo else "") + text[lo:lo + 80] + ("…" if lo + 80 < len(text) else "")
            at = col - lo + (1 if lo else 0)
        caret = " " * at + "^"
        super().__init__(f"syntax error at column {col + 1}: {message}\n    {shown}\n    {caret}")


def names_in(node: Node | None) -> list[Name]:
    """The names an expression uses (not the constants of `CONSTANTS`)."""
    if node is None or isinstance(node, Num):
        return []
    if isinstance(node, Name):
        return [] if node.name in CONSTANTS else [node]
    if isinstance(node, Neg):
        return names_in(node.arg)
    if isinstance(node, Bin):
        return names_in(node.left) + names_in(node.right)
    if isinstance(node, Call):
        return [n for a in node.args for n in names_in(a)]
    if isinstance(node, Vec):
        return names_in(node.x) + names_in(node.y)
    raise TypeError(node)


def substitute(node: Node | None, defs: Mapping[str, Node]) -> Node | None:
    """`node` with every name of `defs` replaced by its expression (a derived parameter is its
    expression: `jaxlink/files/reader.py` expands them where they are used)."""
    if node is None or not defs:
        return node
    return _substitute(node, defs)


def _substitute(node: Node, defs: Mapping[str, Node]) -> Node:
    if isinstance(node, Num):
        return node
    if isinstance(node, Name):
        return defs.get(node.name, node)
    if isinstance(node, Neg):
        return Neg(_substitute(node.arg, defs))
    if isinstance(node, Bin):
        return Bin(node.op, _substitute(node.left, defs), _substitute(node.right, defs))
    if isinstance(node, Call):
        return Call(node.func, tuple(_substitute(a, defs) for a in node.args))
    if isinstance(node, Vec):
        return Vec(_substitute(node.x, defs), _substitute(node.y, defs))
    raise TypeError(node)


def substitute_term(term: Term, defs: Mapping[str, Node]) -> Term:
    """`term` with the names of `defs` replaced (its `text` is kept as written)."""
    if not defs:
        return term
    return dataclasses.replace(term, length=substitute(term.length, defs), angle=substitute(term.angle, defs),
                               x=substitute(term.x, defs), y=substitute(term.y, defs))


# ----------------------------------------------------------------------------- kinds and units

# A dimension is (length power, angle power); a bare number has dimension None ("free").
Dim = tuple
LENGTH: Dim = (Fraction(1), Fraction(0))
ANGLE: Dim = (Fraction(0), Fraction(1))
NUMBER: Dim = (Fraction(0), Fraction(0))
KIND_DIMS = {"length": LENGTH, "angle": ANGLE, "number": NUMBER}
DIM_KINDS = {v: k for k, v in KIND_DIMS.items()}


def _dim_name(d: Dim | None) -> str:
    if d is None:
        return "a bare number"
    if d in DIM_KINDS:
        return "a " + DIM_KINDS[d] if DIM_KINDS[d] != "angle" else "an angle"
    parts = [f"{n}^{p}" for n, p in (("length", d[0]), ("angle", d[1])) if p != 0]
    return "·".join(parts)


class UnitError(Exception):
    """Inconsistent kinds inside an expression (e.g. a length added to an angle)."""


def _add(a: Dim | None, b: Dim | None, op: str) -> Dim | None:
    if a is None:
        return b
    if b is None or a == b:
        return a
    raise UnitError(f"'{op}' of {_dim_name(a)} and {_dim_name(b)}")


def dim_of(node: Node, kinds: Mapping[str, str | None]) -> Dim | None:
    """The dimension of an expression given the kinds of its names (None = bare number or not
    yet known); raises `UnitError` when inconsistent, KeyError for an unknown kind."""
    if isinstance(node, Num):
        return None
    if isinstance(node, Name) and node.name in CONSTANTS:
        return ANGLE
    if isinstance(node, Name):
        k = kinds[node.name]
        if k is None:
            raise KeyError(node.name)
        return KIND_DIMS[k]
    if isinstance(node, Neg):
        return dim_of(node.arg, kinds)
    if isinstance(node, Bin):
        a, b = dim_of(node.left, kinds), dim_of(node.right, kinds)
        if node.op in "+-":
            return _add(a, b, node.op)
        if a is None and b is None:
            return None
        a = a or NUMBER
        b = b or NUMBER
        if node.op == "*":
            return (a[0] + b[0], a[1] + b[1])
        return (a[0] - b[0], a[1] - b[1])
    if isinstance(node, Call):
        dims = [dim_of(x, kinds) for x in node.args]
        f = node.func
        if f in ("sin", "cos", "tan"):
            if dims[0] not in (None, ANGLE):
                raise UnitError(f"{f}() of {_dim_name(dims[0])}; it takes an angle")
            return NUMBER
        if f == "sqrt":
            return None if dims[0] is None else (dims[0][0] / 2, dims[0][1] / 2)
        if f in ("asin", "acos", "atan"):
            if dims[0] not in (None, NUMBER):
                raise UnitError(f"{f}() of {_dim_name(dims[0])}; it takes a pure number")
            return ANGLE
        if f == "atan2":
            _add(dims[0], dims[1], "atan2")
            return ANGLE
    raise TypeError(node)


def kind_constraints(node: Node, expected: Dim | None, kinds: dict, record: Callable) -> None:
    """Propagate an expected dimension down `node`, calling `record(name_node, dim)` for every
    name whose kind this use implies. `kinds` maps names to known kinds (or None)."""

    def known(n: Node) -> tuple[bool, Dim | None]:
        try:
            return True, dim_of(n, kinds)
        except KeyError:
            return False, None

    if isinstance(node, Num):
        return
    if isinstance(node, Name) and node.name in CONSTANTS:
        return
    if isinstance(node, Name):
        if expected is not None:
            record(node, expected)
        return
    if isinstance(node, Neg):
        kind_constraints(node.arg, expected, kinds, record)
        return
    if isinstance(node, Bin):
        if node.op in "+-":
            exp = expected
            if exp is None:
                for child in (node.left, node.right):
                    ok, d = known(child)
                    if ok and d is not None:
                        exp = d
                        break
            kind_constraints(node.left, exp, kinds, record)
            kind_constraints(node.right, exp, kinds, record)
            return
        # * and /: a side whose dimension is known (a bare number counts as a pure number)
        # fixes the other one.
        okl, dl = known(node.left)
        okr, dr = known(node.right)
        dl = dl or NUMBER if okl else None
        dr = dr or NUMBER if okr else None
        if expected is not None:
            if okl and not okr:
                assert dl is not None
                other = (
                    (expected[0] - dl[0], expected[1] - dl[1])
                    if node.op == "*"
                    else (dl[0] - expected[0], dl[1] - expected[1])
                )
                kind_constraints(node.right, other, kinds, record)
            elif okr and not okl:
                assert dr is not None
                other = (
                    (expected[0] - dr[0], expected[1] - dr[1])
                    if node.op == "*"
                    else (expected[0] + dr[0], expected[1] + dr[1])
                )
                kind_constraints(node.left, other, kinds, record)
            elif (not okl and not okr and node.op == "*" and isinstance(node.left, Name)
                  and isinstance(node.right, Name) and node.left.name == node.right.name
                  and (expected[0] / 2, expected[1] / 2) in (LENGTH, ANGLE, NUMBER)):
                # a square x*x of dimension D: x has dimension D/2 (as in the law of cosines)
                record(node.left, (expected[0] / 2, expected[1] / 2))
                return
        kind_constraints(node.left, None, kinds, record) if not okl else None
        kind_constraints(node.right, None, kinds, record) if not okr else None
        return
    if isinstance(node, Call):
        f = node.func
        if f in ("sin", "cos", "tan"):
            kind_constraints(node.args[0], ANGLE, kinds, record)
        elif f in ("asin", "acos", "atan"):
            kind_constraints(node.args[0], NUMBER, kinds, record)
        elif f == "sqrt":
            exp = None if expected is None else (expected[0] * 2, expected[1] * 2)
            kind_constraints(node.args[0], exp, kinds, record)
        elif f == "atan2":
            ok0, d0 = known(node.args[0])
            ok1, d1 = known(node.args[1])
            exp = d0 if ok0 and d0 is not None else (d1 if ok1 else None)
            kind_constraints(node.args[0], exp, kinds, record)
            kind_constraints(node.args[1], exp, kinds, record)
        return
    raise TypeError(node)


# ----------------------------------------------------------------------------- evaluation


@dataclasses.dataclass(frozen=True)
class Units:
    """File unit factors: SI value = file value × factor."""

    length: float  # 1.0 for m, 1e-3 for mm
    angle: float  # 1.0 for rad, pi/180 for deg

    def factor(self, d: Dim) -> float:
        return float(self.length ** float(d[0]) * self.angle ** float(d[1]))


def evaluate(node: Node, env: Mapping, kinds: Mapping[str, str], units: Units, role: Dim):
    """Evaluate `node` in SI. `env` maps names to SI values (floats or JAX arrays); `role` is the
    dimension the result must have (bare numbers are read in the file unit of that role)."""
    value, d = _eval(node, env, kinds, units)
    if d is None:
        return value * units.factor(role)
    if d != role:
        raise UnitError(f"the expression is {_dim_name(d)} where {_dim_name(role)} is expected")
    return value


def _as(value, d: Dim | None, target: Dim, units: Units):
    return value * units.factor(target) if d is None else value


def _eval(node: Node, env, kinds, units):
    if isinstance(node, Num):
        return node.value, None
    if isinstance(node, Name) and node.name in CONSTANTS and node.name not in env:
        return CONSTANTS[node.name], ANGLE
    if isinstance(node, Name):
        return env[node.name], KIND_DIMS[kinds[node.name]]
    if isinstance(node, Neg):
        v, d = _eval(node.arg, env, kinds, units)
        return -v, d
    if isinstance(node, Bin):
        a, da = _eval(node.left, env, kinds, units)
        b, db = _eval(node.right, env, kinds, units)
        if node.op in "+-":
            d = _add(da, db, node.op)
            if d is not None:
                a, b = _as(a, da, d, units), _as(b, db, d, units)
            return (a + b if node.op == "+" else a - b), d
        if da is None and db is None:
            d = None
        else:
            xa, xb = da or NUMBER, db or NUMBER
            d = (xa[0] + xb[0], xa[1] + xb[1]) if node.op == "*" else (xa[0] - xb[0], xa[1] - xb[1])
        if node.op == "*":
            return a * b, d
        if isinstance(a, (int, float)) and isinstance(b, (int, float)):
            # two constants: IEEE division (inf or nan, caught by the finiteness checks), not
            # Python's ZeroDivisionError
            with np.errstate(divide="ignore", invalid="ignore"):
                return float(np.float64(a) / np.float64(b)), d
        return a / b, d
    if isinstance(node, Call):
        vals = [_eval(x, env, kinds, units) for x in node.args]
        f = node.func
        if f in ("sin", "cos", "tan"):
            v, d = vals[0]
            if d not in (None, ANGLE):
                raise UnitError(f"{f}() of {_dim_name(d)}; it takes an angle")
            v = _as(v, d, ANGLE, units)
            return getattr(jnp, f)(v), NUMBER
        if f == "sqrt":
            v, d = vals[0]
            return jnp.sqrt(v), (None if d is None else (d[0] / 2, d[1] / 2))
        if f in ("asin", "acos", "atan"):
            v, d = vals[0]
            if d not in (None, NUMBER):
                raise UnitError(f"{f}() of {_dim_name(d)}; it takes a pure number")
            return {"asin": jnp.arcsin, "acos": jnp.arccos, "atan": jnp.arctan}[f](v), ANGLE
        if f == "atan2":
            (y, dy), (x, dx) = vals
            d = _add(dy, dx, "atan2")
            if d is not None:
                y, x = _as(y, dy, d, units), _as(x, dx, d, units)
            return jnp.arctan2(y, x), ANGLE
    raise TypeError(node)


