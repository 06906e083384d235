"""The best design of a search as a complete mechanism file: results that reproduce.

A search's design is a vector of variables and a *circuit* (a branch sign per dyad, or for a
mechanism solved by continuation the branch reached from the file's configuration). `jaxlink
kinematics` and `jaxlink.solve` instead take the branch nearest to the file's `[unknowns]`
guesses at `[input] start`. So the best file is the input file's text with

1. every `[parameters]` value that differs from the text's (the variables, and any `--set`
   override) replaced by the design's value (file units; `repr` of the float, so that reading
   it back gives the very same number), and
2. every `[unknowns]` guess replaced by the design's solved configuration q at `[input] start`
   on the search's circuit: the closed form (`start.closed_form_start`) or the continuation
   start (`start.continuation_start`) at the search's first input φ₀, continued to `[input]
   start` in steps of at most 5° when the two differ.

Only the numbers are edited, on the lines the reader's `Locator` (`jaxlink/files/locator.py`)
finds, so comments and layout stay. A sketch file (`[sketch]`) has no parameters to edit: its
joints are moved to where the design puts them at `[input] start` on the search's circuit — the
sketch's pose carries both its dimensions and its branch. A value written as `NAME = number` or
`NAME = { value = number, unit = "..." }` on one line is edited; any other layout raises
`MechanismError` (the file cannot be rewritten without losing its layout).
"""

from __future__ import annotations

import math
import re

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import MechanismError
from ..files.locator import Locator
from ..files.reader import ANGLE_UNITS, LENGTH_UNITS, loads
from ..model.mechanism import Mechanism
from ..solvers.assemble import solve

_NUMBER = r"[+-]?(?:inf|nan|(?:\d[\d_]*(?:\.[\d_]*)?|\.\d[\d_]*)(?:[eE][+-]?\d+)?)"
_PLAIN = re.compile(r"^(?P<head>\s*[\"']?(?P<key>[A-Za-z_][A-Za-z0-9_]*)[\"']?\s*=\s*)(?P<num>" + _NUMBER
                    + r")(?P<tail>\s*(?:#.*)?)$")
_INLINE = re.compile(r"^(?P<head>\s*[\"']?(?P<key>[A-Za-z_][A-Za-z0-9_]*)[\"']?\s*=\s*\{.*?\bvalue\s*=\s*)"
                     r"(?P<num>" + _NUMBER + r")(?P<tail>.*)$")
_UNIT = re.compile(r"\bunit\s*=\s*[\"']([^\"']+)[\"']")


def design_configuration(ev, u, c: int):
    """(p (P,) SI, q (n,) SI at `[input] start`) of the design `u` (normalized) on circuit `c`
    of the evaluator `ev`, on the branch the search traced (see the module doc)."""
    mech = ev.mech
    u = jnp.asarray(np.asarray(u, dtype=float))

    def start(uu):
        p = ev.params(uu)
        q0, ok = ev.start(p, c)
        return p, q0, ok

    p, q0, ok = ev.compiled(("best_file.start", int(c)), lambda: jax.jit(start))(u)
    p, q0 = np.asarray(p), np.asarray(q0)
    gap = float(mech.input_start) - float(ev.phi0)
    if gap == 0.0 or not bool(ok):
        return p, q0
    # steps of at most 5°, or for a length input 5 % of the length scale (the solver's lead-in)
    h = math.radians(5.0) if mech.input_kind == "angle" else 0.05 * float(mech.length_scale(jnp.asarray(p)))
    n = max(2, int(math.ceil(abs(gap) / h)) + 1)
    phis = float(ev.phi0) + np.linspace(0.0, gap, n)
    sol = solve(mech, phis, p, q0, points=False)
    return p, np.asarray(sol.q[-1])


def _number(v: float) -> str:
    return repr(float(v))


def _edit(text: str, loc: Locator, lines: list, table: str, name: str, value_file: float, kind: str | None,
          file_units, file: str | None) -> None:
    """Replace the number of `name` in `[table]` on its line of `lines` (in place)."""
    i = loc.line(table, name)
    if i is None:
        raise MechanismError(f"cannot rewrite '{name}': no line '{name} = ...' found in [{table}]", file=file,
                             key=f"{table}.{name}")
    line = lines[i - 1]
    m = _PLAIN.match(line)
    if m and m.group("key") == name:
        lines[i - 1] = m.group("head") + _number(value_file) + m.group("tail")
        return
    m = _INLINE.match(line)
    if m and m.group("key") == name:
        v = value_file
        unit = _UNIT.search(line)
        if unit and kind in ("length", "angle"):
            f = LENGTH_UNITS.get(unit.group(1)) or ANGLE_UNITS.get(unit.group(1))
            if f is not None:
                v = value_file * file_units / f
        lines[i - 1] = m.group("head") + _number(v) + m.group("tail")
        return
    raise MechanismError(f"cannot rewrite '{name}' on line {i}: write it as '{name} = number' on one line",
                         file=file, line=i, key=f"{table}.{name}")


