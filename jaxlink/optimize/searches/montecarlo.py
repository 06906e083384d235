"""Monte Carlo search: designs uniform at random in the bounds, in chunks of the evaluator's
batch, from one seeded stream (`base.drawn`: 256-row blocks, block k from numpy's PCG64 seeded by
(seed, k)), so a resumed search draws exactly the designs of an uninterrupted one, and any `chunk`
draws the same designs (the same result)."""

from __future__ import annotations

from typing import NamedTuple

from ..evaluator import Evaluator
from .base import Progress, drawn, evaluate, next_chunk, progress_start, recorded


class MonteCarloState(NamedTuple):
    progress: Progress


class MonteCarlo:
    """**Arguments:** `ev` (the evaluator), `budget` (mechanism evaluations), `seed`."""

    name = "montecarlo"

    def __init__(self, ev: Evaluator, *, budget: int, seed: int):
        self.ev, self.budget, self.seed = ev, int(budget), int(seed)

    def init(self) -> MonteCarloState:
        return MonteCarloState(progress_start(self.ev.problem.n_variables))

    def done(self, st: MonteCarloState) -> bool:
        return int(st.progress.evaluations) + self.ev.n_circuits > self.budget

    def step(self, st: MonteCarloState) -> MonteCarloState:
        ev, p = self.ev, st.progress
        n = min(ev.chunk, (self.budget - int(p.evaluations)) // ev.n_circuits)
        U = drawn((self.seed,), int(p.designs), n, ev.problem.n_variables)
        return MonteCarloState(next_chunk(recorded(p, U, evaluate(ev, U))))
