"""The designer's numbers, formatted: the Grashof class of every four-bar loop
(`jaxlink.analysis.grashof`), the input's range of motion, the transmission angles and every
output's stroke or swing, dead centres, time ratio and velocity ratio (`jaxlink.analysis.motion`,
`jaxlink.analysis.stroke`) — as the lines `jaxlink check` and `jaxlink kinematics` print, and as the
`designer` object of the kinematics JSON (SI, every key with its unit)."""

from __future__ import annotations

from typing import Any

import numpy as np


def compute(mech) -> tuple[list, Any]:
    """`(four_bars, motion)` of the file's design on its guesses' branch (`motion` None where not
    every block is a dyad or the input is a length)."""
    from ..analysis.grashof import four_bars
    from ..analysis.motion import motion

    return four_bars(mech), motion(mech)


def _transmission_lines(m, name: str, ang, at) -> list[str]:
    """The transmission line of each loop of `m`: its least and largest angle, the inputs where
    they are (`at` formats an input) and the worst, farthest from 90°."""
    out = []
    for i, t in enumerate(m.transmission):
        label = f"loop '{t['loop']}' ({', '.join(t['unknowns'])}{_MEASURED.get(t.get('kind', 'RRR'), '')})"
        out.append(f"{'transmission' if i == 0 else '':<13}{label}: {ang(t['min'])} at {name} = "
                   f"{at(t['min_at'])} … {ang(t['max'])} at {at(t['max_at'])}; worst (farthest from 90°) "
                   f"{ang(t['worst'])}")
    return out


def lines(mech, fbs, m, lu: str) -> list:
    """The text lines (file units: `lu` the length unit's name)."""
    from ..analysis.grashof import describe

    out = [f"{'four-bar' if i == 0 else '':<12}{describe(fb, mech.units.length, lu)}" for i, fb in enumerate(fbs)]
    if m is None:
        return out
    deg = mech.units.angle != 1.0
    name = mech.input_name

    def ang(x, digits=10):
        x = 0.0 if abs(x) < 1e-12 else x  # a limit at 0 found to rounding
        return f"{np.degrees(x):.{digits}g}°" if deg else f"{x:.{digits}g} rad"

    def where_(x):  # within one revolution [0, 360°)
        x = float(np.mod(x, 2 * np.pi))
        return ang(0.0 if x > 2 * np.pi - 1e-12 else x, 6)

    length = mech.input_kind != "angle"
    if length:  # an actuator: its range, the outputs over it
        def inp(x, digits=10):
            return f"{x / mech.units.length:.{digits}g} {lu}"

        ends = [inp(m.low) + ("" if m.lower is not None else " (no limit position down to there: the scan's end)"),
                inp(m.high) + ("" if m.upper is not None else " (no limit position up to there: the scan's end)")]
        if m.low is None:
            out.append(f"motion      {name}: the start does not assemble")
            return out
        out.append(f"motion      {name} from {ends[0]} to {ends[1]}"
                   + (" (limit positions: toggles)" if m.lower is not None and m.upper is not None else "")
                   + f", a range of {inp(m.high - m.low)}")
        out += _transmission_lines(m, name, ang, lambda x: inp(x, 6))
        for i, o in enumerate(m.outputs):
            def val(x, digits=10, o=o):
                return ang(x, digits) if o["kind"] == "rocker" else inp(x, digits)

            what = "swing" if o["kind"] == "rocker" else "stroke"
            out.append(f"{'outputs' if i == 0 else '':<12}{o['kind']} {o['name']}: {what} {val(o['stroke'])} "
                       f"({val(o['min'], 8)} at {name} = {inp(o['min_at'], 6)} … {val(o['max'], 8)} at "
                       f"{inp(o['max_at'], 6)}) over the range")
        return out
    if m.full_turn:
        flats = " and ".join(where_(x) for x in m.change_points)
        through = (f", through the flat position{'s' if len(m.change_points) > 1 else ''} at {name} = {flats} (a "
                   "change point: links in line, where the linkage can switch branch)") if m.change_points else ""
        out.append(f"motion      {name} turns fully (on the guesses' branch){through}")
    elif m.lower is not None and m.upper is not None:
        out.append(f"motion      {name} from {ang(m.lower)} to {ang(m.upper)} (limit positions: toggles), a range "
                   f"of {ang(m.upper - m.lower)}")
    else:
        out.append(f"motion      {name}: the start does not assemble on a whole turn")

    def where(x):  # over a full turn, within one revolution [0, 360°)
        if m.full_turn:
            x = float(np.mod(x, 2 * np.pi))
            x = 0.0 if x > 2 * np.pi - 1e-12 else x
        return ang(x, 6)

    out += _transmission_lines(m, name, ang, where)
    for i, o in enumerate(m.outputs):
        out.append(f"{'outputs' if i == 0 else '':<12}" + _output_line(o, name, ang, where, mech.units.length, lu))
    return out


_MEASURED = {"RRP": "; the link against the guide's normal",
             "RPR": "; the block's push against the slotted link's path"}
"""What a transmission angle measures, where it is not the angle between two links (RRR)."""


