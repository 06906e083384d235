"""Mechanism files: read the TOML text, validate every section, convert to SI, build a `Mechanism`.

Every error names the file, the line (found in the text that was parsed) and the key.

**Domains.** Every number is checked where it is read (`NUMBER_LIMIT` as written, then the
domain of what it is in SI, `DOMAINS` of `jaxlink/model/domains.py`, which the batched evaluators
also hold every design to): a value outside them is refused with the file, line, key,
the value and the allowed range. A `--set` value is checked the same way and blamed on `--set`.
What a value is follows from its kind and its use: a parameter that stands alone as the LENGTH of
a term `NAME @ ANGLE` of a loop is a link length; any other length (a coordinate, an offset, a
slider's position, a point's offset) may be as small as it likes.
"""

from __future__ import annotations

import dataclasses
import math
import pathlib
import re
from typing import Mapping

import jax.numpy as jnp
import numpy as np

from ..errors import MechanismError
from ..model.domains import DOMAINS as DOMAINS  # the one definition (re-exported)
from ..model.domains import link_lengths as _link_lengths
from ..model.mechanism import Mechanism
from . import expr as _expr
from .bodies import read_bodies
from .expr import ANGLE, LENGTH, ExprSyntaxError, UnitError
from .keys import check_keys
from .locator import Locator
from .source import parse_toml

LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "cm": 1e-2}
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
#: largest magnitude of any number written in a mechanism file (in its units)
NUMBER_LIMIT = 1e15
_SI_UNIT = {"length": "m", "angle": "rad", "number": ""}
KNOWN_TABLES = {
    "mechanism", "parameters", "input", "unknowns", "loops", "points",
    "bodies", "joints", "loads", "environment", "optimize", "dynamics", "sketch", "study",
}
#: the keys of `[mechanism]`, of `[input]` and of a parameter given as a table; any other key is
#: refused (`jaxlink/files/keys.py`). `[dynamics]` is reserved: it may be there, empty.
MECHANISM_KEYS = {"name", "description", "length_unit", "angle_unit", "kind"}
INPUT_KEYS = {"name", "start", "body", "at", "axis", "base"}
PARAMETER_KEYS = {"value", "unit"}
DYNAMICS_KEYS: set[str] = set()


def load(source: str | pathlib.Path, *, overrides: Mapping[str, float] | None = None) -> Mechanism:
    """Load and validate a mechanism file (a path or a built-in scene name).

    `overrides` replace parameter values (file units), as `--set` does on the command line
    (`jaxlink/files/overrides.py` reads them). Raises `MechanismError` naming the file, line, key
    and reason for anything wrong.
    """
    from .source import read_source

    path, text = read_source(source)
    return loads(text, file=str(path), overrides=overrides)


