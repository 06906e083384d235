"""A mechanism built in code from joints and links — the Python side of the sketch form of a
linkage file (`[sketch]`, `jaxlink/files/sketch.py`).

    sk = jl.Sketch("four-bar", length_unit="mm", angle_unit="deg")
    sk.frame("A0", 0, 0).frame("B0", 55, 0)
    sk.joint("A", 20, 0).joint("B", 49.2, 44.6).joint("P", 35.1, 36.6)
    sk.link("crank", "A0", "A").link("coupler", "A", "B", "P").link("rocker", "B0", "B")
    sk.crank("crank", name="phi2").points("P")
    mech = sk.mechanism()          # the same Mechanism as jl.loads(sk.toml())

A `Sketch` only collects what it is told; `toml()` writes it as a sketch file and `mechanism()`
reads that text with `jaxlink.loads`, so a mechanism built in code is the one its file gives, with
the same checks and error messages (the line numbers are those of `toml()`).
"""

from __future__ import annotations

import math
from typing import Any, Mapping


class Sketch:
    """A linkage as joints at their positions in one pose, links and plates between them,
    sliders and a driver. Every method returns the sketch (calls chain). Lengths are in
    `length_unit`, angles in `angle_unit` ("m" | "mm" | "cm", "rad" | "deg")."""

    def __init__(self, name: str = "sketch", *, length_unit: str = "m", angle_unit: str = "rad",
                 description: str = ""):
        self.name = name
        self.description = description
        self.length_unit = length_unit
        self.angle_unit = angle_unit
        self._joints: dict[str, tuple[float, float]] = {}
        self._frame: list[str] = []
        self._links: dict[str, tuple[str, ...]] = {}
        self._sliders: dict[str, dict] = {}
        self._input: dict[str, Any] = {}
        self._points: list[str] | None = None
        self._tables: dict[str, Any] = {}

    # ------------------------------------------------------------------ the sketch
    def joint(self, name: str, x: float, y: float) -> Sketch:
        """A joint at (x, y) in the sketch's pose."""
        self._joints[name] = (_finite(x, name), _finite(y, name))
        return self

    def frame(self, name: str, x: float, y: float) -> Sketch:
        """A joint fixed to the frame (a pivot) at (x, y)."""
        self.joint(name, x, y)
        if name not in self._frame:
            self._frame.append(name)
        return self

    def link(self, name: str, *joints: str) -> Sketch:
        """A rigid body through the joints: two make a link, three or more a plate. Its angle is
        the direction from its first joint to its second."""
        self._links[name] = tuple(joints)
        return self

    def slider(self, joint: str, *, on: str = "frame", along: tuple[float, float] | None = None,
               through: str | None = None) -> Sketch:
        """`joint` moves on a line fixed to body `on` ("frame" or a link), through its sketch
        position, with the direction `along` (dx, dy) or towards it from the joint `through` of `on`."""
        spec: dict[str, Any] = {"on": on}
        if along is not None:
            spec["along"] = [float(along[0]), float(along[1])]
        if through is not None:
            spec["through"] = through
        self._sliders[joint] = spec
        return self

    def crank(self, link: str, *, name: str | None = None) -> Sketch:
        """The input: `link` turns about its frame joint; the input is its angle (`name`)."""
        self._input = {"crank": link, **({"name": name} if name else {})}
        return self

    def actuator(self, joint_a: str, joint_b: str, *, name: str | None = None) -> Sketch:
        """The input: a linear actuator between two joints; the input is their distance."""
        self._input = {"actuator": [joint_a, joint_b], **({"name": name} if name else {})}
        return self

    def link_angle(self, link: str, *, name: str | None = None) -> Sketch:
        """The input: the angle of `link` (the direction from its first joint to its second), pivoted
        to the frame or floating (the bar of an elliptic trammel)."""
        self._input = {"link": link, **({"name": name} if name else {})}
        return self

    def slider_position(self, joint: str, *, name: str | None = None) -> Sketch:
        """The input: the signed position of the slider `joint` along its line (`slider`), from the
        line's foot nearest its body's first joint (on the frame: the origin)."""
        self._input = {"slider": joint, **({"name": name} if name else {})}
        return self

    def points(self, *names: str) -> Sketch:
        """The joints whose paths are reported (default: every moving joint)."""
        self._points = list(names)
        return self

    def table(self, name: str, value: Mapping[str, Any]) -> Sketch:
        """Another table of the file as it would be written (e.g. `optimize`)."""
        self._tables[name] = dict(value)
        return self

    # ------------------------------------------------------------------ out
    def tables(self) -> dict:
        """The file's tables (as `tomllib` would read them)."""
        sk: dict[str, Any] = {"frame": list(self._frame)}
        if self._points is not None:
            sk["points"] = list(self._points)
        sk["input"] = dict(self._input)
        sk["joints"] = {n: [x, y] for n, (x, y) in self._joints.items()}
        sk["links"] = {n: list(js) for n, js in self._links.items()}
        if self._sliders:
            sk["sliders"] = {j: dict(s) for j, s in self._sliders.items()}
        mech = {"name": self.name, "length_unit": self.length_unit, "angle_unit": self.angle_unit}
        if self.description:
            mech["description"] = self.description
        return {"mechanism": mech, "sketch": sk, **self._tables}

    def toml(self) -> str:
        """The sketch as the text of a mechanism file."""
        lines: list[str] = []
        t = self.tables()
        _table(lines, "mechanism", t["mechanism"])
        sk = t["sketch"]
        _table(lines, "sketch", {k: v for k, v in sk.items() if not isinstance(v, dict)})
        for k, v in sk.items():
            if isinstance(v, dict):
                _table(lines, f"sketch.{k}", v)
        for k, v in t.items():
            if k not in ("mechanism", "sketch"):
                _table(lines, k, v)
        return "\n".join(lines) + "\n"

    def mechanism(self, *, overrides: Mapping[str, float] | None = None):
        """The `Mechanism` (`jaxlink.loads` of `toml()`)."""
        from ..files.reader import loads

        return loads(self.toml(), file=f"<sketch {self.name}>", overrides=overrides)


def _finite(v, name: str) -> float:
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"joint '{name}': coordinates must be finite, got {v}")
    return v


def _table(lines: list, name: str, table: Mapping) -> None:
    """Append `[name]` with its keys (sub-tables of sub-tables as nested tables)."""
    if lines:
        lines.append("")
    lines.append(f"[{name}]")
    nested = []
    for k, v in table.items():
        if isinstance(v, dict) and any(isinstance(x, dict) for x in v.values()):
            nested.append((k, v))
        else:
            lines.append(f"{_key(k)} = {_value(v)}")
    for k, v in nested:
        _table(lines, f"{name}.{_key(k)}", v)


def _key(k: str) -> str:
    import re

    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else _value(k)


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        if not math.isfinite(v):
            raise ValueError(f"not a finite number: {v}")
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} in a mechanism file: {v!r}")
