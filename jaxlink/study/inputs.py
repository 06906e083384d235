"""The inputs of a study: which parameters carry a tolerance, with what distribution, and what
the study computes — the `[study]` table of a mechanism file (or the same keys from Python).

```toml
[study]
method = "tolerance"        # or "sample", "grid", "sensitivity" (over [study.ranges])
positions = 360             # input positions over the cycle (a full turn of an angle input)
points = ["P"]              # the points whose x, y are responses (default: every point)
metrics = ["stroke", "deviation"]   # scalar cycle metrics (default these two)
samples = 10000             # Monte Carlo samples (0: first order only)
seed = 0
distribution = "normal"     # default distribution of the tolerances
k = 3                       # default coverage: ±t = k σ for a normal tolerance

[study.tolerances]          # file units
l2 = 0.05                   # ±0.05, the table's distribution (normal, ±t = 3σ)
l3 = { tol = 0.05, distribution = "uniform" }   # uniform on [−t, t]: σ = t / √3
l4 = { sigma = 0.01 }       # normal, σ given (the worst case takes ±k σ)
l5 = { tol = 0.05, distribution = "triangular" }        # symmetric on [−t, t]: σ = t / √6
l6 = { tol = 0.05, distribution = "truncated-normal" }  # normal σ_n = t / k cut at ±t
B0 = { radius = 0.1 }       # a circular zone of the frame pivot B0: the parameters B0_x, B0_y
C0 = { box = [0.1, 0.05] }  # a rectangular zone of C0: half-widths in x and y (C0_x, C0_y)

[study.ranges]              # sample, grid, sensitivity: the design space (file units)
l2 = [40, 60]               # uniform over [40, 60] (sample, sensitivity); `levels` values (grid)
```

`sampler` ("sobol", "lhs", "halton", "random"), `levels` (grid: an integer or NAME = n),
`bootstrap` and `confidence` (the Sobol' intervals) belong to the design-space methods
(docs/methods/sensitivity.md); `robust = true` (with `sample` or `grid`, ranges and tolerances) makes
the robust-design map, `limits = { "stroke(s)" = [4.9, 5.1] }` gives specification limits of scalar
responses for its Cpk (docs/methods/tolerance.md).

**The meaning of ±t** (t in the parameter's file unit):

- `uniform`: the value lies uniformly in [x − t, x + t]; σ = t / √3;
- `normal` with `tol`: ±t = k σ (k from the entry, else the table's, default 3), σ = t / k;
- `normal` with `sigma`: σ given, t = k σ (t enters only the linear worst case);
- `uniform` with `sigma`: t = √3 σ;
- `triangular` (symmetric on [x − t, x + t], mode x): σ = t / √6 (`sigma`: t = √6 σ);
- `truncated-normal`: a normal of σ_n = t / k truncated to [x − t, x + t], its σ the truncated
  one, σ = σ_n c(k) (`sigma` is that σ: t = k σ / c(k); `distributions.py`).

**A circular zone** (`radius = r`): the pivot lies in the disc of radius r around its nominal
position, its coordinates the parameters `NAME_x`, `NAME_y` (a frame joint of a sketch file,
file-format.md §16; in a loop file any pair so named). `uniform`: uniformly in the disc, each
coordinate with σ = r / 2 (uncorrelated); `normal`: each coordinate normal with σ = r / k (r is
k σ per coordinate, not a coverage of the disc). Its linear worst case is r times the length of
the response's gradient in (x, y): the largest change over the disc, not over its bounding square.
A circular zone is `uniform` or `normal`.

**A rectangular zone** (`box = [wx, wy]`, half-widths in x and y, file units): each coordinate
toleranced on its own half-width with the entry's distribution (any of them; `normal`: σ = w / k
per coordinate) — exactly two independent scalar tolerances `NAME_x` ±wx and `NAME_y` ±wy, which
is how it is read (`Tolerance.box` names the zone). Its linear worst case is wx |g_x| + wy |g_y|
(a corner of the rectangle), its true worst case that over the rectangle.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, NamedTuple

from ..errors import MechanismError
from ..files.keys import check_keys, suggest
from . import expressions as _expressions
from .distributions import DISTRIBUTIONS as _DISTRIBUTIONS
from .distributions import sigma_per_half_width

METHODS = ("tolerance", "sample", "grid", "sensitivity", "morris", "regression", "dgsm", "vector", "list", "centered")
#: the methods over the ranges (or the tolerances' distributions) that draw their own designs
DRAWN = ("sample", "sensitivity", "morris", "regression", "dgsm")
#: Dakota's parameter studies: designs given by the file (`parameter_studies.read_designs`)
GIVEN = ("vector", "list", "centered")
SAMPLERS = ("sobol", "lhs", "halton", "random")
DISTRIBUTIONS = _DISTRIBUTIONS
METRICS = ("stroke", "speed", "acceleration", "deviation")
KNOWN_KEYS = {"method", "positions", "points", "metrics", "samples", "seed", "distribution", "k", "chunk",
              "rpm", "tolerances", "ranges", "sampler", "levels", "bootstrap", "confidence", "robust", "limits",
              "correlation", "precision", "max_samples", "final", "steps", "list", "step", "second_order"}
TOLERANCE_KEYS = {"tol", "sigma", "radius", "box", "distribution", "k"}
DEFAULTS: dict = {"method": "tolerance", "positions": 360, "metrics": ("stroke", "deviation"), "samples": 10000,
            "seed": 0, "distribution": "normal", "k": 3.0, "sampler": "sobol", "levels": 11, "bootstrap": 100,
            "confidence": 0.95}
#: the default number of samples of the other methods (`sensitivity`: base samples N, N (D + 2) designs)
DEFAULT_SAMPLES = {"tolerance": 10000, "sample": 1024, "sensitivity": 1024, "grid": 0, "morris": 64,
                   "regression": 1024, "dgsm": 256, "vector": 0, "list": 0, "centered": 0}


class Tolerance(NamedTuple):
    """One toleranced input (file units).

    **Fields:** `name` (the parameter, or the frame joint of a zone), `parameters` (`(name,)`, or
    `(NAME_x, NAME_y)` for a zone), `kind` ("length" | "angle" | "number"), `distribution`
    (one of `DISTRIBUTIONS`), `half_width` (t: the value lies in ±t for a bounded distribution,
    ±t = kσ for a normal one; a zone's radius), `sigma` (σ of each coordinate), `zone` (a circular
    zone), `k` (the coverage: ±t = k σ_n of a normal or truncated normal), `box` (the frame joint
    whose rectangular zone this coordinate is, else "").
    """

    name: str
    parameters: tuple
    kind: str
    distribution: str
    half_width: float
    sigma: float
    zone: bool = False
    k: float = 3.0
    box: str = ""


class Range(NamedTuple):
    """One parameter varied over a range (file units) by `sample`, `grid` and `sensitivity`:
    uniformly over [low, high] (`sample`, `sensitivity`), `levels` equally spaced values from low to
    high (`grid`; one level: the midpoint). `parameters` is `(name,)` (as a `Tolerance`'s), `kind`
    "length" | "angle" | "number"."""

    name: str
    parameters: tuple
    kind: str
    low: float
    high: float
    levels: int


class StudyInputs(NamedTuple):
    """A study's inputs, read from `[study]` (`read_study`): `method`, `tolerances` (tuple of
    `Tolerance`), `positions` (over the cycle), `points` (names), `metrics`, `samples` (Monte Carlo
    designs, 0 = none),
    `seed`, `chunk` (designs per batch, None = default), `rpm` (input speed for the speed and
    acceleration metrics; None: per radian of the input); `ranges` (tuple of `Range`), `sampler`
    (the unit-cube sequence of `sample` and `sensitivity`), `bootstrap` (resamples of the Sobol'
    intervals), `confidence` (their level); `robust` (`sample`, `grid`: the robust-design map, the
    first-order tolerance report of every design, `jaxlink.study.robust`), `limits` (tuple of
    `(output, low, high)`: specification limits of scalar responses, file units, for Cpk);
    `correlation` (the rank correlations between inputs:
    `(name, name, rho)` triples, `correlation.py`), `precision` and `max_samples` (the stopping rule,
    `convergence.py`; None: no rule), `designs` (the rows of a `vector`, `list` or `centered` study,
    file units, `parameter_studies.py`), `morris_levels` (the Morris grid's levels p), `second_order`
    (`sensitivity`: the Sobol' S2 too, N (2D + 2) designs; `tolerance`: the second-order mean shift
    and σ from the exact Hessian, `second_order.py`)."""

    method: str
    tolerances: tuple
    positions: int
    points: tuple
    metrics: tuple
    samples: int
    seed: int
    chunk: int | None
    rpm: float | None
    ranges: tuple = ()
    sampler: str = "sobol"
    bootstrap: int = 100
    confidence: float = 0.95
    robust: bool = False
    limits: tuple = ()
    correlation: tuple = ()
    precision: float | None = None
    max_samples: int = 65536
    designs: tuple = ()
    morris_levels: int = 4
    second_order: bool = False

    @property
    def factors(self) -> tuple:
        """The study's inputs: the `ranges` (methods `sample`, `grid`, `sensitivity` when given),
        else the `tolerances` (a zone is one factor of two parameters)."""
        return self.ranges if (self.method != "tolerance" and self.ranges) else self.tolerances

    @property
    def parameters(self) -> tuple:
        """The studied parameters, in order (the factors' parameters; a zone gives two)."""
        return tuple(n for t in self.factors for n in t.parameters)


def read_study(mech, table: Mapping[str, Any] | None = None, **overrides) -> StudyInputs:
    """The study of `mech`: its `[study]` table (or `table`, the same keys), with keyword
    `overrides` of the keys (`samples=`, `positions=`, `seed=`, `tolerances=`, …). Raises
    `MechanismError` naming the file, line and key for anything wrong."""
    try:
        return _read_study(mech, table, overrides)
    except MechanismError as e:
        raise _located(e) from None


def check_study_keys(mech) -> None:
    """Refuse a key the study does not read in the file's `[study]` and in its tolerances' tables
    (`jaxlink/files/keys.py`), with its line: every command that reads a linkage file checks this
    much of `[study]` (`jaxlink study` reads the rest, where its options can change what it needs)."""
    raw = mech.tables.get("study")
    try:
        if not isinstance(raw, Mapping):
            return
        check_keys(raw, KNOWN_KEYS, "study", lambda m, k: _err(mech, m, k))
        tolerances = raw.get("tolerances")
        for name, entry in (tolerances.items() if isinstance(tolerances, Mapping) else ()):
            if isinstance(entry, Mapping):
                check_keys(entry, TOLERANCE_KEYS, f"study.tolerances.{name}",
                           lambda m, k, _n=name: _err(mech, m, f"tolerances.{_n}.{k}"))
    except MechanismError as e:
        raise _located(e) from None


def _read_study(mech, table, overrides) -> StudyInputs:
    raw = mech.tables.get("study") if table is None else table
    if raw is not None and not isinstance(raw, Mapping):
        raise _err(mech, f"[study] must be a table of keys, got {raw!r}")
    t = dict(raw or {})
    t.update({k: v for k, v in overrides.items() if v is not None})
    check_keys(t, KNOWN_KEYS, "study", lambda m, k: _err(mech, m, k))
    method = t.get("method", DEFAULTS["method"])
    if method not in METHODS:
        raise _err(mech, f"'method' must be one of {', '.join(map(repr, METHODS))}, got {method!r}", "method")
    positions = _integer(mech, t, "positions", 8, 100_000)
    if "samples" not in t:
        t["samples"] = DEFAULT_SAMPLES[method]
    samples = _integer(mech, t, "samples", 0, 10**10)
    sampler = t.get("sampler", DEFAULTS["sampler"])
    if sampler not in SAMPLERS:
        raise _err(mech, f"'sampler' must be one of {', '.join(map(repr, SAMPLERS))}, got {sampler!r}", "sampler")
    bootstrap = _integer(mech, t, "bootstrap", 0, 100_000)
    confidence = _number(mech, t, "confidence") if "confidence" in t else float(DEFAULTS["confidence"])
    if not 0 < confidence < 1:
        raise _err(mech, f"'confidence' must lie between 0 and 1, got {confidence:g}", "confidence")
    seed = _integer(mech, t, "seed", 0, 2**32 - 1)
    chunk = _integer(mech, t, "chunk", 1, 10**7) if "chunk" in t else None
    rpm = _number(mech, t, "rpm") if "rpm" in t else None
    if rpm is not None and rpm <= 0:
        raise _err(mech, f"'rpm' must be > 0, got {rpm:g}", "rpm")
    default_dist = t.get("distribution", DEFAULTS["distribution"])
    if default_dist not in DISTRIBUTIONS:
        raise _err(mech, f"'distribution' must be one of {', '.join(map(repr, DISTRIBUTIONS))}, got {default_dist!r}",
                   "distribution")
    default_k = _number(mech, t, "k") if "k" in t else float(DEFAULTS["k"])
    if not default_k > 0:
        raise _err(mech, f"'k' must be > 0, got {default_k:g}", "k")

    points = t.get("points", list(mech.point_names))
    if isinstance(points, str):
        points = [points]
    if not isinstance(points, (list, tuple)) or not all(isinstance(p, str) for p in points):
        raise _err(mech, f"'points' must be a list of point names, got {points!r}", "points")
    for p in points:
        if p not in mech.point_names:
            raise _err(mech, f"unknown point '{p}'; points: {', '.join(mech.point_names) or '(none)'}", "points")
    metrics = t.get("metrics", DEFAULTS["metrics"])
    if isinstance(metrics, str):
        metrics = [metrics]
    if not isinstance(metrics, (list, tuple)) or any(not isinstance(m, str) for m in metrics):
        raise _err(mech, f"'metrics' must be a list of {', '.join(map(repr, METRICS))} or response expressions "
                         f"({_expressions.SYNTAX}), got {metrics!r}", "metrics")
    metrics = _metrics(mech, metrics)

    morris_levels = 4
    if method == "morris":  # `levels`: the Morris grid's p (one integer), not the grid's
        morris_levels = _integer(mech, {"levels": t.pop("levels", 4)}, "levels", 2, 1000)
        if morris_levels % 2:
            raise _err(mech, f"'levels' of a Morris study must be even (Δ = p / (2 (p − 1))), got {morris_levels}",
                       "levels")
    ranges = _ranges(mech, t.get("ranges"), t.get("levels", DEFAULTS["levels"]))
    designs: tuple = ()
    if method in GIVEN:
        from .given import read_designs

        names, rows = read_designs(mech, method, t, _err)
        ranges = tuple(Range(p, (p,), mech.kinds[p], float(rows[:, j].min()), float(rows[:, j].max()), 1)
                       for j, p in enumerate(names))
        designs = tuple(tuple(float(v) for v in r) for r in rows)
    elif any(k in t for k in ("final", "steps", "list", "step")):
        k = next(k for k in ("final", "steps", "list", "step") if k in t)
        raise _err(mech, f"'{k}' belongs to the vector, list and centered studies, not to {method!r}", k)
    precision = _number(mech, t, "precision") if "precision" in t else None
    if precision is not None and not (0 < precision < 1 and method in ("tolerance", "sensitivity")):
        raise _err(mech, f"'precision' (the stopping rule of tolerance's Monte Carlo and sensitivity) must lie "
                         f"between 0 and 1 with one of those methods, got {precision:g} with {method!r}", "precision")
    max_samples = _integer(mech, t, "max_samples", 2, 10**10) if "max_samples" in t else 65536
    tol_raw = t.get("tolerances")
    robust = t.get("robust", False)
    if not isinstance(robust, bool):
        raise _err(mech, f"'robust' must be true or false, got {robust!r}", "robust")
    if robust and (method not in ("sample", "grid") or not ranges or not tol_raw):
        raise _err(mech, "the robust-design map ('robust = true') is an option of the sample and grid methods and "
                         "needs both [study.ranges] (the designs) and [study.tolerances] (the tolerances at each "
                         "design)",
                   "robust")
    limits = _limits(mech, t.get("limits"))
    if method == "grid" and not ranges:
        raise _err(mech, "the grid method needs [study.ranges]: NAME = [low, high] (file units)", "ranges")
    if method in DRAWN and not ranges and not tol_raw:
        raise _err(mech, f"the {method} method needs [study.ranges] (NAME = [low, high], file units) or "
                         "[study.tolerances]", "ranges")
    second_order = t.get("second_order", False)
    if not isinstance(second_order, bool) or (second_order and method not in ("sensitivity", "tolerance")):
        raise _err(mech, f"'second_order' (tolerance: the second-order mean shift and σ; sensitivity: the Sobol' "
                         f"S2) must be true or false, with method = \"tolerance\" or \"sensitivity\"; got "
                         f"{second_order!r} with {method!r}", "second_order")
    more: dict[str, Any] = dict(precision=precision, max_samples=max_samples, designs=designs,
                                morris_levels=morris_levels, second_order=second_order)
    if method != "tolerance" and not tol_raw:
        out = StudyInputs(method, (), positions, tuple(points), tuple(dict.fromkeys(metrics)), samples, seed,
                          chunk, rpm, ranges, sampler, bootstrap, confidence, robust, limits, **more)
        return _correlated(mech, out, t)
    if not isinstance(tol_raw, Mapping) or not tol_raw:
        raise _err(mech, "[study.tolerances] must give at least one tolerance: NAME = t, or NAME = { tol = t, "
                         "distribution = \"uniform\" }, { sigma = s } or { radius = r } (a pivot's zone)",
                   "tolerances")
    tolerances = []
    seen: set = set()
    for name, entry in tol_raw.items():
        for tol in _tolerance(mech, name, entry, default_dist, default_k):
            for p in tol.parameters:
                if p in seen:
                    raise _err(mech, f"'{p}' carries two tolerances", f"tolerances.{name}")
                seen.add(p)
            tolerances.append(tol)
    out = StudyInputs(method, tuple(tolerances), positions, tuple(points), tuple(dict.fromkeys(metrics)),
                      samples, seed, chunk, rpm, ranges, sampler, bootstrap, confidence, robust, limits, **more)
    return _correlated(mech, out, t)


def _metrics(mech, metrics) -> list:
    """The named metrics and the response expressions (`expressions.parse`: checked, written back
    normalized, `Q @ [a, b]` one entry per angle) of `metrics`."""
    out: list = []
    for m in metrics:
        if m in METRICS:
            out.append(m)
        elif _expressions.is_expression(m):
            try:
                out += [e.text for e in _expressions.parse(mech, m)]
            except ValueError as e:
                raise _err(mech, str(e), "metrics") from None
        else:
            raise _err(mech, f"unknown metric '{m}'{suggest(m, METRICS)}; the metrics: {', '.join(map(repr, METRICS))} "
                             f"and the response expressions: {_expressions.SYNTAX}", "metrics")
    return out


def _limits(mech, raw) -> tuple:
    """`[study] limits`: OUTPUT = [low, high] (a scalar response's name, file units; either bound
    may be omitted by giving ±inf as a string "-inf", "inf")."""
    if raw is None:
        return ()
    if not isinstance(raw, Mapping):
        raise _err(mech, f"'limits' must be a table OUTPUT = [low, high], got {raw!r}", "limits")
    out = []
    for name, entry in raw.items():
        vals = []
        if isinstance(entry, (list, tuple)) and len(entry) == 2:
            for v in entry:
                if isinstance(v, str) and v.strip() in ("inf", "+inf", "-inf"):
                    vals.append(float(v))
                elif isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
                    vals.append(float(v))
        if len(vals) != 2 or not vals[0] < vals[1] or not (math.isfinite(vals[0]) or math.isfinite(vals[1])):
            raise _err(mech, f"a specification limit is [low, high] (file units, low < high; \"-inf\" or \"inf\" for "
                             f"a one-sided limit), got {entry!r}", f"limits.{name}")
        out.append((str(name), vals[0], vals[1]))
    return tuple(out)



def _correlated(mech, inputs: StudyInputs, t) -> StudyInputs:
    """`inputs` with the `[study.correlation]` of `t` (checked: `correlation.read_correlation`)."""
    if "correlation" not in t:
        return inputs
    from .correlation import read_correlation

    out = inputs._replace(correlation=read_correlation(mech, inputs, t["correlation"], _err))
    if out.method == "tolerance" and out.second_order:
        from .second_order import unsupported

        why = unsupported(out)
        if why:
            raise _err(mech, why, "correlation")
    return out


def _ranges(mech, raw, levels_raw) -> tuple:
    """The `Range`s of `[study.ranges]` (NAME = [low, high]) with their grid levels (`levels`: one
    integer for every range, or a table NAME = n)."""
    if raw is None:
        return ()
    if not isinstance(raw, Mapping):
        raise _err(mech, f"[study.ranges] must be a table NAME = [low, high], got {raw!r}", "ranges")
    if isinstance(levels_raw, Mapping):
        for name in levels_raw:
            if name not in raw:
                raise _err(mech, f"levels: '{name}' has no range; ranges: {', '.join(raw) or '(none)'}", "levels")
    elif isinstance(levels_raw, bool) or not isinstance(levels_raw, int):
        raise _err(mech, f"'levels' must be an integer ≥ 1 or a table NAME = n, got {levels_raw!r}", "levels")
    out = []
    for name, entry in raw.items():
        key = f"ranges.{name}"
        if name not in mech.parameter_names:
            derived = [d[0] for d in mech.derived]
            why = " (derived: vary the parameters it is computed from)" if name in derived else ""
            raise _err(mech, f"'{name}' is not a parameter{why}{suggest(name, mech.parameter_names)}; "
                           f"parameters: {', '.join(mech.parameter_names)}", key)
        if (not isinstance(entry, (list, tuple)) or len(entry) != 2
                or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in entry)):
            raise _err(mech, f"a range is [low, high] (two finite numbers, file units), got {entry!r}", key)
        lo, hi = float(entry[0]), float(entry[1])
        if not lo < hi:
            raise _err(mech, f"a range needs low < high, got [{lo:g}, {hi:g}]", key)
        n = levels_raw.get(name, DEFAULTS["levels"]) if isinstance(levels_raw, Mapping) else levels_raw
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 100_000:
            raise _err(mech, f"'levels' of '{name}' must be an integer from 1 to 100000, got {n!r}", "levels")
        out.append(Range(name, (name,), mech.kinds[name], lo, hi, int(n)))
    return tuple(out)


def _tolerance(mech, name: str, entry, default_dist: str, default_k: float) -> tuple:
    """The `Tolerance`s of one entry of `[study.tolerances]` (two for a rectangular zone)."""
    key = f"tolerances.{name}"
    if isinstance(entry, bool) or not isinstance(entry, (int, float, Mapping)):
        raise _err(mech, f"a tolerance is a number (±t) or a table {{ tol = t, sigma = s, radius = r, "
                         f"box = [wx, wy], distribution = ..., k = ... }}, got {entry!r}", key)
    e = {"tol": entry} if not isinstance(entry, Mapping) else dict(entry)
    check_keys(e, TOLERANCE_KEYS, f"study.{key}", lambda m, k: _err(mech, m, f"{key}.{k}"))
    dist = e.get("distribution", default_dist)
    if dist not in DISTRIBUTIONS:
        raise _err(mech, f"'distribution' must be one of {', '.join(map(repr, DISTRIBUTIONS))}, got {dist!r}", key)
    k = _number(mech, e, "k", key) if "k" in e else default_k
    if not k > 0:
        raise _err(mech, f"'k' must be > 0, got {k:g}", key)
    given = [g for g in ("tol", "sigma", "radius", "box") if g in e]
    if len(given) != 1:
        raise _err(mech, "give exactly one of 'tol' (±t), 'sigma' (σ), 'radius' (a pivot's circular zone) or "
                         "'box' (a pivot's rectangular zone: [wx, wy])", key)
    if given[0] in ("radius", "box"):
        pair = (f"{name}_x", f"{name}_y")
        what = "circular" if given[0] == "radius" else "rectangular"
        if not all(p in mech.parameter_names for p in pair):
            raise _err(mech, f"a {what} zone needs the pivot's coordinates {pair[0]}, {pair[1]} as parameters "
                             f"(a frame joint of a sketch file); parameters: {', '.join(mech.parameter_names)}", key)
        if any(mech.kinds[p] != "length" for p in pair):
            raise _err(mech, f"{pair[0]}, {pair[1]} must be lengths", key)
    if given[0] == "box":
        box = e["box"]
        if (not isinstance(box, (list, tuple)) or len(box) != 2
                or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < 1e15 for v in box)):
            raise _err(mech, f"'box' is [wx, wy]: the zone's two half-widths (> 0, file units), got {box!r}", key)
        s = sigma_per_half_width(dist, k)
        return tuple(Tolerance(p, (p,), "length", dist, float(w), float(w) * s, False, k, name)
                     for p, w in zip(pair, box))
    value = _number(mech, e, given[0], key)
    if not value > 0:
        raise _err(mech, f"'{given[0]}' must be > 0, got {value:g}", key)
    if given[0] == "radius":
        if dist not in ("uniform", "normal"):
            raise _err(mech, f"a circular zone is 'uniform' (in the disc) or 'normal' (per coordinate), got {dist!r}; "
                             "a rectangular zone ('box') takes any distribution", key)
        sigma = value / 2.0 if dist == "uniform" else value / k
        return (Tolerance(name, pair, "length", dist, value, sigma, True, k),)
    if name not in mech.parameter_names:
        derived = [d[0] for d in mech.derived]
        why = " (derived: tolerance the parameters it is computed from)" if name in derived else ""
        raise _err(mech, f"'{name}' is not a parameter{why}{suggest(name, mech.parameter_names)}; "
                         f"parameters: {', '.join(mech.parameter_names)}", key)
    ratio = sigma_per_half_width(dist, k)  # σ / t
    if given[0] == "tol":
        t, sigma = value, value * ratio
    else:
        sigma, t = value, value / ratio
    return (Tolerance(name, (name,), mech.kinds[name], dist, t, sigma, False, k),)