def loads(text: str, *, file: str = "<string>", overrides: Mapping[str, float] | None = None) -> Mechanism:
    """Like `load`, from the TOML text; `file` names it in error messages, whose lines are those
    of `text`. Every table is checked here, `[bodies]`, `[joints]`, `[loads]` and `[environment]`
    too (`jaxlink/files/bodies.py`)."""
    loc = Locator(text)

    def err(msg, table=None, key=None, item=None, keyname=None):
        line = loc.line(table, key, item) if table is not None else None
        k = keyname or (f"{table}.{key}" if key else table)
        return MechanismError(msg, file=file, line=line, key=k)

    data = parse_toml(text, file)

    mech = data.get("mechanism")
    kind = mech.get("kind", "linkage") if isinstance(mech, dict) else "linkage"
    if kind != "linkage":
        handled = (" (`jaxlink simulate` and `jaxlink jamming` handle it)" if kind == "cam-follower"
                   else " (only kind = \"linkage\" files are mechanisms)")
        raise err(f"this is a {kind!r} scene, not a linkage: the loop solver does not apply{handled}",
                  "mechanism", "kind")
    for table in data:
        if table not in KNOWN_TABLES:
            raise err(
                f"unknown table [{table}]{_expr.suggest(table, KNOWN_TABLES)}; known tables: "
                + ", ".join(sorted(KNOWN_TABLES)),
                table,
            )
    if not isinstance(mech, dict):
        raise MechanismError("missing [mechanism] table (name, length_unit, angle_unit)", file=file)
    check_keys(mech, MECHANISM_KEYS, "mechanism", lambda m, k: err(m, "mechanism", k))
    dynamics = data.get("dynamics", {})
    if not isinstance(dynamics, dict):
        raise err("[dynamics] must be a table (reserved: empty in a linkage file)", "dynamics")
    check_keys(dynamics, DYNAMICS_KEYS, "dynamics", lambda m, k: err(
        m + " ([dynamics] is reserved in a linkage file: jaxlink reads none of its keys yet)", "dynamics", k))
    layout = None
    if "sketch" in data:  # joints and links: derive the loop form (jaxlink/files/sketch.py)
        from .sketch import derive

        data, layout = derive(data, err, file)
    if isinstance(data.get("input"), dict):
        check_keys(data["input"], INPUT_KEYS, "input", lambda m, k: err(m, "input", k))
    name = str(mech.get("name", pathlib.Path(file).stem))
    lu = mech.get("length_unit", "m")
    au = mech.get("angle_unit", "rad")
    if not isinstance(lu, str) or lu not in LENGTH_UNITS:
        raise err(f"bad length unit '{lu}'; use one of {', '.join(LENGTH_UNITS)}", "mechanism", "length_unit")
    if not isinstance(au, str) or au not in ANGLE_UNITS:
        raise err(f"bad angle unit '{au}'; use one of {', '.join(ANGLE_UNITS)}", "mechanism", "angle_unit")
    units = _expr.Units(LENGTH_UNITS[lu], ANGLE_UNITS[au])

    # ---------------------------------------------------------------- names and values
    params_raw = data.get("parameters", {})
    if not isinstance(params_raw, dict):
        raise err("[parameters] must be a table of NAME = value", "parameters")
    declared: dict[str, str] = {}
    pvalues: dict[str, float] = {}
    derived_text: dict[str, str] = {}
    for pname, v in params_raw.items():
        _check_identifier(pname, err, "parameters")
        if isinstance(v, str):  # a derived parameter: an expression of the others
            derived_text[pname] = v
            continue
        if isinstance(v, dict):
            check_keys(v, PARAMETER_KEYS, f"parameters.{pname}",
                       lambda m, k, _p=pname: err(m, "parameters", _p, keyname=f"parameters.{_p}.{k}"))
            if "value" not in v:
                raise err("a parameter table needs 'value' (and optionally 'unit')", "parameters", pname)
            unit = v.get("unit")
            v = v["value"]
            if unit is not None:
                declared[pname] = _kind_of_unit(unit, err, pname)
                if unit in LENGTH_UNITS or unit in ANGLE_UNITS:
                    # convert to the file unit now; SI conversion happens below for all
                    f = LENGTH_UNITS.get(unit) or ANGLE_UNITS[unit]
                    v = _num(v, err, "parameters", pname) * f / units.factor(_expr.KIND_DIMS[declared[pname]])
        pvalues[pname] = _num(v, err, "parameters", pname)

    inp = data.get("input")
    if not isinstance(inp, dict) or "name" not in inp:
        raise MechanismError("missing [input] table with name = \"...\" (the driving coordinate)", file=file,
                             key="input")
    if not isinstance(inp["name"], str):
        raise err(f"'name' must name the driving coordinate (a string), got {inp['name']!r}", "input", "name")
    input_name = inp["name"]
    _check_identifier(input_name, err, "input", "name")
    input_body = inp.get("body")
    if input_body is not None and not isinstance(input_body, str):
        raise err(f"'body' must name the body the input drives, got {input_body!r}", "input", "body")
    input_start = _num(inp.get("start", 0.0), err, "input", "start")

    unk_raw = data.get("unknowns", {})
    if not isinstance(unk_raw, dict) or not unk_raw:
        raise err("[unknowns] must list the dependent coordinates with their guesses", "unknowns")
    guesses: dict[str, float] = {}
    for uname, v in unk_raw.items():
        _check_identifier(uname, err, "unknowns")
        guesses[uname] = _num(v, err, "unknowns", uname)

    # name clashes
    for uname in guesses:
        if uname in pvalues:
            raise err(f"'{uname}' is both a parameter and an unknown; rename one", "unknowns", uname)
    if input_name in pvalues:
        raise err(f"the input '{input_name}' is also a parameter", "input", "name")
    if input_name in guesses:
        raise err(f"the input '{input_name}' is also an unknown", "input", "name")
    for dname in derived_text:
        if dname in guesses:
            raise err(f"'{dname}' is both a parameter and an unknown; rename one", "unknowns", dname)
        if dname == input_name:
            raise err(f"the input '{dname}' is also a parameter", "input", "name")
    defs = _derived(derived_text, pvalues, guesses, input_name, err)
    reserved = set(_expr.FUNCTIONS) | set(_expr.CONSTANTS)
    for n in list(pvalues) + list(derived_text) + list(guesses) + [input_name]:
        if n in reserved:
            raise MechanismError(f"'{n}' is reserved (a function or the constant pi) and cannot name a quantity",
                                 file=file)

    # ---------------------------------------------------------------- loops and points
    def parse_terms(table: str, required: bool, named: tuple = ()):
        """The lists of terms of `table`; a term that is the NAME of a point (of `named`, or of a
        point defined above in [points]) stands for that point's terms."""
        raw = data.get(table, {})
        if not isinstance(raw, dict) or (required and not raw):
            raise err(f"[{table}] must be a table of NAME = [\"term\", ...]", table)
        out: list = []
        for lname, terms in raw.items():
            if not isinstance(terms, list):
                raise err(f"{table}.{lname} must be a list of terms like \"a @ phi2\"", table, lname)
            if not terms:
                raise err(f"{table}.{lname} is empty: a {table[:-1]} needs at least one term", table, lname)
            parsed: list = []
            for i, t in enumerate(terms):
                ref = re.fullmatch(r"\s*([+-]?)\s*([A-Za-z_][A-Za-z0-9_]*)\s*", t) if isinstance(t, str) else None
                if table == "loops" and ref and ref.group(2) in dict(named):
                    # a point used in a loop: its terms, in place
                    s = -1 if ref.group(1) == "-" else 1
                    parsed.extend(dataclasses.replace(u, sign=s * u.sign) for u in dict(named)[ref.group(2)])
                    continue
                if table == "loops" and ref:
                    raise err(f"'{ref.group(2)}' is not a point of [points]{_expr.suggest(ref.group(2), dict(named))};"
                              " a term is 'LENGTH @ ANGLE', '(X, Y)' or the name of a point", table, lname,
                              item=str(t), keyname=f"{table}.{lname}[{i}]")
                if table == "points" and ref and ref.group(2) in raw:
                    # a point that starts from (or adds) another point: its terms, in place
                    done = dict(out)
                    if ref.group(2) not in done:
                        raise err(f"point '{ref.group(2)}' is used in {table}.{lname} before it is defined "
                                  "(or by itself); define it above", table, lname, item=str(t),
                                  keyname=f"{table}.{lname}[{i}]")
                    s = -1 if ref.group(1) == "-" else 1
                    parsed.extend(dataclasses.replace(u, sign=s * u.sign) for u in done[ref.group(2)])
                    continue
                if table == "points" and ref:
                    raise err(f"'{ref.group(2)}' is not a point of [points]{_expr.suggest(ref.group(2), raw)}; a term "
                              "is 'LENGTH @ ANGLE', '(X, Y)' or the name of a point defined above", table, lname,
                              item=str(t), keyname=f"{table}.{lname}[{i}]")
                try:
                    parsed.append(_expr.substitute_term(_expr.parse_term(t), defs))
                except ExprSyntaxError as exc:
                    raise err(str(exc), table, lname, item=str(t), keyname=f"{table}.{lname}[{i}]") from None
            out.append((lname, tuple(parsed)))
        return tuple(out)

    points = parse_terms("points", False)
    loops = parse_terms("loops", True, points)

    known_names = set(pvalues) | set(guesses) | {input_name}
    for table, group in (("loops", loops), ("points", points)):
        for lname, terms in group:
            for i, term in enumerate(terms):
                for node in term.nodes():
                    for nm in _expr.names_in(node):
                        if nm.name not in known_names:
                            raise err(
                                f"unknown name '{nm.name}' in \"{term.text}\"{_expr.suggest(nm.name, known_names)}"
                                " — declare it under [parameters] or [unknowns]",
                                table, lname, item=term.text, keyname=f"{table}.{lname}[{i}]",
                            )

    n_eq = 2 * len(loops)
    if n_eq != len(guesses):
        raise err(
            f"{len(loops)} loop(s) give {n_eq} scalar equations but there are {len(guesses)} unknowns "
            f"({', '.join(guesses)}); each loop closes in x and y, so unknowns must be 2 × loops",
            "unknowns",
        )
    used_in_loops = {nm.name for _, ts in loops for t in ts for nd in t.nodes() for nm in _expr.names_in(nd)}
    for uname in guesses:
        if uname not in used_in_loops:
            raise err(f"unknown '{uname}' appears in no loop", "unknowns", uname)
    if input_name not in used_in_loops:
        raise err(f"the input '{input_name}' appears in no loop: nothing drives the mechanism", "input", "name")

    # ---------------------------------------------------------------- kinds (units) inference
    kinds: dict[str, str | None] = {n: None for n in known_names}
    kinds.update(declared)
    where: dict[str, str] = {}

    roles = []
    for table, group in (("loops", loops), ("points", points)):
        for lname, terms in group:
            for i, term in enumerate(terms):
                key = f"{table}.{lname}[{i}]"
                if term.polar:
                    roles.append((term.length, LENGTH, table, lname, term, key))
                    roles.append((term.angle, ANGLE, table, lname, term, key))
                else:
                    roles.append((term.x, LENGTH, table, lname, term, key))
                    roles.append((term.y, LENGTH, table, lname, term, key))

    changed = True
    while changed:
        changed = False
        for node, role, table, lname, term, key in roles:

            def record(nm, dim, _t=table, _l=lname, _term=term, _key=key):
                nonlocal changed
                kind = _expr.DIM_KINDS.get(dim)
                if kind is None:
                    raise err(
                        f"'{nm.name}' would have to be {_expr._dim_name(dim)} in \"{_term.text}\"; "
                        "only lengths, angles and pure numbers are supported",
                        _t, _l, item=_term.text, keyname=_key,
                    )
                if kinds[nm.name] is None:
                    kinds[nm.name] = kind
                    where[nm.name] = f"\"{_term.text}\" ({_key})"
                    changed = True
                elif kinds[nm.name] != kind:
                    first = where.get(nm.name, "its declared unit")
                    raise err(
                        f"'{nm.name}' is used as {'an' if kind == 'angle' else 'a'} {kind} in \"{_term.text}\" "
                        f"but as {'an' if kinds[nm.name] == 'angle' else 'a'} {kinds[nm.name]} in {first}"
                        + _through(_term.text, derived_text),
                        _t, _l, item=_term.text, keyname=_key,
                    )

            try:
                _expr.kind_constraints(node, role, kinds, record)
            except UnitError as exc:
                raise err(f"inconsistent units in \"{term.text}\": {exc}", table, lname, item=term.text,
                          keyname=key) from None

    for n in [input_name, *guesses]:
        if kinds[n] is None:
            raise err(f"cannot tell whether '{n}' is a length or an angle from its use in the loops",
                      "unknowns" if n in guesses else "input", n if n in guesses else "name")
    used = {nm.name for node, *_ in roles for nm in _expr.names_in(node)}
    for n in pvalues:
        if kinds[n] is None:
            if n in used:
                raise err(
                    f"cannot tell the unit of parameter '{n}' from its use; declare it as "
                    f"{n} = {{ value = {pvalues[n]}, unit = \"mm\" }} (or \"deg\", \"1\")",
                    "parameters", n,
                )
            kinds[n] = "number"

    derived_kinds = {}
    for dname, node in defs.items():
        try:
            d = _expr.dim_of(node, kinds)
        except UnitError as exc:
            raise err(f"inconsistent units in \"{derived_text[dname]}\": {exc}", "parameters", dname) from None
        derived_kinds[dname] = _expr.DIM_KINDS.get(d) if d is not None else None
    # full dimension check of every expression (catches e.g. length + angle inside a product)
    for node, role, table, lname, term, key in roles:
        try:
            d = _expr.dim_of(node, kinds)
            if d is not None and d != role:
                raise UnitError(f"it is {_expr._dim_name(d)} where {_expr._dim_name(role)} is expected")
        except UnitError as exc:
            raise err(f"inconsistent units in \"{term.text}\": {exc}", table, lname, item=term.text,
                      keyname=key) from None

    # ---------------------------------------------------------------- overrides and SI values
    pnames = tuple(pvalues)
    overridden: set[str] = set()
    if overrides:
        for k, v in overrides.items():
            if k in derived_text:
                raise MechanismError(
                    f"--set {k}: '{k}' is derived (\"{derived_text[k]}\"); set the parameters it is computed from",
                    file=file,
                )
            if k not in pvalues:
                raise MechanismError(
                    f"--set {k}: no such parameter{_expr.suggest(k, pnames)}; parameters: {', '.join(pnames)}",
                    file=file,
                )

            def set_err(msg, *_, _k=k, _v=v, **__):
                return MechanismError(f"--set {_k}={_v!r}: {msg}")

            pvalues[k] = _num(v, set_err, "parameters", k)
            overridden.add(k)

    def blame(pname: str, msg: str) -> MechanismError:
        """An error about parameter `pname`: on `--set` if it was overridden, else on its line."""
        if pname in overridden:
            return MechanismError(f"--set {pname}={pvalues[pname]:g}: {msg}")
        return err(msg, "parameters", pname)

    def in_domain(name: str, value: float, kind: str, make, what: str | None = None) -> None:
        """Refuse a value (file units) outside the SI domain (`DOMAINS`) of what it is (`what`:
        "link length", default its kind)."""
        what = what or kind
        lo, hi = DOMAINS[what]
        si = abs(value * fac[kind])
        if si > hi or 0.0 < si < lo:
            unit = {"length": lu, "angle": au, "number": ""}[kind]
            rng = (f"0 or {lo:g} to {hi:g} {_SI_UNIT[kind]}" if lo else f"{-hi:g} to {hi:g} {_SI_UNIT[kind]}").strip()
            a = "an" if what[0] in "aeiou" else "a"
            raise make(f"{what} '{name}' = {value:g}{(' ' + unit) if unit else ''} is out of range: {a} {what} "
                       f"is {rng}" + (" in magnitude" if lo else ""))
    fac: dict[str, float] = {"length": units.length, "angle": units.angle, "number": 1.0}
    # link lengths: parameters standing alone as the LENGTH of a term `NAME @ ANGLE` of a loop
    links, _signed = _link_lengths((loops, points), pvalues)
    for n in pnames:
        in_domain(n, pvalues[n], kinds[n] or "number", lambda m, _n=n: blame(_n, m),
                  "link length" if n in links and kinds[n] == "length" else None)
    for n in guesses:
        in_domain(n, guesses[n], kinds[n] or "number", lambda m, _n=n: err(m, "unknowns", _n))
    in_domain(input_name, input_start, kinds[input_name] or "number", lambda m: err(m, "input", "start"))
    p_si = np.asarray([pvalues[n] * fac[kinds[n] or "number"] for n in pnames], dtype=np.float64)
    q_si = np.asarray([guesses[n] * fac[kinds[n] or "number"] for n in guesses], dtype=np.float64)

    # a parameter standing alone as the LENGTH of a term (of a loop or a point) must be >= 0
    for pn in pnames:
        if pn in _signed and pvalues[pn] < 0:
            raise blame(pn, f"length '{pn}' = {pvalues[pn]} is negative; a link length must be ≥ 0 "
                            f"(put the sign in front of the term instead: \"-{pn} @ ...\")")

    input_start_si = float(input_start) * fac[kinds[input_name] or "number"]
    body_model = read_bodies(data, file=file, err=err, kinds=kinds, length_unit=units.length,
                             input_name=input_name, input_body=input_body, defs=defs)

    tables = {k: v for k, v in data.items() if k not in ("mechanism", "parameters", "input", "unknowns",
                                                          "loops", "points")}
    mechanism = Mechanism(
        name=name,
        description=str(mech.get("description", "")),
        file=file,
        units=units,
        parameter_names=pnames,
        parameter_kinds=tuple(kinds[n] for n in pnames),
        parameters=p_si,
        input_name=input_name,
        input_kind=kinds[input_name],
        input_body=input_body,
        input_start=input_start_si,
        unknown_names=tuple(guesses),
        unknown_kinds=tuple(kinds[n] for n in guesses),
        guess=q_si,
        loops=loops,
        points=points,
        tables=tables,
        kinds=dict(kinds),
        bodies=body_model,
        derived=tuple((n, derived_text[n], derived_kinds[n] or "number", defs[n]) for n in derived_text),
        sketch=None if layout is None else dataclasses.replace(layout, joints=tuple(
            (j, tuple(_expr.substitute_term(_expr.parse_term(t), defs) for t in ts)) for j, ts in layout.joints)),
    )
    # evaluate once at the guess, where it holds (the input at `[input] start`), in numpy float64,
    # to catch anything left (e.g. sqrt of a negative number)
    r, xy = _at_guess_checked(mechanism)
    if not np.all(np.isfinite(r)):
        lname = loops[int(np.flatnonzero(~np.isfinite(r))[0]) // 2][0]
        raise err(f"loop '{lname}' gives a non-finite value at the guess (the input at [input] start); "
                  "check the expressions (sqrt of a negative number? division by zero?)", "loops", lname)
    if points:
        bad = ~np.all(np.isfinite(xy), axis=1)
        if bad.any():
            pname = points[int(np.flatnonzero(bad)[0])][0]
            raise err(f"point '{pname}' is not finite at the guess (the input at [input] start); "
                      "check its expressions (sqrt of a negative number? division by zero?)", "points", pname)
    return mechanism


def _at_guess(mech, phi):
    """The residual and the points at the guesses (the input at `phi`, `[input] start`)."""
    q, p = mech.guess, mech.parameters
    return mech.residual(q, phi, p), mech.point_positions(q, phi, p)


def _at_guess_checked(mech) -> tuple:
    """`_at_guess` as numpy arrays: in a command of the command line with its cache on, one stored
    program (`jaxlink.cache.traced`: a repeated command does not trace it, 0.1–0.3 s); elsewhere
    evaluated as it goes (a library's `load` compiles nothing new for a new structure)."""
    from ..cache import in_one_command, traced

    phi = np.asarray(mech.input_start, dtype=np.float64)
    if in_one_command():
        r, xy = traced("load_at_guess", _at_guess, (mech, phi))
    else:
        r, xy = _at_guess(mech.replace(parameters=jnp.asarray(mech.parameters), guess=jnp.asarray(mech.guess)),
                          jnp.asarray(phi))
    return np.asarray(r), np.asarray(xy)


def _derived(texts: dict, base: dict, guesses: dict, input_name: str, err) -> dict:
    """The derived parameters (`NAME = "expression"` in [parameters]), each expanded down to the
    parameters with a value: {name: node}. Their expressions use parameters only (values or
    derived, in any order, without a cycle)."""
    parsed = {}
    for name, text in texts.items():
        try:
            parsed[name] = _expr.parse_expr(text)
        except ExprSyntaxError as exc:
            raise err(str(exc), "parameters", name, item=text) from None
        for nm in _expr.names_in(parsed[name]):
            if nm.name in base or nm.name in texts:
                continue
            what = ("an unknown" if nm.name in guesses else "the input" if nm.name == input_name else None)
            if what:
                raise err(f"derived parameter '{name}' = \"{text}\" uses {what} '{nm.name}': a derived parameter "
                          "is computed from parameters only", "parameters", name, item=text)
            raise err(f"unknown name '{nm.name}' in \"{text}\"{_expr.suggest(nm.name, [*base, *texts])}: a derived "
                      "parameter is computed from the other parameters", "parameters", name, item=text)
    done: dict = {}

    def expand(name: str, stack: tuple) -> _expr.Node:
        if name in done:
            return done[name]
        if name in stack:
            cycle = " → ".join([*stack[stack.index(name):], name])
            raise err(f"derived parameters refer to each other in a cycle: {cycle}", "parameters", name)
        inner = {nm.name: expand(nm.name, (*stack, name)) for nm in _expr.names_in(parsed[name]) if nm.name in texts}
        done[name] = _expr.substitute(parsed[name], inner)
        return done[name]

    for name in texts:
        expand(name, ())
    return done


def _through(text: str, derived_text: dict) -> str:
    """A note naming the derived parameters a term uses (where a name's use may come from)."""
    used = [n for n in dict.fromkeys(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", text)) if n in derived_text]
    return "".join(f" (through the derived parameter {n} = \"{derived_text[n]}\")" for n in used)


def _check_identifier(name: str, err, table: str, key: str | None = None) -> None:
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", str(name)):
        raise err(f"'{name}' is not a valid name (letters, digits and _, not starting with a digit)",
                  table, key or name)


def _num(v, err, table: str, key: str) -> float:
    """A finite number within ±`NUMBER_LIMIT` (as written in the file)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise err(f"'{key}' must be a number, got {_show(v)}", table, key)
    if isinstance(v, int) and abs(v) > NUMBER_LIMIT:
        raise err(f"'{key}' = {_show(v)} is too large: a number in a mechanism file is within "
                  f"±{NUMBER_LIMIT:g}", table, key)
    v = float(v)
    if not math.isfinite(v):
        raise err(f"'{key}' = {v} is not finite", table, key)
    if abs(v) > NUMBER_LIMIT:
        raise err(f"'{key}' = {v:g} is too large: a number in a mechanism file is within ±{NUMBER_LIMIT:g}",
                  table, key)
    return v


def _show(v) -> str:
    """`repr(v)`, shortened (a 400-digit integer is shown by its first digits and its length)."""
    if isinstance(v, int) and not isinstance(v, bool) and abs(v) > 10**30:
        digits = len(str(abs(v))) if abs(v) < 10**4000 else "more than 4000"
        return f"{str(v)[:12] if abs(v) < 10**4000 else ''}… ({digits} digits)"
    text = repr(v)
    return text if len(text) <= 60 else text[:57] + "…"


def _kind_of_unit(unit, err, pname: str) -> str:
    if not isinstance(unit, str):
        raise err(f"'unit' must be a string such as \"mm\", got {_show(unit)}", "parameters", pname)
    if unit in LENGTH_UNITS:
        return "length"
    if unit in ANGLE_UNITS:
        return "angle"
    if unit in ("1", "", "none"):
        return "number"
    raise err(f"bad unit '{unit}'; use one of {', '.join([*LENGTH_UNITS, *ANGLE_UNITS, '1'])}",
              "parameters", pname)
