"""The sketch form of a linkage file: joints at their positions in one pose, the links and plates
between them, sliders and the driver — translated into the loop form (parameters, input,
unknowns, loops, points) that the rest of jaxlink reads.

    [sketch]
    frame = ["A0", "B0"]              # the joints fixed to the frame
    points = ["P"]                    # the paths to report (default: every moving joint)
    [sketch.input]
    crank = "crank"                   # a link turning about its frame joint ...
    # actuator = ["C1", "C2"]         # ... or a linear actuator: the input is the distance C1–C2
    # link = "bar"                    # ... or any link's angle (a floating link's too)
    # slider = "B"                    # ... or a slider's signed position on its line
    name = "phi2"                     # default: theta_<crank> (crank), s_<C1>_<C2> (actuator)
    [sketch.joints]                   # NAME = [x, y], file length unit, all in the same pose
    A0 = [0, 0]
    ...
    [sketch.links]                    # NAME = [joint, joint, ...]: 2 joints a link, 3 or more a plate
    crank = ["A0", "A"]
    coupler = ["A", "B", "P"]
    [sketch.sliders]                  # JOINT = { on = BODY, along = [dx, dy] } or { on = BODY, through = JOINT }
    B = { on = "frame", along = [1, 0] }

**What is derived** (every name below is a parameter that `--set`, `[optimize]` and studies vary):

- a frame joint F: its coordinates `F_x`, `F_y` (a term `(F_x, F_y)` from the origin);
- a link or plate b with joints [r, j2, j3, …]: its angle θ_b is the direction r → j2 (the unknown
  `theta_b`; for the crank the input). `b` = |r j2|; each further joint jk: `b_jk` = |r jk| and
  `b_jk_angle` = the angle from r → j2 to r → jk. The vector between two other joints of a plate
  is a derived parameter (`b_ji_jk`, `b_ji_jk_angle`: law of cosines), so that every loop holds
  each unknown angle in one vector (a dyad takes the closed form);
- a slider J on body b: the line through J's sketch position, fixed to b, with the direction
  `along` (in the sketch) or towards J from the joint `through`: `J_angle` its direction (from
  b's direction r → j2; on the frame, from the x axis), `J_offset` its distance from b's first
  joint (or the origin; absent with `through`), the unknown `s_J` the position along it;
- an actuator between C1 and C2: the input is their distance, `theta_C1_C2` the unknown angle;
- a driven link (`link`): its angle θ_b is the input (no unknown), pivoted or floating; a driven
  slider (`slider = "J"`): `s_J` is the input (a length), no unknown.

**The loops** are found dyad by dyad: from the joints already placed (the frame, then the crank),
the shortest chain of bodies through unplaced joints that closes on placed joints with exactly two
new unknowns is one loop (an Assur group of class II: `jaxlink/model/structure.py` orders it and
`jaxlink/solvers/dyads.py` solves it in closed form); what cannot be split so is closed by the
fundamental cycles of what is left (Newton). The sketch's pose gives the guesses, so it is the
assembly branch. Grübler's count must give mobility 1: 3·(moving bodies) − 2·(pin pairs) −
(sliders) = 1.
"""

from __future__ import annotations

import dataclasses
import math
import re
from typing import Any, Callable

from ..errors import MechanismError
from .keys import check_keys
from .keys import suggest as _suggest
from .sketch_bodies import body_tables
from .sketch_loops import ORIGIN as _ORIGIN
from .sketch_loops import Edge as _Edge
from .sketch_loops import close_loops
from .sketch_loops import neg as _neg
from .sketch_loops import text as _text

FRAME = "frame"
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_SKETCH_KEYS = {"frame", "points", "input", "joints", "links", "sliders", "masses"}
_INPUT_KEYS = {"crank", "actuator", "link", "slider", "name"}
_DRIVES = ("crank", "actuator", "link", "slider")
_SLIDER_KEYS = {"on", "along", "through"}
#: tables a sketch file may not have: the sketch derives them
DERIVED_TABLES = ("parameters", "input", "unknowns", "loops", "points", "bodies", "joints")


