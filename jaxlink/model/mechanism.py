"""The model of a linkage: its structure (static) and its numbers (a pytree).

A `Mechanism` is a JAX pytree: its leaves are the numbers a search varies — `parameters` (SI,
ordered as `parameter_names`) and `guess` (SI, ordered as `unknown_names`) — and everything else
(names, loops, points, units: the `Structure`) is static, hashed by its content (`Structure.key`). So a
mechanism can be passed through `jax.jit`, `vmap` and `grad` like any array argument; a change of
numbers reuses the compiled functions, a change of structure compiles new ones, and the same file
loaded twice (or under another name) reuses them. The solvers also take the
parameters as an explicit array `p`, so `vmap` over designs and `grad` with respect to dimensions
reach them without rebuilding the mechanism.

Residual: each loop i is a closed polygon of vectors,

    Φ_i(q; φ, p) = Σ_j s_j L_j (cos θ_j, sin θ_j)  +  Σ_j s_j (X_j, Y_j)  = 0  ∈ R²,

with q the unknowns (angles in rad, lengths in m), φ the input and p the parameters; term j has
the sign s_j and either a length L_j and an angle θ_j (polar) or components (X_j, Y_j).
"""

from __future__ import annotations

import dataclasses
import sys
from typing import Any, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import MechanismError
from ..files import expr as _expr
from ..files.expr import ANGLE, LENGTH, Term


