"""Tables in the file's units (`--units file`): the same columns in the file's length and angle units.

Every column of a table ends in its unit (`P_x_m`, `phi3_rad_s2`, `drive_torque_N_m`, `input_deg`;
`converged` and `result` have none). The unit of a column is the longest of `SI_UNITS` its name
ends with (after an underscore): the names are `NAME_UNIT` by construction, so a name is never read
as another unit. In the file's units (`FileUnits`, from `[mechanism] length_unit`, `angle_unit`):

| SI column | file column | factor (file = SI × factor) |
|---|---|---|
| `_m`, `_m_s`, `_m_s2` | `_mm`, `_mm_s`, `_mm_s2` (`cm`, `m`) | 1000 (100, 1) |
| `_rad`, `_rad_s`, `_rad_s2` | `_deg`, `_deg_s`, `_deg_s2` (or kept in rad) | 180/π (1) |
| `_deg` (an input angle, as asked) | kept (`_rad` in a file in radians) | 1 (π/180) |
| `_N_m` (a torque) | `_N_mm` | 1000 |
| `_N` (a force) | kept | 1 |

A length input's column (`input_m`) in the file's length unit is rounded to 15 significant digits,
so that it prints as the values were asked for (`--start 0.3`: 0.3 mm, not 0.30000000000000004).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

LENGTH_UNITS = {1.0: "m", 1e-2: "cm", 1e-3: "mm"}
"""The file's length units by their factor to metres (`[mechanism] length_unit`)."""

SI_UNITS = ("rad_s2", "rad_s", "m_s2", "N_m", "m_s", "rad", "deg", "m", "N")
"""The units a column name may end with, longest first."""


class FileUnits(NamedTuple):
    """The file's units: `length` ("mm", "cm", "m") and `angle` ("deg", "rad") with the factors
    that take SI values to them (`length_factor`: 1000 for mm; `angle_factor`: 180/π for deg)."""

    length: str
    angle: str
    length_factor: float
    angle_factor: float

    def speed(self, input_kind: str) -> tuple:
        """(the unit of an input speed, its factor from rad/s or m/s): `deg/s`, `mm/s`, …"""
        if input_kind == "angle":
            return f"{self.angle}/s", self.angle_factor
        return f"{self.length}/s", self.length_factor


def file_units(mech) -> FileUnits:
    """The units of `mech`'s file. Exact factors: 1/length (1000.0 for mm), 180/π for degrees."""
    u = float(mech.units.length)
    name = LENGTH_UNITS.get(u)
    if name is None:
        raise ValueError(f"length unit factor {u} is not one of the file format's (m, cm, mm)")
    inv = 1.0 / u
    length_factor = float(round(inv)) if abs(inv - round(inv)) < 1e-9 * inv else inv
    deg = float(mech.units.angle) != 1.0
    return FileUnits(name, "deg" if deg else "rad", length_factor, 180.0 / math.pi if deg else 1.0)


def unit_of(column: str) -> str | None:
    """The unit a column name ends with (one of `SI_UNITS`), or None (`converged`, `result`)."""
    for u in SI_UNITS:
        if column.endswith("_" + u) and len(column) > len(u) + 1:
            return u
    return None


def converted_unit(unit: str, units: FileUnits) -> tuple:
    """(the unit in the file's units, the factor from the SI unit) of one of `SI_UNITS`."""
    lu, au, lf, af = units
    if unit == "N_m":  # a torque: force × length
        return f"N_{lu}", lf
    base = {"m": (lu, lf), "rad": (au, af), "N": ("N", 1.0),
            "deg": ("deg", 1.0) if au == "deg" else ("rad", math.pi / 180.0)}
    quantity, _, rate = unit.partition("_")  # "m_s2": the length's second rate
    name, factor = base[quantity]
    return (f"{name}_{rate}" if rate else name), factor


def convert(columns, data, units: FileUnits | None) -> tuple:
    """`(columns, data)` in the file's `units` (None: as they are, SI). `data` (N, len(columns))."""
    if units is None:
        return list(columns), np.asarray(data)
    cols, out = [], np.array(data, dtype=float, copy=True)
    for j, c in enumerate(columns):
        u = unit_of(c)
        if u is None:
            cols.append(c)
            continue
        new, factor = converted_unit(u, units)
        cols.append(c[: -len(u)] + new)
        if factor != 1.0:
            out[:, j] = out[:, j] * factor
            if j == 0 and u == "m":  # a length input as asked (decimal in the file's unit)
                out[:, j] = [float(f"{x:.15g}") if math.isfinite(x) else x for x in out[:, j]]
    return cols, out


def input_unit_text(input_kind: str, units: FileUnits | None) -> tuple:
    """(the unit text of an input value in messages, its factor from the input column of an SI
    table: degrees for an angle, metres for a length)."""
    if input_kind == "angle":
        if units is None or units.angle == "deg":
            return "°", 1.0
        return " rad", math.pi / 180.0
    if units is None:
        return " m", 1.0
    return f" {units.length}", units.length_factor
