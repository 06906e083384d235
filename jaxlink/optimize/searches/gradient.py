"""Gradient search on the smoothed objective: L-BFGS from a batch of presampled starts.

A Monte Carlo presample (`base.PresampledStarts`) picks the best `starts` feasible designs (each
on its best circuit; for the `points` objective also moved to their best similarity placement,
`align.py`), then L-BFGS (`lbfgs.py`: optax's direction, bounds by u = (1 − cos πv)/2) runs from
all of them in lock step on `Evaluator.smooth_single`, with exact gradients by implicit
differentiation through the path solve. The exact objective of the iterates decides the best.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..evaluator import Evaluator
from ..sharding import put
from . import lbfgs
from .base import (
    Batch,
    Pool,
    PresampledStarts,
    Progress,
    counted,
    empty_pool,
    evaluate,
    next_chunk,
    progress_start,
    recorded,
    start_indices,
)


def smooth_value_and_grad(ev: Evaluator):
    """Compiled (v (S, V), circuits (S,)) → (smoothed objective (S,), its gradient in v (S, V));
    +inf and a zero gradient where the design is infeasible or either is not finite."""

    def build():
        def one(v, c):
            value, grad = jax.value_and_grad(lambda vv: ev.smooth_single(lbfgs.u_of_v(vv), c))(v)
            ok = jnp.isfinite(value) & jnp.all(jnp.isfinite(grad))
            return jnp.where(ok, value, jnp.inf), jnp.where(ok, grad, 0.0)

        return jax.jit(jax.vmap(one))

    return ev.compiled(("gradient.smooth_value_and_grad",), build)


class GradientState(NamedTuple):
    progress: Progress
    phase: np.int64  # 0 presample, 1 search
    pool: Pool
    iteration: np.int64
    v: np.ndarray  # (S, V) iterates (unbounded variables)
    c: np.ndarray  # (S,) their circuits
    value: np.ndarray  # (S,) smoothed objective at v
    grad: np.ndarray  # (S, V) its gradient
    active: np.ndarray  # (S,) starts still moving
    lbfgs: Any  # optax's ScaleByLBFGSState, leading axis = starts
    mark: np.float64 = np.float64(np.inf)  # the best exact value when it last dropped by 1e-6
    stall: np.int64 = np.int64(0)  # iterations since then


class Gradient(PresampledStarts):
    """L-BFGS from a batch of starts (see the module doc).

    Per iteration and start: the direction d = −H g (reset to −g when it is not a descent
    direction), then a backtracking (Armijo) line search f(v + t d) ≤ f(v) + 10⁻⁴ t g·d,
    t = 1, ½, ¼, … (at most `linesearch_steps`; the first step and a reset one move at most 0.05
    in v); every trial is one batched value-and-gradient of all starts (2 evaluations each), and
    an infeasible trial (+inf) just fails the test. A start whose step or gradient has vanished
    stops moving; the L-BFGS memory advances only for starts that moved. After each chunk the
    exact objective of the iterates (1 evaluation each) updates the best.

    **Arguments** (keyword, else `[optimize]`): `starts` (16), `presample` (8 × starts, at most
    a quarter of the budget), `iterations` (200), `memory` (10), `linesearch_steps` (10),
    `chunk_iterations` (5, iterations per checkpoint).

    **Defaults from the problem** (`budget=None`: no budget given, neither as argument nor as
    `[optimize] budget`): `starts` = clip(5 V, 16, 64) for V variables, `presample` = 1024 V
    designs (each on every circuit), `iterations` = 400, no evaluation budget; the search stops
    when no start improves: the best exact objective has not dropped by 10⁻⁶ (relative) over
    the last `patience` iterations (40). With `time` (seconds, `[optimize] time`), the presample
    ends after 30 % of it and the search when it is spent (the runner stops there too). Keys
    and arguments that are given override each of these.
    """

    name = "gradient"

    def __init__(self, ev: Evaluator, *, budget: int | None, seed: int, starts: int | None = None,
                 presample: int | None = None, iterations: int | None = None, memory: int = 10,
                 linesearch_steps: int = 10, chunk_iterations: int = 5, time: float | None = None,
                 patience: int | None = None):
        pr = ev.problem
        V = pr.n_variables
        self.auto = budget is None
        self.ev, self.budget, self.seed = ev, (2**62 if budget is None else int(budget)), int(seed)
        s = int(starts or pr.option("starts", int(np.clip(5 * V, 16, 64)) if self.auto else 16))
        self.S = -(-s // ev.n_devices) * ev.n_devices
        self.presample = min(int(presample or pr.option("presample", 1024 * V if self.auto else 8 * self.S)),
                             max(self.S, self.budget // (4 * ev.n_circuits)))
        self.iterations = int(iterations or pr.option("iterations", 400 if self.auto else 200))
        self.linesearch_steps = int(linesearch_steps)
        self.chunk_iterations = int(chunk_iterations)
        self.memory = int(memory)
        self.time = time if time is not None else pr.option("time")
        self.patience = patience if patience is not None else (40 if self.auto else None)
        from ..align import placement_of

        self.placement = placement_of(pr, ev) if pr.objective == "points" else None

    def init(self) -> GradientState:
        S, V = self.S, self.ev.problem.n_variables
        return GradientState(progress_start(V), np.int64(0), empty_pool(S, V), np.int64(0), np.zeros((S, V)),
                             np.zeros(S, np.int64), np.full(S, np.inf), np.zeros((S, V)), np.zeros(S, bool),
                             lbfgs.initial(self.memory, S, V))

    # ------------------------------------------------------------------ presample
    def presampled(self, st: GradientState, U):
        b = evaluate(self.ev, U)
        p = recorded(st.progress, U, b)
        if self.placement is not None:
            p, U, b = self._aligned(p, U, b)
        return st._replace(progress=p), U, b.value, b.circuit

    def _aligned(self, p: Progress, U, b: Batch):
        """Presampled feasible designs moved to their best similarity placement (`align.py`),
        evaluated, and pooled with the originals. Costs 2 evaluations per feasible design."""
        from ..align import apply_similarity, icp_similarity

        ev, pr = self.ev, self.ev.problem
        ok = np.flatnonzero(b.feasible)
        if len(ok) == 0:
            return p, U, b
        xy, _ = ev.paths(U[ok], b.circuit[ok])
        p = counted(p, len(ok))
        targets = jnp.asarray(np.asarray(pr.option("targets"), dtype=float))
        s, th, t, _ = (np.asarray(a) for a in icp_similarity(jnp.asarray(xy), targets))
        X = apply_similarity(pr, pr.to_file_units(U[ok]), s, th, t, self.placement)
        U2 = np.clip(pr.to_unit(X), 0.0, 1.0)
        b2 = evaluate(ev, U2, b.circuit[ok])
        p = recorded(p, U2, b2)
        both = Batch(np.concatenate([b.value, b2.value]), np.concatenate([b.feasible, b2.feasible]),
                     np.concatenate([b.circuit, b2.circuit]), None, b.evaluations + b2.evaluations)
        return p, np.concatenate([U, U2]), both

    # ------------------------------------------------------------------ search
    def _value_and_grad(self, p: Progress, v, c):
        value, grad = smooth_value_and_grad(self.ev)(*put((jnp.asarray(v), jnp.asarray(c)), self.ev.sharding))
        return counted(p, 2 * self.S), np.asarray(value), np.asarray(grad)

    def started(self, st: GradientState) -> GradientState:
        idx = start_indices(st.pool)
        if idx is None or int(st.progress.evaluations) + 3 * self.S > self.budget:
            return st._replace(progress=st.progress._replace(done=np.bool_(True)))
        v = lbfgs.v_of_u(st.pool.u[idx])
        c = np.asarray(st.pool.circuit[idx], np.int64)
        p, value, grad = self._value_and_grad(st.progress, v, c)
        return st._replace(progress=p, phase=np.int64(1), v=v, c=c, value=value, grad=grad,
                           active=np.isfinite(value), lbfgs=lbfgs.initial(self.memory, self.S, len(v[0])))

    def _iteration(self, st: GradientState) -> GradientState:
        v, g, f, p = st.v, st.grad, st.value, st.progress
        d, new_state = lbfgs.directions(self.ev, self.memory)(jnp.asarray(g), st.lbfgs, jnp.asarray(v))
        d = np.asarray(d)
        slope = np.sum(d * g, axis=1)
        bad = ~(slope < 0) | ~np.all(np.isfinite(d), axis=1)
        d = np.where(bad[:, None], -g, d)
        slope = np.where(bad, -np.sum(g * g, axis=1), slope)
        # the first step: at most 0.05 in the normalized variables
        dn = np.max(np.abs(d), axis=1)
        t = np.where((int(st.iteration) == 0) | bad, np.minimum(1.0, 0.05 / np.maximum(dn, 1e-300)), 1.0)
        searching = st.active.copy()
        new_v, new_f, new_g = v.copy(), f.copy(), g.copy()
        for _ in range(self.linesearch_steps):
            # a trial costs 2S; S more are kept for the exact evaluation at the end of the chunk
            if not searching.any() or int(p.evaluations) + 3 * self.S > self.budget:
                break
            trial = np.where(searching[:, None], v + t[:, None] * d, v)
            p, tf, tg = self._value_and_grad(p, trial, st.c)
            accept = searching & np.isfinite(tf) & (tf <= f + 1e-4 * t * slope)
            new_v[accept], new_f[accept], new_g[accept] = trial[accept], tf[accept], tg[accept]
            searching &= ~accept
            t = np.where(searching, 0.5 * t, t)
        moved = np.any(new_v != v, axis=1)
        # a start that could not move (step underflow, stationary point) stops
        small = np.max(np.abs(new_g), axis=1) <= 1e-12 * np.maximum(1.0, np.abs(new_f))
        return st._replace(progress=p, iteration=st.iteration + 1, v=new_v, value=new_f, grad=new_g,
                           active=st.active & moved & ~small,
                           lbfgs=lbfgs.select(moved, lbfgs.to_numpy(new_state), st.lbfgs))

    def searched(self, st: GradientState) -> GradientState:
        n = 0
        for _ in range(self.chunk_iterations):
            if (int(st.iteration) >= self.iterations or not st.active.any()
                    or int(st.progress.evaluations) + 2 * self.S + self.S > self.budget
                    or (self.time is not None and float(st.progress.wall_s) >= float(self.time))
                    or (self.patience is not None and int(st.stall) >= self.patience)):
                st = st._replace(progress=st.progress._replace(done=np.bool_(True)))
                break
            st = self._iteration(st)
            n += 1
        # the exact objective at the current iterates decides the best (S evaluations)
        U = np.asarray(lbfgs.u_of_v(jnp.asarray(st.v)))
        p = recorded(st.progress, U, evaluate(self.ev, U, st.c))
        # no start improves: the best has not dropped by 1e-6 (relative) for `patience` iterations
        if float(p.best_value) < float(st.mark) - 1e-6 * abs(float(st.mark)) or not np.isfinite(st.mark):
            st = st._replace(mark=np.float64(p.best_value), stall=np.int64(0))
        else:
            st = st._replace(stall=np.int64(st.stall + n))
        return st._replace(progress=next_chunk(p))

