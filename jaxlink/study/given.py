"""The designs of Dakota's parameter studies (`vector`, `list`, `centered`) read from `[study]`
(file units); jaxlink/study/parameter_studies.py evaluates them (its module doc gives each study)."""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from ..files.keys import suggest


def _value(mech, name: str) -> float:
    """The file's value of parameter `name` (file units)."""
    return float(mech.parameters[mech.parameter_index(name)] / mech.kind_factor(mech.kinds[name]))


def _table(mech, t, key: str, err: Callable, what: str) -> dict:
    raw = t.get(key)
    if not isinstance(raw, dict) or not raw:
        raise err(mech, f"the {what} study needs [study.{key}]: a table NAME = …", key)
    for name in raw:
        if name not in mech.parameter_names:
            derived = [d[0] for d in mech.derived]
            why = " (derived: vary the parameters it is computed from)" if name in derived else ""
            raise err(mech, f"'{name}' is not a parameter{why}{suggest(name, mech.parameter_names)}; "
                            f"parameters: {', '.join(mech.parameter_names)}",
                      f"{key}.{name}")
    return raw


def _finite(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)


def _steps(mech, t, err: Callable, default: int) -> int:
    n = t.get("steps", default)
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 100_000:
        raise err(mech, f"'steps' must be an integer from 1 to 100000, got {n!r}", "steps")
    return int(n)


def read_designs(mech, method: str, t: dict[str, Any], err: Callable) -> tuple[list, np.ndarray]:
    """(names, designs (n, T)) of a `vector`, `list` or `centered` study from the `[study]` keys `t` (see
    the module doc); `err(mech, message, key)` makes the error raised."""
    if method == "vector":
        final = _table(mech, t, "final", err, "vector")
        n = _steps(mech, t, err, 10)
        names = list(final)
        x0 = np.asarray([_value(mech, p) for p in names])
        for p in names:
            if not _finite(final[p]):
                raise err(mech, f"a final value is a finite number (file units), got {final[p]!r}", f"final.{p}")
        x1 = np.asarray([float(final[p]) for p in names])
        rows = x0 + np.arange(n + 1)[:, None] / n * (x1 - x0)
    elif method == "list":
        table = _table(mech, t, "list", err, "list")
        names = list(table)
        cols = []
        for p in names:
            c = table[p]
            if not isinstance(c, (list, tuple)) or not c or not all(_finite(v) for v in c):
                raise err(mech, f"a list is [v1, v2, …] of finite numbers (file units), got {c!r}", f"list.{p}")
            cols.append([float(v) for v in c])
        if len({len(c) for c in cols}) != 1:
            raise err(mech, "the lists must be of equal length (one value per design): "
                            + ", ".join(f"{p} {len(c)}" for p, c in zip(names, cols)), "list")
        rows = np.asarray(cols).T
    elif method == "centered":
        step = _table(mech, t, "step", err, "centered")
        k = _steps(mech, t, err, 1)
        names = list(step)
        for p in names:
            if not _finite(step[p]) or not step[p] > 0:
                raise err(mech, f"a step is a number > 0 (file units), got {step[p]!r}", f"step.{p}")
        x0 = np.asarray([_value(mech, p) for p in names])
        out = [x0]
        offsets = np.concatenate([np.arange(-k, 0), np.arange(1, k + 1)])
        for j, p in enumerate(names):
            for i in offsets:
                x = x0.copy()
                x[j] += i * float(step[p])
                out.append(x)
        rows = np.asarray(out)
    else:
        raise ValueError(f"not a parameter study: {method!r}")
    if len(rows) > 10**7:
        raise err(mech, f"the {method} study has {len(rows)} designs; at most 10^7", "steps")
    return names, rows
