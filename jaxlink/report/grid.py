"""The input grid of a report: the input values as the user asked for them, whether the grid is one
full revolution, and the runs of positions that failed (for warnings and shaded plot ranges).

Angles are shown in degrees; when the input is an angle, angles in messages and summaries are
reduced to [0, 360) (a peak "at 375°" is at 15°), and on a grid of exactly one revolution a run of
failed positions that wraps past the end continues at the start ("340°–10°").
"""

from __future__ import annotations

from decimal import Decimal

import numpy as np

from ..results import RESULTS


def exact_grid(start: float, step: float, count: int) -> np.ndarray:
    """`start + k·step` for k < count, computed in decimal so that the floats print as the
    decimals asked for (15.0, not 14.999999999999998; 0.3, not 0.30000000000000004)."""
    s, d = Decimal(repr(float(start))), Decimal(repr(float(step)))
    return np.array([float(s + k * d) for k in range(int(count))])


def full_turn(inputs, kind: str) -> bool:
    """True when `inputs` (SI, rad) are an evenly spaced angle grid of exactly one revolution:
    N steps of size h with N·|h| = 2π (the last position joined to the first closes a curve)."""
    x = np.asarray(inputs, dtype=float)
    if kind != "angle" or x.size < 3:
        return False
    d = np.diff(x)
    h = d[0]
    if h == 0 or not np.allclose(d, h, rtol=1e-9, atol=1e-12):
        return False
    return abs(abs(h) * x.size - 2 * np.pi) < 1e-9 * 2 * np.pi


def reduce_deg(x):
    """Angles in degrees reduced to [0, 360) (without a −0 or a 360 from rounding)."""
    r = np.mod(np.asarray(x, dtype=float), 360.0)
    r = np.where(np.isclose(r, 360.0, rtol=0, atol=1e-9), 0.0, r)
    return r + 0.0


def runs(mask, periodic: bool = False) -> list:
    """Index runs `(first, last)` (inclusive, in grid order) where `mask` is True. On a periodic
    grid a run that ends at the last position and one that starts at the first are one run
    (returned with first > last)."""
    m = np.asarray(mask, dtype=bool)
    out, i, n = [], 0, m.size
    while i < n:
        if m[i]:
            j = i
            while j + 1 < n and m[j + 1]:
                j += 1
            out.append((i, j))
            i = j + 1
        else:
            i += 1
    if periodic and len(out) > 1 and out[0][0] == 0 and out[-1][1] == n - 1:
        out = [(out[-1][0], out[0][1])] + out[1:-1]
    return out


def format_value(x: float, kind: str) -> str:
    """One input value for a message: degrees (reduced to [0, 360)) or metres."""
    if kind == "angle":
        return f"{float(reduce_deg(x)):g}°"
    return f"{x:g} m"


def format_input(x: float, kind: str) -> str:
    """One input value as the user gave it (titles of plots and drawings): degrees not reduced (a
    run from −100° starts at "-100°", not "260°") or metres."""
    if kind == "angle":
        return f"{float(x) + 0.0:g}°"
    return f"{x:g} m"


def format_runs(values, index_runs, kind: str, limit: int = 6) -> str:
    """`135°–225°, 340°–10°` (at most `limit` runs, then how many more)."""
    parts = []
    for a, b in index_runs[:limit]:
        if a == b:
            parts.append(format_value(values[a], kind))
        elif kind == "angle":
            parts.append(f"{float(reduce_deg(values[a])):g}°–{float(reduce_deg(values[b])):g}°")
        else:
            parts.append(f"{values[a]:g}–{values[b]:g} m")
    if len(index_runs) > limit:
        parts.append(f"and {len(index_runs) - limit} more ranges")
    return ", ".join(parts)


def failure_text(result, values, kind: str, periodic: bool, good=(RESULTS.converged,)) -> str:
    """What failed where: `19 × cannot_assemble at 135°–225°: <what to do>; …`, one part per
    result code not in `good`, with the input ranges (`values` in display units: degrees for an
    angle input, metres for a length input)."""
    res = np.asarray(result)
    parts = []
    for code in np.unique(res[~np.isin(res, good)]):
        sel = res == code
        where = format_runs(values, runs(sel, periodic), kind)
        parts.append(f"{int(sel.sum())} × {RESULTS.name(code)} at {where}: {RESULTS.message(code)}")
    return "; ".join(parts)
