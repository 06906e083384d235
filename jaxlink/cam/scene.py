"""Loading a cam-follower scene file (`kind = "cam-follower"`), e.g. the built-in
`sinker-cam`. The format is documented in `docs/reference/file-format.md` (section 14) and in the scene's comments.

Tables: `[mechanism]` (name, kind, description), `[dynamics]` (m, C, log_decrement or
k_over_m, f, R1-R3, F_P, g, damping, normal_force), `[machine]` (n, D), `[cam]` (L, rise_deg,
split, arc, chord, and `[[cam.geometry]]` entries with name, R, descent_deg), `[simulate]`
(geometry, method, rtol, atol, points) and `[jamming]` (tol). Units: SI, angles in degrees,
`n` in rev/min. Unknown keys are errors (they are usually typos).

`--set NAME=VALUE` overrides use `table.key` or a bare key that is unique across tables;
VALUE is read as for the linkage files (`jaxlink/files/overrides.py`): TOML (`0.1`,
`[0.1, 0.12]`, `"polygon"`), a bare word as a string. Error lines come from the `Locator`
(`jaxlink/files/locator.py`) of the text that was parsed.
"""

from __future__ import annotations

import dataclasses
import math
import pathlib

from ..errors import MechanismError
from ..files.expr import suggest
from ..files.keys import check_keys
from ..files.locator import Locator
from ..files.overrides import parse_set
from ..files.source import parse_toml
from .sinker import SinkerParams, make_params
from .track import CamGeometry, butt_speed

KIND = "cam-follower"

_SCHEMA: dict[str, dict[str, type]] = {
    "mechanism": {"name": str, "kind": str, "description": str},
    "dynamics": {"m": float, "C": float, "log_decrement": float, "k_over_m": float,
                 "f": list, "R1": float, "R2": float, "R3": float, "F_P": float, "g": float,
                 "damping": str, "normal_force": str},
    "machine": {"n": float, "D": float},
    "cam": {"L": float, "rise_deg": float, "split": list, "arc": str, "chord": float,
            "geometry": list},
    "simulate": {"geometry": list, "method": str, "rtol": float, "atol": float,
                 "points": int},
    "jamming": {"tol": float},
}
_GEOMETRY_KEYS = {"name": str, "R": float, "descent_deg": float}
_DEFAULTS = {
    "dynamics": {"m": 1.5e-3, "C": 3.5e4, "log_decrement": math.log(2.0), "f": [0.1],
                 "R1": 3.2014, "R2": 3.1216, "R3": 6.323, "F_P": 0.0, "g": 9.81,
                 "damping": "always", "normal_force": "C*lag/cos"},
    "machine": {"n": 350.0, "D": 0.096},
    "cam": {"L": 19.88e-3, "rise_deg": 30.0, "split": [5.9, 5.4], "arc": "exact",
            "chord": 1e-4},
    "simulate": {"method": "auto", "rtol": 1e-6, "atol": 1e-10, "points": 2001},
    "jamming": {"tol": 1e-4},
}
METHODS = ("auto", "explicit", "implicit")


@dataclasses.dataclass
class SinkerScene:
    """A loaded cam-follower scene (plain Python; see `params` for the pytree)."""

    path: str
    name: str
    description: str
    params: SinkerParams  # scalar leaves; `f` = the first friction coefficient
    f_values: list[float]
    geometries: list[CamGeometry]
    speed: float  # butt speed v (m/s)
    sim_geometries: list[str]
    method: str
    rtol: float
    atol: float
    points: int
    jam_tol: float
    k_over_m_fixed: bool  # k/m given directly (True) or from the log decrement

    def geometry(self, name: str) -> CamGeometry:
        for g in self.geometries:
            if g.name == name:
                return g
        raise MechanismError(f"no geometry named {name!r}; the file has "
                             + ", ".join(g.name for g in self.geometries),
                             file=self.path, key="simulate.geometry")


def _apply_set(data: dict, overrides, path: str) -> set[tuple[str, str]]:
    done = set()
    for name, value in overrides:
        if "." in name:
            table, key = name.split(".", 1)
        else:
            tables = [t for t, keys in _SCHEMA.items() if name in keys and t != "mechanism"]
            if len(tables) != 1:
                bare = {k for t, keys in _SCHEMA.items() for k in keys if t != "mechanism"}
                raise MechanismError(
                    f"--set {name}: unknown parameter{suggest(name, bare)}" if not tables else
                    f"--set {name}: ambiguous, write one of "
                    + ", ".join(f"{t}.{name}" for t in tables), file=path, key=name)
            table, key = tables[0], name
        if table not in _SCHEMA or key not in _SCHEMA[table] or key == "geometry" and \
                table == "cam":
            known = [f"{t}.{k}" for t, keys in _SCHEMA.items() for k in keys if t != "mechanism"]
            raise MechanismError(f"--set {name}: unknown parameter{suggest(name, known)}", file=path,
                                 key=name)
        data.setdefault(table, {})[key] = value
        done.add((table, key))
    return done