def _output_line(o, name, ang, where, length_factor, lu) -> str:
    """One output's stroke or swing, dead centres, time ratio and velocity ratio, in file units."""
    def val(x, digits=10):
        return ang(x, digits) if o["kind"] == "rocker" else f"{x / length_factor:.{digits}g} {lu}"

    vunit = "" if o["kind"] == "rocker" else f" {lu}/rad"
    vel = (f"velocity ratio d{o['name']}/d{name} {o['velocity_min'] / (1 if vunit == '' else length_factor):.6g} at "
           f"{where(o['velocity_min_at'])} … {o['velocity_max'] / (1 if vunit == '' else length_factor):.6g}{vunit} at "
           f"{where(o['velocity_max_at'])}")
    what = "swing" if o["kind"] == "rocker" else "stroke"
    head = f"{o['kind']} {o['name']}: {what} {val(o['stroke'])} ({val(o['min'], 8)} … {val(o['max'], 8)})"
    if o["time_ratio"] is None:
        return f"{head}, no dead centre; {vel}"
    flat = (o.get("min_flat", False), o.get("max_flat", False))
    if not any(flat):
        ends = f"dead centres at {name} = {where(o['min_at'])} and {where(o['max_at'])}"
    else:  # an extreme at a change point: the rate jumps across zero there, it is not a dead centre
        kinds = ["flat position (change point, the rate jumps)" if f else "dead centre" for f in flat]
        ends = (f"{kinds[0]} at {name} = {where(o['min_at'])} and {kinds[1]} at {where(o['max_at'])}"
                if flat[0] != flat[1] else f"flat positions (change points, the rate jumps) at {name} = "
                f"{where(o['min_at'])} and {where(o['max_at'])}")
    return (f"{head}, {ends}; "
            f"rise {ang(o['rise'], 8)}, fall {ang(o['fall'], 8)}: time ratio {o['time_ratio']:.10g}; {vel}")


def _f(x):
    return None if x is None else float(x)


def to_json(mech, fbs, m) -> dict:
    """The `designer` object of the kinematics JSON: SI, every key with its unit (`_m`, `_rad`,
    `_m_per_rad` for a slider's velocity ratio); where things happen in the input's unit (`_at_rad`,
    `input_rad`; a length input `_at_m`, `input_m`, its range `lower_m`, `upper_m`, `low_m`,
    `high_m`)."""
    out: dict = {"four_bars": [
        {"loop": fb.loop, "grashof": fb.grashof, "type": fb.type, "shortest": fb.shortest,
         "links_m": {k: (None if v is None else (list(map(float, v)) if isinstance(v, tuple) else float(v)))
                     for k, v in fb.links.items()},
         "s_plus_l_m": float(fb.s + fb.longest), "p_plus_q_m": float(fb.pq)} for fb in fbs]}
    if m is None:
        out["motion"] = None
        return out
    iu = "rad" if mech.input_kind == "angle" else "m"  # the input's unit: where things are
    outputs = []
    for o in m.outputs:
        u = "rad" if o["kind"] == "rocker" else "m"
        v = "" if o["kind"] == "rocker" else "_m_per_rad"
        outputs.append({
            "name": o["name"], "kind": o["kind"], f"{'swing' if u == 'rad' else 'stroke'}_{u}": _f(o["stroke"]),
            f"min_{u}": _f(o["min"]), f"max_{u}": _f(o["max"]),
            f"min_at_{iu}": _f(o["min_at"]), f"max_at_{iu}": _f(o["max_at"]),
            "dead_centres": [{f"input_{iu}": float(x), f"value_{u}": float(y)} for x, y in o["dead_centres"]],
            "flat_positions": [{f"input_{iu}": float(x), f"value_{u}": float(y)}
                               for x, y in o.get("flat_positions", [])],
            "min_at_flat": bool(o.get("min_flat", False)), "max_at_flat": bool(o.get("max_flat", False)),
            "rise_rad": _f(o["rise"]), "fall_rad": _f(o["fall"]), "time_ratio": _f(o["time_ratio"]),
            f"velocity_ratio_min{v}": _f(o["velocity_min"]), f"velocity_ratio_min_at_{iu}": _f(o["velocity_min_at"]),
            f"velocity_ratio_max{v}": _f(o["velocity_max"]), f"velocity_ratio_max_at_{iu}": _f(o["velocity_max_at"]),
        })
    out["motion"] = {
        "full_turn": bool(m.full_turn), f"lower_{iu}": _f(m.lower), f"upper_{iu}": _f(m.upper),
        **({} if iu == "rad" else {"low_m": _f(m.low), "high_m": _f(m.high)}),
        "change_points_rad": [float(x) for x in m.change_points],
        "transmission": [{"loop": t["loop"], "kind": t.get("kind", "RRR"), "unknowns": list(t["unknowns"]),
                          "min_rad": float(t["min"]), f"min_at_{iu}": float(t["min_at"]), "max_rad": float(t["max"]),
                          f"max_at_{iu}": float(t["max_at"]), "worst_rad": float(t["worst"])}
                         for t in m.transmission],
        "outputs": outputs,
    }
    return out