@dataclasses.dataclass(frozen=True, eq=False)
class Structure:
    """The static part of a mechanism (hashed by its content, `key`): names, units, loops, points,
    tables, and the functions of the loops. Fields are SI; see the module docstring for the residual.

    **Fields:**

    - `name`, `description`, `file`: from `[mechanism]`.
    - `units`: the file's unit factors (SI = file value × factor).
    - `parameter_names`, `parameter_kinds` ("length" | "angle" | "number"), `parameters` (SI).
    - `input_name`, `input_kind`, `input_body`, `input_start` (SI: the input value at which the
      guesses of `[unknowns]` hold; `[input] start`, default 0).
    - `unknown_names`, `unknown_kinds`, `guess` (SI, at `input_start`).
    - `loops`, `points`: tuples of `(name, tuple[Term])`.
    - `tables`: the raw TOML of the optional tables (`bodies`, `joints`, `loads`, `optimize`, …).
    - `derived`: the derived parameters `(name, expression, kind, node)`, `node` the expression
      expanded down to `parameter_names`; the loops, points and body tables hold them expanded
      (they are functions of `parameters`, not entries of it: `derived_values`).
    - `sketch`: the joints, bodies, sliders and driver of a file written as a sketch (joints and
      links, `jaxlink/files/sketch.py`), from which the loops were derived; None for a loop file.
    """

    name: str
    description: str
    file: str
    units: _expr.Units
    parameter_names: tuple
    parameter_kinds: tuple
    input_name: str
    input_kind: str
    input_body: str | None
    input_start: float
    unknown_names: tuple
    unknown_kinds: tuple
    loops: tuple
    points: tuple
    tables: Mapping[str, Any]
    kinds: Mapping[str, str]
    bodies: Any = None  # jaxlink.model.bodies.Model of [bodies]/[joints]/[loads]/[environment], or None
    derived: tuple = ()  # derived parameters: (name, expression text, kind, expanded node)
    sketch: Any = None  # jaxlink.files.sketch.Sketch when the file is written as joints and links, or None

    # ------------------------------------------------------------------ identity
    # What the compiled functions depend on: everything but the labels (`name`, `description`,
    # `file`). Two structures with the same key are interchangeable under `jax.jit`, so loading a
    # file again reuses its compilations (`input_start` is part of the key: the lead-in is traced
    # from it as a constant, also inside the caller's own `jit`).
    _LABELS = ("name", "description", "file")

    @property
    def key(self) -> str:
        """A text that equal structures share (the repr of every field but the labels)."""
        try:
            return self.__dict__["_key"]
        except KeyError:
            with np.printoptions(threshold=sys.maxsize):
                key = repr(tuple((f.name, _canonical(f.name, getattr(self, f.name))) for f in dataclasses.fields(self)
                                 if f.name not in self._LABELS))
            object.__setattr__(self, "_key", key)
            object.__setattr__(self, "_hash", hash(key))
            return key

    def __eq__(self, other):
        if self is other:
            return True
        if not isinstance(other, Structure):
            return NotImplemented
        return hash(self) == hash(other) and self.key == other.key

    def __hash__(self):
        try:
            return self.__dict__["_hash"]
        except KeyError:
            self.key  # noqa: B018 (computes and stores the hash)
            return self.__dict__["_hash"]

    # ------------------------------------------------------------------ sizes
    @property
    def n_unknowns(self) -> int:
        return len(self.unknown_names)

    @property
    def n_equations(self) -> int:
        return 2 * len(self.loops)

    @property
    def point_names(self) -> tuple:
        return tuple(n for n, _ in self.points)

    def parameter_index(self, name: str) -> int:
        try:
            return self.parameter_names.index(name)
        except ValueError:
            raise MechanismError(
                f"unknown parameter '{name}'{_expr.suggest(name, self.parameter_names)}; "
                f"parameters: {', '.join(self.parameter_names)}",
                file=self.file,
            ) from None

    def derived_values(self, p) -> dict:
        """{name: SI value} of the derived parameters at the parameters `p` (SI)."""
        env = {n: p[i] for i, n in enumerate(self.parameter_names)}
        return {n: _expr.evaluate(node, env, self.kinds, self.units, _expr.KIND_DIMS[kind])
                for n, _text, kind, node in self.derived}

    def to_si(self, name: str, value: float) -> float:
        """A value of a parameter, unknown or the input, given in file units, in SI."""
        kind = self.kinds[name]
        return float(value) * self.kind_factor(kind)

    def from_si(self, name: str, value):
        return value / self.kind_factor(self.kinds[name])

    def kind_factor(self, kind: str) -> float:
        return {"length": self.units.length, "angle": self.units.angle}.get(kind, 1.0)

    # ------------------------------------------------------------------ compiled functions
    def env(self, q, phi, p) -> dict:
        env = {n: p[i] for i, n in enumerate(self.parameter_names)}
        if q is not None:
            env.update({n: q[i] for i, n in enumerate(self.unknown_names)})
        env[self.input_name] = phi
        return env

    def term_vector(self, term: Term, env, trig=None):
        """(x, y) of one term in SI. `trig` optionally maps names to known (cos, sin) of their
        value, so that angles like `q + c` need no new trigonometry (see `unit_vector`)."""
        if term.polar:
            assert term.length is not None and term.angle is not None
            length = _expr.evaluate(term.length, env, self.kinds, self.units, LENGTH)
            c, s = self.unit_vector(term.angle, env, trig)
            return term.sign * length * c, term.sign * length * s
        assert term.x is not None and term.y is not None
        x = _expr.evaluate(term.x, env, self.kinds, self.units, LENGTH)
        y = _expr.evaluate(term.y, env, self.kinds, self.units, LENGTH)
        return term.sign * x, term.sign * y

    def unit_vector(self, node, env, trig=None):
        """(cos θ, sin θ) of an angle expression θ. Sums and differences that contain names of
        `trig` are composed by the angle-addition formulas from their cached (cos, sin)."""
        if trig:
            if isinstance(node, _expr.Name) and node.name in trig:
                return trig[node.name]
            if isinstance(node, (_expr.Bin, _expr.Neg)) and any(n.name in trig for n in _expr.names_in(node)):
                if isinstance(node, _expr.Neg):
                    c, s = self.unit_vector(node.arg, env, trig)
                    return c, -s
                if node.op in "+-":
                    ca, sa = self.unit_vector(node.left, env, trig)
                    cb, sb = self.unit_vector(node.right, env, trig)
                    if node.op == "+":
                        return ca * cb - sa * sb, sa * cb + ca * sb
                    return ca * cb + sa * sb, sa * cb - ca * sb
        v = _expr.evaluate(node, env, self.kinds, self.units, ANGLE)
        return jnp.cos(v), jnp.sin(v)

    def _sum(self, terms, env, which: str, trig=None):
        """Sum of the terms that depend on the unknowns (`which="var"`), do not ("const"), or all."""
        unknowns = set(self.unknown_names)
        sx, sy = 0.0, 0.0
        for term in terms:
            dep = any(n.name in unknowns for node in term.nodes() for n in _expr.names_in(node))
            if which == "all" or (which == "var") == dep:
                x, y = self.term_vector(term, env, trig)
                sx, sy = sx + x, sy + y
        return sx, sy

    def residual(self, q, phi, p):
        """Φ(q; φ, p), shape (2·loops,): x and y closure of every loop, in metres."""
        env = self.env(q, phi, p)
        out = []
        for _, terms in self.loops:
            out.extend(self._sum(terms, env, "all"))
        return _stack(out, q)

    def residual_const(self, phi, p):
        """The part of Φ that does not depend on q (evaluated once per input position)."""
        env = self.env(None, phi, p)
        out = []
        for _, terms in self.loops:
            out.extend(self._sum(terms, env, "const"))
        return _stack(out, p)

    def residual_var(self, q, phi, p, const, trig=None):
        """Φ = residual_var + residual_const: the part that depends on q, plus `const`. `trig`
        optionally maps names to known (cos, sin) of their values (see `unit_vector`)."""
        env = self.env(q, phi, p)
        out = []
        for _, terms in self.loops:
            out.extend(self._sum(terms, env, "var", trig))
        return _stack(out, q) + const

    def point_positions(self, q, phi, p, trig=None):
        """Positions of the points of interest, shape (n_points, 2), metres. `trig` optionally
        maps names to known (cos, sin) of their values (see `unit_vector`)."""
        if not self.points:
            return jnp.zeros((0, 2), dtype=jnp.result_type(q))
        env = self.env(q, phi, p)
        rows = [jnp.stack(_broadcast(*self._sum(terms, env, "all", trig), like=q)) for _, terms in self.points]
        return jnp.stack(rows)

    def joint_positions(self, q, phi, p, trig=None):
        """Positions of the joints of a sketch file (`sketch.joints`, in its order), shape
        (n_joints, 2), metres; None for a loop file."""
        if self.sketch is None:
            return None
        env = self.env(q, phi, p)
        rows = [jnp.stack(_broadcast(*self._sum(terms, env, "all", trig), like=q)) for _, terms in self.sketch.joints]
        return jnp.stack(rows)

    def length_scale(self, p):
        """A length that sets the residual tolerance: the largest |length parameter| (m). In NumPy
        for a NumPy `p` (no JAX operation dispatched outside a program; the same exact value)."""
        idx = [i for i, k in enumerate(self.parameter_kinds) if k == "length"]
        xp = np if isinstance(p, np.ndarray) else jnp
        if not idx:
            return xp.asarray(1.0, dtype=xp.result_type(p))
        return xp.maximum(xp.max(xp.abs(p[xp.asarray(idx)])), xp.finfo(xp.result_type(p)).tiny)

    def mobility_from_loops(self) -> int:
        """Coordinates (unknowns + input) minus independent scalar loop equations."""
        return self.n_unknowns + 1 - self.n_equations



