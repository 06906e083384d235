"""Design search (`jaxlink optimize`): objectives, the batched evaluator, uniform / Monte Carlo /
gradient searches (`searches/`), checkpoints. See docs/methods/optimize.md.

`run(problem_or_evaluator, method, budget=..., seed=...)` searches and returns a `SearchResult`
(`.to_json()`: the document `jaxlink optimize --out` writes).

The names below are imported when first used (PEP 562): a command that only checks a file's
`[optimize]` table (`jaxlink check`, `kinematics`) imports `problem` alone, not the searches
and their optimizer library (about 0.1 s of its start-up)."""

import importlib as _importlib
import typing as _typing

if _typing.TYPE_CHECKING:
    from .distributed import initialize_distributed as initialize_distributed
    from .evaluator import Evaluator as Evaluator
    from .objectives import OBJECTIVES as OBJECTIVES
    from .objectives import Objective as Objective
    from .objectives import PathData as PathData
    from .problem import Problem as Problem
    from .problem import problem_from as problem_from
    from .searches.result import SearchResult as SearchResult
    from .searches.runner import run as run

_WHERE = {
    "initialize_distributed": ".distributed",
    "Evaluator": ".evaluator",
    "OBJECTIVES": ".objectives",
    "Objective": ".objectives",
    "PathData": ".objectives",
    "Problem": ".problem",
    "problem_from": ".problem",
    "SearchResult": ".searches.result",
    "run": ".searches.runner",
}

__all__ = list(_WHERE)


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(_importlib.import_module(_WHERE[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_WHERE))
