"""A design search spread over several processes (one per host, or several on one host) with
`jax.distributed`.

Every process runs the same deterministic search loop (the same seeds, the same designs drawn);
each batch of designs is cut into one contiguous share per process, each process evaluates its
share on its own devices (`Evaluator`), and the values are gathered to every process
(`multihost_utils.process_allgather`), so that all processes hold the same state and choose the
same next designs. The result is the one of a single process (tested with two CPU processes).
Process 0 alone writes the output files; all read them on `--resume` (a shared filesystem).

What is spread: every `Evaluator.evaluate` batch — the uniform and Monte Carlo searches whole,
the gradient search's presample. The gradient search's iterations (a few dozen starts) run on
every process alike.

Start one process per host (or per GPU) with the same coordinator address:

    jaxlink optimize FILE --coordinator HOST:PORT --num-processes N --process-id I …

or, from Python, `jaxlink.optimize.initialize_distributed(...)` before any other JAX call. On a
cluster whose scheduler JAX recognizes (SLURM, Open MPI), `initialize_distributed()` without
arguments reads the addresses from the environment. On CPUs the processes exchange values through
Gloo (`jax_cpu_collectives_implementation`).
"""

from __future__ import annotations

import jax
import numpy as np


def initialize_distributed(coordinator: str | None = None, num_processes: int | None = None,
                           process_id: int | None = None) -> tuple[int, int]:
    """Join (or start, as process 0) a group of `num_processes` processes coordinated at
    `coordinator` ("HOST:PORT"); all None: from the cluster's environment. Call it before any
    other JAX work. Returns (this process's index, the number of processes)."""
    try:
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    except Exception:  # a JAX without Gloo: CPU processes then cannot exchange values
        pass
    jax.distributed.initialize(coordinator_address=coordinator, num_processes=num_processes, process_id=process_id)
    return jax.process_index(), jax.process_count()


def process_share(n: int) -> tuple[int, int, int]:
    """(start, stop, share) of this process's contiguous rows of a batch of `n` (every process's
    share padded to `share` rows)."""
    count, index = jax.process_count(), jax.process_index()
    share = -(-n // count)
    start = min(n, index * share)
    return start, min(n, start + share), share


def gathered(local: dict, n: int) -> dict:
    """The per-process results `local` (dict of arrays, each this process's rows) of a batch of
    `n` rows, gathered to every process in row order."""
    from jax.experimental import multihost_utils

    start, stop, share = process_share(n)
    out = {}
    for key, a in local.items():
        a = np.asarray(a)
        padded = np.concatenate([a, np.zeros((share - len(a),) + a.shape[1:], a.dtype)]) if len(a) < share else a
        every = np.asarray(multihost_utils.process_allgather(padded, tiled=False))  # (count, share, ...)
        rows = []
        for i in range(jax.process_count()):
            lo = min(n, i * share)
            rows.append(every[i][: min(n, lo + share) - lo])
        out[key] = np.concatenate(rows) if rows else a[:0]
    return out


def is_writer() -> bool:
    """Whether this process writes the outputs (process 0)."""
    return jax.process_index() == 0
