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
