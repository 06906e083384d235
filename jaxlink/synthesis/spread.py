"""A search round's batches cut into blocks of a fixed size and spread over this process's devices
and over several processes, without changing a single bit of the answer.

XLA compiles a reduction (a sum over a candidate's samples) into code whose order of additions
depends on the whole batch's shape, so that the same candidate computed in a batch of 8 and in a
batch of 16 can differ in the last bit, and 300 Adam steps make that another design. So every
batch of `n` rows is cut into `blocks(n, cap)`: the fewest blocks of at most `cap` rows, all of one
size (the last padded with the batch's first row), a size that depends on `n` and `cap` only; one
program compiled for one block computes every block, on whichever device. Devices and processes
take whole blocks (`Layout.mine`: a contiguous run of blocks per process, dealt to its devices in
turn), so the same executable code computes every candidate whatever the number of devices or
processes, the one-device case included: bit for bit the same answer (tests/test_synthesis_spread.py).

The blocks are dispatched to their devices before any result is read (JAX dispatches
asynchronously): the devices compute at once. A block's random draws (the screen's poses) come
from the batch's key folded with the block's index: they do not depend on who computes it. Every
process gathers every block's results (`Blocked.__call__`), so that all take the same decisions;
a decision made from the clock is process 0's (`agreed`).
"""

from __future__ import annotations

import time
from typing import Any, Callable, NamedTuple, Sequence

import jax
import numpy as np


