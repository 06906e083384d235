"""The `[optimize]` section of a mechanism file, parsed and validated.

```toml
[optimize]
point = "Z"                                   # the point the objective is about
variables = { l2 = [0, 4], l22 = [0, 4], gamma = [-30, 30] }   # bounds, file units
samples = 36                                  # input positions per design (a full revolution)
objective = "ellipse"                         # a name of the objective registry
start = 75                                    # first input value (file units; default [input] start)
circuits = "auto"                             # "file": keep the file's assembly branch; "all": try
                                              # every circuit of a closed-form (dyad) mechanism;
                                              # "auto" (default): "all" for the path objective
                                              # `points` on a dyad mechanism, else "file"
```

Objective-specific keys (`axes`, `targets`, …) are read by the objective (`objectives/`); search
knobs (`starts`, `iterations`, `uniform`, `chunk`) by the searches (`_search.py`).
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any, Mapping

import numpy as np

from ..errors import MechanismError
from ..model.mechanism import Mechanism

#: domains of the integer keys: (smallest, largest)
INTEGER_DOMAINS = {
    "samples": (3, 100_000), "report_samples": (3, 1_000_000), "starts": (1, 100_000),
    "presample": (1, 10_000_000), "iterations": (1, 10_000_000), "chunk": (1, 1_000_000),
    "budget": (1, 10**12), "seed": (0, 2**32 - 1), "memory": (1, 1000), "al_every": (1, 1_000_000),
    "sign_changes": (0, 1000),
}
#: domains of the number keys (of the searches and of the built-in objectives, file units):
#: (lower, upper, lower bound included)
NUMBER_DOMAINS = {
    "al_rho": (0.0, 1e12, False), "stroke": (0.0, 1e12, False), "stroke_tol": (0.0, 1e12, True),
    "dwell_weight": (0.0, 1e6, True), "abs_tol": (0.0, 1e12, False), "mu_min": (0.0, 90.0, True),
    "rod_max": (0.0, 90.0, True), "toggle_min": (0.0, 180.0, True), "amax_max": (0.0, 1e12, False),
    "penalty": (0.0, 1e12, True), "rpm": (-1e7, 1e7, True), "time": (0.0, 1e7, False),
}
#: share of the available memory one batch of the evaluator may take (the rest: JAX, the searches)
MEMORY_SHARE = 0.5

KNOWN_KEYS = {
    # problem
    "point", "variables", "samples", "objective", "start", "circuits", "start_method",
    "report_samples", "placement",
    # searches
    "starts", "presample", "iterations", "uniform", "chunk", "budget", "seed", "time",
    "gradient_solver", "memory", "al_rho", "al_every",
}


@dataclasses.dataclass(frozen=True, eq=False)
class Problem:
    """A design-search problem: the mechanism, which parameters vary within which bounds, how the
    path is sampled and the objective's options.

    **Fields:**

    - `mech`: the mechanism (its `parameters` are the file's design; they fix everything that
      does not vary and the assembly branch).
    - `names`: the varied parameters; `index`: their positions in `mech.parameter_names`.
    - `lower`, `upper`: bounds in file units, shape (V,); `factor`: file unit → SI per variable.
    - `point`: index of the point in `mech.point_names`.
    - `phis`: (samples,) input values (SI), a full revolution from `start` (angle input).
    - `circuits`: "file" | "all" | "auto" (resolved by the `Evaluator`: "all" for `points` on a
      dyad mechanism, else "file").
    - `options`: the whole `[optimize]` table (objective and search options).
    """

    mech: Mechanism
    names: tuple
    index: tuple
    lower: np.ndarray
    upper: np.ndarray
    factor: np.ndarray
    point: int
    phis: np.ndarray
    circuits: str
    start_method: str
    objective: str
    options: Mapping[str, Any]

    @property
    def n_variables(self) -> int:
        return len(self.names)

    def to_file_units(self, u):
        """Normalized u ∈ [0, 1]^V → variables in file units."""
        return self.lower + np.asarray(u) * (self.upper - self.lower)

    def to_unit(self, x):
        return (np.asarray(x) - self.lower) / (self.upper - self.lower)

    def file_design(self) -> np.ndarray:
        """The file's values of the variables (file units)."""
        return np.array([self.mech.from_si(n, self.mech.parameters[i]) for n, i in zip(self.names, self.index)])

    def option(self, key: str, default=None):
        return self.options.get(key, default)

    def error(self, message: str, key: str | None = None) -> MechanismError:
        return MechanismError(message, file=self.mech.file, key="optimize" + (f".{key}" if key else ""))


