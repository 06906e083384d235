"""Design search (`jaxlink optimize`): objectives, the batched evaluator, uniform / Monte Carlo /
gradient searches (`searches/`), checkpoints. See docs/methods/optimize.md.

`run(problem_or_evaluator, method, budget=..., seed=...)` searches and returns a `SearchResult`
(`.to_json()`: the document `jaxlink optimize --out` writes)."""

from .distributed import initialize_distributed as initialize_distributed
from .evaluator import Evaluator as Evaluator
from .objectives import OBJECTIVES as OBJECTIVES
from .objectives import Objective as Objective
from .objectives import PathData as PathData
from .problem import Problem as Problem
from .problem import problem_from as problem_from
from .searches.result import SearchResult as SearchResult
from .searches.runner import run as run
