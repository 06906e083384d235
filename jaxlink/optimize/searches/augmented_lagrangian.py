"""Gradient search for objectives with constraints (`Objective.constraints`), selected by
`[optimize] gradient_solver = "al-lbfgs"`: minimize f subject to c_E(x) = 0, c_I(x) ≤ 0
(normalized constraint values) from a batch of starts.

- **Starts**: a Monte Carlo presample (`base.PresampledStarts`) ranked by the objective's `rank`
  value (default its value); the `starts` best.
- **Augmented Lagrangian** (per start, multipliers λ, weight ρ = `al_rho`):
  Φ = f + λ_E·c_E + ρ/2 |c_E|² + ρ/2 Σ_I [max(0, c_I + λ_I/ρ)² − (λ_I/ρ)²]; every `al_every`
  calls λ_E += ρ c_E, λ_I = max(0, λ_I + ρ c_I), and Φ, ∇Φ are re-evaluated at the current
  points. With the multipliers the active constraints are met exactly at a moderate ρ, instead
  of the ill-conditioned walls of a quadratic penalty.
- **L-BFGS** on Φ (`lbfgs.py`: optax's direction, memory `memory`; bounds by
  u = (1 − cos πv)/2) with a backtracking Armijo line search *per start*: every batched call
  evaluates one trial point of every start (value and gradient, 2 evaluations), and each start
  accepts its trial or shortens its own step (quadratic interpolation within [0.1 t, 0.5 t]),
  so no start waits for the others' line searches. An accepted step stores its curvature pair
  when s·y > 10⁻¹⁰ |s| |y|. A direction that is not a descent direction, or one from no pair,
  is replaced by −∇Φ with a first step of at most `step0` in v (the memory is forgotten); after
  `max_backtracks` failed trials a start forgets its pairs and steps along −∇Φ. After a
  multiplier update the pairs are kept (Φ changed only by the multiplier terms). An accepted
  step without a stored pair, and a multiplier update, give optax's state the new point without
  a pair (`lbfgs.anchored`): optax then writes an empty pair (into the oldest pair's slot) and
  that one direction starts from H₀ = I instead of (s·y / y·y) I.
- The exact objective of every trial point comes with its gradient call (one path solve): the
  best exact value seen decides the result, at no extra evaluations.
- The batched value-and-gradient is compiled in a thread while the presample runs; an error
  there is raised when the search starts.

`iterations` counts batched calls (trial points per start). **Arguments** (keyword, else
`[optimize]`): `starts` (16), `presample` (256 × starts, at most a quarter of the budget),
`iterations` (600), `memory` (20), `al_rho` (1), `al_every` (20), `max_backtracks` (8),
`chunk_iterations` (10 calls per checkpoint).
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
    Pool,
    PresampledStarts,
    Progress,
    compile_ahead,
    counted,
    empty_pool,
    evaluate,
    improved,
    next_chunk,
    progress_start,
    recorded,
    start_indices,
)


def constraint_count(ev: Evaluator) -> int:
    V = ev.problem.n_variables
    return int(jax.eval_shape(lambda u: ev.constrained_single(u, 0)[1], jnp.zeros(V)).shape[0])


def merit_value_and_grad(ev: Evaluator):
    """Jitted (v (S, V), circuits (S,), λ (S, K), ρ) → (Φ (S,), ∇Φ in v (S, V), constraints
    (S, K), exact objective (S,), feasible (S,)); Φ = +inf and ∇Φ = 0 where the design is
    infeasible or either is not finite."""

    def build():
        E = ev.objective.equalities

        def one(v, c, lam, rho):
            def merit(vv):
                f, cons, exact, feas = ev.constrained_single(lbfgs.u_of_v(vv), c)
                ce, ci = cons[:E], cons[E:]
                le, li = lam[:E], lam[E:]
                val = (f + jnp.sum(le * ce) + 0.5 * rho * jnp.sum(ce * ce)
                       + 0.5 * rho * jnp.sum(jnp.maximum(0.0, ci + li / rho) ** 2 - (li / rho) ** 2))
                return jnp.where(feas & jnp.isfinite(val), val, jnp.inf), (cons, exact, feas)

            (val, (cons, exact, feas)), grad = jax.value_and_grad(merit, has_aux=True)(v)
            ok = jnp.isfinite(val) & jnp.all(jnp.isfinite(grad))
            return jnp.where(ok, val, jnp.inf), jnp.where(ok, grad, 0.0), cons, exact, feas

        return jax.jit(jax.vmap(one, in_axes=(0, 0, 0, None)))

    return ev.compiled(("augmented_lagrangian.merit_value_and_grad",), build)


class ALState(NamedTuple):
    progress: Progress
    phase: np.int64  # 0 presample, 1 search
    pool: Pool
    iteration: np.int64  # batched calls made
    c: np.ndarray  # (S,) circuits
    lam: np.ndarray  # (S, K) multipliers
    v: np.ndarray  # (S, V) current points (unbounded variables)
    phi: np.ndarray  # (S,) Φ at v
    grad: np.ndarray  # (S, V) ∇Φ at v
    cons: np.ndarray  # (S, K) constraint values at v
    direction: np.ndarray  # (S, V)
    slope: np.ndarray  # (S,) ∇Φ·direction
    step: np.ndarray  # (S,) the next trial step along the direction
    backtracks: np.ndarray  # (S,) failed trials since the last accepted one
    since: np.int64  # calls since the last multiplier update
    lbfgs: Any  # optax's ScaleByLBFGSState, leading axis = starts (remembers (v, ∇Φ))


class AugmentedLagrangian(PresampledStarts):
    """See the module doc."""

    name = "gradient"

    def __init__(self, ev: Evaluator, *, budget: int, seed: int, starts: int | None = None,
                 presample: int | None = None, iterations: int | None = None, memory: int | None = None,
                 al_rho: float | None = None, al_every: int | None = None, max_backtracks: int = 8,
                 chunk_iterations: int = 10):
        pr = ev.problem
        if ev.objective.constraints is None:
            raise pr.error(f"gradient_solver = \"al-lbfgs\" needs an objective with constraints; "
                           f"'{pr.objective}' has none (use \"lbfgs\")", "gradient_solver")
        self.ev, self.budget, self.seed = ev, int(budget), int(seed)
        s = int(starts or pr.option("starts", 16))
        self.S = -(-s // ev.n_devices) * ev.n_devices
        self.presample = min(int(presample or pr.option("presample", 256 * self.S)),
                             max(self.S, self.budget // (4 * ev.n_circuits)))
        self.iterations = int(iterations or pr.option("iterations", 600))
        self.memory = int(memory or pr.option("memory", 20))
        self.rho = float(al_rho or pr.option("al_rho", 1.0))
        self.every = int(al_every or pr.option("al_every", 20))
        self.max_backtracks = int(max_backtracks)
        self.chunk_iterations = int(chunk_iterations)
        self.step0 = 0.02  # the first (and a restarted) step moves at most this far in v
        self.K = constraint_count(ev)

    def init(self) -> ALState:
        S, V, K = self.S, self.ev.problem.n_variables, self.K
        z = np.zeros(S)
        return ALState(progress_start(V), np.int64(0), empty_pool(S, V), np.int64(0), np.zeros(S, np.int64),
                       np.zeros((S, K)), np.zeros((S, V)), np.full(S, np.inf), np.zeros((S, V)), np.zeros((S, K)),
                       np.zeros((S, V)), z, z, np.zeros(S, np.int64), np.int64(0), lbfgs.initial(self.memory, S, V))

    # ------------------------------------------------------------------ the batched call
    def _arrays(self, *arrays):
        if self.ev.n_devices == 1:
            return arrays
        return put(tuple(jnp.asarray(a) for a in arrays), self.ev.sharding)

    def _executables(self):
        """Futures of the compiled value-and-gradient and L-BFGS directions for this search's
        shapes, compiled in threads (`compile_ahead`: `result()` raises what the compilation
        raised); kept on the evaluator."""
        ev, S, V, K, M = self.ev, self.S, self.ev.problem.n_variables, self.K, self.memory
        merit = ev.compiled(("augmented_lagrangian.merit_value_and_grad.executable", S), lambda: compile_ahead(
            merit_value_and_grad(ev), *self._arrays(np.zeros((S, V)), np.zeros(S, np.int64), np.zeros((S, K))),
            self.rho))
        directions = ev.compiled(("lbfgs.directions.executable", M, S), lambda: compile_ahead(
            lbfgs.directions(ev, M), np.zeros((S, V)), lbfgs.initial(M, S, V), np.zeros((S, V))))
        return merit, directions

    def _call(self, p: Progress, v, c, lam):
        """(progress, Φ, ∇Φ, constraints) at the points v of every start; counts 2 evaluations
        per start and keeps the best exact value."""
        val, grad, cons, exact, feas = self._executables()[0].result()(*self._arrays(v, c, lam), self.rho)
        feas = np.asarray(feas)
        p = counted(p, 2 * self.S, feas)
        p = improved(p, 0.5 - 0.5 * np.cos(np.pi * v), np.asarray(exact), c)
        return p, np.array(val), np.array(grad), np.array(cons)

    # ------------------------------------------------------------------ presample
    def presampled(self, st: ALState, U):
        self._executables()  # compile the search while the presample runs
        b = evaluate(self.ev, U, rank=True)
        return st._replace(progress=recorded(st.progress, U, b)), U, b.rank, b.circuit

    def started(self, st: ALState) -> ALState:
        for compiled in self._executables():
            compiled.result()
        idx = start_indices(st.pool)
        if idx is None or int(st.progress.evaluations) + 2 * self.S > self.budget:
            return st._replace(progress=st.progress._replace(done=np.bool_(True)))
        c = np.asarray(st.pool.circuit[idx], np.int64)
        lam = np.zeros((self.S, self.K))
        v = lbfgs.v_of_u(st.pool.u[idx])
        p, phi, grad, cons = self._call(st.progress, v, c, lam)
        st = st._replace(progress=p, phase=np.int64(1), c=c, lam=lam, v=v, phi=phi, grad=grad, cons=cons,
                         lbfgs=lbfgs.forgotten(st.lbfgs, v, grad))
        return self._directions(st, np.ones(self.S, bool), st.lbfgs, np.zeros((self.S, self.ev.problem.n_variables)))

    # ------------------------------------------------------------------ L-BFGS, per start
    def _directions(self, st: ALState, which, state, d) -> ALState:
        """New directions and first trial steps for the starts `which`, from the L-BFGS
        directions `d` and states `state` at their current points (see the module doc)."""
        G = st.grad
        slope = np.sum(d * G, axis=1)
        bad = ~(slope < 0) | ~np.all(np.isfinite(d), axis=1) | lbfgs.empty(state)
        d = np.where(bad[:, None], -G, d)
        slope = np.where(bad, -np.sum(G * G, axis=1), slope)
        t = np.where(bad, np.minimum(1.0, self.step0 / np.maximum(np.max(np.abs(d), axis=1), 1e-300)), 1.0)
        state = lbfgs.select(bad, lbfgs.forgotten(state, st.v, G), state)
        return st._replace(direction=np.where(which[:, None], d, st.direction), slope=np.where(which, slope, st.slope),
                           step=np.where(which, t, st.step), backtracks=np.where(which, 0, st.backtracks),
                           lbfgs=lbfgs.select(which, state, st.lbfgs))

    def _iteration(self, st: ALState) -> ALState:
        v, F, G, d, t, slope = st.v, st.phi, st.grad, st.direction, st.step, st.slope
        alive = np.isfinite(F)
        trial = np.where(alive[:, None], v + t[:, None] * d, v)
        p, tF, tG, tC = self._call(st.progress, trial, st.c, st.lam)
        acc = alive & np.isfinite(tF) & (tF <= F + 1e-4 * t * slope)
        # the curvature pairs of the accepted steps (a pair without curvature is not stored)
        s_, y_ = trial - v, tG - G
        sy = np.sum(s_ * y_, axis=1)
        pair = acc & (sy > 1e-10 * np.linalg.norm(s_, axis=1) * np.linalg.norm(y_, axis=1))
        nv = np.where(acc[:, None], trial, v)
        nG = np.where(acc[:, None], tG, G)
        state = lbfgs.select(acc & ~pair, lbfgs.anchored(st.lbfgs, nv, nG), st.lbfgs)
        dL, state = self._executables()[1].result()(nG, state, nv)
        st = st._replace(progress=p, v=nv, phi=np.where(acc, tF, F), grad=nG,
                         cons=np.where(acc[:, None], tC, st.cons))
        st = self._directions(st, acc, lbfgs.to_numpy(state), np.asarray(dL))
        # rejected: shorten the step (quadratic interpolation, within [0.1 t, 0.5 t]) or restart
        rej = alive & ~acc
        nback = np.where(rej, st.backtracks + 1, st.backtracks)
        restart = rej & (nback > self.max_backtracks)
        with np.errstate(divide="ignore", invalid="ignore"):
            tq = -slope * t**2 / (2.0 * (tF - F - slope * t))
        tq = np.where(np.isfinite(tq), np.clip(tq, 0.1 * t, 0.5 * t), 0.25 * t)
        st = st._replace(step=np.where(rej, tq, st.step), backtracks=nback)
        if restart.any():
            st = self._directions(st, restart, lbfgs.forgotten(st.lbfgs, st.v, st.grad), st.direction)
            st = st._replace(step=np.where(restart, 0.1 * st.step, st.step))
        st = st._replace(iteration=st.iteration + 1, since=st.since + 1)
        if st.since >= self.every:
            st = self._multipliers(st)
        return st

    def _multipliers(self, st: ALState) -> ALState:
        E = self.ev.objective.equalities
        C, lam = st.cons, st.lam.copy()
        lam[:, :E] = lam[:, :E] + self.rho * C[:, :E]
        lam[:, E:] = np.maximum(0.0, lam[:, E:] + self.rho * C[:, E:])
        ok = np.isfinite(st.phi) & np.all(np.isfinite(C), axis=1)
        st = st._replace(lam=np.where(ok[:, None], lam, st.lam), since=np.int64(0))
        if int(st.progress.evaluations) + 2 * self.S > self.budget:
            return st
        p, phi, grad, cons = self._call(st.progress, st.v, st.c, st.lam)
        st = st._replace(progress=p, phi=phi, grad=grad, cons=cons)
        # the curvature pairs are kept (Φ changed only by the multiplier terms): the state
        # remembers the new gradient, so this direction stores no pair
        dL, state = self._executables()[1].result()(grad, lbfgs.anchored(st.lbfgs, st.v, grad), st.v)
        return self._directions(st, np.ones(self.S, bool), lbfgs.to_numpy(state), np.asarray(dL))

    def searched(self, st: ALState) -> ALState:
        for _ in range(self.chunk_iterations):
            if (int(st.iteration) >= self.iterations or not np.isfinite(st.phi).any()
                    or int(st.progress.evaluations) + 2 * self.S > self.budget):
                st = st._replace(progress=st.progress._replace(done=np.bool_(True)))
                break
            st = self._iteration(st)
        return st._replace(progress=next_chunk(st.progress))
