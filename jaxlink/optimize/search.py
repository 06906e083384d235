"""Uniform search, Monte Carlo and gradient search on the same batched evaluator.

All three run in deterministic chunks (see `_checkpoint.py`) and count *mechanism evaluations*:
one design solved over its revolution on one circuit = 1; a value-and-gradient of one design = 2
(forward solve + backward pass: the implicit-differentiation backward pass costs 1.3–1.7 forward
solves, spec/anchors.md, so counting it as one more evaluation is fair). Under `vmap` a line
search runs until its slowest start is done: every start is charged for every executed trial.

- `uniform`, `grid`: a full grid of n points per variable (n = ⌊budget^(1/V)⌋, bounds included),
  evaluated in lexicographic order.
- `uniform`, `coordinate`: the seed's parameter-by-parameter stepping — from the file's design,
  sweep one variable at a time over n points (others fixed at the best so far), keep the best,
  go on to the next variable; after each cycle over all variables the sweep range shrinks to ±2
  steps of the previous one around the best.
- `montecarlo`: designs uniform at random in the bounds (numpy PCG64 seeded by (seed, chunk)).
- `gradient`: a Monte Carlo presample picks the best `starts` feasible designs (each on its best
  circuit), then L-BFGS (optax, zoom line search) runs from all of them in parallel on the
  smoothed objective, with exact gradients by implicit differentiation through the path solve;
  bounds by the smooth map u = (1 − cos πv)/2. The best start wins. With
  `gradient_solver = "al-lbfgs"` (objectives with constraints, e.g. `dwell`): an augmented
  Lagrangian with per-start line searches instead (`AugmentedLagrangian`).
"""

from __future__ import annotations

import functools
import math
import threading
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax

from . import checkpoint as _checkpoint
from .evaluator import Evaluator
from .sharding import put

METHODS = ("uniform", "montecarlo", "gradient")


def _common_state():
    return {
        "chunk": np.int64(0), "evaluations": np.int64(0), "designs": np.int64(0), "infeasible": np.int64(0),
        "best_value": np.float64(np.inf), "best_u": None, "best_circuit": np.int64(0), "wall_s": np.float64(0.0),
        "done": np.bool_(False),
    }


def _update_best(state, U, res):
    v = res["value"]
    if len(v) == 0:
        return
    i = int(np.argmin(v))  # first of equal values: deterministic
    if np.isfinite(v[i]) and v[i] < state["best_value"]:
        state["best_value"] = np.float64(v[i])
        state["best_u"] = np.asarray(U[i], dtype=np.float64)
        state["best_circuit"] = np.int64(res["circuit"][i])


def _count(state, ev, res, n):
    state["evaluations"] += np.int64(n * (ev.n_circuits if res.get("all_circuits") else 1))
    state["designs"] += np.int64(len(res["value"]))
    state["infeasible"] += np.int64((~res["feasible"]).sum())


def _evaluate(ev: Evaluator, U, circuits=None):
    res = ev.evaluate(U, circuits)
    res["all_circuits"] = circuits is None and ev.n_circuits > 1
    return res


# ----------------------------------------------------------------------------- Monte Carlo


