"""What every search shares: its progress record, the counting of mechanism evaluations, the
best-so-far update, and the presampled-starts skeleton of the gradient searches.

A search is an object with `init() -> state`, `done(state) -> bool` and `step(state) -> state`
(one deterministic chunk). Its state is a NamedTuple of numpy arrays (a pytree of fixed
structure from `init` on, so a checkpoint is its leaves) whose `progress` field is a `Progress`.

**Counting.** One mechanism evaluation = one design solved over its revolution on one circuit
(with `circuits = "all"` and no circuit given, one per circuit); a value and gradient of one
design = 2 (the forward solve and the backward pass of the implicit differentiation, which costs
about one more solve). Under `vmap` every start is charged for every trial it is given.
"""

from __future__ import annotations

import abc
import time
from concurrent.futures import Future, ThreadPoolExecutor
from typing import NamedTuple, Protocol

import numpy as np

from ..evaluator import Evaluator
from ..timing import waited


class Progress(NamedTuple):
    """Counters and the best design so far (every search)."""

    chunk: np.int64  # chunks done
    evaluations: np.int64  # mechanism evaluations (see the module doc)
    designs: np.int64  # designs evaluated
    infeasible: np.int64  # of which infeasible
    best_value: np.float64  # exact objective of the best design; +inf until a feasible one is seen
    best_u: np.ndarray  # (V,) its normalized design (zeros while best_value is +inf)
    best_circuit: np.int64  # its circuit
    wall_s: np.float64  # seconds spent in `step`
    done: np.bool_  # the search ended by itself
    compile_s: np.float64 = np.float64(0.0)  # of `wall_s`, seconds of compilation (`timing.py`)
    # the `RUNNERS_UP` best distinct designs seen (the best first; +inf: empty): the designs the
    # result falls back to when the best is not certified (`result.summarized`)
    runners_value: np.ndarray = np.full(0, np.inf)
    runners_u: np.ndarray = np.zeros((0, 0))
    runners_circuit: np.ndarray = np.zeros(0, np.int64)

    @property
    def found(self) -> bool:
        return bool(np.isfinite(self.best_value))


#: designs kept besides the best, to fall back to when the best is not certified
RUNNERS_UP = 8


def progress_start(n_variables: int) -> Progress:
    return Progress(chunk=np.int64(0), evaluations=np.int64(0), designs=np.int64(0), infeasible=np.int64(0),
                    best_value=np.float64(np.inf), best_u=np.zeros(n_variables), best_circuit=np.int64(0),
                    wall_s=np.float64(0.0), done=np.bool_(False), compile_s=np.float64(0.0),
                    runners_value=np.full(RUNNERS_UP, np.inf), runners_u=np.zeros((RUNNERS_UP, n_variables)),
                    runners_circuit=np.zeros(RUNNERS_UP, np.int64))


class Search(Protocol):
    name: str

    def init(self): ...

    def done(self, state) -> bool: ...

    def step(self, state): ...


class Batch(NamedTuple):
    """Exact objective of a batch of designs (`Evaluator.evaluate`) and what it cost."""

    value: np.ndarray  # (B,), +inf if infeasible
    feasible: np.ndarray  # (B,)
    circuit: np.ndarray  # (B,) the circuit evaluated (the best one with circuits = "all")
    rank: np.ndarray | None  # (B,) the objective's start-ranking value, if asked for
    evaluations: int


def evaluate(ev: Evaluator, U, circuits=None, *, rank: bool = False) -> Batch:
    res = ev.evaluate(U, circuits, rank=rank)
    per = ev.n_circuits if circuits is None and ev.n_circuits > 1 else 1
    return Batch(res["value"], res["feasible"], res["circuit"], res.get("rank"), len(res["value"]) * per)


