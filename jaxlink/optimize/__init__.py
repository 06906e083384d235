"""Design search (`jaxlink optimize`): objectives, the batched evaluator, uniform / Monte Carlo /
gradient searches, checkpoints. See docs/optimize.md."""

from .evaluator import Evaluator as Evaluator
from .objectives import OBJECTIVES as OBJECTIVES
from .objectives import Objective as Objective
from .objectives import PathData as PathData
from .problem import Problem as Problem
from .problem import problem_from as problem_from
