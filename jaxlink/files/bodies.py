"""Reading `[bodies.*]`, `[joints.*]`, `[loads.*]` and `[environment]` of a mechanism file into the
body model (`jaxlink/model/bodies.py`), when the file is loaded (`jaxlink/files/reader.py`).

File format (lengths and angles in the file's units, like `[points]`; masses in kg, inertias in
kg·m², forces in N, stiffness in N/m)::

    [bodies.coupler]
    angle = "phi3"                         # orientation: an angle expression (needed with inertia)
    mass = 0.0093258                       # kg (default 0: massless)
    centroid = ["l2 @ phi2", "l3/2 @ phi3"]  # vector sum from the origin (needed with mass)
    inertia = 2.7977e-6                    # kg·m² about the centroid (default 0)

    [joints.B]
    bodies = ["crank", "coupler"]          # two bodies; "ground" is the frame
    kind = "revolute"                      # or "prismatic" (default revolute)
    at = ["l2 @ phi2"]                     # the joint's point (vector sum)
    axis = "90"                            # prismatic only: sliding direction, an angle expression

    [loads.weight]                         # a constant force at a point of a body
    kind = "force"
    body = "slider"
    at = ["(l1 + l7, 0)", "s @ 90"]
    force = [0.0, -98.0665]                # N

    [loads.brake]                          # a constant moment on a body (counter-clockwise +)
    kind = "torque"
    body = "rocker"
    torque = -1.5                          # N·m

    [loads.spring]                         # a linear spring between points of two bodies
    kind = "spring"
    bodies = ["ground", "lever"]
    from = ["(0, 40)"]                     # on the first body
    to = ["l2 @ phi2", "20 @ phi3"]        # on the second body
    stiffness = 3100.0                     # N/m
    length = 30.0                          # length (file unit) at which the tension is `preload`
    preload = 6.2                          # N, tension (negative: the spring pushes)

    [environment]
    gravity = [0.0, -9.81]                 # m/s²

The spring law and the joint unknowns are in `jaxlink/model/bodies.py`. A file that declares
bodies, joints or loads declares them for kinetostatics, so all of it is checked at load:
`[input] body` must name the body the drive acts on. An angle input drives it with a torque; a
length input (a cylinder, a driven slider) with a force, which needs where it acts and its
direction::

    [input]
    name = "s"                             # the cylinder's length
    body = "rocker"                        # the body the drive force acts on
    at = ["r @ theta"]                     # where (a vector sum, a point of the body)
    axis = "psi"                           # its direction: the one in which s grows
    base = "ground"                        # the body taking the reaction (default the ground)
"""

from __future__ import annotations

from typing import Callable, Mapping

from ..errors import MechanismError
from ..model.bodies import GROUND, JOINT_CLASS, Body, Force, Joint, Model, Spring, Torque
from . import expr as _expr
from .expr import ANGLE, LENGTH, ExprSyntaxError, UnitError
from .keys import check_keys

BODY_KEYS = {"angle", "mass", "centroid", "inertia", "description"}
JOINT_KEYS = {"bodies", "kind", "at", "axis", "description"}
LOAD_KEYS = {
    "force": {"kind", "body", "at", "force", "description"},
    "torque": {"kind", "body", "torque", "description"},
    "spring": {"kind", "bodies", "from", "to", "stiffness", "length", "preload", "description"},
}
ENV_KEYS = {"gravity"}


