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
from typing import Any, Mapping

import numpy as np

from ..errors import MechanismError
from ..model.mechanism import Mechanism

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

    # point
    if not mech.point_names:
        raise err("the mechanism has no [points]; the objective needs one", "point")
    point = table.get("point", mech.point_names[0])
    if point not in mech.point_names:
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
                or not all(isinstance(b, (int, float)) and not isinstance(b, bool) for b in bounds)):
            raise err(f"bounds of '{name}' must be [lower, upper] numbers, got {bounds!r}", f"variables.{name}")
        a, b = float(bounds[0]), float(bounds[1])
        if not (math.isfinite(a) and math.isfinite(b)) or not a < b:
            raise err(f"bounds of '{name}' must be finite with lower < upper, got [{a}, {b}]", f"variables.{name}")
        kind = mech.kinds[name]
        names.append(name)
        index.append(mech.parameter_index(name))
        lo.append(a)
        hi.append(b)
        fac.append(mech.kind_factor(kind))

    # samples and the input positions
    samples = table.get("samples", 72)
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 3:
        raise err(f"'samples' must be an integer ≥ 3, got {samples!r}", "samples")
    start = table.get("start")
    if start is None:
        phi0 = mech.input_start
    else:
        if isinstance(start, bool) or not isinstance(start, (int, float)) or not math.isfinite(start):
            raise err(f"'start' must be a number (file units of the input), got {start!r}", "start")
        phi0 = mech.to_si(mech.input_name, start)
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
    if objective not in OBJECTIVES:
        raise err(f"unknown objective '{objective}'; known: {', '.join(OBJECTIVES)}", "objective")

    return Problem(
        mech=mech, names=tuple(names), index=tuple(index), lower=np.asarray(lo), upper=np.asarray(hi),
        factor=np.asarray(fac), point=mech.point_names.index(point), phis=phis, circuits=circuits,
        start_method=start_method, objective=objective, options=table,
    )
