"""`--set NAME=VALUE` overrides, shared by the linkage files (`jaxlink/files/reader.py`) and the
cam-follower scenes (`jaxlink/cam/scene.py`).

VALUE is read as a TOML value (`2`, `1e-3`, `[0.1, 0.12]`, `"polygon"`); what TOML does not
accept is read as a Python float (`.5`, `5.`), else kept as a bare word (a string).
"""

from __future__ import annotations

import math

from ..errors import MechanismError

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib  # type: ignore[no-redef]


def parse_value(raw: str):
    """A `--set` VALUE: TOML, else a float, else the bare word."""
    raw = raw.strip()
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except (tomllib.TOMLDecodeError, ValueError, RecursionError):
        pass
    try:
        return float(raw)
    except ValueError:
        return raw


def parse_set(items) -> list[tuple[str, object]]:
    """`["C=1e5", "cam.arc=polygon"]` -> `[("C", 100000.0), ("cam.arc", "polygon")]` (in order)."""
    out = []
    for item in items or []:
        if "=" not in item:
            raise MechanismError(f"--set {item!r}: expected NAME=VALUE, e.g. --set l2=2.0")
        name, raw = item.split("=", 1)
        name = name.strip()
        if not name:
            raise MechanismError(f"--set {item!r}: the NAME before '=' is empty")
        out.append((name, parse_value(raw)))
    return out


def parse_numbers(items) -> dict[str, float]:
    """`--set` items whose values must be finite numbers (parameters of a linkage file, in its units)."""
    out = {}
    for (name, value), item in zip(parse_set(items), items or []):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise MechanismError(f"--set {_short(item)}: '{_short(item.split('=', 1)[1].strip())[1:-1]}' "
                                 "is not a number")
        if isinstance(value, int) and abs(value) > 1e15 or not math.isfinite(value):
            raise MechanismError(f"--set {_short(item)}: the value must be finite, within ±1e15")
        out[name] = float(value)
    return out


def _short(item: str, n: int = 60) -> str:
    return repr(item) if len(item) <= n else repr(item[:n]) + f"… ({len(item)} characters)"


# ----------------------------------------------------------------------------- study overrides

#: what `--tol NAME=KIND:VALUE` may set in a `[study.tolerances]` entry (a bare VALUE: `tol`, or a
#: zone's `radius`)
TOL_KINDS = ("tol", "sigma", "radius", "box")


def study_table(raw, *, tol=(), dist=(), limits=()) -> tuple[dict | None, dict[str, str]]:
    """The `[study]` table `raw` (None: the file has none) with the `jaxlink study` options applied,
    and which option set which key (`study.tolerances.l2` -> `--tol l2=0.05`), to blame an error
    on the option (`blamed`). The same meaning as the keys (docs/reference/file-format.md §17):

    - `--tol NAME=T` sets NAME's ±t (file units; a zone's `radius` where the file gives one);
      `NAME=sigma:S`, `NAME=radius:R`, `NAME=box:WX,WY` the other kinds. An entry's other keys
      (its distribution, k) are kept; NAME without an entry gets one.
    - `--dist D` sets `[study] distribution` (the tolerances without their own); `--dist NAME=D`
      sets NAME's own.
    - `--limits OUTPUT=LOW,HIGH` sets `limits.OUTPUT` (`-inf`, `inf` for a one-sided limit).

    Returns `(raw, {})` unchanged when no option is given."""
    if not (tol or dist or limits):
        return raw, {}
    table = dict(raw) if isinstance(raw, dict) else ({} if raw is None else raw)
    if not isinstance(table, dict):
        return raw, {}
    blame: dict[str, str] = {}
    entries = dict(table.get("tolerances") or {}) if isinstance(table.get("tolerances") or {}, dict) else {}
    for item in tol or ():
        name, value = _pair("--tol", item, "NAME=T (file units), e.g. --tol l2=0.05, or NAME=sigma:0.01")
        kind, _, text = value.rpartition(":") if ":" in value else ("", "", value)
        kind = kind.strip()
        old = entries.get(name)
        entry = dict(old) if isinstance(old, dict) else {}
        if not kind:
            kind = "radius" if "radius" in entry else "tol"
        if kind not in TOL_KINDS:
            raise MechanismError(f"--tol {item}: unknown kind '{kind}'{_suggest(kind, TOL_KINDS)}; "
                                 f"NAME=T, or NAME=KIND:VALUE with KIND one of {', '.join(TOL_KINDS)}")
        number = parse_value(f"[{text}]" if kind == "box" else text)
        for k in TOL_KINDS:
            entry.pop(k, None)
        entry[kind] = number
        entries[name] = entry
        blame[f"study.tolerances.{name}"] = f"--tol {item}"
    if tol:
        table["tolerances"] = entries
    from ..study.distributions import DISTRIBUTIONS

    for item in dist or ():
        value = item.split("=", 1)[-1].strip()
        if value not in DISTRIBUTIONS:
            raise MechanismError(f"--dist {item}: unknown distribution '{value}'{_suggest(value, DISTRIBUTIONS)}; "
                                 f"distributions: {', '.join(DISTRIBUTIONS)}")
        if "=" in item:
            name, value = _pair("--dist", item, "D (every tolerance without its own) or NAME=D")
            if name not in entries:
                raise MechanismError(f"--dist {item}: '{name}' has no tolerance{_suggest(name, entries)}; "
                                     f"tolerances: {', '.join(entries) or '(none)'} (give one with --tol {name}=T)")
            old = entries[name]
            entries[name] = {**(old if isinstance(old, dict) else {"tol": old}), "distribution": value}
            table["tolerances"] = entries
            blame[f"study.tolerances.{name}"] = f"--dist {item}"
        else:
            table["distribution"] = item.strip()
            blame["study.distribution"] = f"--dist {item}"
    bounds = dict(table.get("limits") or {}) if isinstance(table.get("limits") or {}, dict) else {}
    for item in limits or ():
        if "=" not in item:
            raise MechanismError(f"--limits {item!r}: expected OUTPUT=LOW,HIGH, e.g. --limits 'stroke(s_B)=4.9,5.1'")
        name, _, text = item.rpartition("=")
        name = name.strip()
        parts = [p.strip() for p in text.split(",")]
        if not name or len(parts) != 2:
            raise MechanismError(f"--limits {item}: expected OUTPUT=LOW,HIGH (file units; -inf or inf for a one-sided "
                                 "limit)")
        bounds[name] = [p if p in ("inf", "+inf", "-inf") else parse_value(p) for p in parts]
        blame[f"study.limits.{name}"] = f"--limits {item}"
    if limits:
        table["limits"] = bounds
    return table, blame


def blamed(error: MechanismError, blame: dict[str, str]) -> MechanismError:
    """`error` on the option that set its key (`study_table`'s `blame`), or itself when the key is the
    file's."""
    key = error.key or ""
    for k in sorted(blame, key=len, reverse=True):
        if key == k or key.startswith(k + "."):
            return MechanismError(f"{blame[k]}: {error.reason}")
    return error


def _pair(option: str, item: str, form: str) -> tuple[str, str]:
    if "=" not in item:
        raise MechanismError(f"{option} {item!r}: expected {form}")
    name, value = item.split("=", 1)
    if not name.strip() or not value.strip():
        raise MechanismError(f"{option} {item!r}: expected {form}")
    return name.strip(), value.strip()


def _suggest(word: str, names) -> str:
    from .keys import suggest

    return suggest(word, names)