class Mechanism:
    """A mechanism: its `structure` (static) and its numbers `parameters` (P,) and `guess` (n,), SI.

    Every attribute of the `Structure` (names, units, loops, `residual`, `point_positions`, …) is
    reachable on the mechanism itself (`mech.unknown_names`, `mech.residual(q, phi, p)`).
    `Mechanism(parameters=…, guess=…, structure=…)` or, from the structure's fields,
    `Mechanism(parameters=…, guess=…, name=…, …)`. A pytree (leaves: parameters, guess);
    immutable; `replace(parameters=…)` gives a copy with other numbers and the same structure.
    """

    __slots__ = ("parameters", "guess", "structure")
    parameters: Any
    guess: Any
    structure: Structure

    def __init__(self, *, parameters, guess, structure: Structure | None = None, **fields):
        if structure is None:
            structure = Structure(**fields)
        elif fields:
            raise TypeError(f"Mechanism: give either a structure or its fields, not both ({', '.join(fields)})")
        object.__setattr__(self, "parameters", parameters)
        object.__setattr__(self, "guess", guess)
        object.__setattr__(self, "structure", structure)

    def __setattr__(self, name, value):
        raise dataclasses.FrozenInstanceError(f"cannot assign to field '{name}' (a Mechanism is immutable)")

    def __getattr__(self, name):
        if name in Mechanism.__slots__:  # not yet set (copying, unpickling)
            raise AttributeError(name)
        return getattr(self.structure, name)

    def __repr__(self):
        return (f"Mechanism({self.structure.name!r}: {len(self.structure.parameter_names)} parameters, "
                f"{len(self.structure.unknown_names)} unknowns, {len(self.structure.loops)} loops, "
                f"{len(self.structure.points)} points)")

    def replace(self, *, parameters=None, guess=None) -> Mechanism:
        """A copy with other numbers (SI) and the same structure (compiled functions are reused)."""
        return Mechanism(parameters=self.parameters if parameters is None else parameters,
                         guess=self.guess if guess is None else guess, structure=self.structure)

    def with_parameters(self, **values_in_file_units) -> np.ndarray:
        """The parameter vector (SI) with some values replaced (given in file units)."""
        p = np.array(self.parameters, dtype=float)
        for k, v in values_in_file_units.items():
            p[self.parameter_index(k)] = self.to_si(k, v)
        return p


def _canonical(name: str, value):
    """A field's value for the key: `kinds` (a lookup built from a set, whose order changes from
    one process to the next) as sorted items; everything else as it is (order matters there)."""
    return tuple(sorted(value.items())) if name == "kinds" else value


def _flatten(m: Mechanism):
    return (m.parameters, m.guess), m.structure


def _unflatten(structure, leaves):
    return Mechanism(parameters=leaves[0], guess=leaves[1], structure=structure)


jax.tree_util.register_pytree_node(Mechanism, _flatten, _unflatten)


def _broadcast(*vals, like):
    dtype = jnp.result_type(like)
    return [jnp.asarray(v, dtype=dtype) for v in vals]


def _stack(vals, like):
    return jnp.stack(_broadcast(*vals, like=like))
