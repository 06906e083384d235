"""A search round's batches spread over this process's devices and over several processes.

The candidate axis of every batch (the screen's random poses, the rank's and the refinement's
candidates) is cut into one contiguous share per process (`optimize.distributed.process_share`),
each share padded (its first row repeated) to a multiple of this process's device count and put on
a one-axis mesh over its devices (`optimize.sharding`), and the rows each process computed are
gathered to every process (`optimize.distributed.gathered`), so that all processes hold the whole
batch and take the same decisions. Candidates are independent: a candidate's numbers are the same
whatever share or device computed them (tested against one device and one process).

The screen draws its poses from a key: in a share, every process draws the whole batch's poses
(a few floats a candidate: cheap beside tracing them) and keeps its rows, so that a pose does not
depend on the split.

One device and one process (`Layout.single`): the programs are called as they are, unsharded.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import numpy as np


class Layout(NamedTuple):
    """Where a batch's rows go: `devices` of this process, `processes` in all, this one's index `process`."""

    devices: int
    processes: int
    process: int

    @property
    def single(self) -> bool:
        return self.devices == 1 and self.processes == 1

    def share(self, n: int) -> tuple[int, int, int]:
        """(first row, end row, padded rows) of this process's share of a batch of `n`: the shares
        of `optimize.distributed.process_share`, padded to a multiple of the device count."""
        size = -(-n // self.processes)
        lo = min(n, self.process * size)
        hi = min(n, lo + size)
        return lo, hi, -(-max(size, 1) // self.devices) * self.devices


def layout() -> Layout:
    """This process's devices and its place among the processes (`jax.distributed`)."""
    return Layout(len(jax.local_devices()), jax.process_count(), jax.process_index())


def sharding():
    """The candidate axis over this process's devices (`optimize.sharding.design_sharding`)."""
    from ..optimize.sharding import design_sharding

    return design_sharding()


def abstract(shape: tuple[int, ...], dtype, sharded: bool) -> jax.ShapeDtypeStruct:
    """An argument of a program lowered for a share: the candidate axis on the mesh, or replicated."""
    from jax.sharding import NamedSharding, PartitionSpec

    s = sharding()
    return jax.ShapeDtypeStruct(shape, dtype, sharding=s if sharded else NamedSharding(s.mesh, PartitionSpec()))


def pad(x: np.ndarray, rows: int) -> np.ndarray:
    """`x` with its first row repeated up to `rows` rows."""
    from ..optimize.sharding import pad_rows

    return pad_rows(np.asarray(x), rows)[0] if len(x) < rows else np.asarray(x)


class Spread:
    """A compiled program for one share (`Layout.share`) called on whole batches: the `rows`
    arguments (their positions) cut to this process's share, padded and put on the mesh, the others
    replicated; the outputs (a tuple, candidate axis first) cut back and gathered to every process.
    `n`: the batch's rows."""

    def __init__(self, program: Callable, rows: tuple[int, ...], where: Layout, n: int):
        self.program, self.rows, self.where, self.n = program, rows, where, n

    def __call__(self, *args):
        from jax.sharding import NamedSharding, PartitionSpec

        lo, hi, b = self.where.share(self.n)
        s = sharding()
        rep = NamedSharding(s.mesh, PartitionSpec())
        placed = []
        for i, a in enumerate(args):
            if i in self.rows:
                if len(a) != self.n:
                    raise AssertionError(f"a batch of {len(a)} rows for a program of {self.n}")
                placed.append(jax.device_put(pad(np.asarray(a)[lo:hi], b), s))
            else:
                placed.append(jax.device_put(np.asarray(a), rep))
        out = [np.asarray(o)[:hi - lo] for o in self.program(*placed)]
        if self.where.processes == 1:
            return tuple(out)
        from ..optimize.distributed import gathered

        every = gathered({str(i): o for i, o in enumerate(out)}, self.n)
        return tuple(every[str(i)] for i in range(len(out)))


def agreed(value: int) -> int:
    """`value` as process 0 has it, on every process (a decision the processes must share)."""
    if jax.process_count() == 1:
        return value
    from jax.experimental import multihost_utils

    return int(np.asarray(multihost_utils.broadcast_one_to_all(np.int32(value))))
