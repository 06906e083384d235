"""The reaction tables of a sketch (`jaxlink/files/sketch.py`) with masses or loads: `[bodies.*]`
and `[joints.*]` derived from the links, their joints and sliders (read then by
`jaxlink/files/bodies.py` as if written by hand)."""

from __future__ import annotations

import math

from ..model.bodies import GROUND
from .keys import check_keys
from .keys import suggest as _suggest

FRAME = "frame"
_MASS_KEYS = {"mass", "inertia", "centroid"}
_BLOCK_KEYS = {"mass", "inertia"}


def body_tables(masses, loads, err, *, bodies, frame, sliders, theta, crank, actuator, chain, xy, body_angle, ang,
                 lu_factor) -> tuple[dict, dict, dict]:
    """The reaction tables (`[bodies.*]`, `[joints.*]`, the loads with joint names replaced by
    their vector sums) of a sketch with masses or loads: a body per link (its angle, mass,
    centroid and inertia), a revolute joint per pair of bodies a joint pins together (the frame
    counts), and per slider a massless block that slides on its body (prismatic) and turns on the
    joint (revolute)."""
    if actuator is not None:
        raise err("reactions of a sketch driven by an actuator are not derived yet: drive it by a crank, or "
                  "write the loop form with [bodies] and [joints]", "sketch", "masses")
    if not isinstance(masses, dict):
        raise err("[sketch.masses] must be a table: LINK = { mass = kg, inertia = kg·m², centroid = [x, y] }",
                  "sketch", "masses")
    out_b: dict = {}
    for b, js in bodies.items():
        spec = masses.get(b, {})
        if not isinstance(spec, dict):
            raise err(f"masses of '{b}' must be {{ mass = kg, inertia = kg·m², centroid = [x, y] }}",
                      "sketch.masses", b)
        check_keys(spec, _MASS_KEYS, f"sketch.masses.{b}",
                   lambda m, k, _b=b: err(m, "sketch.masses", _b, keyname=f"sketch.masses.{_b}.{k}"))
        table: dict = {"angle": theta[b]}
        m = spec.get("mass", 0.0)
        if isinstance(m, bool) or not isinstance(m, (int, float)) or not math.isfinite(m) or m < 0:
            raise err(f"the mass of '{b}' must be a number ≥ 0 (kg), got {m!r}", "sketch.masses", b)
        if m:
            r = js[0]
            c = spec.get("centroid")
            if c is None:  # the middle of a link; the mean of a plate's joints
                c = [sum(xy[j][0] for j in js) / len(js), sum(xy[j][1] for j in js) / len(js)]
            if not isinstance(c, list) or len(c) != 2 or not all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in c):
                raise err(f"the centroid of '{b}' must be [x, y] in the sketch's pose", "sketch.masses", b)
            dx, dy = c[0] - xy[r][0], c[1] - xy[r][1]
            dist = math.hypot(dx, dy)
            off = ang(math.remainder(math.atan2(dy, dx) - body_angle[b], 2 * math.pi))
            cen = [*chain(r)]
            if dist > 0:
                cen.append(f"{float(f'{dist:.15g}')!r} @ {theta[b]} + ({float(f'{off:.15g}')!r})")
            table["mass"] = float(m)
            table["centroid"] = cen
            inertia = spec.get("inertia")
            if inertia is None:
                if len(js) != 2 or "centroid" in spec:
                    raise err(f"'{b}' needs its inertia (kg·m² about its centroid); only a link of two joints "
                              "with the centroid in its middle defaults to a uniform bar, m L²/12", "sketch.masses", b)
                length = math.dist(xy[js[0]], xy[js[1]]) * lu_factor
                inertia = m * length * length / 12.0
            table["inertia"] = inertia
        out_b[b] = table
    for b in masses:
        if b not in bodies and b not in sliders:
            raise err(f"'{b}' in [sketch.masses] is neither a link nor a slider{_suggest(b, [*bodies, *sliders])}",
                      "sketch.masses", b)
    out_j: dict = {}
    for j in xy:
        holders = ([GROUND] if j in frame else []) + [b for b, js in bodies.items() if j in js]
        if j in sliders:  # the block: slides on its body, turns on the joint
            sl = sliders[j]
            block = f"{j}_block"
            on = GROUND if sl["on"] == FRAME else sl["on"]
            axis = f"{j}_angle" if sl["on"] == FRAME else f"{theta[sl['on']]} + {j}_angle"
            out_b[block] = {"angle": axis}
            spec = masses.get(j, {})
            if isinstance(spec, dict):
                check_keys(spec, _BLOCK_KEYS, f"sketch.masses.{j}",
                           lambda m, k, _j=j: err(m + " (a slider's block: its centroid is the joint)", "sketch.masses",
                                                  _j, keyname=f"sketch.masses.{_j}.{k}"))
            if not isinstance(spec, dict):
                raise err(f"the slider '{j}''s block takes {{ mass = kg, inertia = kg·m² }} (its centroid is the "
                          "joint)", "sketch.masses", j)
            m = spec.get("mass", 0.0)
            if isinstance(m, bool) or not isinstance(m, (int, float)) or not math.isfinite(m) or m < 0:
                raise err(f"the mass of '{j}' must be a number ≥ 0 (kg), got {m!r}", "sketch.masses", j)
            if m:
                out_b[block].update(mass=float(m), centroid=chain(j), inertia=spec.get("inertia", 0.0))
            out_j[f"{j}_slide"] = {"bodies": [on, block], "kind": "prismatic", "at": chain(j), "axis": axis}
            holders = [block, *holders]
        for k, other in enumerate(holders[1:]):
            out_j[j if k == 0 else f"{j}_{k + 1}"] = {"bodies": [holders[0], other], "at": chain(j)}
    loads_out: dict = {}
    if isinstance(loads, dict):
        for name, spec in loads.items():
            if not isinstance(spec, dict):
                loads_out[name] = spec
                continue
            spec = dict(spec)
            for key in ("at", "from", "to"):
                if isinstance(spec.get(key), str) and spec[key] in xy:  # a joint's name: its position
                    spec[key] = chain(spec[key])
            loads_out[name] = spec
    return out_b, out_j, loads_out


