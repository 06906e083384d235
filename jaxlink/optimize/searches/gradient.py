"""Gradient search on the smoothed objective: L-BFGS from a batch of presampled starts, refilled
from a pool, with a least-squares polish of the best.

A Monte Carlo presample (`base.PresampledStarts`) keeps the `pool` best feasible designs (each on
its best circuit; for the `points` objective also moved to their best similarity placement,
`align.py`, in one fused batch). L-BFGS (`lbfgs.py`: optax's direction, bounds by
u = (1 − cos πv)/2) runs from `starts` of them in lock step on `Evaluator.smooth_exact_single`,
with exact gradients by implicit differentiation through the path solve; a start that stops or
stalls is replaced by the next pooled design. Every trial also gives the exact objective, which
decides the best. An objective with residuals (`points`) ends with Levenberg–Marquardt on the
best designs (`Gradient._polished`), which follows the feasibility boundary (`boundary.py`).
Compiled functions have fixed shapes (the chunk, half a chunk, `starts`, the polished starts):
nothing recompiles per chunk or per iteration.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..evaluator import Evaluator
from ..sharding import pad_rows, put
from . import boundary as _boundary
from . import lbfgs
from .base import (
    Batch,
    Pool,
    PresampledStarts,
    Progress,
    counted,
    empty_pool,
    evaluate,
    improved,
    next_chunk,
    progress_start,
    recorded,
)


def smooth_value_and_grad(ev: Evaluator):
    """Compiled (v (S, V), circuits (S,)) → (smoothed objective (S,), its gradient in v (S, V),
    exact objective (S,)) from one path solve per design; +inf and a zero gradient where the
    design is infeasible or either is not finite (the exact value +inf where infeasible)."""

    def build():
        def one(v, c):
            (value, exact), grad = jax.value_and_grad(
                lambda vv: ev.smooth_exact_single(lbfgs.u_of_v(vv), c), has_aux=True)(v)
            ok = jnp.isfinite(value) & jnp.all(jnp.isfinite(grad))
            return jnp.where(ok, value, jnp.inf), jnp.where(ok, grad, 0.0), exact

        return jax.jit(jax.vmap(one))

    return ev.compiled(("gradient.smooth_value_and_grad",), build)


def residuals_and_jacobian(ev: Evaluator):
    """Compiled (v (S, V), circuits (S,)) → (residuals r (S, R), their Jacobian in v (S, R, V),
    feasible (S,)) of an objective with residuals (`Objective.residuals`, value = Σ r²), by
    forward-mode differentiation through the path solve; zeros where infeasible."""

    def build():
        def res(vv, c):
            path, feas = ev.path(lbfgs.u_of_v(vv), c, jnp.asarray(ev.problem.phis, vv.dtype), ev.objective.order)
            r = ev.objective.residuals(path)
            return r, (r, feas)

        def one(v, c):
            J, (r, feas) = jax.jacfwd(lambda vv: res(vv, c), has_aux=True)(v)
            ok = feas & jnp.all(jnp.isfinite(r)) & jnp.all(jnp.isfinite(J))
            return jnp.where(ok, r, 0.0), jnp.where(ok, J, 0.0), ok

        return jax.jit(jax.vmap(one))

    return ev.compiled(("gradient.residuals_and_jacobian",), build)


#: mechanism evaluations of a search given no budget (the sizes chosen from the problem): a count,
#: so that the default search ends at the same design on any machine and under any load. Sized on
#: the eight literature cases of benchmarks/fourbar-path from plain files (9 variables, 2 circuits,
#: 360 samples), on 2 CPU cores: most stop by themselves (no start improves) before it
AUTO_BUDGET = 400_000


class GradientState(NamedTuple):
    progress: Progress
    phase: np.int64  # 0 presample, 1 search
    pool: Pool
    iteration: np.int64
    v: np.ndarray  # (S,) iterates (unbounded variables)
    c: np.ndarray  # (S,) their circuits
    value: np.ndarray  # (S,) smoothed objective at v
    grad: np.ndarray  # (S, V) its gradient
    active: np.ndarray  # (S,) starts still moving
    lbfgs: Any  # optax's ScaleByLBFGSState, leading axis = starts
    mark: np.float64 = np.float64(np.inf)  # the best exact value when it last dropped by 1e-6
    stall: np.int64 = np.int64(0)  # iterations since then
    queue: np.ndarray = np.zeros(0, np.int64)  # pool rows not yet started, in order (−1: none)
    lane_mark: np.ndarray = np.zeros(0)  # (S,) each start's value when it last dropped enough
    lane_stall: np.ndarray = np.zeros(0, np.int64)  # (S,) its iterations since then
    age: np.ndarray = np.zeros(0, np.int64)  # (S,) iterations since the lane's start


class Gradient(PresampledStarts):
    """L-BFGS from a batch of starts, refilled from a queue of presampled designs (see the
    module doc).

    Per iteration and start: the direction d = −H g (reset to −g when it is not a descent
    direction), then a backtracking (Armijo) line search f(v + t d) ≤ f(v) + 10⁻⁴ t g·d,
    t = 1, ½, ¼, … (at most `linesearch_steps`; a start's first step and a reset one move at
    most 0.05 in v); every trial is one batched value-and-gradient of all starts (2 evaluations
    each; it also gives the exact objective of the trial, which updates the best), and an
    infeasible trial (+inf) just fails the test. The L-BFGS memory advances only for starts that
    moved.

    **Starts.** The presample keeps the `pool` best designs (by ranking value); the search
    starts `starts` of them (the best, skipping near-duplicates: within 0.01 of a better one in
    every normalized variable, same circuit) and keeps the rest in a queue. A start that has
    stopped (its step or gradient vanished) or stalled (its smoothed value did not drop by
    1 %, relative, over the last 10 iterations) is replaced by the next design of the queue,
    with a fresh L-BFGS memory — except the start holding the best design, which goes on until
    it stops or stalls by the strict test (10⁻⁶ over `patience` iterations): a local refinement
    of the best. The search ends when the queue is empty and no start improves: the best exact
    objective has not dropped by 10⁻⁶ (relative) over the last `patience` iterations (40), or
    every start stopped; or after `iterations`.

    **Arguments** (keyword, else `[optimize]`): `starts` (16), `presample` (8 × starts, at most
    a quarter of the budget), `iterations` (200), `memory` (10), `linesearch_steps` (10),
    `chunk_iterations` (5, iterations per checkpoint), `pool` (2 × starts: designs kept from
    the presample, started in turn), `boundary` (True: the least-squares polish follows the
    feasibility boundary, `boundary.py`; False: the polish as before it, for comparison).

    **Defaults from the problem** (`budget=None`: no budget given, neither as argument nor as
    `[optimize] budget`): `starts` = clip(5 V, 16, 64) for V variables, `presample` = 1024 V
    designs (each on every circuit), `iterations` = 2000 and a budget of `AUTO_BUDGET` (400 000)
    mechanism evaluations: counts only, so that the default search ends at the same design on
    any machine. No time limit unless one is given: with `time` (seconds, `[optimize] time`), a
    cap, the presample ends after 30 % of it and the runner stops the search before a chunk that
    would not fit (`runner.run`; the result then depends on the machine's speed, and says so).
    Keys and arguments that are given override each of these.
    """

    name = "gradient"

    def __init__(self, ev: Evaluator, *, budget: int | None, seed: int, starts: int | None = None,
                 presample: int | None = None, iterations: int | None = None, memory: int = 10,
                 linesearch_steps: int = 10, chunk_iterations: int = 5, time: float | None = None,
                 patience: int | None = None, pool: int | None = None, boundary: bool = True):
        pr = ev.problem
        V = pr.n_variables
        self.auto = budget is None
        self.ev, self.budget, self.seed = ev, (AUTO_BUDGET if budget is None else int(budget)), int(seed)
        s = int(starts or pr.option("starts", int(np.clip(5 * V, 16, 64)) if self.auto else 16))
        self.S = -(-s // ev.n_devices) * ev.n_devices
        self.presample = min(int(presample or pr.option("presample", 1024 * V if self.auto else 8 * self.S)),
                             max(self.S, self.budget // (4 * ev.n_circuits)))
        self.pool_size = max(self.S, int(pool or 2 * self.S))
        self.iterations = int(iterations or pr.option("iterations", 2000 if self.auto else 200))
        self.linesearch_steps = int(linesearch_steps)
        self.chunk_iterations = int(chunk_iterations)
        self.memory = int(memory)
        # a time limit only when one is given (a cap: the presample ends after 30 % of it)
        self.time = time if time is not None else pr.option("time", None)
        self.patience = patience if patience is not None else 40
        self.lane_patience, self.lane_drop = 10, 1e-2
        self.polish_iterations, self.polish_starts = 40, 8
        self.boundary = bool(boundary)  # the polish follows the feasibility boundary (boundary.py)
        # with a least-squares polish to follow, the search stops on a looser test (the polish
        # converges the last digits faster than L-BFGS crawls to them)
        self.drop = 1e-4 if ev.objective.residuals is not None else 1e-6
        from ..align import placement_of

        self.placement = placement_of(pr, ev) if pr.objective == "points" else None

    def stop_reason(self, st: GradientState) -> str:
        """Why the ended search `st` ended: "iterations" (`iterations` done), "budget" (the
        evaluations left could not pay another trial) or "converged" (no start improves, every
        start stopped, or no feasible design to start from)."""
        if int(st.iteration) >= self.iterations:
            return "iterations"
        if int(st.progress.evaluations) + 3 * self.S > self.budget:
            return "budget"
        return "converged"

    def init(self) -> GradientState:
        S, V = self.S, self.ev.problem.n_variables
        return GradientState(progress_start(V), np.int64(0), empty_pool(self.pool_size, V), np.int64(0),
                             np.zeros((S, V)), np.zeros(S, np.int64), np.full(S, np.inf), np.zeros((S, V)),
                             np.zeros(S, bool), lbfgs.initial(self.memory, S, V), np.float64(np.inf), np.int64(0),
                             np.full(self.pool_size, -1, np.int64), np.full(S, np.inf), np.zeros(S, np.int64),
                             np.zeros(S, np.int64))

    # ------------------------------------------------------------------ presample
    def presampled(self, st: GradientState, U):
        ev = self.ev
        if self.placement is None:
            b = evaluate(ev, U)
            return st._replace(progress=recorded(st.progress, U, b)), U, b.value, b.circuit
        # every circuit (one batch of the chunk's size), then the feasible designs on their best
        # circuit aligned to the targets and re-evaluated, in blocks of half a chunk (the last
        # block padded: two compiled shapes in all)
        from ..align import aligned_batch

        b = evaluate(ev, pad_rows(U, ev.chunk)[0])
        n = len(U)
        b = Batch(b.value[:n], b.feasible[:n], b.circuit[:n], None, n * ev.n_circuits)
        p = recorded(st.progress, U, b)
        ok = np.flatnonzero(b.feasible)
        block = max(1, ev.chunk // 2)
        U2s: list[np.ndarray] = []
        v2s: list[np.ndarray] = []
        ok2s: list[np.ndarray] = []
        for s in range(0, len(ok), block):
            rows = ok[s:s + block]
            uu, m = pad_rows(U[rows], block)
            cc, _ = pad_rows(np.asarray(b.circuit[rows]), block)
            out = aligned_batch(ev, self.placement)(*put((jnp.asarray(uu), jnp.asarray(cc)), ev.sharding))
            U2s.append(np.asarray(out[0], dtype=float)[:m])
            v2s.append(np.asarray(out[1])[:m])
            ok2s.append(np.asarray(out[2])[:m])
        if not ok2s:
            return st._replace(progress=p), U, b.value, b.circuit
        U2, v2, ok2 = np.concatenate(U2s), np.concatenate(v2s), np.concatenate(ok2s)
        ev.evaluations += 2 * len(ok)
        ev.infeasible += int(np.count_nonzero(~ok2))
        p = counted(p, len(ok))  # the path of each feasible design again, for its alignment
        p = recorded(p, U2, Batch(v2, ok2, b.circuit[ok], None, len(ok)))
        return (st._replace(progress=p), np.concatenate([U, U2]), np.concatenate([b.value, v2]),
                np.concatenate([b.circuit, b.circuit[ok]]))

    # ------------------------------------------------------------------ search
    def _value_and_grad(self, p: Progress, v, c):
        value, grad, exact = smooth_value_and_grad(self.ev)(*put((jnp.asarray(v), jnp.asarray(c)), self.ev.sharding))
        value, grad, exact = np.asarray(value), np.asarray(grad), np.asarray(exact)
        p = counted(p, 2 * self.S, np.isfinite(exact))
        p = improved(p, np.asarray(lbfgs.u_of_v(jnp.asarray(v))), exact, c)
        return p, value, grad

    def started(self, st: GradientState) -> GradientState:
        queue = distinct(st.pool)
        if len(queue) == 0 or int(st.progress.evaluations) + 3 * self.S > self.budget:
            return st._replace(progress=st.progress._replace(done=np.bool_(True)))
        S = self.S
        first = queue[np.arange(S) % len(queue)]  # fewer distinct designs than starts: repeats
        rest = np.full(self.pool_size, -1, np.int64)
        rest[:max(0, len(queue) - S)] = queue[S:]
        v = lbfgs.v_of_u(st.pool.u[first])
        c = np.asarray(st.pool.circuit[first], np.int64)
        p, value, grad = self._value_and_grad(st.progress, v, c)
        return st._replace(progress=p, phase=np.int64(1), v=v, c=c, value=value, grad=grad,
                           active=np.isfinite(value), lbfgs=lbfgs.initial(self.memory, S, len(v[0])),
                           queue=rest, lane_mark=value.copy(), lane_stall=np.zeros(S, np.int64),
                           age=np.zeros(S, np.int64))

    def _iteration(self, st: GradientState) -> GradientState:
        v, g, f, p = st.v, st.grad, st.value, st.progress
        d, new_state = lbfgs.directions(self.ev, self.memory)(jnp.asarray(g), st.lbfgs, jnp.asarray(v))
        d = np.asarray(d)
        slope = np.sum(d * g, axis=1)
        bad = ~(slope < 0) | ~np.all(np.isfinite(d), axis=1)
        d = np.where(bad[:, None], -g, d)
        slope = np.where(bad, -np.sum(g * g, axis=1), slope)
        # a start's first step: at most 0.05 in the normalized variables
        dn = np.max(np.abs(d), axis=1)
        t = np.where((st.age == 0) | bad, np.minimum(1.0, 0.05 / np.maximum(dn, 1e-300)), 1.0)
        searching = st.active.copy()
        new_v, new_f, new_g = v.copy(), f.copy(), g.copy()
        for _ in range(self.linesearch_steps):
            if not searching.any() or int(p.evaluations) + 2 * self.S > self.budget:
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
        dropped = new_f < st.lane_mark - self.lane_drop * np.abs(st.lane_mark)
        return st._replace(progress=p, iteration=st.iteration + 1, v=new_v, value=new_f, grad=new_g,
                           active=st.active & moved & ~small,
                           lbfgs=lbfgs.select(moved, lbfgs.to_numpy(new_state), st.lbfgs),
                           lane_mark=np.where(dropped, new_f, st.lane_mark),
                           lane_stall=np.where(dropped, 0, st.lane_stall + 1), age=st.age + 1)

    def _refilled(self, st: GradientState) -> GradientState:
        """Stopped or stalled starts replaced by the next designs of the queue (the start at the
        best design only when stopped, or stalled by the strict test)."""
        waiting = st.queue[st.queue >= 0]
        if len(waiting) == 0:
            return st
        U = np.asarray(lbfgs.u_of_v(jnp.asarray(st.v)))
        best = np.all(np.abs(U - st.progress.best_u[None]) <= 1e-12, axis=1) & (st.c == st.progress.best_circuit)
        stalled = st.lane_stall >= np.where(best, self.patience, self.lane_patience)
        free = np.flatnonzero(~st.active | stalled)[:len(waiting)]
        if len(free) == 0 or int(st.progress.evaluations) + 2 * self.S > self.budget:
            return st
        rows = waiting[:len(free)]
        queue = np.full_like(st.queue, -1)
        queue[:len(waiting) - len(rows)] = waiting[len(rows):]
        v, c = st.v.copy(), st.c.copy()
        v[free] = lbfgs.v_of_u(st.pool.u[rows])
        c[free] = st.pool.circuit[rows]
        p, value, grad = self._value_and_grad(st.progress, v, c)
        mask = np.zeros(self.S, bool)
        mask[free] = True
        fresh = lbfgs.initial(self.memory, self.S, v.shape[1])
        return st._replace(progress=p, v=v, c=c, value=np.where(mask, value, st.value),
                           grad=np.where(mask[:, None], grad, st.grad),
                           active=np.where(mask, np.isfinite(value), st.active),
                           lbfgs=lbfgs.select(mask, fresh, st.lbfgs), queue=queue,
                           lane_mark=np.where(mask, value, st.lane_mark),
                           lane_stall=np.where(mask, 0, st.lane_stall), age=np.where(mask, 0, st.age))

    def searched(self, st: GradientState) -> GradientState:
        n = 0
        for _ in range(self.chunk_iterations):
            st = self._refilled(st)
            waiting = bool((st.queue >= 0).any())
            if (int(st.iteration) >= self.iterations or not st.active.any()
                    or int(st.progress.evaluations) + 2 * self.S > self.budget
                    or (not waiting and int(st.stall) >= self.patience)):
                st = st._replace(progress=st.progress._replace(done=np.bool_(True)))
                break
            st = self._iteration(st)
            n += 1
        if bool(st.progress.done) and self.ev.objective.residuals is not None:
            st = st._replace(progress=self._polished(st))
        p = st.progress
        # no start improves: the best has not dropped by `self.drop` (relative) for `patience`
        # iterations
        if float(p.best_value) < float(st.mark) - self.drop * abs(float(st.mark)) or not np.isfinite(st.mark):
            st = st._replace(mark=np.float64(p.best_value), stall=np.int64(0))
        else:
            st = st._replace(stall=np.int64(st.stall + n))
        return st._replace(progress=next_chunk(p))


    def _polished(self, st: GradientState) -> Progress:
        """Levenberg–Marquardt on the residuals of the best design and the 7 best other final
        starts, in one batch: step dv = −(JᵀJ + λ diag JᵀJ)⁻¹ Jᵀr, accepted where Σr² drops (λ ÷ 3), else
        λ × 4; at most `polish_iterations`, each 1 + V evaluations per start (the Jacobian by
        forward mode). Where the least-squares structure is known this converges in a few steps
        where L-BFGS on Σr² crawls. With `boundary` (a mechanism of dyads) each step keeps the
        screen's margin ≥ `boundary.TARGET` to first order, and a trial near the boundary is
        projected back onto it first (`boundary.py`): the polish slides along the feasibility
        boundary instead of stopping where it touches it."""
        p, V = st.progress, st.v.shape[1]
        nd = self.ev.n_devices
        S = min(self.S, -(-self.polish_starts // nd) * nd)
        # with the boundary followed (a mechanism of dyads on a revolution): the screen's margin
        # m and its gradient a come with the residuals, the step keeps m ≥ TARGET to first order
        # and a trial near the boundary is projected back onto it (`boundary.py`). That costs
        # `PROJECTION_STEPS` + 1 margin-only evaluations with their forward tangents per design
        # and call (measured +35 % of a polish call at V = 4), charged 2 per polished start.
        follow = self.boundary and self.ev.between
        cost = S * (1 + V) + (2 * S if follow else 0)
        if not p.found or int(p.evaluations) + 2 * cost > self.budget:
            return p
        # the best design and the S − 1 best other final starts
        order = np.argsort(np.where(np.isfinite(st.value), st.value, np.inf), kind="stable")[:S]
        v, c = st.v[order].copy(), st.c[order].copy()
        v[-1], c[-1] = lbfgs.v_of_u(p.best_u), p.best_circuit
        fn = _boundary.polish_call(self.ev) if follow else residuals_and_jacobian(self.ev)

        def call(p, v, near=None):
            args = (jnp.asarray(v), jnp.asarray(c)) + (() if near is None else (jnp.asarray(near),))
            out = [np.array(a) for a in fn(*put(args, self.ev.sharding))]
            if follow:
                v, out = out[0], out[1:]
            r, J, ok, *ma = out
            F = np.where(ok, np.sum(r * r, axis=1), np.inf)
            p = counted(p, cost, ok)
            return improved(p, np.asarray(lbfgs.u_of_v(jnp.asarray(v))), F, c), v, r, J, F, ma

        p, v, r, J, F, ma = call(p, v, np.zeros(S, bool) if follow else None)
        lam = np.full(S, 1e-3)
        live = np.isfinite(F)
        for _ in range(self.polish_iterations):
            if not live.any() or int(p.evaluations) + cost > self.budget:
                break
            A = np.einsum("srv,srw->svw", J, J)
            g = np.einsum("srv,sr->sv", J, r)
            dg = np.maximum(np.diagonal(A, axis1=1, axis2=2), 1e-12 * np.max(np.abs(A), axis=(1, 2))[:, None] + 1e-300)
            M = A + lam[:, None, None] * (dg[:, :, None] * np.eye(V)[None])
            try:
                if follow:
                    dv, binds = _boundary.constrained(M, g, *ma)
                else:
                    dv = -np.linalg.solve(M, g[..., None])[..., 0]
            except np.linalg.LinAlgError:
                break
            dv = np.where(live[:, None] & np.all(np.isfinite(dv), axis=1, keepdims=True), dv, 0.0)
            # the designs near the boundary are projected back onto it
            near = live & (binds | (ma[0] < _boundary.NEAR)) if follow else None
            p, trial, r2, J2, F2, ma2 = call(p, v + dv, near)
            acc = live & (F2 < F)
            v[acc], r[acc], J[acc] = trial[acc], r2[acc], J2[acc]
            for x, x2 in zip(ma, ma2):
                x[acc] = x2[acc]
            small = acc & (F - F2 <= 1e-9 * F)
            F = np.where(acc, F2, F)
            lam = np.where(acc, lam / 3.0, lam * 4.0)
            live &= (lam < 1e12) & ~small
        return p


def distinct(pool: Pool, tol: float = 0.01) -> np.ndarray:
    """Rows of the feasible pool designs in pool order (best first), skipping a design within
    `tol` of a better kept one in every normalized variable on the same circuit."""
    kept: list[int] = []
    for i in np.flatnonzero(np.isfinite(pool.value)):
        if not any(pool.circuit[j] == pool.circuit[i] and np.max(np.abs(pool.u[j] - pool.u[i])) <= tol
                   for j in kept):
            kept.append(int(i))
    return np.asarray(kept, np.int64)
