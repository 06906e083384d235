"""What a study will need before it starts: memory and checkpoint disk, estimated from its inputs,
and a clear refusal (`MechanismError`, exit status 2 on the command line) when it does not fit —
naming the option, the estimate and what is available — instead of an allocation that fails
hours in (a `MemoryError`) or a checkpoint that fills the disk.

**What grows with the samples** (n designs, or N base samples, or r trajectories; M responses
along the cycle with the deviations, S scalar ones, T parameters, R bootstrap resamples; 8 bytes a
float64):

- `sample`, `grid`, parameter studies: every design's row is kept (its parameters, its flag, its
  scalar responses): n (T + S + 1) × 8 bytes, twice (the chunks and their concatenation); the
  checkpoint writes the same rows once;
- `regression`: every response of every design is kept (the ranks need them all):
  n (T + M + 1) × 8 bytes, four times (the chunks, their concatenation, the ranks and the sort);
  the checkpoint writes the rows once;
- `sensitivity` (N base samples), `morris` (r trajectories), `dgsm` (n designs): the bootstrap's
  counts of every sample in every resample (`sobol.bootstrap_counts`: R × N uint16, drawn as an
  N × R int64 array, each resample's column copied and counted): (10 R + 16) N bytes (`morris`:
  and its trajectories, 16 (D + 2) T r); their checkpoint holds the estimators' sums only (a size
  that does not depend on N);
- the tolerance study's Monte Carlo: streamed (its memory is the batch's, its checkpoint the
  moments'): nothing grows with the samples;
- the checkpoint's files: 4 kB a chunk file and 16 kB of state besides their arrays;
- every study: one batch of responses, `chunk` (M + T) × 8 bytes, four times.

A study is refused where the estimate exceeds `MEMORY_SHARE` of the available memory
(`jaxlink.optimize.problem.available_memory`: the host's `MemAvailable`, or the accelerator's
free memory) or where its checkpoint would exceed `DISK_SHARE` of the free space of its folder.
"""

from __future__ import annotations

import shutil
from typing import NamedTuple

from ..errors import MechanismError

#: share of the available memory a study may plan to take (the rest: JAX, its compiled programs)
MEMORY_SHARE = 0.5
#: share of the checkpoint folder's free space its checkpoint may plan to take
DISK_SHARE = 0.9
#: bytes per sample and bootstrap resample of the bootstrap counts (an int64 draw, a uint16 count)
BOOTSTRAP_BYTES = 10
#: and per sample (one resample's column copied and counted: two int64 arrays)
BOOTSTRAP_COLUMN = 16
#: the checkpoint's bytes besides its arrays: per chunk file (the npz's headers), and its state
CHUNK_FILE = 4096
STATE_FILES = 16384


class Need(NamedTuple):
    """A study's estimate: `memory` and `checkpoint` (bytes), `samples` (designs, base samples
    or trajectories: what `samples` counts), `per` (memory bytes per count), `disk_per` (checkpoint
    bytes per count), `what` (words: what grows)."""

    memory: int
    checkpoint: int
    samples: int
    per: float
    disk_per: float
    what: str


def available_memory() -> int:
    """Bytes available to the study (the host's, or the accelerator's): a seam for the tests."""
    from ..optimize.problem import available_memory as _available

    return _available()


def free_disk(path) -> int:
    """Free bytes of the file system of `path` (the checkpoint's folder): a seam for the tests."""
    return int(shutil.disk_usage(path).free)


def estimate(study, method: str, count: int) -> Need:
    """What `method` (`sample`, `grid`, `regression`, `sensitivity`, `morris`, `dgsm`, a
    parameter study, `tolerance`) of `study` (a `tolerance.Study`) with `count` samples needs
    (see the module doc)."""
    inputs = study.inputs
    r = study.responses
    T = len(inputs.parameters)
    K = len(inputs.points) if "deviation" in inputs.metrics else 0
    M = len(r.labels) + K
    S = sum(1 for (_n, _u, k) in r.labels if k is None) + K
    R = int(inputs.bootstrap)
    count = int(count)
    batch = 4 * int(study.chunk) * (M + T) * 8
    if method in ("sample", "grid", "vector", "list", "centered"):
        row = (T + S + 1) * 8
        per, disk, what = 2.0 * row, float(row), f"every design's row ({T + S + 1} numbers)"
    elif method == "regression":
        row = (T + M + 1) * 8
        per, disk, what = 4.0 * row, float(row), f"every response of every design ({T + M + 1} numbers a design)"
    elif method in ("sensitivity", "morris", "dgsm"):
        per, disk = float(BOOTSTRAP_BYTES * R + BOOTSTRAP_COLUMN), 0.0
        what = f"the bootstrap's counts of every sample in its {R} resamples, {per:g} bytes a sample; --bootstrap"
        if method == "morris":  # the trajectories: (D + 1) points and the signs of T columns, twice
            per += 2 * 8 * (len(inputs.factors) + 2) * T
            what += " and the trajectories"
    else:  # the tolerance study's Monte Carlo: streamed
        per, disk, what = 0.0, 0.0, "the batch"
    # the checkpoint's state: the estimators' sums (Sobol': 2 + 3D per output and replicate), else the nominal's
    sums = method in ("sensitivity", "morris", "dgsm")
    state = STATE_FILES + ((R + 1) * M * (3 * len(inputs.factors) + 4) * 8 if sums else M * 8)
    if disk:
        disk += CHUNK_FILE / max(1, int(study.chunk))
    return Need(int(batch + per * count), int(disk * count + state), count, per, disk, what)


def check(study, method: str, count: int, *, checkpoint=None, option: str = "samples") -> Need:
    """Refuse (`MechanismError`, key `study.samples`) a study whose estimate (`estimate`) exceeds
    `MEMORY_SHARE` of `available_memory()`, or whose checkpoint (`checkpoint`: a
    `checkpoint.Checkpoint`, or None) exceeds `DISK_SHARE` of `free_disk` of its folder; the
    message names the option, the estimate, what is available and how many samples fit."""
    need = estimate(study, method, count)
    mech = study.mech
    noun = {"sensitivity": "base samples", "morris": "trajectories"}.get(method, "designs")
    avail = int(available_memory())
    if need.memory > MEMORY_SHARE * avail:
        fit = _fit(MEMORY_SHARE * avail - (need.memory - need.per * count), need.per)
        raise MechanismError(
            f"{option} = {count} (--samples or [study] samples): this {method} study of {count} {noun} needs about "
            f"{_size(need.memory)} of memory ({need.what}), more than {MEMORY_SHARE:.0%} of the {_size(avail)} "
            f"available; at most {fit} {noun} fit", file=mech.file, key="study.samples")
    if checkpoint is not None and need.checkpoint > 0:
        free = int(free_disk(checkpoint.dir))
        if need.checkpoint > DISK_SHARE * free:
            fit = _fit(DISK_SHARE * free - (need.checkpoint - need.disk_per * count), need.disk_per)
            raise MechanismError(
                f"{option} = {count} (--samples or [study] samples): the checkpoint of this {method} study "
                f"({checkpoint.dir}) would write about {_size(need.checkpoint)}, more than {DISK_SHARE:.0%} of the "
                f"{_size(free)} free there; at most {fit} {noun} fit (or give --out another disk)",
                file=mech.file, key="study.samples")
    return need


def _fit(room: float, per: float) -> int:
    return max(0, int(room // per)) if per > 0 else 0


def _size(n: float) -> str:
    for unit, f in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= f:
            return f"{n / f:.3g} {unit}"
    return f"{int(n)} bytes"