def problem_from(mech: Mechanism, overrides: Mapping[str, Any] | None = None) -> Problem:
    """Parse `mech.tables["optimize"]` (with `overrides` of its keys) into a `Problem`.

    Raises `MechanismError` (file, key, reason) for anything wrong.
    """
    table = dict(mech.tables.get("optimize") or {})
    table.update(overrides or {})

    def err(msg, key=None):
        return MechanismError(msg, file=mech.file, key="optimize" + (f".{key}" if key else ""))

    if not table:
        raise err("the file has no [optimize] section; add one (point, variables, samples, objective)")
    from .objectives import OBJECTIVES

    for k in table:
        if k not in KNOWN_KEYS and k not in OBJECTIVES.known_keys():
            raise err(f"unknown key '{k}'; known keys: {', '.join(sorted(KNOWN_KEYS | OBJECTIVES.known_keys()))}", k)

    _check_domains(table, err)

    # point
    if not mech.point_names:
        raise err("the mechanism has no [points]; the objective needs one", "point")
    point = table.get("point", mech.point_names[0])
    if not isinstance(point, str) or point not in mech.point_names:
        raise err(f"unknown point '{point}'; points: {', '.join(mech.point_names)}", "point")

    # variables
    variables = table.get("variables")
    if not isinstance(variables, dict) or not variables:
        raise err("'variables' must be a table NAME = [lower, upper] (file units) with at least one entry",
                  "variables")
    names, index, lo, hi, fac = [], [], [], [], []
    for name, bounds in variables.items():
        if name not in mech.parameter_names:
            raise err(f"'{name}' is not a parameter; parameters: {', '.join(mech.parameter_names)}",
                      f"variables.{name}")
        if (not isinstance(bounds, (list, tuple)) or len(bounds) != 2
                or not all(_finite(b) is not None for b in bounds)):
            raise err(f"bounds of '{name}' must be [lower, upper] numbers, got {bounds!r}", f"variables.{name}")
        a, b = float(bounds[0]), float(bounds[1])
        if not (math.isfinite(a) and math.isfinite(b)) or not a < b:
            raise err(f"bounds of '{name}' must be finite with lower < upper, got [{a}, {b}]", f"variables.{name}")
        kind = mech.kinds[name]
        from ..files.reader import DOMAINS

        limit = DOMAINS[kind or "number"][1] / mech.kind_factor(kind)
        if max(abs(a), abs(b)) > limit:
            raise err(f"bounds of '{name}' must be within ±{limit:g} (file units; the domain of a {kind}), "
                      f"got [{a:g}, {b:g}]", f"variables.{name}")
        names.append(name)
        index.append(mech.parameter_index(name))
        lo.append(a)
        hi.append(b)
        fac.append(mech.kind_factor(kind))

    # samples and the input positions
    samples = table.get("samples", 72)
    start = table.get("start")
    if start is None:
        phi0 = mech.input_start
    else:
        if _finite(start) is None:
            raise err(f"'start' must be a number (file units of the input), got {start!r}", "start")
        phi0 = mech.to_si(mech.input_name, start)
        if abs(phi0) > 1e4:
            raise err(f"'start' = {start:g} is out of range: the input is within ±1e4 rad", "start")
    if mech.input_kind != "angle":
        raise err("design search needs a rotating (angle) input: the path is a full revolution", "samples")
    phis = phi0 + 2.0 * np.pi * np.arange(samples) / samples

    circuits = table.get("circuits", "auto")
    if circuits not in ("file", "all", "auto"):
        raise err(f"'circuits' must be \"file\", \"all\" or \"auto\", got {circuits!r}", "circuits")
    start_method = table.get("start_method", "auto")
    if start_method not in ("auto", "closed_form", "continuation"):
        raise err(f"'start_method' must be \"auto\", \"closed_form\" or \"continuation\", got {start_method!r}",
                  "start_method")

    objective = table.get("objective", "points")
    if not isinstance(objective, str) or objective not in OBJECTIVES:
        raise err(f"unknown objective '{objective}'; known: {', '.join(OBJECTIVES)}", "objective")

    return Problem(
        mech=mech, names=tuple(names), index=tuple(index), lower=np.asarray(lo), upper=np.asarray(hi),
        factor=np.asarray(fac), point=mech.point_names.index(point), phis=phis, circuits=circuits,
        start_method=start_method, objective=objective, options=table,
    )


