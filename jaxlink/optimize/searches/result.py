"""The result of a design search (`jaxlink.optimize.run`) and its JSON document (what
`jaxlink optimize --out` writes)."""

from __future__ import annotations

import copy
import dataclasses
from typing import Any, Mapping

import numpy as np

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
    - `search_wall_s`: `wall_s` without compilation, `compile_s`: the compilation in it
      (tracing, lowering, XLA; `jaxlink/optimize/timing.py`); `trace`: the best-so-far over time,
      a list of `{evaluations, seconds, objective}` (seconds: search seconds without compilation;
      objective: the search's exact value at its samples) at every chunk that improved it.
    - `best_file`: the path of the best design's mechanism file, when one was written
      (`run(..., out=...)`: `OUT.best.toml`), else None.
    - `extra`: method-specific entries of the JSON document (`uniform`: "grid" or "coordinate").

    **Methods:** `best_file_text()` (the input file's text with the best design's values and its
    guesses on the found circuit: `jaxlink kinematics` on it traces the search's path) and
    `best_mechanism()` (that file read back, a `Mechanism`); both need the result of `run` on
    this process's evaluator (a result read back from JSON has neither).
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
    budget: int | None
    file: str | None
    objective_kind: str
    variables: Mapping[str, list]
    samples: int
    devices: int
    extra: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    search_wall_s: float = 0.0
    compile_s: float = 0.0
    trace: tuple = ()
    best_file: str | None = None
    certificate: Mapping[str, Any] | None = None
    fallback: int | None = None
    reason: str | None = None
    _best: Any = dataclasses.field(default=None, repr=False, compare=False)  # (evaluator, u, circuit)

    def best_file_text(self, text: str | None = None) -> str:
        """The best design as a complete mechanism file (`jaxlink/optimize/best_file.py`): the
        searched file's text (or `text`) with the design's parameters and guesses on its circuit."""
        if self._best is None:
            raise ValueError("this result has no feasible design (or was not made by `run` in this process)")
        from ..best_file import best_file_text

        ev, u, c = self._best
        return best_file_text(ev, u, c, text)

    def best_mechanism(self):
        """The best design as a `Mechanism` (`best_file_text()` read back): `jaxlink.solve` on it,
        from its own guesses, traces the search's path."""
        from ...files.reader import loads

        return loads(self.best_file_text(), file=self.best_file or (self.file or "<best design>"))

    def to_json(self) -> dict:
        """The JSON document of `jaxlink optimize --out` (a fresh dict)."""
        if self.parameters is None:
            best: dict = {"parameters": None, "objective": None, "metrics": {}, "feasible": False,
                          "certified": False, "reason": self.reason}
        else:
            best = {"parameters": dict(self.parameters), "feasible": self.feasible, "circuit": self.circuit,
                    "objective": self.value, "metrics": copy.deepcopy(dict(self.metrics)),
                    "search_objective": self.search_value, **dict(self.certificate or {}),
                    "fallback": self.fallback}
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
            "search_wall_s": self.search_wall_s,
            "compile_s": self.compile_s,
            "trace": [dict(t) for t in self.trace],
            "best_file": self.best_file,
        }
        out.update(self.extra)
        return out


def trace_point(p: Progress) -> dict:
    """One entry of the best-so-far trace: evaluations, search seconds (without compilation), the
    best objective at the search's samples."""
    return {"evaluations": int(p.evaluations), "seconds": float(p.wall_s - p.compile_s),
            "objective": float(p.best_value)}


def traced(log_path) -> list:
    """The best-so-far trace recorded in a search's log (`OUT.log.jsonl`), for a resumed search."""
    import json

    out: list = []
    best = float("inf")
    for line in open(log_path, encoding="utf-8").read().splitlines():
        r = json.loads(line)
        v = r.get("best_value")
        if v is not None and v < best:
            best = v
            out.append({"evaluations": int(r["evaluations"]),
                        "seconds": float(r["wall_s"] - r.get("compile_s", 0.0)), "objective": float(v)})
    return out


def summarized(ev: Evaluator, method: str, p: Progress, *, seed: int, budget: int | None, complete: bool,
               extra: Mapping[str, Any] | None = None, trace=(), best_file: str | None = None) -> SearchResult:
    """The result of a search on `ev` whose progress is `p`. The best design is re-measured
    (`Evaluator.report`) and must be *certified* to assemble over its whole revolution; if it is
    not, the next of the runners-up (`Progress.runners_*`, best first) that is certified is the
    result (`fallback` counts the better ones passed over), and with none, no design (`reason`
    says why)."""
    pr = ev.problem
    best: dict = dict(parameters=None, value=None, search_value=None, metrics={}, feasible=False, circuit=None)
    chosen = None
    reason = None
    if p.found:
        cands = [(np.asarray(p.best_u, dtype=float), int(p.best_circuit), float(p.best_value))]
        for v, u, c in zip(p.runners_value, p.runners_u, p.runners_circuit):
            if np.isfinite(v) and not any(int(c) == cc and np.array_equal(u, uu) for uu, cc, _ in cands):
                cands.append((np.asarray(u, dtype=float), int(c), float(v)))
        first: dict = {}
        for k, (u, c, v) in enumerate(cands):
            rep = ev.report(u, c)
            first = first or rep
            if rep["feasible"] and rep["certified"]:
                best = dict(parameters=rep["parameters"], value=rep["objective"], search_value=v,
                            metrics=rep["metrics"], feasible=True, circuit=rep["circuit"])
                best["certificate"] = {key: rep[key] for key in ("certificate", "certified", "margin", "margin_at",
                                                                 "dense_positions") if key in rep}
                best["fallback"] = k
                chosen = (ev, tuple(map(float, u)), int(c))
                break
        if chosen is None:
            reason = _uncertified_reason(ev, len(cands), first)
    else:
        reason = ("no feasible design found: every design tried failed to assemble over its revolution (widen the "
                  "bounds, check the file's design, or give more --budget / --time)")
    designs = int(p.designs)
    return SearchResult(
        method=method, **best, evaluations=int(p.evaluations), designs=designs,
        infeasible_fraction=(int(p.infeasible) / designs) if designs else 0.0, wall_s=float(p.wall_s),
        complete=bool(complete), seed=int(seed), budget=None if budget is None else int(budget),
        file=pr.mech.file, objective_kind=pr.objective,
        variables={n: [float(a), float(b)] for n, a, b in zip(pr.names, pr.lower, pr.upper)},
        samples=len(pr.phis), devices=ev.n_devices, extra=dict(extra or {}),
        search_wall_s=float(p.wall_s - p.compile_s), compile_s=float(p.compile_s),
        trace=tuple(dict(t) for t in trace), best_file=best_file, reason=reason, _best=chosen)


def _uncertified_reason(ev: Evaluator, n: int, rep: dict) -> str:
    """Why none of the `n` best designs is a result (`rep`: the best one's report)."""
    mech = ev.mech
    what = (f"none of the {n} best designs found is certified to" if n > 1
            else "the best design found is not certified to")
    if rep.get("certificate") == "reach margin" and not rep["certified"]:
        why = (f"the best one cannot be assembled between two of the {len(ev.problem.phis)} checked positions "
               f"(a dyad's reach margin {rep['margin']:.3g} < 0 at {mech.input_name} = {rep['margin_at']:.6g} "
               "in the file's unit)")
    else:
        why = (f"the best one does not assemble at every one of the {ev.report_samples} positions of the dense "
               "re-solve")
    return (f"no design found that assembles over the whole revolution: {what}; {why}. Raise "
            "[optimize] samples (more checked positions), or widen the bounds, or give more --budget / --time")
