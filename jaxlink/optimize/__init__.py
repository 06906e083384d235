"""Design search (`jaxlink optimize`): objectives, the batched evaluator, uniform / Monte Carlo /
gradient searches, checkpoints. See docs/optimize.md."""

from ._evaluator import Evaluator as Evaluator
from ._objectives import OBJECTIVES as OBJECTIVES
from ._objectives import Objective as Objective
from ._objectives import PathData as PathData
from ._problem import Problem as Problem
from ._problem import problem_from as problem_from