def _check_domains(table: Mapping[str, Any], err) -> None:
    """Every integer and number key of `INTEGER_DOMAINS` / `NUMBER_DOMAINS` present in `table`
    within its domain; the error names the key, the value and the range."""
    for key, (lo, hi) in INTEGER_DOMAINS.items():
        if key in table:
            v = table[key]
            if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
                shown = repr(v) if not isinstance(v, int) or abs(v) < 10**30 else "a larger integer"
                raise err(f"'{key}' must be an integer from {lo} to {hi}, got {shown}", key)
    for key, (low, high, closed) in NUMBER_DOMAINS.items():
        if key in table:
            x = table[key]
            ok = (not isinstance(x, bool) and isinstance(x, (int, float)) and abs(x) <= 1e300
                  and math.isfinite(float(x)) and (low <= x if closed else low < x) and x <= high)
            if not ok:
                shown = repr(x) if not isinstance(x, int) or abs(x) < 10**30 else "a larger integer"
                raise err(f"'{key}' must be a number {'≥' if closed else '>'} {low:g} and ≤ {high:g}, got {shown}", key)


def available_memory() -> int:
    """Bytes the evaluator may use: the default JAX device's limit on an accelerator, else the
    host's available memory (`MemAvailable` of /proc/meminfo, else the physical memory)."""
    import jax

    dev = jax.devices()[0]
    if dev.platform != "cpu":
        stats = dev.memory_stats() or {}
        if stats.get("bytes_limit"):
            return int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0))
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 8 * 2**30


def batch_bytes(problem: Problem, chunk: int) -> int:
    """Estimated memory of one batch of `chunk` designs: per design and input position, the
    unknowns, their Jacobian, the residual, the points and their derivatives (float64), times 8
    for the intermediates of the solve and of forward-mode differentiation."""
    n = problem.mech.n_unknowns
    per_position = n * n + 6 * n + 6 * len(problem.mech.point_names) + 16
    return int(chunk) * len(problem.phis) * per_position * 8 * 8


def check_size(problem: Problem, chunk: int, chunk_from: str = "chunk") -> None:
    """Refuse a batch (`chunk` designs × `samples` positions) estimated to need more than
    `MEMORY_SHARE` of the available memory, saying what it would need (`batch_bytes`)."""
    need, avail = batch_bytes(problem, chunk), available_memory()
    if need > MEMORY_SHARE * avail:
        fit = max(0, int(MEMORY_SHARE * avail // max(1, need // max(1, chunk))))
        raise problem.error(
            f"samples = {len(problem.phis)} positions × {chunk_from} = {chunk} designs per batch needs about "
            f"{need / 2**30:.3g} GiB, more than {MEMORY_SHARE:.0%} of the {avail / 2**30:.3g} GiB available; "
            f"lower 'samples' or the chunk (at most {fit} designs per batch at these samples)", "samples")


def _finite(v) -> float | None:
    """`v` as a finite float, or None if it is not a number or not finite (a 400-digit integer)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    try:
        x = float(v)
    except OverflowError:
        return None
    return x if math.isfinite(x) else None
