"""The `[optimize]` section of a mechanism file, parsed and validated.

```toml
[optimize]
point = "Z"                                   # the point the objective is about
variables = { l2 = [0, 4], l22 = [0, 4], gamma = [-30, 30] }   # bounds, file units
samples = 36                                  # input positions per design (a full revolution)
objective = "ellipse"                         # a name of the objective registry
start = 75                                    # first input value (file units; default [input] start)
stop = 650                                    # a length input only: the last input value (file units);
                                              # the samples span start … stop (an angle input: a revolution)
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
from ..files.keys import check_keys, suggest
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
#: the string keys of the searches and their values (a search given none of these keys in Python
#: refuses the value again: `jaxlink/optimize/searches/__init__.py`)
CHOICES = {"uniform": ("grid", "coordinate"), "gradient_solver": ("lbfgs", "al-lbfgs")}
#: the objectives that take an open path (a length input's stroke from `start` to `stop`)
OPEN_PATH_OBJECTIVES = ("points",)
#: share of the available memory one batch of the evaluator may take (the rest: JAX, the searches)
MEMORY_SHARE = 0.5

KNOWN_KEYS = {
    # problem
    "point", "variables", "samples", "objective", "start", "stop", "circuits", "start_method",
    "report_samples", "placement",
    # searches
    "starts", "presample", "iterations", "uniform", "chunk", "budget", "seed", "time",
    "gradient_solver", "memory", "al_rho", "al_every",
}
#: the keys of `placement = { x = NAME, y = NAME, angle = NAME }`
PLACEMENT_KEYS = {"x", "y", "angle"}


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
    - `phis`: (samples,) input values (SI): an angle input's full revolution from `start`, a length
      input's `samples` equally spaced values from `start` to `stop`, both included (`inputs`).
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

    @property
    def periodic(self) -> bool:
        """Whether the inputs are a revolution (an angle input: the path is closed) rather than a
        length input's stroke from `start` to `stop` (an open path)."""
        return self.mech.input_kind == "angle"

    def inputs(self, samples: int) -> np.ndarray:
        """`samples` input values (SI) over the problem's range: a revolution from the first input
        (k·2π/samples), or for a length input from the first to the last input, both included."""
        if self.periodic:
            return self.phis[0] + 2.0 * np.pi * np.arange(samples) / samples
        return np.linspace(self.phis[0], self.phis[-1], samples)

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

    Raises `MechanismError` (file, line, key, reason) for anything wrong.
    """
    try:
        return _problem_from(mech, overrides)
    except MechanismError as e:
        raise located(e) from None


def check_table(mech: Mechanism) -> None:
    """Validate the file's `[optimize]` table as `jaxlink optimize` does — its keys, their domains,
    the point, the variables and their bounds, the objective's own keys (its factory reads them)
    and whether the start method and circuits suit the mechanism — compiling nothing. Every
    command that loads a file calls it (`jaxlink/cli/mechanism.py`, `load_from_args`), so a file
    that `optimize` would refuse is refused by `check` and `kinematics` too, with the same message.
    Nothing to check when the file has no `[optimize]` table (or an empty one)."""
    table = mech.tables.get("optimize")
    if table is None or (isinstance(table, dict) and not table):
        return
    try:
        # a table without `variables` sets up no search (needle-arachne's: the roles of the dwell
        # metrics): what it has is checked, what a search needs is not asked for
        problem = _problem_from(mech, None, search=not isinstance(table, dict) or "variables" in table)
        if problem.objective:
            from .objectives import OBJECTIVES

            OBJECTIVES.build(problem)
        start_method(problem)
    except MechanismError as e:
        raise located(e) from None


def start_method(problem: Problem) -> tuple[tuple | None, str]:
    """`(dyads, method)`: the mechanism's dyads (`jaxlink.solvers.dyads.classify`, None when some
    block has no closed form) and the start method `start_method` resolves to ("auto":
    "closed_form" on dyads, else "continuation"). Refuses "closed_form" and `circuits = "all"` on a
    mechanism that is not made of dyads."""
    from ..solvers import dyads as _dyads

    dyads = _dyads.classify(problem.mech)
    method = problem.start_method
    if method == "auto":
        method = "closed_form" if dyads is not None else "continuation"
    if method == "closed_form" and dyads is None:
        raise problem.error("start_method = \"closed_form\" needs a mechanism made of dyads (RRR/RRP/PP "
                            "blocks); use \"continuation\"", "start_method")
    if problem.circuits == "all" and dyads is None:
        raise problem.error("circuits = \"all\" needs a mechanism made of dyads; use \"file\"", "circuits")
    return dyads, method


def located(e: MechanismError) -> MechanismError:
    """`e` with the line of its `[optimize]` key in its file (read again: the `Problem` keeps the
    values, not the text); `e` itself when it has a line, names no file that can be read, or no
    `optimize` key."""
    if e.line is not None or not e.file or not (e.key or "").startswith("optimize"):
        return e
    from ..files.locator import Locator
    from ..files.source import read_source

    try:
        _, text = read_source(e.file)
    except (MechanismError, OSError):
        return e
    table, _, rest = (e.key or "").partition(".")
    key, _, item = rest.partition(".")
    loc = Locator(text)
    line = (loc.line(table, key, item) if key and item else None) or (loc.line(table, key) if key else None)
    line = line or loc.line(table)
    return MechanismError(e.reason, file=e.file, line=line, key=e.key) if line else e


def _problem_from(mech: Mechanism, overrides: Mapping[str, Any] | None, *, search: bool = True) -> Problem:
    """`problem_from`; `search=False` (`check_table` of a table without `variables`): every key
    present checked, none required — no variables, the point and the angle input only if given,
    the objective only if named or, when not, the one objective that reads the table's own keys
    (else `objective` is "" and no objective is built)."""
    raw = mech.tables.get("optimize")

    def err(msg, key=None):
        return MechanismError(msg, file=mech.file, key="optimize" + (f".{key}" if key else ""))

    if raw is not None and not isinstance(raw, dict):
        raise err(f"[optimize] must be a table of keys, got {raw!r}")
    table = dict(raw or {})
    table.update(overrides or {})

    if not table:
        raise err("the file has no [optimize] section; add one (point, variables, samples, objective)")
    from .objectives import OBJECTIVES

    check_keys(table, KNOWN_KEYS | OBJECTIVES.known_keys(), "optimize", err)
    if isinstance(table.get("placement"), dict):
        check_keys(table["placement"], PLACEMENT_KEYS, "optimize.placement", lambda m, k: err(m, f"placement.{k}"))

    _check_domains(table, err)
    for key, choices in CHOICES.items():
        if key in table and table[key] not in choices:
            raise err(f"'{key}' must be one of {', '.join(map(repr, choices))}, got {table[key]!r}", key)

    # point
    if search and not mech.point_names:
        raise err("the mechanism has no [points]; the objective needs one", "point")
    point = table.get("point", mech.point_names[0] if mech.point_names else None)
    if (search or point is not None) and (not isinstance(point, str) or point not in mech.point_names):
        raise err(f"unknown point '{point}'; points: {', '.join(mech.point_names) or '(none)'}", "point")

    # variables
    variables = table.get("variables", None if search else {})
    if not isinstance(variables, dict) or (search and not variables):
        raise err("'variables' must be a table NAME = [lower, upper] (file units) with at least one entry",
                  "variables")
    names, index, lo, hi, fac = [], [], [], [], []
    for name, bounds in variables.items():
        if name not in mech.parameter_names:
            raise err(f"'{name}' is not a parameter{suggest(name, mech.parameter_names)}; "
                      f"parameters: {', '.join(mech.parameter_names)}",
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
    stop = table.get("stop")
    if mech.input_kind == "angle":
        if stop is not None:
            raise err("'stop' is for a length input (the last value of its stroke); an angle input's samples are "
                      "a full revolution from 'start'", "stop")
        phis = phi0 + 2.0 * np.pi * np.arange(samples) / samples
    else:
        if stop is None and search:
            raise err(f"the input '{mech.input_name}' is a length (a driven slider or cylinder): give 'stop', the "
                      f"last value of the stroke the path is sampled over (file units; from 'start', default "
                      "[input] start)", "stop")
        if stop is not None and _finite(stop) is None:
            raise err(f"'stop' must be a number (file units of the input), got {stop!r}", "stop")
        phi1 = phi0 if stop is None else mech.to_si(mech.input_name, stop)
        if abs(phi1) > 1e4:
            raise err(f"'stop' = {stop:g} is out of range: the input is within ±1e4 m", "stop")
        if search and phi1 == phi0:
            raise err(f"'stop' = {stop:g} is the start: the stroke must have a length", "stop")
        phis = np.linspace(phi0, phi1, samples)

    circuits = table.get("circuits", "auto")
    if circuits not in ("file", "all", "auto"):
        raise err(f"'circuits' must be \"file\", \"all\" or \"auto\", got {circuits!r}", "circuits")
    start_method = table.get("start_method", "auto")
    if start_method not in ("auto", "closed_form", "continuation"):
        raise err(f"'start_method' must be \"auto\", \"closed_form\" or \"continuation\", got {start_method!r}",
                  "start_method")

    objective = table.get("objective", "points" if search else _objective_reading(table))
    if (search or objective) and (not isinstance(objective, str) or objective not in OBJECTIVES):
        raise err(f"unknown objective '{objective}'; known: {', '.join(OBJECTIVES)}", "objective")
    if objective and objective not in OPEN_PATH_OBJECTIVES and mech.input_kind != "angle":
        raise err(f"objective '{objective}' is about a closed path over a revolution; a length input's path is open "
                  f"(from 'start' to 'stop'): use {', '.join(map(repr, OPEN_PATH_OBJECTIVES))}", "objective")

    return Problem(
        mech=mech, names=tuple(names), index=tuple(index), lower=np.asarray(lo), upper=np.asarray(hi),
        factor=np.asarray(fac), point=mech.point_names.index(point) if point is not None else -1, phis=phis,
        circuits=circuits,        start_method=start_method, objective=objective, options=table,
    )


def _objective_reading(table: Mapping[str, Any]) -> str:
    """The one objective whose keys include every objective key of `table` ("" if none or several)."""
    from .objectives import OBJECTIVES

    own = {k for k in table if k not in KNOWN_KEYS}
    fits = [name for name in OBJECTIVES if own and own <= set(OBJECTIVES.keys_of(name))]
    return fits[0] if len(fits) == 1 else ""


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