def read_bodies(
    data: Mapping,
    *,
    file: str,
    err: Callable[..., MechanismError],
    kinds: Mapping[str, str | None],
    length_unit: float,
    input_name: str,
    input_body: str | None,
    defs: Mapping | None = None,
) -> Model | None:
    """The body model of a parsed file `data` (the TOML tables), or None when it declares no
    bodies, joints or loads (`[environment]` alone is still checked).

    **Arguments:**

    - `err(message, table, key=None, item=None)`: the reader's error factory; it finds the line of
      `key` in `[table]` (or of `item` in its value) in the text that was parsed.
    - `kinds`: "length" | "angle" | "number" of every parameter, unknown and the input.
    - `length_unit`: metres per file length unit.
    - `input_name`, `input_body`: from `[input]`.

    Raises `MechanismError` naming the file, line, key and reason for anything wrong: bodies
    without joints (or joints without bodies), an unknown body, a body with no joints, a joint
    that is not one of `JOINT_CLASS` between two bodies, negative mass or inertia, a mass without
    a centroid, an inertia without an angle, an expression with an unknown name or the wrong unit,
    a statically indeterminate (or under-constrained) joint layout, a missing input body.
    """
    env_raw = data.get("environment", {})
    if not isinstance(env_raw, dict):
        raise err("[environment] must be a table", "environment")
    unknown_keys(env_raw, ENV_KEYS, "environment", err)
    g = env_raw.get("gravity", [0.0, 0.0])
    if (not isinstance(g, list) or len(g) != 2
            or not all(_finite(x) for x in g)):
        raise err("'gravity' must be [gx, gy] in m/s², e.g. [0, -9.81]", "environment", "gravity")

    bodies_raw = data.get("bodies", {})
    joints_raw = data.get("joints", {})
    loads_raw = data.get("loads", {})
    if not (bodies_raw or joints_raw or loads_raw):
        return None
    if not isinstance(bodies_raw, dict) or not bodies_raw:
        raise MechanismError(
            "[joints] and [loads] need [bodies.NAME] tables (angle, mass, centroid, inertia); this file has no "
            "bodies", file=file, key="bodies")
    if not isinstance(joints_raw, dict) or not joints_raw:
        raise MechanismError(
            "[bodies] need [joints.NAME] tables (bodies = [A, B], kind, at) that hold them; this file has none",
            file=file, key="joints")
    known = set(kinds)

    def check_names(node, table, key, text):
        for nm in _expr.names_in(node):
            if nm.name not in known:
                raise err(f"unknown name '{nm.name}' in \"{text}\"{_expr.suggest(nm.name, known)} — "
                          "use parameters, unknowns and the input", table, key, item=text)

    def check_dim(node, role, table, key, text):
        try:
            d = _expr.dim_of(node, kinds)
        except UnitError as exc:
            raise err(f"inconsistent units in \"{text}\": {exc}", table, key, item=text) from None
        if d is not None and d != role:
            hint = ""
            bad = [nm.name for nm in _expr.names_in(node) if kinds.get(nm.name) == "number"]
            if bad:
                hint = (f" ('{bad[0]}' is not used as a length or angle in the loops, so its unit is unknown: "
                        f"declare it as {bad[0]} = {{ value = ..., unit = \"mm\" }} or \"deg\")")
            raise err(f"\"{text}\" is {_expr._dim_name(d)} where {_expr._dim_name(role)} is expected{hint}",
                      table, key, item=text)

    def vector_sum(value, table, key):
        if isinstance(value, str):
            value = [value]
        if not isinstance(value, list) or not value:
            raise err(f"'{key}' must be a vector sum: a list of terms like [\"l2 @ phi2\", \"l3/2 @ phi3\"]",
                      table, key)
        terms = []
        for t in value:
            try:
                term = _expr.substitute_term(_expr.parse_term(t), defs or {})
            except ExprSyntaxError as exc:
                raise err(str(exc), table, key, item=str(t)) from None
            if term.polar:
                check_names(term.length, table, key, term.text)
                check_names(term.angle, table, key, term.text)
                check_dim(term.length, LENGTH, table, key, term.text)
                check_dim(term.angle, ANGLE, table, key, term.text)
            else:
                for nd in (term.x, term.y):
                    check_names(nd, table, key, term.text)
                    check_dim(nd, LENGTH, table, key, term.text)
            terms.append(term)
        return tuple(terms)

    def angle_expr(value, table, key):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if not _finite(value):
                raise err(f"'{key}' must be a finite angle within ±{NUMBER_LIMIT:g}", table, key)
            value = repr(float(value))
        if not isinstance(value, str):
            raise err(f"'{key}' must be an angle expression like \"phi3\" or \"90\"", table, key)
        try:
            node = _expr.substitute(_expr.parse_expr(value), defs or {})
        except ExprSyntaxError as exc:
            raise err(str(exc), table, key, item=value) from None
        check_names(node, table, key, value)
        check_dim(node, ANGLE, table, key, value)
        return node

    def number(d, key, table, *, default=None, nonneg=False):
        if key not in d:
            if default is None:
                raise err(f"missing '{key}'", table)
            return float(default)
        v = d[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise err(f"'{key}' must be a number, got {v!r}", table, key)
        if not _finite(v):
            shown = repr(v) if abs(v) < 10**30 else "an integer of more than 30 digits"
            raise err(f"'{key}' = {shown} is not a finite number within ±{NUMBER_LIMIT:g}", table, key)
        v = float(v)
        if nonneg and v < 0:
            raise err(f"'{key}' = {v:g} is negative; it must be ≥ 0", table, key)
        return v

    # ------------------------------------------------------------------ bodies
    bodies = []
    for bname, b in bodies_raw.items():
        table = f"bodies.{bname}"
        if not isinstance(b, dict):
            raise err("a body must be a table [bodies.NAME] with angle, mass, centroid, inertia", "bodies", bname)
        if bname == GROUND:
            raise err("'ground' is the frame and cannot be declared as a body", "bodies", bname)
        unknown_keys(b, BODY_KEYS, table, err)
        mass = number(b, "mass", table, default=0.0, nonneg=True)
        inertia = number(b, "inertia", table, default=0.0, nonneg=True)
        angle = angle_expr(b["angle"], table, "angle") if "angle" in b else None
        centroid = vector_sum(b["centroid"], table, "centroid") if "centroid" in b else None
        if mass > 0 and centroid is None:
            raise err(f"body '{bname}' has mass {mass:g} kg but no 'centroid' (a vector sum, e.g. "
                      "[\"l2 @ phi2\", \"l3/2 @ phi3\"])", table, "mass")
        if inertia > 0 and angle is None:
            raise err(f"body '{bname}' has an inertia but no 'angle' (an expression of its orientation, "
                      "e.g. \"phi3\")", table, "inertia")
        bodies.append(Body(bname, angle, mass, inertia, centroid))
    index = {b.name: i for i, b in enumerate(bodies)}

    def body_index(name, table, key):
        if name == GROUND:
            return -1
        if name not in index:
            raise err(f"unknown body '{name}'{_expr.suggest(str(name), [*index, GROUND])}; bodies: "
                      + ", ".join([GROUND, *index]), table, key, item=str(name))
        return index[name]

    # ------------------------------------------------------------------ joints
    joints = []
    for jname, j in joints_raw.items():
        table = f"joints.{jname}"
        if not isinstance(j, dict):
            raise err("a joint must be a table [joints.NAME] with bodies, kind, at", "joints", jname)
        unknown_keys(j, JOINT_KEYS, table, err)
        kind, a, b_ = joint_members(j, str(jname), table, err, body_index)
        if "at" not in j:
            raise err(f"joint '{jname}' needs 'at': the point where it is (a vector sum)", table)
        at = vector_sum(j["at"], table, "at")
        axis = None
        if kind == "prismatic":
            if "axis" not in j:
                raise err(f"prismatic joint '{jname}' needs 'axis': the sliding direction, an angle "
                          "expression such as \"90\" or \"phi3\"", table)
            axis = angle_expr(j["axis"], table, "axis")
        elif "axis" in j:
            raise err("'axis' is only for prismatic joints", table, "axis")
        joints.append(Joint(str(jname), kind, a, b_, at, axis))

    used = {j.a for j in joints} | {j.b for j in joints}
    for i, b in enumerate(bodies):
        if i not in used:
            raise err(f"body '{b.name}' has no joints: connect it with a [joints.NAME] table", "bodies." + b.name)

    # ------------------------------------------------------------------ loads
    forces, torques, springs = [], [], []
    if not isinstance(loads_raw, dict):
        raise err("[loads] must hold tables [loads.NAME]", "loads")
    for lname, ld in loads_raw.items():
        table = f"loads.{lname}"
        if not isinstance(ld, dict):
            raise err("a load must be a table [loads.NAME] with a kind", "loads", lname)
        kind = ld.get("kind")  # type: ignore[assignment]
        if kind not in LOAD_KEYS:
            raise err(f"load kind {kind!r}{_expr.suggest(str(kind), LOAD_KEYS)}: use one of {', '.join(LOAD_KEYS)}",
                      table, "kind" if "kind" in ld else None)
        unknown_keys(ld, LOAD_KEYS[kind], table, err)
        if kind == "force":
            for k in ("body", "at", "force"):
                if k not in ld:
                    raise err(f"a force needs '{k}'", table)
            f = ld["force"]
            if (not isinstance(f, list) or len(f) != 2
                    or not all(_finite(x) for x in f)):
                raise err("'force' must be [Fx, Fy] in N (two finite numbers)", table, "force")
            forces.append(Force(str(lname), body_index(ld["body"], table, "body"),
                                vector_sum(ld["at"], table, "at"), (float(f[0]), float(f[1]))))
        elif kind == "torque":
            if "body" not in ld:
                raise err("a torque needs 'body'", table)
            bi = body_index(ld["body"], table, "body")
            if bi >= 0 and bodies[bi].angle is None:
                raise err(f"body '{ld['body']}' needs an 'angle' to take a torque load (its power needs the "
                          "angular velocity)", table, "body")
            torques.append(Torque(str(lname), bi, number(ld, "torque", table)))
        else:
            for k in ("bodies", "from", "to", "stiffness", "length"):
                if k not in ld:
                    raise err(f"a spring needs '{k}'", table)
            pair = ld["bodies"]
            if not isinstance(pair, list) or len(pair) != 2:
                raise err("'bodies' must name the two bodies the spring joins", table, "bodies")
            a, b_ = (body_index(x, table, "bodies") for x in pair)
            length = number(ld, "length", table, nonneg=True) * length_unit
            springs.append(Spring(str(lname), a, b_, vector_sum(ld["from"], table, "from"),
                                  vector_sum(ld["to"], table, "to"), number(ld, "stiffness", table, nonneg=True),
                                  length, number(ld, "preload", table, default=0.0)))

    # ------------------------------------------------------------------ input and statics count
    length_input = kinds[input_name] == "length"
    if kinds[input_name] not in ("angle", "length"):
        raise err("bodies need an angle input (a crank driven by a torque) or a length input (a cylinder or a "
                  "slider driven by a force)", "input", "name")
    what = "the driving force" if length_input else "the driving torque"
    if not input_body:
        raise err(f"a file with bodies needs [input] body = \"NAME\": the body {what} acts on", "input")
    if input_body not in index:
        raise err(f"[input] body '{input_body}' is not a declared body{_expr.suggest(str(input_body), index)}; "
                  "bodies: " + ", ".join(index), "input", "body")
    inp = data.get("input", {})
    drive_at = drive_axis = None
    drive_base = -1
    if length_input:
        for k in ("at", "axis"):
            if k not in inp:
                raise err(f"the length input '{input_name}' is driven by a force on body '{input_body}': [input] needs "
                          "'at' (where it acts, a vector sum) and 'axis' (its direction, an angle expression: the "
                          "direction in which the input grows, e.g. a cylinder's angle)", "input")
        drive_at = vector_sum(inp["at"], "input", "at")
        drive_axis = angle_expr(inp["axis"], "input", "axis")
        if "base" in inp:
            if not isinstance(inp["base"], str):
                raise err("'base' must name the body that takes the drive's reaction (default \"ground\")",
                          "input", "base")
            drive_base = body_index(inp["base"], "input", "base")
            if drive_base == index[input_body]:
                raise err(f"[input] base '{inp['base']}' is the driven body itself: the drive acts between two "
                          "bodies", "input", "base")
    else:
        for k in ("at", "axis", "base"):
            if k in inp:
                raise err(f"[input] '{k}' is for a length input (a drive force); an angle input's drive is a torque "
                          f"on body '{input_body}'", "input", k)
    # each joint of class t has t unknowns; with the drive torque they must match 3 balances per body
    removed = sum(JOINT_CLASS[j.kind] for j in joints)
    n_eq, n_unk = 3 * len(bodies), removed + 1
    if n_eq != n_unk:
        what = ("statically indeterminate (redundant joints): the reactions are not unique"
                if n_eq < n_unk else "under-constrained: the joints do not hold every body")
        raise MechanismError(
            f"{len(bodies)} moving bodies give {n_eq} equilibrium equations but {len(joints)} joints and the drive "
            f"{'force' if length_input else 'torque'} "
            f"give {n_unk} unknowns (Grübler mobility 3·{len(bodies)} − {removed} = {n_eq - removed}, "
            f"kinetostatics needs 1): {what}", file=file, key="joints")

    return Model(tuple(bodies), tuple(joints), tuple(forces), tuple(torques), tuple(springs),
                 (float(g[0]), float(g[1])), index[input_body], drive_at, drive_axis, drive_base)


def joint_members(j: Mapping, jname: str, table: str, err, body_index) -> tuple[str, int, int]:
    """The kind and the two members (`body_index` of each name) of one `[joints.NAME]` table: the
    single definition of what a joint may be (`JOINT_CLASS` in `jaxlink/model/bodies.py`)."""
    pair = j.get("bodies")
    if not isinstance(pair, list) or len(pair) != 2 or not all(isinstance(x, str) for x in pair):
        raise err("'bodies' must name exactly two bodies, e.g. [\"ground\", \"crank\"] (a pin shared by more "
                  "bodies is several joints)", table, "bodies")
    a, b = (body_index(x, table, "bodies") for x in pair)
    if a == b:
        raise err(f"joint '{jname}' connects '{pair[0]}' to itself", table, "bodies")
    kind = j.get("kind", "revolute")
    if kind not in JOINT_CLASS:
        raise err(f"joint kind {kind!r}{_expr.suggest(str(kind), JOINT_CLASS)}; use one of "
                  + ", ".join(f'"{k}"' for k in JOINT_CLASS), table, "kind")
    return kind, a, b


def unknown_keys(d: Mapping, allowed, table: str, err) -> None:
    """Refuse a key of `[table]` not in `allowed` (`jaxlink/files/keys.py`), on its line."""
    check_keys(d, allowed, table, lambda m, k: err(m, table, k))


#: largest magnitude of a number of [bodies], [joints], [loads], [environment] (SI)
NUMBER_LIMIT = 1e15


def _finite(x) -> bool:
    """A number (not a bool), finite and within ±`NUMBER_LIMIT` (a 400-digit integer is not)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool) and abs(x) <= NUMBER_LIMIT