def improved(p: Progress, U, value, circuit) -> Progress:
    """`p` with the best of the designs `U` (values `value`, circuits `circuit`) if it is better
    (the first of equal values: deterministic)."""
    if len(value) == 0:
        return p
    p = _runners(p, U, value, circuit)
    i = int(np.argmin(value))
    if np.isfinite(value[i]) and value[i] < p.best_value:
        return p._replace(best_value=np.float64(value[i]), best_u=np.asarray(U[i], dtype=np.float64),
                          best_circuit=np.int64(circuit[i]))
    return p


def _runners(p: Progress, U, value, circuit) -> Progress:
    """`p` with the designs `U` competing for the `RUNNERS_UP` best distinct designs (by value,
    then by arrival; a design equal to a kept one on the same circuit is skipped)."""
    K = len(p.runners_value)
    value = np.asarray(value, dtype=np.float64)
    new = np.flatnonzero(np.isfinite(value))
    if K == 0 or len(new) == 0:
        return p
    new = new[np.argsort(value[new], kind="stable")[:K]]
    vals = np.concatenate([p.runners_value, value[new]])
    us = np.concatenate([p.runners_u, np.asarray(U, dtype=np.float64)[new]])
    cs = np.concatenate([p.runners_circuit, np.asarray(circuit, dtype=np.int64)[new]])
    kept: list[int] = []
    for i in np.argsort(vals, kind="stable"):
        if not np.isfinite(vals[i]) or len(kept) == K:
            break
        if not any(cs[j] == cs[i] and np.array_equal(us[j], us[i]) for j in kept):
            kept.append(int(i))
    rv, ru, rc = np.full(K, np.inf), np.zeros_like(p.runners_u), np.zeros(K, np.int64)
    rv[:len(kept)], ru[:len(kept)], rc[:len(kept)] = vals[kept], us[kept], cs[kept]
    return p._replace(runners_value=rv, runners_u=ru, runners_circuit=rc)


def counted(p: Progress, evaluations: int, feasible=None) -> Progress:
    """`p` with `evaluations` more, and the designs `feasible` (B,) counted if given."""
    p = p._replace(evaluations=p.evaluations + np.int64(evaluations))
    if feasible is not None:
        p = p._replace(designs=p.designs + np.int64(len(feasible)),
                       infeasible=p.infeasible + np.int64((~np.asarray(feasible)).sum()))
    return p


def recorded(p: Progress, U, batch: Batch) -> Progress:
    """`p` after the evaluated batch: counted, and its best design kept."""
    return improved(counted(p, batch.evaluations, batch.feasible), U, batch.value, batch.circuit)


def next_chunk(p: Progress) -> Progress:
    return p._replace(chunk=p.chunk + 1)


BLOCK = 256  # rows per seeded block of random designs


def drawn(key: tuple[int, ...], start: int, n: int, n_variables: int) -> np.ndarray:
    """Rows `start … start + n − 1` of a seeded stream of uniform designs in [0, 1]^V: block k
    (rows 256 k … 256 k + 255) comes from numpy's PCG64 seeded by `key + (k,)`. The designs do not
    depend on how the stream is cut into chunks, so a search draws the same designs with any
    `chunk` (a 256-row chunk k is block k, as before the blocks existed)."""
    if n <= 0:
        return np.zeros((0, n_variables))
    first, last = start // BLOCK, (start + n - 1) // BLOCK
    rows = np.concatenate([np.random.default_rng([*key, k]).random((BLOCK, n_variables))
                           for k in range(first, last + 1)])
    off = start - first * BLOCK
    return rows[off:off + n]


def compile_ahead(fn, *args):
    """Compile the jitted `fn` for `args` in a thread (XLA compiles without holding the GIL, so
    the caller goes on evaluating meanwhile). The future's `result()` is the compiled executable,
    or raises what the tracing or compilation raised."""
    executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="jaxlink-compile")
    try:
        return _TimedFuture(executor.submit(lambda: fn.lower(*args).compile()))
    finally:
        executor.shutdown(wait=False)