def file_text(mech: Mechanism, p, q, text: str | None = None) -> str:
    """The text of `mech`'s file (or `text`) with the parameters `p` and the guesses `q` (SI)
    written in (see the module doc). The result is checked: reading it back gives exactly `p`
    and `q` (to rounding of the unit conversion)."""
    if text is None:
        if not mech.file or mech.file.startswith("<"):
            raise MechanismError("the mechanism was not read from a file: give its text")
        with open(mech.file, encoding="utf-8") as fh:
            text = fh.read()
    original = loads(text, file=mech.file or "<string>")
    loc = Locator(text)
    lines = text.splitlines()
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    if mech.sketch is not None:
        return _sketch_text(mech, p, q, text, loc, lines)
    p0 = np.asarray(original.parameters, dtype=float)
    for k, name in enumerate(mech.parameter_names):
        if p[k] != p0[original.parameter_index(name)]:
            kind = mech.kinds[name]
            _edit(text, loc, lines, "parameters", name, float(mech.from_si(name, p[k])), kind,
                  mech.kind_factor(kind), mech.file)
    for k, name in enumerate(mech.unknown_names):
        kind = mech.kinds[name]
        _edit(text, loc, lines, "unknowns", name, float(mech.from_si(name, q[k])), kind,
              mech.kind_factor(kind), mech.file)
    out = "\n".join(lines) + ("\n" if text.endswith("\n") else "")
    back = loads(out, file=mech.file or "<string>")
    if not (np.allclose(back.parameters, p, rtol=1e-14, atol=0) and np.allclose(back.guess, q, rtol=1e-14,
                                                                                   atol=1e-300)):
        raise MechanismError("the rewritten file does not read back as the design (internal error)",
                             file=mech.file)
    return out


_JOINT = re.compile(r"^(?P<head>\s*[\"']?(?P<key>[A-Za-z_][A-Za-z0-9_]*)[\"']?\s*=\s*\[\s*)(?P<x>" + _NUMBER
                    + r")(?P<mid>\s*,\s*)(?P<y>" + _NUMBER + r")(?P<tail>\s*\].*)$")


def _sketch_text(mech: Mechanism, p, q, text: str, loc: Locator, lines: list) -> str:
    """A sketch file with the design: every joint moved to where the design puts it at `[input]
    start` on the circuit of `q` (the sketch's pose is its dimensions and its branch)."""
    xy = np.asarray(mech.joint_positions(jnp.asarray(q), jnp.asarray(mech.input_start), jnp.asarray(p)),
                    dtype=float) / float(mech.units.length)
    for (name, _), (x, y) in zip(mech.sketch.joints, xy):
        i = loc.line("sketch.joints", name) or loc.line("sketch", "joints", item=name)
        m = _JOINT.match(lines[i - 1]) if i is not None else None
        if i is None or m is None or m.group("key") != name:
            raise MechanismError(f"cannot rewrite joint '{name}': write it as '{name} = [x, y]' on one line",
                                 file=mech.file, line=i, key=f"sketch.joints.{name}")
        lines[i - 1] = (m.group("head") + _number(x) + m.group("mid") + _number(y) + m.group("tail"))
    out = "\n".join(lines) + ("\n" if text.endswith("\n") else "")
    back = loads(out, file=mech.file or "<string>")
    # the dimensions come back from the coordinates (hypot, atan2) to the last digits
    scale = float(np.max(np.abs(p))) if p.size else 1.0
    if not (np.allclose(back.parameters, p, rtol=1e-12, atol=1e-12 * scale)
            and np.allclose(back.guess, q, rtol=1e-12, atol=1e-12)):
        raise MechanismError("the rewritten sketch does not read back as the design (internal error)",
                             file=mech.file)
    return out


def best_file_text(ev, u, c: int, text: str | None = None) -> str:
    """The mechanism file of design `u` (normalized) on circuit `c` of the evaluator `ev`: the
    input file's text with the design's parameters and its guesses on the found circuit."""
    p, q = design_configuration(ev, u, c)
    return file_text(ev.mech, p, q, text)