class MonteCarlo:
    name = "montecarlo"

    def __init__(self, ev: Evaluator, *, budget: int, seed: int, **_):
        self.ev, self.budget, self.seed = ev, int(budget), int(seed)

    def init(self):
        return _common_state()

    def done(self, st):
        return st["evaluations"] + self.ev.n_circuits > self.budget

    def step(self, st):
        ev = self.ev
        n = min(ev.chunk, (self.budget - int(st["evaluations"])) // ev.n_circuits)
        rng = np.random.default_rng([self.seed, int(st["chunk"])])
        U = rng.random((ev.chunk, ev.problem.n_variables))[:n]
        res = _evaluate(ev, U)
        _count(st, ev, res, n)
        _update_best(st, U, res)
        st["chunk"] += 1
        return st


# ----------------------------------------------------------------------------- uniform


class UniformGrid:
    name = "uniform"

    def __init__(self, ev: Evaluator, *, budget: int, seed: int, **_):
        self.ev, self.budget = ev, int(budget)
        V = ev.problem.n_variables
        per = max(1, self.budget // ev.n_circuits)
        n = max(2, int(math.floor(per ** (1.0 / V) + 1e-9)))
        self.n, self.total = n, n**V

    def init(self):
        return _common_state()

    def done(self, st):
        return int(st["designs"]) >= self.total

    def step(self, st):
        ev = self.ev
        a = int(st["designs"])
        idx = np.arange(a, min(a + ev.chunk, self.total))
        multi = np.stack(np.unravel_index(idx, (self.n,) * ev.problem.n_variables), axis=1)
        U = multi / (self.n - 1)
        res = _evaluate(ev, U)
        _count(st, ev, res, len(U))
        _update_best(st, U, res)
        st["chunk"] += 1
        return st


class UniformCoordinate:
    name = "uniform"

    def __init__(self, ev: Evaluator, *, budget: int, seed: int, sweep: int = 21, **_):
        self.ev, self.budget, self.n = ev, int(budget), int(sweep)

    def init(self):
        st = _common_state()
        pr = self.ev.problem
        st["center"] = np.clip(pr.to_unit(pr.file_design()), 0.0, 1.0)
        st["half"] = np.float64(0.5)
        st["axis"] = np.int64(0)
        return st

    def done(self, st):
        return st["evaluations"] + self.n * self.ev.n_circuits > self.budget

    def step(self, st):
        ev = self.ev
        V = ev.problem.n_variables
        j = int(st["axis"])
        c = st["center"].copy()
        if st["half"] >= 0.5:
            vals = np.linspace(0.0, 1.0, self.n)
        else:
            vals = np.clip(c[j] + np.linspace(-st["half"], st["half"], self.n), 0.0, 1.0)
        U = np.repeat(c[None], self.n, axis=0)
        U[:, j] = vals
        res = _evaluate(ev, U)
        _count(st, ev, res, len(U))
        _update_best(st, U, res)
        if st["best_u"] is not None:
            st["center"] = st["best_u"].copy()
        st["axis"] = np.int64((j + 1) % V)
        if j == V - 1:
            step = 2 * st["half"] / (self.n - 1)
            st["half"] = np.float64(2 * step)
        st["chunk"] += 1
        return st


# ----------------------------------------------------------------------------- gradient


def _u_of_v(v):
    return 0.5 - 0.5 * jnp.cos(jnp.pi * v)


def _v_of_u(u):
    return np.arccos(np.clip(1.0 - 2.0 * np.asarray(u), -1.0, 1.0)) / np.pi


class _PresampledStarts:
    """Shared skeleton of the gradient searches: phase 0 draws a seeded Monte Carlo presample in
    chunks and keeps the `S` best designs (by `_pool_value`), then `_start` begins phase 1, whose
    chunks `_search_chunk` runs. Subclasses set `ev`, `budget`, `seed`, `S`, `presample`."""

    def init(self):
        st = _common_state()
        st["phase"] = np.int64(0)  # 0 presample, 1 search
        st["pool_value"] = np.full(self.S, np.inf)
        st["pool_u"] = np.zeros((self.S, self.ev.problem.n_variables))
        st["pool_circuit"] = np.zeros(self.S, np.int64)
        st["pool_n"] = np.int64(0)
        st["iteration"] = np.int64(0)
        return st

    def done(self, st):
        return bool(st["done"])

    def step(self, st):
        if int(st["phase"]) == 0:
            return self._presample_chunk(st)
        return self._search_chunk(st)

    def _presample_evaluate(self, st, U):
        """Evaluate (and count) presampled designs; returns the (U, res) to pool."""
        raise NotImplementedError

    def _pool_value(self, res):
        return res["value"]

    def _presample_chunk(self, st):
        ev = self.ev
        left = self.presample - int(st["pool_n"])
        n = min(ev.chunk, left, max(0, (self.budget - int(st["evaluations"])) // ev.n_circuits))
        if n > 0:
            rng = np.random.default_rng([self.seed, 1_000_003, int(st["chunk"])])
            U = rng.random((ev.chunk, ev.problem.n_variables))[:n]
            U, res = self._presample_evaluate(st, U)
            # keep the S best (stable order: by value, then by arrival)
            vals = np.concatenate([st["pool_value"], self._pool_value(res)])
            us = np.concatenate([st["pool_u"], U])
            cs = np.concatenate([st["pool_circuit"], res["circuit"]])
            order = np.argsort(vals, kind="stable")[: self.S]
            st["pool_value"], st["pool_u"], st["pool_circuit"] = vals[order], us[order], cs[order]
            st["pool_n"] += np.int64(n)
        st["chunk"] += 1
        if int(st["pool_n"]) >= self.presample or n == 0:
            self._start(st)
        return st


class Gradient(_PresampledStarts):
    """L-BFGS from a batch of starts (see module doc).

    Per iteration and start: the direction d = −H g from optax's `scale_by_lbfgs` (memory 10;
    reset to −g when it is not a descent direction), then a backtracking (Armijo) line search
    f(v + t d) ≤ f(v) + 10⁻⁴ t g·d, t = 1, ½, ¼, … (at most `linesearch_steps`); every trial is one
    batched value-and-gradient of all starts (2 evaluations each), and an infeasible trial
    (+inf) just fails the test. A start whose step or gradient has vanished stops moving.
    Knobs (keyword or `[optimize]`): `starts` (16), `presample` (8 × starts), `iterations` (200),
    `memory` (10), `linesearch_steps` (10), `chunk_iterations` (5, iterations per checkpoint).
    """

    name = "gradient"

    def __init__(self, ev: Evaluator, *, budget: int, seed: int, starts: int | None = None, presample: int | None = None,
                 iterations: int | None = None, memory: int = 10, linesearch_steps: int = 10,
                 chunk_iterations: int = 5, **_):
        self.ev, self.budget, self.seed = ev, int(budget), int(seed)
        pr = ev.problem
        s = int(starts or pr.option("starts", 16))
        self.S = -(-s // ev.n_devices) * ev.n_devices
        # at most a quarter of the budget goes to the presample
        self.presample = min(int(presample or pr.option("presample", 8 * self.S)),
                             max(self.S, self.budget // (4 * ev.n_circuits)))
        self.iterations = int(iterations or pr.option("iterations", 200))
        self.linesearch_steps = int(linesearch_steps)
        self.chunk_iterations = int(chunk_iterations)
        self.memory = int(memory)
        self.lbfgs = optax.scale_by_lbfgs(memory_size=self.memory)
        from .align import placement_of

        self.placement = placement_of(pr) if pr.objective == "points" else None

    # ------------------------------------------------------------------ jitted pieces
    @property
    def _vg(self):
        # cached on the evaluator: a second search on it does not recompile
        cache = self.ev.__dict__.setdefault("_jit_cache", {})
        if "value_and_grad" not in cache:
            ev = self.ev

            def one(v, c):
                value, grad = jax.value_and_grad(lambda vv: ev.smooth_single(_u_of_v(vv), c))(v)
                ok = jnp.isfinite(value) & jnp.all(jnp.isfinite(grad))
                return jnp.where(ok, value, jnp.inf), jnp.where(ok, grad, 0.0)

            cache["value_and_grad"] = jax.jit(jax.vmap(one))
        return cache["value_and_grad"]

    @property
    def _dir(self):
        cache = self.ev.__dict__.setdefault("_jit_cache", {})
        key = ("lbfgs_direction", self.memory)
        if key not in cache:
            lbfgs = self.lbfgs

            def one(grad, state, v):
                d, state = lbfgs.update(grad, state, v)
                return -d, state

            cache[key] = jax.jit(jax.vmap(one))
        return cache[key]

    def _value_and_grad(self, st, v):
        value, grad = self._vg(*put((jnp.asarray(v), jnp.asarray(st["c"])), self.ev.sharding))
        st["evaluations"] += np.int64(2 * self.S)
        return np.asarray(value), np.asarray(grad)

    def _presample_evaluate(self, st, U):
        res = _evaluate(self.ev, U)
        _count(st, self.ev, res, len(U))
        _update_best(st, U, res)
        if self.placement is not None:
            U, res = self._aligned(st, U, res)
        return U, res

    def _aligned(self, st, U, res):
        """Presampled feasible designs moved to their best similarity placement (`_align.py`),
        evaluated, and pooled with the originals. Costs 2 evaluations per feasible design."""
        from .align import apply_similarity, icp_similarity

        ev, pr = self.ev, self.ev.problem
        ok = np.flatnonzero(res["feasible"])
        if len(ok) == 0:
            return U, res
        xy, _ = ev.paths(U[ok], res["circuit"][ok])
        st["evaluations"] += np.int64(len(ok))
        targets = jnp.asarray(np.asarray(pr.option("targets"), dtype=float))
        s, th, t, _ = (np.asarray(a) for a in icp_similarity(jnp.asarray(xy), targets))
        X = apply_similarity(pr, pr.to_file_units(U[ok]), s, th, t)
        U2 = np.clip(pr.to_unit(X), 0.0, 1.0)
        res2 = _evaluate(ev, U2, res["circuit"][ok])
        _count(st, ev, res2, len(U2))
        _update_best(st, U2, res2)
        both = {k: np.concatenate([res[k], res2[k]]) for k in ("value", "feasible", "circuit")}
        return np.concatenate([U, U2]), both

    def _start(self, st):
        ok = np.isfinite(st["pool_value"])
        if not ok.any() or int(st["evaluations"]) + 3 * self.S > self.budget:
            st["done"] = np.bool_(True)
            return
        # starts not found feasible: repeat the best ones (they then move alike; harmless)
        idx = np.where(ok, np.arange(self.S), np.flatnonzero(ok)[np.arange(self.S) % ok.sum()])
        st["v"] = _v_of_u(st["pool_u"][idx])
        st["c"] = np.asarray(st["pool_circuit"][idx], np.int64)
        st["value"], st["grad"] = self._value_and_grad(st, st["v"])
        st["active"] = np.isfinite(st["value"])
        self._save_opt(st, jax.vmap(self.lbfgs.init)(jnp.asarray(st["v"])))
        st["phase"] = np.int64(1)

    def _save_opt(self, st, opt_state):
        for i, leaf in enumerate(jax.tree_util.tree_leaves(opt_state)):
            st[f"opt_{i}"] = np.asarray(leaf)
        st["opt_n"] = np.int64(len(jax.tree_util.tree_leaves(opt_state)))

    def _load_opt(self, st):
        template = jax.eval_shape(jax.vmap(self.lbfgs.init), jnp.zeros((self.S, self.ev.problem.n_variables)))
        leaves = [jnp.asarray(st[f"opt_{i}"]) for i in range(int(st["opt_n"]))]
        return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(template), leaves)

    def _iteration(self, st):
        v, g, f = st["v"], st["grad"], st["value"]
        opt_state = self._load_opt(st)
        d, new_state = self._dir(jnp.asarray(g), opt_state, jnp.asarray(v))
        d = np.asarray(d)
        slope = np.sum(d * g, axis=1)
        bad = ~(slope < 0) | ~np.all(np.isfinite(d), axis=1)
        d = np.where(bad[:, None], -g, d)
        slope = np.where(bad, -np.sum(g * g, axis=1), slope)
        # the first step: at most 0.05 in the normalized variables
        dn = np.max(np.abs(d), axis=1)
        t = np.where((int(st["iteration"]) == 0) | bad, np.minimum(1.0, 0.05 / np.maximum(dn, 1e-300)), 1.0)
        searching = st["active"].copy()
        new_v, new_f, new_g = v.copy(), f.copy(), g.copy()
        for _ in range(self.linesearch_steps):
            # a trial costs 2S; S more are kept for the exact evaluation at the end of the chunk
            if not searching.any() or int(st["evaluations"]) + 3 * self.S > self.budget:
                break
            trial = np.where(searching[:, None], v + t[:, None] * d, v)
            tf, tg = self._value_and_grad(st, trial)
            accept = searching & np.isfinite(tf) & (tf <= f + 1e-4 * t * slope)
            new_v[accept], new_f[accept], new_g[accept] = trial[accept], tf[accept], tg[accept]
            searching &= ~accept
            t = np.where(searching, 0.5 * t, t)
        moved = np.any(new_v != v, axis=1)
        # a start that could not move (step underflow, stationary point) stops
        small = np.max(np.abs(new_g), axis=1) <= 1e-12 * np.maximum(1.0, np.abs(new_f))
        st["active"] = st["active"] & moved & ~small
        # the L-BFGS memory advances only for starts that moved
        keep = jax.tree_util.tree_map(
            lambda new, old: np.where(moved.reshape((-1,) + (1,) * (np.ndim(new) - 1)), np.asarray(new),
                                      np.asarray(old)), new_state, opt_state)
        self._save_opt(st, keep)
        st["v"], st["value"], st["grad"] = new_v, new_f, new_g
        st["iteration"] += 1

    def _search_chunk(self, st):
        for _ in range(self.chunk_iterations):
            if (int(st["iteration"]) >= self.iterations or not st["active"].any()
                    or int(st["evaluations"]) + 2 * self.S + self.S > self.budget):
                st["done"] = np.bool_(True)
                break
            self._iteration(st)
        # the exact objective at the current iterates decides the best (S evaluations)
        U = np.asarray(_u_of_v(jnp.asarray(st["v"])))
        res = _evaluate(self.ev, U, st["c"])
        _count(st, self.ev, res, len(U))
        _update_best(st, U, res)
        st["chunk"] += 1
        return st


class AugmentedLagrangian(_PresampledStarts):
    """Gradient search for objectives with constraints (`Objective.constraints`), selected by
    `[optimize] gradient_solver = "al-lbfgs"`: minimize f subject to c_E(x) = 0, c_I(x) ≤ 0
    (normalized) from a batch of starts.

    - **Starts**: a Monte Carlo presample (`presample` designs, numpy PCG64 seeded by (seed,
      chunk)) ranked by the objective's `rank` value (default its value); the `starts` best.
    - **Augmented Lagrangian** (per start, multipliers λ, weight ρ = `al_rho`):
      Φ = f + λ_E·c_E + ρ/2 |c_E|² + ρ/2 Σ_I [max(0, c_I + λ_I/ρ)² − (λ_I/ρ)²]; every
      `al_every` steps λ_E += ρ c_E, λ_I = max(0, λ_I + ρ c_I) and Φ, ∇Φ are re-evaluated at
      the current points. With the multipliers the active constraints are met exactly at a
      moderate ρ, instead of the ill-conditioned walls of a quadratic penalty.
    - **L-BFGS** on Φ (memory `memory`), bounds by u = (1 − cos πv)/2, with a backtracking
      (Armijo, quadratic interpolation) line search *per start*: every batched call evaluates
      one trial point of every start (one value and gradient each, 2 evaluations), and each
      start accepts its trial or shortens its own step, so no start waits for the others'
      line searches. After `max_backtracks` failed trials a start forgets its curvature pairs
      and steps along −∇Φ.
    - The exact objective of every trial point comes with its gradient call (one path solve):
      the best exact value seen decides the result, at no extra evaluations.
    - The batched value-and-gradient is compiled in a background thread while the presample runs.

    `iterations` counts batched calls (trial points per start). Knobs (keyword or `[optimize]`):
    `starts` (16), `presample` (256 × starts, at most a quarter of the budget), `iterations`
    (600), `memory` (20), `al_rho` (1), `al_every` (20), `chunk_iterations` (10 calls per
    checkpoint).
    """

    name = "gradient"

    def __init__(self, ev: Evaluator, *, budget: int, seed: int, starts: int | None = None,
                 presample: int | None = None, iterations: int | None = None, memory: int | None = None,
                 al_rho: float | None = None, al_every: int | None = None, max_backtracks: int = 8,
                 chunk_iterations: int = 10, **_):
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

    @property
    def _vg(self):
        cache = self.ev.__dict__.setdefault("_jit_cache", {})
        if "al_value_and_grad" not in cache:
            ev = self.ev
            E = ev.objective.equalities

            def one(v, c, lam, rho):
                def phi(vv):
                    f, cons, exact, feas = ev.constrained_single(_u_of_v(vv), c)
                    ce, ci = cons[:E], cons[E:]
                    le, li = lam[:E], lam[E:]
                    val = (f + jnp.sum(le * ce) + 0.5 * rho * jnp.sum(ce * ce)
                           + 0.5 * rho * jnp.sum(jnp.maximum(0.0, ci + li / rho) ** 2 - (li / rho) ** 2))
                    return jnp.where(feas & jnp.isfinite(val), val, jnp.inf), (cons, exact, feas)

                (val, (cons, exact, feas)), grad = jax.value_and_grad(phi, has_aux=True)(v)
                ok = jnp.isfinite(val) & jnp.all(jnp.isfinite(grad))
                return jnp.where(ok, val, jnp.inf), jnp.where(ok, grad, 0.0), cons, exact, feas

            cache["al_value_and_grad"] = jax.jit(jax.vmap(one, in_axes=(0, 0, 0, None)))
        return cache["al_value_and_grad"]

    @functools.cached_property
    def n_constraints(self) -> int:
        V = self.ev.problem.n_variables
        return int(jax.eval_shape(lambda u: self.ev.constrained_single(u, 0)[1], jnp.zeros(V)).shape[0])

    def _precompile(self):
        """Compile the batched value-and-gradient ahead of its first call (run in a thread while
        the presample is evaluated: XLA compiles without holding the GIL)."""
        try:
            S, V, K = self.S, self.ev.problem.n_variables, self.n_constraints
            self._vg.lower(*self._args(np.zeros((S, V)), np.zeros(S, np.int64), np.zeros((S, K))), self.rho).compile()
        except Exception:  # noqa: BLE001, S110 - the first real call compiles (and reports) instead
            pass

    def _args(self, *arrays):
        if self.ev.n_devices == 1:
            return arrays
        return put(tuple(jnp.asarray(a) for a in arrays), self.ev.sharding)

    def _call(self, st, v):
        val, grad, cons, exact, feas = self._vg(*self._args(v, st["c"], st["lam"]), self.rho)
        st["evaluations"] += np.int64(2 * self.S)
        st["designs"] += np.int64(self.S)
        feas = np.asarray(feas)
        st["infeasible"] += np.int64((~feas).sum())
        exact = np.asarray(exact)
        _update_best(st, 0.5 - 0.5 * np.cos(np.pi * v), {"value": exact, "circuit": st["c"]})
        return np.array(val), np.array(grad), np.array(cons)

    # ------------------------------------------------------------------ presample
    def _presample_evaluate(self, st, U):
        if getattr(self, "_compiler", None) is None:  # compile the search while the presample runs
            self._compiler = threading.Thread(target=self._precompile, daemon=True)
            self._compiler.start()
        res = self.ev.evaluate(U, rank=True)
        res["all_circuits"] = self.ev.n_circuits > 1
        _count(st, self.ev, res, len(U))
        _update_best(st, U, res)
        return U, res

    def _pool_value(self, res):
        return res["rank"]

    def _start(self, st):
        if getattr(self, "_compiler", None) is not None:
            self._compiler.join()
        ok = np.isfinite(st["pool_value"])
        if not ok.any() or int(st["evaluations"]) + 2 * self.S > self.budget:
            st["done"] = np.bool_(True)
            return
        S, V, M, K = self.S, self.ev.problem.n_variables, self.memory, self.n_constraints
        idx = np.where(ok, np.arange(S), np.flatnonzero(ok)[np.arange(S) % ok.sum()])
        st["c"] = np.asarray(st["pool_circuit"][idx], np.int64)
        st["lam"] = np.zeros((S, K))
        st["v"] = _v_of_u(st["pool_u"][idx])
        st["F"], st["G"], st["C"] = self._call(st, st["v"])
        st["mem_s"] = np.zeros((S, M, V))
        st["mem_y"] = np.zeros((S, M, V))
        st["mem_n"] = np.zeros(S, np.int64)
        st["nback"] = np.zeros(S, np.int64)
        st["since"] = np.int64(0)
        self._directions(st, np.ones(S, bool))
        st["phase"] = np.int64(1)

    # ------------------------------------------------------------------ L-BFGS, per start
    def _two_loop(self, st):
        """−H∇Φ of every start from its curvature pairs (oldest first; vectorized)."""
        Ss, Ys, n = st["mem_s"], st["mem_y"], st["mem_n"]
        M = Ss.shape[1]
        q = st["G"].copy()
        alpha = np.zeros((len(q), M))
        sy = np.einsum("imv,imv->im", Ss, Ys)
        valid = np.arange(M)[None, :] < n[:, None]
        rho = np.where(valid, 1.0 / np.where(valid, sy, 1.0), 0.0)
        for j in reversed(range(M)):
            a = rho[:, j] * np.einsum("iv,iv->i", Ss[:, j], q)
            alpha[:, j] = a
            q -= a[:, None] * Ys[:, j]
        last = np.maximum(n - 1, 0)
        ys, yy = Ys[np.arange(len(q)), last], Ys[np.arange(len(q)), last]
        sl = Ss[np.arange(len(q)), last]
        gamma = np.where(n > 0, np.einsum("iv,iv->i", sl, ys) / np.maximum(np.einsum("iv,iv->i", yy, yy), 1e-300),
                         1.0)
        r = gamma[:, None] * q
        for j in range(M):
            b = rho[:, j] * np.einsum("iv,iv->i", Ys[:, j], r)
            r += (alpha[:, j] - b)[:, None] * Ss[:, j]
        return -r

    def _directions(self, st, which):
        """New search directions and first trial steps for the starts `which`."""
        G = st["G"]
        d = self._two_loop(st)
        slope = np.sum(d * G, axis=1)
        bad = ~(slope < 0) | ~np.all(np.isfinite(d), axis=1) | (st["mem_n"] == 0)
        reset = bad & (st["mem_n"] > 0)
        st["mem_n"] = np.where(which & reset, 0, st["mem_n"])
        d = np.where(bad[:, None], -G, d)
        slope = np.where(bad, -np.sum(G * G, axis=1), slope)
        t = np.where(bad, np.minimum(1.0, self.step0 / np.maximum(np.max(np.abs(d), axis=1), 1e-300)), 1.0)
        for k, new in (("d", d), ("slope", slope), ("t", t)):
            st[k] = np.where(which.reshape((-1,) + (1,) * (new.ndim - 1)), new, st[k]) if k in st else new
        st["nback"] = np.where(which, 0, st["nback"])

    def _iteration(self, st):
        v, F, G, d, t, slope = st["v"], st["F"], st["G"], st["d"], st["t"], st["slope"]
        alive = np.isfinite(F)
        trial = np.where(alive[:, None], v + t[:, None] * d, v)
        tF, tG, tC = self._call(st, trial)
        acc = alive & np.isfinite(tF) & (tF <= F + 1e-4 * t * slope)
        # curvature pairs of the accepted steps
        s_, y_ = trial - v, tG - G
        sy = np.sum(s_ * y_, axis=1)
        good = acc & (sy > 1e-10 * np.linalg.norm(s_, axis=1) * np.linalg.norm(y_, axis=1))
        M = self.memory
        for i in np.flatnonzero(good):
            n = int(st["mem_n"][i])
            if n == M:
                st["mem_s"][i, :-1], st["mem_y"][i, :-1] = st["mem_s"][i, 1:].copy(), st["mem_y"][i, 1:].copy()
                n -= 1
            st["mem_s"][i, n], st["mem_y"][i, n] = s_[i], y_[i]
            st["mem_n"][i] = n + 1
        st["v"] = np.where(acc[:, None], trial, v)
        st["F"] = np.where(acc, tF, F)
        st["G"] = np.where(acc[:, None], tG, G)
        st["C"] = np.where(acc[:, None], tC, st["C"])
        self._directions(st, acc)
        # rejected: shorten the step (quadratic interpolation, within [0.1 t, 0.5 t]) or restart
        rej = alive & ~acc
        st["nback"] = np.where(rej, st["nback"] + 1, st["nback"])
        restart = rej & (st["nback"] > self.max_backtracks)
        with np.errstate(divide="ignore", invalid="ignore"):
            tq = -slope * t**2 / (2.0 * (tF - F - slope * t))
        tq = np.where(np.isfinite(tq), np.clip(tq, 0.1 * t, 0.5 * t), 0.25 * t)
        st["t"] = np.where(rej, tq, st["t"])
        if restart.any():
            st["mem_n"] = np.where(restart, 0, st["mem_n"])
            self._directions(st, restart)
            st["t"] = np.where(restart, 0.1 * st["t"], st["t"])
        st["iteration"] += 1
        st["since"] += 1
        if st["since"] >= self.every:
            self._multipliers(st)

    def _multipliers(self, st):
        E = self.ev.objective.equalities
        C, lam = st["C"], st["lam"].copy()
        lam[:, :E] = lam[:, :E] + self.rho * C[:, :E]
        lam[:, E:] = np.maximum(0.0, lam[:, E:] + self.rho * C[:, E:])
        st["lam"] = np.where(np.isfinite(st["F"])[:, None] & np.all(np.isfinite(C), axis=1)[:, None], lam, st["lam"])
        st["since"] = np.int64(0)
        if int(st["evaluations"]) + 2 * self.S > self.budget:
            return
        st["F"], st["G"], st["C"] = self._call(st, st["v"])
        self._directions(st, np.ones(self.S, bool))
        # keep the curvature pairs: Φ changed only by the multiplier terms

    def _search_chunk(self, st):
        for _ in range(self.chunk_iterations):
            if (int(st["iteration"]) >= self.iterations or not np.isfinite(st["F"]).any()
                    or int(st["evaluations"]) + 2 * self.S > self.budget):
                st["done"] = np.bool_(True)
                break
            self._iteration(st)
        st["chunk"] += 1
        return st


def searcher(ev: Evaluator, method: str, *, budget: int, seed: int, uniform: str = "grid", **knobs):
    if method == "montecarlo":
        return MonteCarlo(ev, budget=budget, seed=seed, **knobs)
    if method == "uniform":
        cls = {"grid": UniformGrid, "coordinate": UniformCoordinate}[uniform]
        return cls(ev, budget=budget, seed=seed, **knobs)
    if method == "gradient":
        solver = knobs.pop("gradient_solver", None) or ev.problem.option("gradient_solver", "lbfgs")
        if solver == "al-lbfgs":
            return AugmentedLagrangian(ev, budget=budget, seed=seed, **knobs)
        if solver != "lbfgs":
            raise ev.problem.error(f"'gradient_solver' must be \"lbfgs\" or \"al-lbfgs\", got {solver!r}",
                                   "gradient_solver")
        return Gradient(ev, budget=budget, seed=seed, **knobs)
    raise ValueError(f"unknown method {method!r}; use one of {METHODS}")


# ----------------------------------------------------------------------------- driver


def _to_saveable(st):
    return {k: (np.zeros(0) if v is None else v) for k, v in st.items()}


def _from_saved(st):
    st = dict(st)
    if st.get("best_u") is not None and np.size(st["best_u"]) == 0:
        st["best_u"] = None
    for k, v in list(st.items()):
        if isinstance(v, np.ndarray) and v.ndim == 0:
            st[k] = v[()]
    return st


def summary(ev: Evaluator, method: str, st: dict, *, seed: int, budget: int, complete: bool, extra=None) -> dict:
    """The OUT.json document (spec/README.md): method, best (parameters in file units, objective,
    metrics), evaluations, wall_s, infeasible_fraction, and more."""
    pr = ev.problem
    if st.get("best_u") is not None:
        best = ev.report(st["best_u"], int(st["best_circuit"]))
        best["search_objective"] = float(st["best_value"])
    else:
        best = {"parameters": None, "objective": None, "metrics": {}, "feasible": False}
    designs = int(st["designs"])
    out = {
        "method": method,
        "file": pr.mech.file,
        "objective_kind": pr.objective,
        "variables": {n: [float(a), float(b)] for n, a, b in zip(pr.names, pr.lower, pr.upper)},
        "best": best,
        "evaluations": int(st["evaluations"]),
        "evaluation_unit": "one design solved over its revolution on one circuit; value+gradient = 2",
        "designs": designs,
        "wall_s": float(st["wall_s"]),
        "infeasible_fraction": (int(st["infeasible"]) / designs) if designs else 0.0,
        "seed": int(seed),
        "budget": int(budget),
        "samples": len(pr.phis),
        "devices": ev.n_devices,
        "complete": bool(complete),
    }
    if extra:
        out.update(extra)
    return out


def run(ev: Evaluator, method: str, *, budget: int, seed: int = 0, out=None, resume: bool = False,
        progress: bool = False, stop_after_chunks: int | None = None, **knobs) -> dict:
    """Run a search; returns the summary dict (also written to `out` if given).

    `stop_after_chunks` (testing): stop after that many chunks of this call, as if killed.
    """
    from ..errors import MechanismError

    s = searcher(ev, method, budget=budget, seed=seed, **knobs)
    extra = {"uniform": knobs.get("uniform", "grid")} if method == "uniform" else {}
    fp = _checkpoint.fingerprint(ev.problem, method, seed, budget, repr(sorted(knobs.items())))
    files = _checkpoint.paths(out) if out else None
    st = None
    if resume:
        if not files:
            raise MechanismError("--resume needs --out (the search's output file)")
        saved = _checkpoint.load_state(files[1])
        if saved is not None:
            if str(saved.get("fingerprint")) != fp:
                raise MechanismError(
                    f"{files[1]}: this checkpoint belongs to another search (file, [optimize], method, "
                    "seed, budget or knobs differ); run without --resume to start afresh")
            st = _from_saved({k: v for k, v in saved.items() if k != "fingerprint"})
    if st is None:
        st = s.init()
        if files:
            files[2].unlink(missing_ok=True)
            files[1].unlink(missing_ok=True)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=budget, initial=int(st["evaluations"]), unit="eval", desc=method, dynamic_ncols=True)
    chunks = 0
    try:
        while not s.done(st):
            if stop_after_chunks is not None and chunks >= stop_after_chunks:
                break
            t0 = time.perf_counter()
            before = int(st["evaluations"])
            st = s.step(st)
            st["wall_s"] = np.float64(st["wall_s"] + time.perf_counter() - t0)
            chunks += 1
            if bar is not None:
                bar.update(int(st["evaluations"]) - before)
                if np.isfinite(st["best_value"]):
                    bar.set_postfix(best=f"{float(st['best_value']):.6g}")
            if files:
                _checkpoint.save_state(files[1], {**_to_saveable(st), "fingerprint": np.asarray(fp)})
                _checkpoint.append_log(files[2], {
                    "chunk": int(st["chunk"]), "evaluations": int(st["evaluations"]),
                    "designs": int(st["designs"]), "infeasible": int(st["infeasible"]),
                    "best_value": float(st["best_value"]) if np.isfinite(st["best_value"]) else None,
                    "best_parameters": (None if st.get("best_u") is None else
                                        dict(zip(ev.problem.names, map(float, ev.problem.to_file_units(st["best_u"]))))),
                    "wall_s": float(st["wall_s"]),
                })
                _checkpoint.write_json_atomic(
                    files[0], summary(ev, method, st, seed=seed, budget=budget, complete=False, extra=extra))
    finally:
        if bar is not None:
            bar.close()
    complete = bool(s.done(st))
    result = summary(ev, method, st, seed=seed, budget=budget, complete=complete, extra=extra)
    if files:
        _checkpoint.write_json_atomic(files[0], result)
    return result
