"""Uniform searches: a full grid, or the parameter-by-parameter stepping.

- `UniformGrid`: n points per variable (n = ⌊(budget / circuits)^(1/V)⌋, at least 2, bounds
  included), all n^V designs in lexicographic order, one evaluator batch per chunk.
- `UniformCoordinate`: from the file's design, sweep one variable at a time over `sweep` points
  (the others fixed at the best so far), keep the best, go on to the next variable; after each
  cycle over all variables the sweep range shrinks to ±2 steps of the previous sweep around the
  best.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..evaluator import Evaluator
from .base import Progress, evaluate, next_chunk, progress_start, recorded


class GridState(NamedTuple):
    progress: Progress


class UniformGrid:
    """**Arguments:** `ev`, `budget` (mechanism evaluations; fixes n), `seed` (unused)."""

    name = "uniform"

    def __init__(self, ev: Evaluator, *, budget: int, seed: int = 0):
        self.ev, self.budget = ev, int(budget)
        V = ev.problem.n_variables
        per = max(1, self.budget // ev.n_circuits)
        self.n = max(2, int(math.floor(per ** (1.0 / V) + 1e-9)))
        self.total = self.n**V

    def init(self) -> GridState:
        return GridState(progress_start(self.ev.problem.n_variables))

    def done(self, st: GridState) -> bool:
        return int(st.progress.designs) >= self.total

    def step(self, st: GridState) -> GridState:
        ev, p = self.ev, st.progress
        a = int(p.designs)
        idx = np.arange(a, min(a + ev.chunk, self.total))
        U = np.stack(np.unravel_index(idx, (self.n,) * ev.problem.n_variables), axis=1) / (self.n - 1)
        return GridState(next_chunk(recorded(p, U, evaluate(ev, U))))


class CoordinateState(NamedTuple):
    progress: Progress
    center: np.ndarray  # (V,) the design the sweeps go through
    half: np.float64  # half-width of the sweep (normalized); ≥ 0.5: the whole range
    axis: np.int64  # the variable swept next


class UniformCoordinate:
    """**Arguments:** `ev`, `budget`, `seed` (unused), `sweep` (points per sweep, 21)."""

    name = "uniform"

    def __init__(self, ev: Evaluator, *, budget: int, seed: int = 0, sweep: int = 21):
        self.ev, self.budget, self.n = ev, int(budget), int(sweep)

    def init(self) -> CoordinateState:
        pr = self.ev.problem
        return CoordinateState(progress_start(pr.n_variables), np.clip(pr.to_unit(pr.file_design()), 0.0, 1.0),
                               np.float64(0.5), np.int64(0))

    def done(self, st: CoordinateState) -> bool:
        return int(st.progress.evaluations) + self.n * self.ev.n_circuits > self.budget

    def step(self, st: CoordinateState) -> CoordinateState:
        ev = self.ev
        V = ev.problem.n_variables
        j = int(st.axis)
        c = np.array(st.center, dtype=np.float64)
        if st.half >= 0.5:
            vals = np.linspace(0.0, 1.0, self.n)
        else:
            vals = np.clip(c[j] + np.linspace(-st.half, st.half, self.n), 0.0, 1.0)
        U = np.repeat(c[None], self.n, axis=0)
        U[:, j] = vals
        p = recorded(st.progress, U, evaluate(ev, U))
        half = np.float64(2 * (2 * st.half / (self.n - 1))) if j == V - 1 else st.half
        return CoordinateState(next_chunk(p), p.best_u.copy() if p.found else st.center, half, np.int64((j + 1) % V))
