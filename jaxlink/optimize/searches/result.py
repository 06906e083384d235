"""The result of a design search (`jaxlink.optimize.run`) and its JSON document (what
`jaxlink optimize --out` writes)."""

from __future__ import annotations

import copy
import dataclasses
from typing import Any, Mapping

from ..evaluator import Evaluator
from .base import Progress

EVALUATION_UNIT = "one design solved over its revolution on one circuit; value+gradient = 2"


@dataclasses.dataclass(frozen=True)
class SearchResult:
    """A design search's outcome.

    **Fields:**

    - `method`: "uniform", "montecarlo" or "gradient".
    - `parameters`: the best design, variables in file units (None: no feasible design found).
    - `value`: its exact objective re-measured with the report samples (None if infeasible
      there); `search_value`: its objective at the search's samples; `metrics`: the objective's
      metrics of it; `feasible`, `circuit`: as re-measured.
    - `evaluations` (mechanism evaluations, see `jaxlink.optimize.searches.base`), `designs`,
      `infeasible_fraction`, `wall_s` (seconds in the search's steps), `complete` (False if it
      was stopped before its end).
    - `seed`, `budget`, `file`, `objective_kind`, `variables` (bounds in file units), `samples`,
      `devices`: what was searched, and how.
    - `extra`: method-specific entries of the JSON document (`uniform`: "grid" or "coordinate").
    """

    method: str
    parameters: Mapping[str, float] | None
    value: float | None
    search_value: float | None
    metrics: Mapping[str, Any]
    feasible: bool
    circuit: int | None
    evaluations: int
    designs: int
    infeasible_fraction: float
    wall_s: float
    complete: bool
    seed: int
    budget: int
    file: str | None
    objective_kind: str
    variables: Mapping[str, list]
    samples: int
    devices: int
    extra: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    def to_json(self) -> dict:
        """The JSON document of `jaxlink optimize --out` (a fresh dict)."""
        if self.parameters is None:
            best: dict = {"parameters": None, "objective": None, "metrics": {}, "feasible": False}
        else:
            best = {"parameters": dict(self.parameters), "feasible": self.feasible, "circuit": self.circuit,
                    "objective": self.value, "metrics": copy.deepcopy(dict(self.metrics)),
                    "search_objective": self.search_value}
        out = {
            "method": self.method,
            "file": self.file,
            "objective_kind": self.objective_kind,
            "variables": {k: list(v) for k, v in self.variables.items()},
            "best": best,
            "evaluations": self.evaluations,
            "evaluation_unit": EVALUATION_UNIT,
            "designs": self.designs,
            "wall_s": self.wall_s,
            "infeasible_fraction": self.infeasible_fraction,
            "seed": self.seed,
            "budget": self.budget,
            "samples": self.samples,
            "devices": self.devices,
            "complete": self.complete,
        }
        out.update(self.extra)
        return out


def summarized(ev: Evaluator, method: str, p: Progress, *, seed: int, budget: int, complete: bool,
               extra: Mapping[str, Any] | None = None) -> SearchResult:
    """The result of a search on `ev` whose progress is `p`; the best design is re-measured
    (`Evaluator.report`)."""
    pr = ev.problem
    if p.found:
        rep = ev.report(p.best_u, int(p.best_circuit))
        best = dict(parameters=rep["parameters"], value=rep["objective"], search_value=float(p.best_value),
                    metrics=rep["metrics"], feasible=rep["feasible"], circuit=rep["circuit"])
    else:
        best = dict(parameters=None, value=None, search_value=None, metrics={}, feasible=False, circuit=None)
    designs = int(p.designs)
    return SearchResult(
        method=method, **best, evaluations=int(p.evaluations), designs=designs,
        infeasible_fraction=(int(p.infeasible) / designs) if designs else 0.0, wall_s=float(p.wall_s),
        complete=bool(complete), seed=int(seed), budget=int(budget), file=pr.mech.file, objective_kind=pr.objective,
        variables={n: [float(a), float(b)] for n, a, b in zip(pr.names, pr.lower, pr.upper)},
        samples=len(pr.phis), devices=ev.n_devices, extra=dict(extra or {}))