def _located(e: MechanismError) -> MechanismError:
    """`e` with the line of its `[study]` key in its file (read again), when it can be found."""
    if e.line is not None or not e.file or not (e.key or "").startswith("study"):
        return e
    from ..files.locator import Locator
    from ..files.source import read_source

    try:
        _, text = read_source(e.file)
    except (MechanismError, OSError):
        return e
    loc = Locator(text)
    parts = (e.key or "").split(".")
    line = None
    if len(parts) >= 3:
        line = loc.line(".".join(parts[:2]), parts[2]) or loc.line(parts[0], parts[1])
    elif len(parts) == 2:
        line = loc.line(parts[0], parts[1])
    line = line or loc.line(parts[0])
    return MechanismError(e.reason, file=e.file, line=line, key=e.key) if line else e


def _err(mech, msg: str, key: str | None = None) -> MechanismError:
    return MechanismError(msg, file=mech.file, key="study" + (f".{key}" if key else ""))


def _integer(mech, t, key: str, lo: int, hi: int) -> int:
    v = t.get(key, DEFAULTS.get(key))
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        raise _err(mech, f"'{key}' must be an integer from {lo} to {hi:g}, got {v!r}", key)
    return int(v)


def _number(mech, t, key: str, where: str | None = None) -> float:
    v = t.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)) or abs(v) > 1e15:
        raise _err(mech, f"'{key}' must be a finite number, got {v!r}", where or key)
    return float(v)