class _TimedFuture:
    """A future whose first blocking `result()` counts its wait as compilation (`timing.waited`)."""

    def __init__(self, future: Future):
        self._future = future

    def done(self) -> bool:
        return self._future.done()

    def result(self):
        if not self._future.done():
            t0 = time.perf_counter()
            try:
                return self._future.result()
            finally:
                waited(time.perf_counter() - t0)
        return self._future.result()


# ----------------------------------------------------------------------------- presampled starts


class Pool(NamedTuple):
    """The `S` best presampled designs (by ranking value, then by arrival)."""

    value: np.ndarray  # (S,) ranking values, +inf for empty slots
    u: np.ndarray  # (S, V)
    circuit: np.ndarray  # (S,)
    n: np.int64  # designs presampled so far


def empty_pool(starts: int, n_variables: int) -> Pool:
    return Pool(np.full(starts, np.inf), np.zeros((starts, n_variables)), np.zeros(starts, np.int64), np.int64(0))


def pooled(pool: Pool, U, values, circuits) -> Pool:
    """`pool` with the designs `U` (ranking values `values`) competing for its slots."""
    vals = np.concatenate([pool.value, values])
    order = np.argsort(vals, kind="stable")[: len(pool.value)]
    return Pool(vals[order], np.concatenate([pool.u, U])[order], np.concatenate([pool.circuit, circuits])[order],
                pool.n)


def start_indices(pool: Pool) -> np.ndarray | None:
    """(S,) pool rows to start from: every feasible one, the empty slots filled with repeats of
    the best (they then move alike; harmless); None if none is feasible."""
    ok = np.isfinite(pool.value)
    if not ok.any():
        return None
    S = len(ok)
    return np.where(ok, np.arange(S), np.flatnonzero(ok)[np.arange(S) % ok.sum()])


class PresampledStarts(abc.ABC):
    """Skeleton of the gradient searches. Phase 0 draws a seeded Monte Carlo presample (`drawn`
    with the key (seed, 1000003)) in chunks and pools the `S` best designs; then
    `started` begins phase 1, whose chunks `searched` runs. The state has the fields `progress`,
    `phase` (0 presample, 1 search) and `pool`; subclasses set `ev`, `budget`, `seed`, `S`,
    `presample` and define `presampled`, `started` and `searched`."""

    ev: Evaluator
    budget: int
    seed: int
    S: int
    presample: int

    def done(self, st) -> bool:
        return bool(st.progress.done)

    def step(self, st):
        return self._presample_chunk(st) if int(st.phase) == 0 else self.searched(st)

    @abc.abstractmethod
    def presampled(self, st, U):
        """Evaluate (and count) presampled designs: (state, designs to pool, their ranking values,
        their circuits)."""

    @abc.abstractmethod
    def started(self, st):
        """The state that begins phase 1 from the pooled presample."""

    @abc.abstractmethod
    def searched(self, st):
        """One chunk of phase 1 (the method's own iterations)."""

    def _presample_chunk(self, st):
        ev = self.ev
        p = st.progress
        n = min(ev.chunk, self.presample - int(st.pool.n), max(0, (self.budget - int(p.evaluations)) // ev.n_circuits))
        if n > 0:
            U = drawn((self.seed, 1_000_003), int(st.pool.n), n, ev.problem.n_variables)
            st, U, values, circuits = self.presampled(st, U)
            st = st._replace(pool=pooled(st.pool, U, values, circuits)._replace(n=st.pool.n + np.int64(n)))
        st = st._replace(progress=next_chunk(st.progress))
        limit = getattr(self, "time", None)
        out_of_time = limit is not None and float(st.progress.wall_s) >= 0.3 * float(limit)
        if int(st.pool.n) >= self.presample or n == 0 or (out_of_time and bool(np.isfinite(st.pool.value).any())):
            st = self.started(st)
        return st