@dataclasses.dataclass(frozen=True)
class Layout:
    """What a sketch file names, kept on the model (`Structure.sketch`) for the drawing and the
    designer's numbers: no numbers, only names and the vector sums of the joints.

    - `joints`: `(name, terms)` of every joint, its position as a vector sum from the origin
      (`derive` gives the terms as strings of the loop form; the model holds them parsed, as
      `jaxlink.files.expr.Term`s with the derived parameters expanded: `Structure.joint_positions`);
    - `frame`: the frame joints; `bodies`: `(name, joint names)` of every link and plate;
    - `sliders`: `(joint, body)`; `input`: `("crank", link)`, `("actuator", (C1, C2))`,
      `("link", link)` (a floating link's angle) or `("slider", joint)` (its signed position).
    """

    joints: tuple
    frame: tuple
    bodies: tuple
    sliders: tuple
    input: tuple


def derive(data: dict, err: Callable[..., MechanismError], file: str) -> tuple[dict, Layout]:
    """The loop-form tables of a file written as a sketch (`data` the parsed TOML), and its
    layout. `err(msg, table, key, item=…)` makes an error naming the line."""
    sk = data["sketch"]
    if not isinstance(sk, dict):
        raise err("[sketch] must be a table (frame, points, input, joints, links, sliders)", "sketch")
    for t in DERIVED_TABLES:
        if t in data:
            raise err(f"a sketch file derives [{t}] from the joints and links; remove [{t}] (`jaxlink check` "
                      "prints what was derived)", t)
    check_keys(sk, _SKETCH_KEYS, "sketch", lambda m, k: err(m, "sketch", k))
    lu = data.get("mechanism", {}).get("length_unit", "m")
    deg = data.get("mechanism", {}).get("angle_unit", "rad") == "deg"

    def ang(rad: float) -> float:
        return math.degrees(rad) if deg else rad

    quarter = "90" if deg else "pi/2"

    # ------------------------------------------------------------------ joints
    joints_raw = sk.get("joints")
    if not isinstance(joints_raw, dict) or not joints_raw:
        raise err("[sketch.joints] must give every joint's position in one pose: NAME = [x, y] "
                  f"(in {lu})", "sketch", "joints")
    xy: dict[str, tuple[float, float]] = {}
    for name, v in joints_raw.items():
        _identifier(name, err, "sketch.joints")
        if (not isinstance(v, list) or len(v) != 2
                or not all(isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in v)):
            raise err(f"joint '{name}' must be [x, y] (two finite numbers in {lu}), got {v!r}", "sketch.joints", name)
        xy[name] = (float(v[0]), float(v[1]))
    scale = max(1e-300, max(math.hypot(x, y) for x, y in xy.values()),
                max(math.hypot(a[0] - b[0], a[1] - b[1]) for a in xy.values() for b in xy.values()))
    tiny = 1e-12 * scale

    def joint_list(v, table, key, what, least=1):
        if isinstance(v, str):
            v = [v]
        if not isinstance(v, list) or len(v) < least or not all(isinstance(j, str) for j in v):
            raise err(f"{what} must be a list of joint names" + (f" (at least {least})" if least > 1 else ""),
                      table, key)
        for j in v:
            if j not in xy:
                raise err(f"'{j}' is not a joint of [sketch.joints]{_suggest(j, xy)}", table, key, item=j)
        if len(set(v)) != len(v):
            raise err(f"{what} names a joint twice", table, key)
        return tuple(v)

    frame = joint_list(sk.get("frame", []), "sketch", "frame", "'frame'")
    if not frame:
        raise err("[sketch] needs frame = [\"A0\", ...]: the joints fixed to the frame", "sketch", "frame")

    # ------------------------------------------------------------------ links and plates
    links_raw = sk.get("links")
    if not isinstance(links_raw, dict) or not links_raw:
        raise err("[sketch.links] must list the moving links: NAME = [joint, joint, ...]", "sketch", "links")
    bodies: dict[str, tuple] = {}
    for name, v in links_raw.items():
        _identifier(name, err, "sketch.links")
        if name == FRAME:
            raise err("'frame' is the frame: list its joints in [sketch] frame", "sketch.links", name)
        js = joint_list(v, "sketch.links", name, f"link '{name}'", least=2)
        on_frame = [j for j in js if j in frame]
        if len(on_frame) > 1:
            raise err(f"link '{name}' holds two frame joints ({', '.join(on_frame)}): it cannot move",
                      "sketch.links", name)
        if math.dist(xy[js[0]], xy[js[1]]) <= tiny:
            raise err(f"link '{name}': its first two joints {js[0]} and {js[1]} are at the same place; they "
                      "give its direction", "sketch.links", name)
        bodies[name] = js

    # ------------------------------------------------------------------ the input
    inp = sk.get("input")
    if isinstance(inp, dict):
        check_keys(inp, _INPUT_KEYS, "sketch.input", lambda m, k: err(m, "sketch.input", k))
    if not isinstance(inp, dict) or sum(k in inp for k in _DRIVES) != 1:
        raise err("[sketch.input] needs one of crank = \"LINK\" (a link turning about its frame joint), "
                  "actuator = [\"C1\", \"C2\"] (a linear actuator: the input is their distance), link = \"LINK\" "
                  "(any link's angle, a floating link's too) or slider = \"J\" (the signed position of slider J "
                  "on its line)", "sketch", "input")
    crank = None
    actuator = None
    driven_slider = None
    drive = next(k for k in _DRIVES if k in inp)
    if drive == "link":  # a link's angle, pivoted to the frame or not: the direction of its first two joints
        crank = inp["link"]
        if not isinstance(crank, str) or crank not in bodies:
            raise err(f"link = {crank!r} is not a link of [sketch.links]{_suggest(str(crank), bodies)}",
                      "sketch.input", "link")
        input_name = inp.get("name", f"theta_{crank}")
    elif drive == "slider":
        driven_slider = inp["slider"]
        input_name = inp.get("name", f"s_{driven_slider}")
    elif "crank" in inp:
        crank = inp["crank"]
        if not isinstance(crank, str) or crank not in bodies:
            raise err(f"crank = {crank!r} is not a link of [sketch.links]{_suggest(str(crank), bodies)}",
                      "sketch.input", "crank")
        piv = [j for j in bodies[crank] if j in frame]
        if not piv:
            raise err(f"the crank '{crank}' has no frame joint to turn about", "sketch.input", "crank")
        rest = [j for j in bodies[crank] if j != piv[0]]
        bodies[crank] = (piv[0], *rest)  # it turns about its frame joint: the reference
        if math.dist(xy[piv[0]], xy[rest[0]]) <= tiny:
            raise err(f"the crank '{crank}': {piv[0]} and {rest[0]} are at the same place", "sketch.input", "crank")
        input_name = inp.get("name", f"theta_{crank}")
    elif drive == "actuator":
        actuator = joint_list(inp["actuator"], "sketch.input", "actuator", "'actuator'", least=2)
        if len(actuator) != 2:
            raise err("actuator = [\"C1\", \"C2\"]: the two joints it pushes apart", "sketch.input", "actuator")
        if math.dist(xy[actuator[0]], xy[actuator[1]]) <= tiny:
            raise err("the actuator's two joints are at the same place", "sketch.input", "actuator")
        input_name = inp.get("name", f"s_{actuator[0]}_{actuator[1]}")
    if not isinstance(input_name, str) or not _NAME.fullmatch(input_name):
        raise err(f"name = {input_name!r} must be a name (letters, digits, _)", "sketch.input", "name")

    # ------------------------------------------------------------------ sliders
    sliders_raw = sk.get("sliders", {})
    if not isinstance(sliders_raw, dict):
        raise err("[sketch.sliders] must be a table: JOINT = { on = BODY, along = [dx, dy] }", "sketch", "sliders")
    sliders: dict[str, dict] = {}
    for j, v in sliders_raw.items():
        if j not in xy:
            raise err(f"'{j}' is not a joint of [sketch.joints]{_suggest(j, xy)}", "sketch.sliders", j)
        if isinstance(v, dict):
            check_keys(v, _SLIDER_KEYS, f"sketch.sliders.{j}",
                       lambda m, k, _j=j: err(m, "sketch.sliders", _j, keyname=f"sketch.sliders.{_j}.{k}"))
        if not isinstance(v, dict) or "on" not in v or (("along" in v) == ("through" in v)):
            raise err(f"slider '{j}' = {{ on = BODY, along = [dx, dy] }} or {{ on = BODY, through = JOINT }}: the "
                      "body its line is fixed to, and the line's direction", "sketch.sliders", j)
        on = v["on"]
        if on != FRAME and on not in bodies:
            raise err(f"slider '{j}': on = {on!r} is neither 'frame' nor a link{_suggest(str(on), bodies)}",
                      "sketch.sliders", j)
        if j in (frame if on == FRAME else bodies[on]):
            raise err(f"slider '{j}' is a joint of '{on}' itself: it cannot slide on it", "sketch.sliders", j)
        if not any(j in js for js in bodies.values()):
            raise err(f"slider '{j}' is on no link: a slider is a joint of a link that moves on a line of "
                      "another body", "sketch.sliders", j)
        if "through" in v:
            t = v["through"]
            if not isinstance(t, str) or t not in (frame if on == FRAME else bodies[on]):
                raise err(f"slider '{j}': through = {t!r} must be a joint of '{on}'", "sketch.sliders", j)
            d = (xy[j][0] - xy[t][0], xy[j][1] - xy[t][1])
            if math.hypot(*d) <= tiny:
                raise err(f"slider '{j}' is at its 'through' joint {t}: the line has no direction",
                          "sketch.sliders", j)
        else:
            d = v["along"]
            if (not isinstance(d, list) or len(d) != 2 or not all(
                    isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in d)
                    or math.hypot(*d) == 0):
                raise err(f"slider '{j}': along = [dx, dy] is the line's direction, two numbers not both 0",
                          "sketch.sliders", j)
            t = None  # type: ignore[assignment]
        sliders[j] = {"on": on, "dir": (float(d[0]), float(d[1])), "through": t}  # type: ignore[dict-item]
    if driven_slider is not None and driven_slider not in sliders:
        raise err(f"slider = {driven_slider!r} is not a slider of [sketch.sliders]"
                  f"{_suggest(str(driven_slider), sliders)}", "sketch.input", "slider")

    # ------------------------------------------------------------------ Grübler
    members = {j: sum(j in js for js in bodies.values()) + (j in frame) for j in xy}
    pairs = sum(max(0, m - 1) for m in members.values())
    mobility = 3 * len(bodies) - 2 * pairs - len(sliders)
    if mobility != 1:
        raise err(f"the sketch has mobility {mobility} by Grübler (3 × {len(bodies)} moving links − 2 × {pairs} "
                  f"pin pairs − {len(sliders)} sliders); a linkage driven by one input needs 1"
                  + (" (a joint that should be shared by two links? a missing link?)" if mobility > 1 else
                     " (a link too many? a joint shared by too many links?)"), "sketch")
    for j, m in members.items():
        if m == 0 and j not in sliders:
            raise err(f"joint '{j}' is on no link and not on the frame", "sketch.joints", j)

    # ------------------------------------------------------------------ parameters, unknowns, edges
    params: dict[str, Any] = {}
    unknowns: dict[str, float] = {}
    edges: list[_Edge] = []

    def num(x: float) -> float:
        return float(f"{x:.15g}") + 0.0

    for f in frame:
        params[f"{f}_x"], params[f"{f}_y"] = num(xy[f][0]), num(xy[f][1])
        edges.append(_Edge(_ORIGIN, f, ((1, f"({f}_x, {f}_y)"),), frozenset(), FRAME))

    def angle_of(a: str, b: str) -> float:
        return math.atan2(xy[b][1] - xy[a][1], xy[b][0] - xy[a][0])

    def wrap(x: float) -> float:
        return math.remainder(x, 2 * math.pi)

    body_angle: dict[str, float] = {FRAME: 0.0}
    theta: dict[str, str] = {}
    start = 0.0
    # the polar form of each joint of each body from the body's first joint: (length name, angle name | None)
    polar: dict[tuple, tuple] = {}
    for b, js in bodies.items():
        r = js[0]
        body_angle[b] = angle_of(r, js[1])
        theta[b] = input_name if b == crank else f"theta_{b}"
        if b == crank:
            start = ang(body_angle[b])
        else:
            unknowns[theta[b]] = num(ang(body_angle[b]))
        params[b] = num(math.dist(xy[r], xy[js[1]]))
        polar[b, js[1]] = (b, None)
        for jk in js[2:]:
            params[f"{b}_{jk}"] = num(math.dist(xy[r], xy[jk]))
            params[f"{b}_{jk}_angle"] = num(ang(wrap(angle_of(r, jk) - body_angle[b]))) if math.dist(
                xy[r], xy[jk]) > tiny else 0.0
            polar[b, jk] = (f"{b}_{jk}", f"{b}_{jk}_angle")
    derived: dict[str, str] = {}

    def body_vector(b: str, u: str, v: str) -> tuple:
        """The terms of the vector u → v on body b (both joints of b)."""
        js = bodies[b]
        th = theta[b]
        if u == js[0] or v == js[0]:
            other = v if u == js[0] else u
            length, off = polar[b, other]
            term = f"{length} @ {th}" + (f" + {off}" if off else "")
            return ((1 if u == js[0] else -1, term),)
        (li, ai), (lk, ak) = polar[b, u], polar[b, v]
        name = f"{b}_{u}_{v}"
        if name not in derived:
            if ai is None:
                derived[name] = f"sqrt({li}*{li} + {lk}*{lk} - 2*{li}*{lk}*cos({ak}))"
                derived[f"{name}_angle"] = f"atan2({lk}*sin({ak}), {lk}*cos({ak}) - {li})"
            elif ak is None:
                derived[name] = f"sqrt({li}*{li} + {lk}*{lk} - 2*{li}*{lk}*cos({ai}))"
                derived[f"{name}_angle"] = f"atan2(-{li}*sin({ai}), {lk} - {li}*cos({ai}))"
            else:
                derived[name] = f"sqrt({li}*{li} + {lk}*{lk} - 2*{li}*{lk}*cos({ak} - {ai}))"
                derived[f"{name}_angle"] = (f"atan2({lk}*sin({ak}) - {li}*sin({ai}), "
                                            f"{lk}*cos({ak}) - {li}*cos({ai}))")
        return ((1, f"{name} @ {th} + {name}_angle"),)

    for b, js in bodies.items():
        for i, u in enumerate(js):
            for v in js[i + 1:]:
                if math.dist(xy[u], xy[v]) > tiny:
                    vs = frozenset() if b == crank else frozenset({theta[b]})
                    edges.append(_Edge(u, v, ("lazy", b), vs, b))  # terms made when used
    for j, sl in sliders.items():
        on, t = sl["on"], sl["through"]
        s_name = input_name if j == driven_slider else f"s_{j}"
        d = sl["dir"]
        dn = math.hypot(*d)
        dx, dy = d[0] / dn, d[1] / dn
        alpha = wrap(math.atan2(dy, dx) - body_angle[on])
        params[f"{j}_angle"] = num(ang(alpha))
        th = "" if on == FRAME else f"{theta[on]} + "
        vs = frozenset(({s_name} - {input_name}) | (set() if on in (FRAME, crank) else {theta[on]}))
        if t is not None:
            ref = t
        else:
            ref = _ORIGIN if on == FRAME else bodies[on][0]
        rx, ry = (0.0, 0.0) if ref == _ORIGIN else xy[ref]
        ex, ey = xy[j][0] - rx, xy[j][1] - ry
        s0 = ex * dx + ey * dy
        e = dx * ey - dy * ex  # the line's distance from ref, to the left of its direction
        terms = []
        if t is None and (on == FRAME or abs(e) > tiny):
            params[f"{j}_offset"] = num(abs(e))
            terms.append((1, f"{j}_offset @ {th}{j}_angle {'+' if e >= 0 else '-'} {quarter}"))
        terms.append((1, f"{s_name} @ {th}{j}_angle"))
        if j == driven_slider:
            start = num(s0)
        else:
            unknowns[s_name] = num(s0)
        edges.append(_Edge(ref, j, tuple(terms), vs, on))
    if actuator is not None:
        c1, c2 = actuator
        th = f"theta_{c1}_{c2}"
        unknowns[th] = num(ang(angle_of(c1, c2)))
        start = num(math.dist(xy[c1], xy[c2]))
        edges.append(_Edge(c1, c2, ((1, f"{input_name} @ {th}"),), frozenset({th}), "actuator"))
    for n in list(params) + list(unknowns):
        if n == input_name or (n in params and n in unknowns):
            raise err(f"the derived name '{n}' is given twice (a joint or link named like another's derived "
                      "name?); rename one", "sketch")

    def terms_of(e: _Edge, forward: bool) -> tuple:
        if e.terms and e.terms[0] == "lazy":
            ts = body_vector(e.body, e.u, e.v)
        else:
            ts = e.terms
        return ts if forward else _neg(ts)

    # ------------------------------------------------------------------ loops, dyad by dyad
    loops, pos = close_loops(edges, input_name, set(unknowns), terms_of, err)
    missing = [j for j in xy if j not in pos]
    if missing:
        raise err(f"joint(s) {', '.join(missing)} cannot be placed from the frame through the links", "sketch")

    # ------------------------------------------------------------------ points and the tables
    pts = sk.get("points")
    if pts is None:
        report = tuple(j for j in xy if j not in frame)
    else:
        report = joint_list(pts, "sketch", "points", "'points'")

    def chain(j: str) -> list[str]:
        return [_text(s, t) for s, t in pos[j]]

    out = {k: v for k, v in data.items() if k != "sketch"}
    if ("masses" in sk or "loads" in data or "environment" in data) and drive in ("link", "slider"):
        raise err(f"reactions of a sketch driven by a {drive}'s {'angle' if drive == 'link' else 'position'} are "
                  "not derived yet: drive it by a crank, or write [bodies] and [joints] in the loop form",
                  "sketch.input", drive)
    if "masses" in sk or "loads" in data or "environment" in data:
        bodies_t, joints_t, loads_t = body_tables(
            sk.get("masses", {}), data.get("loads", {}), err, bodies=bodies, frame=frame, sliders=sliders,
            theta=theta, crank=crank, actuator=actuator, chain=chain, xy=xy, body_angle=body_angle, ang=ang,
            lu_factor={"m": 1.0, "mm": 1e-3, "cm": 1e-2}.get(lu, 1.0))
        out["bodies"], out["joints"] = bodies_t, joints_t
        if loads_t:
            out["loads"] = loads_t
    au = "deg" if deg else "rad"
    out["parameters"] = {**{n: {"value": v, "unit": au if n.endswith("_angle") else lu} for n, v in params.items()},
                         **{n: derived[n] for n in derived}}
    out["input"] = {"name": input_name, "start": num(start)}
    if "bodies" in out and crank is not None:
        out["input"]["body"] = crank
    out["unknowns"] = unknowns
    out["loops"] = loops
    out["points"] = {j: chain(j) for j in report}
    layout = Layout(
        joints=tuple((j, tuple(chain(j))) for j in xy),
        frame=frame,
        bodies=tuple(bodies.items()),
        sliders=tuple((j, sl["on"]) for j, sl in sliders.items()),
        input=(drive, crank if drive in ("crank", "link") else actuator if drive == "actuator" else driven_slider),
    )
    return out, layout


def _identifier(name: str, err, table: str) -> None:
    if not _NAME.fullmatch(str(name)):
        raise err(f"'{name}' is not a valid name (letters, digits and _, not starting with a digit)", table, name)


