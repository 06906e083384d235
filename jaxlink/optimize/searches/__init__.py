"""The design searches, one module per method, and their registry `searcher`.

- `uniform`: a full grid (`UniformGrid`) or the parameter-by-parameter stepping
  (`UniformCoordinate`), chosen by `uniform = "grid" | "coordinate"`;
- `montecarlo`: designs uniform at random in the bounds (`MonteCarlo`);
- `gradient`: L-BFGS from presampled starts on the smoothed objective (`Gradient`), or with
  `gradient_solver = "al-lbfgs"` an augmented Lagrangian for objectives with constraints
  (`AugmentedLagrangian`).

Every search runs in deterministic chunks on one batched `Evaluator` and counts mechanism
evaluations (`base.py`); `runner.run` drives one with checkpoints (`jaxlink.optimize.run`).
"""

from __future__ import annotations

from typing import Any

from ..evaluator import Evaluator
from .augmented_lagrangian import AugmentedLagrangian as AugmentedLagrangian
from .base import Search as Search
from .gradient import Gradient as Gradient
from .montecarlo import MonteCarlo as MonteCarlo
from .uniform import UniformCoordinate as UniformCoordinate
from .uniform import UniformGrid as UniformGrid

METHODS = ("uniform", "montecarlo", "gradient")
UNIFORM = {"grid": UniformGrid, "coordinate": UniformCoordinate}
GRADIENT_SOLVERS: dict[str, Any] = {"lbfgs": Gradient, "al-lbfgs": AugmentedLagrangian}


DEFAULT_BUDGET = 10000


def searcher(ev: Evaluator, method: str, *, budget: int | None, seed: int, uniform: str = "grid",
             time: float | None = None, **knobs) -> Search:
    """The search `method` on `ev` with a `budget` of mechanism evaluations and `seed`.

    **Arguments:** `budget` None: the `lbfgs` gradient search chooses its sizes from the problem
    and stops when no start improves (`Gradient`); the other methods take `DEFAULT_BUDGET`.
    `time`: seconds (the gradient search ends its presample after 30 % of it; the runner stops
    every search when it is spent). `uniform` ("grid" or "coordinate", method `uniform`);
    `knobs`: the method's keyword arguments (`starts`, `presample`, `iterations`, …; see each
    class), and for `gradient` also `gradient_solver` (default: `[optimize] gradient_solver`,
    else "lbfgs").
    """
    solver = None
    if method == "gradient":
        solver = knobs.pop("gradient_solver", None) or ev.problem.option("gradient_solver", "lbfgs")
    fixed = DEFAULT_BUDGET if budget is None else budget  # what the methods without a default take
    if method == "montecarlo":
        return MonteCarlo(ev, budget=fixed, seed=seed, **knobs)
    if method == "uniform":
        if uniform not in UNIFORM:
            raise ev.problem.error(f"'uniform' must be \"grid\" or \"coordinate\", got {uniform!r}", "uniform")
        return UNIFORM[uniform](ev, budget=fixed, seed=seed, **knobs)
    if method == "gradient":
        if solver not in GRADIENT_SOLVERS:
            raise ev.problem.error(f"'gradient_solver' must be \"lbfgs\" or \"al-lbfgs\", got {solver!r}",
                                   "gradient_solver")
        if solver == "lbfgs":
            return Gradient(ev, budget=budget, seed=seed, time=time, **knobs)
        return GRADIENT_SOLVERS[solver](ev, budget=fixed, seed=seed, **knobs)
    raise ValueError(f"unknown method {method!r}; use one of {METHODS}")