def blocks(n: int, cap: int) -> tuple[int, int]:
    """(count, size) of the blocks a batch of `n` rows is cut into: the fewest blocks of at most
    `cap` rows, all of one size (count × size ≥ n; the excess, fewer than count rows, is padding)."""
    if n < 1 or cap < 1:
        raise ValueError(f"a batch of {n} rows in blocks of at most {cap}")
    k = -(-n // cap)
    return k, -(-n // k)


class Layout(NamedTuple):
    """Where blocks go: the first `devices` local devices of this process, `processes` processes in
    all, this one the `process`-th."""

    devices: int
    processes: int
    process: int

    def mine(self, k: int) -> range:
        """The blocks (of `k`) this process computes: a contiguous run, ⌈k / processes⌉ a process."""
        per = -(-k // self.processes)
        return range(min(k, self.process * per), min(k, (self.process + 1) * per))


def layout() -> Layout:
    """This process's devices and its place among the processes (`jax.distributed`)."""
    return Layout(len(jax.local_devices()), jax.process_count(), jax.process_index())


def pad(x: np.ndarray, rows: int) -> np.ndarray:
    """`x` with its first row repeated up to `rows` rows."""
    x = np.asarray(x)
    if len(x) >= rows:
        return x
    return np.concatenate([x, np.repeat(x[:1], rows - len(x), 0)])


class OutOfTime(Exception):
    """A batch abandoned between two blocks: the blocks left would not end by its `Blocked.deadline`."""


class Blocked:
    """A batch of `n` rows computed block by block (`blocks(n, size)`: `size` is the block's rows)
    by `programs` (one compiled program per device of `where`, the same code, for one block).
    The arguments at positions `rows` have the candidate axis first and are cut into blocks; the
    one at `keyed` (a PRNG key, or None) is folded with each block's index; the others go whole to
    every block. The outputs (a tuple, candidate axis first) come back whole, in row order, on
    every process (NumPy arrays). `programs` may also be a function that returns them (waiting for
    programs still compiling): called at their first use. `deadline` (a `time.perf_counter()`
    time, or None; one process only): the blocks are then computed a device's turn at a time, and
    the batch is abandoned (`OutOfTime`) before a turn when the turns left would not end by it at
    the time a turn takes (`turn_s`: measured on this batch's turns so far, before its first one
    on the call before; unknown before any, when only a deadline already passed stops it) — a run
    stops before its limit, not a block after it; the same bits for the blocks computed."""

    deadline: float | None = None
    #: the seconds one turn of blocks (one block per device) took, last measured (None: never)
    turn_s: float | None = None

    def __init__(self, programs: Sequence[Callable] | Callable[[], Sequence[Callable]], rows: tuple[int, ...],
                 keyed: int | None, where: Layout, n: int, size: int):
        self._programs, self.rows, self.keyed, self.where, self.n, self.size = programs, rows, keyed, where, n, size
        self.count = -(-n // size)

    @property
    def programs(self) -> Sequence[Callable]:
        """The programs, one per device (waited for on the first use when given as a function)."""
        if callable(self._programs):
            self._programs = list(self._programs())
        return self._programs

    def __call__(self, *args: Any) -> tuple[np.ndarray, ...]:
        devices = jax.local_devices()[:self.where.devices]
        programs = self.programs  # waited for (a program still compiling) before the clock of the turns
        k, size = self.count, self.size
        for i in self.rows:
            if len(args[i]) != self.n:
                raise AssertionError(f"a batch of {len(args[i])} rows for a program of {self.n}")
        cut = {i: pad(args[i], k * size) for i in self.rows}
        whole: dict[tuple[int, int], jax.Array] = {}
        mine = self.where.mine(k)
        pending: list = []
        turns = -(-len(mine) // len(devices))
        began = time.perf_counter() if self.deadline is not None else 0.0
        for j, blk in enumerate(mine):
            if self.deadline is not None and j % len(devices) == 0:  # a turn of every device done
                if pending:
                    jax.block_until_ready(pending[-1])
                now = time.perf_counter()
                done = j // len(devices)
                if done:
                    self.turn_s = (now - began) / done
                left = (turns - done) * (self.turn_s or 0.0)
                if now + left > self.deadline:
                    raise OutOfTime(f"a batch's {len(mine) - j} blocks left of {len(mine)}, {self.turn_s or 0.0:.2g} s "
                                    f"each, would not end in the {self.deadline - now:.1f} s left")
            d = j % len(devices)
            put = []
            for i, a in enumerate(args):
                if i in cut:
                    put.append(jax.device_put(cut[i][blk * size:(blk + 1) * size], devices[d]))
                elif i == self.keyed:
                    put.append(jax.device_put(jax.random.fold_in(a, blk), devices[d]))
                else:
                    if (i, d) not in whole:
                        whole[i, d] = jax.device_put(np.asarray(a), devices[d])
                    put.append(whole[i, d])
            pending.append(programs[d](*put))  # dispatched: every device starts before any is read
        local = [np.concatenate([np.asarray(out[o]) for out in pending]) for o in range(len(pending[0]))] \
            if pending else []
        if self.deadline is not None and turns:
            self.turn_s = (time.perf_counter() - began) / turns
        if self.where.processes == 1:
            return tuple(x[:self.n] for x in local)
        return tuple(x[:self.n] for x in _gathered(local, self.where, k, size, self._shapes()))

    def _shapes(self):
        """The outputs' (row shape, dtype): what a process with no block sends (padding only)."""
        return [(o.shape[1:], o.dtype) for o in self.programs[0].out_info]


def _gathered(local: list, where: Layout, k: int, size: int, shapes) -> list[np.ndarray]:
    """Every process's blocks' rows (`local`: this process's, in block order), on every process,
    in row order: each process's run padded to ⌈k / processes⌉ blocks, gathered, concatenated."""
    from jax.experimental import multihost_utils

    per = -(-k // where.processes) * size
    out = []
    for o, (shape, dtype) in enumerate(shapes):
        a = local[o] if local else np.zeros((0,) + tuple(shape), dtype)
        a = np.concatenate([a, np.zeros((per - len(a),) + a.shape[1:], a.dtype)]) if len(a) < per else a
        every = np.asarray(multihost_utils.process_allgather(a, tiled=False))  # (processes, per, ...)
        out.append(every.reshape((-1,) + every.shape[2:]))
    return out


def agreed(value: int) -> int:
    """`value` as process 0 has it, on every process (a decision the processes must share)."""
    if jax.process_count() == 1:
        return value
    from jax.experimental import multihost_utils

    return int(np.asarray(multihost_utils.broadcast_one_to_all(np.int32(value))))