def load_scene(path_or_name: str, overrides: list[str] | None = None) -> SinkerScene:
    """Load and validate a cam-follower scene (a path or a built-in scene name).

    **Arguments:**

    - `path_or_name`: a TOML file or a built-in scene name (`sinker-cam`).
    - `overrides`: `--set` items, `"NAME=VALUE"`.

    Raises `MechanismError` naming the file, line and key of anything wrong.
    """
    from ..files.source import read_source

    p, text = read_source(path_or_name)
    return loads_scene(text, file=str(p), overrides=overrides)


def loads_scene(text: str, *, file: str = "<string>", overrides: list[str] | None = None) -> SinkerScene:
    """Like `load_scene`, from the TOML text; `file` names it in error messages, whose lines are
    those of `text`."""
    path = file
    loc = Locator(text)
    data = parse_toml(text, path)

    overridden = set()

    def err(msg, table, key, sub=None, *, index=None, subkey=None):
        """`sub` extends the key (`[2].R`); `index`, `subkey`: the entry of an array of tables
        `[[table.key]]` and its key, to find the line."""
        name = f"{table}.{key}" + (sub or "")
        if (table, key) in overridden:
            return MechanismError(msg + " (value from --set)", file=path, key=name)
        if index is None:
            line = loc.line(table, key)
        else:
            line = loc.line(f"{table}.{key}", subkey, index=index)
        return MechanismError(msg, file=path, line=line, key=name)

    mech = data.get("mechanism")
    if not isinstance(mech, dict):
        raise MechanismError("missing [mechanism] table", file=path, key="mechanism")
    if mech.get("kind") != KIND:
        raise err(f"kind must be {KIND!r} for a cam-follower scene, got {mech.get('kind')!r}",
                  "mechanism", "kind")
    overridden.update(_apply_set(data, parse_set(overrides), path))
    for table, content in data.items():  # every number finite and within ±1e15, nested ones too
        for key, value in (content.items() if isinstance(content, dict) else ()):
            stack = [value]
            while stack:
                v = stack.pop()
                if isinstance(v, dict):
                    stack += list(v.values())
                elif isinstance(v, list):
                    stack += v
                elif isinstance(v, (int, float)) and not isinstance(v, bool) and not abs(v) <= 1e15:
                    shown = repr(v) if abs(v) < 10**30 else "an integer of more than 30 digits"
                    raise err(f"must be finite and within ±1e15, got {shown}", table, key)
    for table, content in data.items():
        if table not in _SCHEMA:
            raise MechanismError(f"unknown table [{table}]{suggest(table, _SCHEMA)}; known: "
                                 + ", ".join(_SCHEMA), file=path, line=loc.line(table), key=table)
        if not isinstance(content, dict):
            raise MechanismError(f"[{table}] must be a table", file=path, line=loc.line("", table),
                                 key=table)
        check_keys(content, _SCHEMA[table], table, lambda m, k, _t=table: err(m, _t, k))
        for key, value in content.items():
            want = _SCHEMA[table][key]
            if want is float and isinstance(value, (int, float)) and not isinstance(value, bool) \
                    and not abs(value) <= 1e15:  # nan, inf, a 400-digit integer
                shown = repr(value) if abs(value) < 10**30 else "an integer of more than 30 digits"
                raise err(f"must be a finite number within ±1e15, got {shown}", table, key)
            if want is float and isinstance(value, int) and not isinstance(value, bool):
                content[key] = float(value)
            elif want is list and not isinstance(value, list) and key in ("f", "geometry") \
                    and table != "cam":
                content[key] = [value]
            elif not isinstance(value, want) or isinstance(value, bool):
                raise err(f"expected a {want.__name__}, got {value!r}", table, key)

    def get(table, key):
        return data.get(table, {}).get(key, _DEFAULTS.get(table, {}).get(key))

    def positive(table, key):
        v = get(table, key)
        if not (isinstance(v, float) and math.isfinite(v) and v > 0):
            raise err(f"must be a positive number, got {v!r}", table, key)
        return v

    m, c = positive("dynamics", "m"), positive("dynamics", "C")
    n_rpm, diameter = positive("machine", "n"), positive("machine", "D")
    length, chord = positive("cam", "L"), positive("cam", "chord")
    delta = positive("dynamics", "log_decrement")
    k_over_m = get("dynamics", "k_over_m")
    if k_over_m is not None and not (math.isfinite(k_over_m) and k_over_m >= 0):
        raise err("must be a number >= 0 (1/s)", "dynamics", "k_over_m")
    f_values = get("dynamics", "f")
    if not f_values or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                               and 0 <= x < 1 for x in f_values):
        raise err(f"must be a list of friction coefficients in [0, 1), got {f_values!r}",
                  "dynamics", "f")
    f_values = [float(x) for x in f_values]
    damping = get("dynamics", "damping")
    if damping not in ("always", "contact"):
        raise err(f"must be 'always' or 'contact', got {damping!r}", "dynamics", "damping")
    normal = get("dynamics", "normal_force")
    if normal not in ("C*lag/cos", "C*lag"):
        raise err(f"must be 'C*lag/cos' or 'C*lag', got {normal!r}", "dynamics",
                  "normal_force")
    rs = [get("dynamics", k) for k in ("R1", "R2", "R3")]
    fp, grav = get("dynamics", "F_P"), get("dynamics", "g")
    rise = get("cam", "rise_deg")
    if not 0 < rise < 90:
        raise err(f"must be in (0, 90) degrees, got {rise!r}", "cam", "rise_deg")
    split = get("cam", "split")
    if len(split) != 2 or not all(isinstance(x, (int, float)) and x > 0 for x in split):
        raise err(f"must be two positive numbers, got {split!r}", "cam", "split")
    arc = get("cam", "arc")
    if arc not in ("exact", "polygon"):
        raise err(f"must be 'exact' or 'polygon', got {arc!r}", "cam", "arc")
    raw_geoms = data.get("cam", {}).get("geometry")
    if not raw_geoms:
        raise MechanismError("no [[cam.geometry]] entries", file=path, key="cam.geometry")
    geoms = []
    for i, gd in enumerate(raw_geoms):
        sub = f"[{i}]"
        if not isinstance(gd, dict):
            raise err("each [[cam.geometry]] must be a table", "cam", "geometry", sub, index=i)
        check_keys(gd, _GEOMETRY_KEYS, "cam.geometry", lambda m, k, _i=i, _s=sub: err(
            m, "cam", "geometry", f"{_s}.{k}", index=_i, subkey=k))
        for key, typ in _GEOMETRY_KEYS.items():
            if key not in gd:
                raise err(f"missing key {key!r}", "cam", "geometry", sub, index=i)
            if typ is float and not (isinstance(gd[key], (int, float))
                                     and not isinstance(gd[key], bool)):
                raise err(f"{key} must be a number", "cam", "geometry", f"{sub}.{key}", index=i, subkey=key)
        if not gd["R"] > 0:
            raise err("R must be positive (m)", "cam", "geometry", f"{sub}.R", index=i, subkey="R")
        if not rise < gd["descent_deg"] < 90:
            raise err(f"descent_deg must lie between rise_deg ({rise}) and 90",
                      "cam", "geometry", f"{sub}.descent_deg", index=i, subkey="descent_deg")
        g = CamGeometry(str(gd["name"]), float(gd["R"]), math.radians(rise),
                        math.radians(float(gd["descent_deg"])), length=length,
                        split=(float(split[0]), float(split[1])), arc=arc, chord=chord)
        x_arc = g.radius * (math.sin(g.descent_angle) - math.sin(g.rise_angle))
        if x_arc >= length:
            raise err(f"the transition arc ({x_arc * 1e3:.2f} mm) does not fit in L",
                      "cam", "geometry", f"{sub}.R", index=i, subkey="R")
        geoms.append(g)
    names = [g.name for g in geoms]
    if len(set(names)) != len(names):
        raise err("geometry names must be unique", "cam", "geometry")
    sim_geoms = get("simulate", "geometry") or [names[0]]
    for nm in sim_geoms:
        if nm not in names:
            raise err(f"no geometry named {nm!r}; the file has " + ", ".join(names),
                      "simulate", "geometry")
    method = get("simulate", "method")
    if method not in METHODS:
        raise err(f"must be one of {', '.join(METHODS)}, got {method!r}", "simulate",
                  "method")
    rtol, atol = positive("simulate", "rtol"), positive("simulate", "atol")
    points = get("simulate", "points")
    if not (isinstance(points, int) and points >= 2):
        raise err("must be an integer >= 2", "simulate", "points")
    jam_tol = positive("jamming", "tol")
    params = make_params(m=m, C=c, k_over_m=k_over_m, log_decrement=delta, f=f_values[0],
                         R_sum=sum(rs), F_P=fp, g=grav, damping_always=damping == "always",
                         cos_in_N=normal == "C*lag/cos")
    return SinkerScene(
        path=path, name=str(mech.get("name", pathlib.Path(path).stem)),
        description=str(mech.get("description", "")), params=params, f_values=f_values,
        geometries=geoms, speed=butt_speed(n_rpm, diameter), sim_geometries=list(sim_geoms),
        method=method, rtol=rtol, atol=atol, points=points, jam_tol=jam_tol,
        k_over_m_fixed=k_over_m is not None)
