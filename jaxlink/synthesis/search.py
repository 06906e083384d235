"""The search: screen many random candidates of every topology on the batched tracer, refine the
best by gradient on the smooth surrogate, check and score the refined ones exactly.

One **round** (repeated with fresh candidates until the time limit):

1. **screen**: `samples` random poses per topology (every joint uniform in [−1, 1]²), traced at
   `SCREEN_T` inputs over a turn; each sub-interval (a closed target: the whole turn; an open one:
   16 starts × 4 lengths, a quarter to a whole turn), if every dyad closes at its samples, is
   resampled to 32 points by arclength, normalised, and described by its sorted radii (a rotation
   invariant); the `screen_keep` per topology nearest to the target's descriptor go on;
2. **rank**: those, traced at 64 inputs, by a chamfer distance at 32 rotations; the best `refine`
   per topology are rotated to their best angle;
3. **refine**: from the second round on, half of each topology's slots restart from the two best
   refined poses so far (the first as it is, the others jittered by `jitter` × its RMS radius);
   Adam (optax) on the pose (and the sub-interval's start and length for an open
   target) against the surrogate `distance.soft_chamfer`, plus a penalty keeping every dyad's
   margin above `MARGIN_FLOOR` at the samples; all candidates of all topologies in one batch;
4. **score**: the refined candidates of each topology, best by the surrogate first, traced exactly
   (`tracer.trace_exact`, float64) at `n_trace` inputs, checked over their whole interval
   (`assembly.certify`) and matched (`distance.match`), until `per_topology` pass (at most
   `SCORE_TRIES` × `per_topology` tried); the topologies side by side in `SCORE_THREADS` threads,
   the most promising first; in a time-limited search in one process, once a design is found, no
   score starts past the time limit (less `SCORE_RESERVE_S`).

After each full round, and while a full round would not fit in the time left, a **polishing
round**: refine and score only, every slot on the best three topologies' best refined so far
(`_polish_slots`). The three programs are compiled before the first round, at once (`programs`).
With `rounds` = N the search runs exactly N rounds, full and polishing alternating (what it does
when time is no limit), whatever the time: the same result on any machine.

The screen's, the rank's and the refinement's batches are cut into blocks of a size that depends
on the batch and the platform only (`block_caps`: small blocks on a CPU, whole batches on a GPU),
one program a block (`spread.Blocked`), the blocks spread over this process's devices and over the
processes of a `jax.distributed` group: the same numbers bit for bit as on one device in one
process (a program's bits depend on its batch's shape: `spread`). Several processes take the same
decisions: every one holds every batch's results, and the time decisions are process 0's
(`spread.agreed`).
"""

from __future__ import annotations

import functools
import os
import time
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..cache import compiled
from ..model.domains import joints_inside
from . import checkpoint as _ckpt
from . import distance as _dist
from . import size as _size
from . import spread as _spread
from . import transmission as _tm
from .assembly import Assembly, certify
from .mechanism import placed_pose
from .polish import BACK
from .polish import polish as _polish
from .polish import program as _polish_program
from .polish import program_timed as _polish_program_timed
from .sortnet import sort_first
from .target import Target, arclength_resample
from .topology import CRANK, Topology, as_arrays, bodies
from .tracer import trace, trace_exact

SCREEN_T = 64
DESC_N = 32
RANK_T = 64
REFINE_T = 128
TARGET_N = 100
MARGIN_FLOOR = 0.02
#: a round scores a topology's refined candidates in the surrogate's order until `per_topology`
#: pass the exact check, at most this many times `per_topology` of them
SCORE_TRIES = 4
#: the threads that score a round's candidates (NumPy float64 and SciPy k-d trees, one topology a
#: task): 43 ten-bar topologies' 86+ scores took 6-18 s of a 58 s letter on an H200's host shared by
#: 5 processes, where the device's screen, rank and refinement took about 1 s
SCORE_THREADS = max(1, min(4, os.cpu_count() or 1))
_STARTS = 16
#: a timed target's points in the screen (subsampled or padded to it, `timed_samples`); the refinement
#: takes `REFINE_T`
TIMED_SCREEN_T = 32
#: the input fractions of the interval where a timed candidate's margins are also kept up (the
#: refinement's penalty: its samples are the target's points, maybe few)
_TIMED_MARGIN_T = 64
_SPANS = (0.25, 0.5, 0.75, 1.0)
_ROT = 32
_DT = jnp.float32
#: XLA options of the screen and the rank (run once a round: compiling them fast matters more than running them fast)
_QUICK: dict[str, Any] = {"xla_backend_optimization_level": 0}
#: the most rows of one block of the screen's, the rank's and the refinement's batches (`spread.blocks`:
#: one program per block, whatever the devices; a candidate's bits depend on its block's size)
SCREEN_BLOCK = 1024
RANK_BLOCK = 64
REFINE_BLOCK = 8
#: the refinement's block in a `quick` search: chosen when a quick search compiled its refinement at XLA's
#: lowest level, where blocks of 8 slots took 9.8 s against 7.6 s for one batch of 56 (a default round);
#: the refinement now compiles at the full level in every search (`programs`), where the block's size
#: does not change the time, and the quick block stays (another block: other bits); it depends only
#: on the batch and `quick`, never on the devices
REFINE_BLOCK_QUICK = 64
#: the caps of the screen's, the rank's and the refinement's blocks on an accelerator (a GPU, at either
#: level): there a block's kernels run at their launch latency, not at their throughput, and the blocks
#: of one batch run one after another on the one device (a full round of the 43 topologies up to ten
#: links has 344 refinement slots: 43 blocks of 8, each 300 Adam steps of small kernels), so one block
#: takes a whole batch of the default search (8192 screened poses a topology, 344 slots; the rank's
#: 5504 rows in 3 blocks: its distances at 32 rotations, about 1 GB a block); on a CPU XLA spreads one block's
#: work over the cores and the small blocks cost nothing. The caps depend on the platform only, never
#: on the number of devices or processes: on one platform the same bits whatever the layout (`spread`)
ACCEL_BLOCKS = (8192, 2048, 512)


#: a search of at most this time limit (s) is `quick` unless told (`quick_of`)
QUICK_S = 15.0

#: the rounds of a search given neither `rounds` nor a time limit: a full round and a polishing
#: round (then the final polishes), about what the former default limit of 60 s ran on a quiet
#: 2-core CPU with the 16 topologies up to eight links; a count, the same designs on any machine
DEFAULT_ROUNDS = 2

#: a time-limited search in one process abandons a round still running at this many times its
#: limit (`spread.Blocked`'s deadline, between blocks), keeping the rounds done: a run overruns its
#: limit by at most 10 %, the last block's time and the designs' writing included
ABANDON_AT = 1.05


def quick_of(time_limit: float | None, quick: bool | None) -> bool:
    """Whether a search with this time limit is `quick` (if given, else a time limit of at most
    `QUICK_S`; no time limit: not quick): a closed or timed target's screen compiled at XLA's lowest
    level, no final polish by default, the refinement's blocks of `REFINE_BLOCK_QUICK` (`programs`,
    `search`)."""
    if quick is not None:
        return bool(quick)
    return time_limit is not None and time_limit <= QUICK_S


def checked_blocks(blocks) -> tuple[int, int, int] | None:
    """`blocks` (the caps of `programs`' blocks: screen, rank, refinement) as three whole numbers,
    or None; ValueError naming the value otherwise."""
    if blocks is None:
        return None
    try:
        caps = tuple(blocks)
    except TypeError:
        caps = ()
    if len(caps) != 3 or not all(isinstance(c, (int, np.integer)) and not isinstance(c, bool) and c >= 1
                                 for c in caps):
        raise ValueError(f"blocks = {blocks!r}: three whole numbers of rows, at least 1 each (the screen's, "
                         "the rank's and the refinement's blocks), or None for the platform's")
    return int(caps[0]), int(caps[1]), int(caps[2])


def _platform() -> str:
    """The platform of this process's devices ("cpu", "gpu", ...)."""
    return jax.local_devices()[0].platform


def default_blocks(quick: bool) -> tuple[int, int, int]:
    """The caps `programs` takes on this process's devices (`block_caps` of their platform)."""
    return block_caps(_platform(), quick)


def block_caps(platform: str, quick: bool) -> tuple[int, int, int]:
    """The caps (screen, rank, refinement) of `programs`' blocks on devices of `platform` ("cpu",
    "gpu", ...), for a `quick` search or not."""
    if platform == "cpu":
        return SCREEN_BLOCK, RANK_BLOCK, REFINE_BLOCK_QUICK if quick else REFINE_BLOCK
    return ACCEL_BLOCKS


class Programs(NamedTuple):
    """The three compiled programs of a search (`programs`): callables on the dynamic arguments,
    each computing its batch in blocks (`spread.Blocked`)."""

    screen: _spread.Blocked
    rank: _spread.Blocked | None  # None for a timed target (no rank)
    refine: _spread.Blocked


def programs(n_topos: int, n_dyads: int, closed: bool, *, samples: int, screen_keep: int, refine: int,
             steps: int, quick: bool = False, where: _spread.Layout | None = None,
             polish_points: int = 0, sliders: bool = False, timed: bool = False,
             bounded: bool = False, blocks: tuple[int, int, int] | None = None,
             deadline: float | None = None) -> Programs:
    """Compile the screen, the rank and the refinement for these shapes, all three at once (XLA
    compiles in parallel threads; on a cold start compiling is most of a short search's time).
    The rank compiles at XLA's lowest optimisation level (about half the compile time, its run
    time about the same), and the screen when `quick` and `closed` (an open target's screen, 64
    sub-arcs a candidate, would run longer than its compiling saves). The refinement always
    compiles at the full level: at the lowest its 300 steps ran 2-3 times as long, more than the
    compiling saved even in a short search (the 16 built-ins, 15 s, 2 cores: its round 32.7 s cold
    and 26.1 s warm against 23.5 and 14.8 s; a four-bar: 5.3 s cold against 5.5 s, its round 1.7
    against 1.5 s warm). `polish_points` > 0: the
    float64 polish's program for a target of that many points is compiled beside them, into its
    memo (`polish.program`, which `polish.polish` then finds ready). `sliders`: the topologies may
    hold slider dyads (`tracer.trace`; other programs, the RRR ones unchanged without it).
    Each program computes one block of its batch (`spread.blocks`, at most `block_caps` rows: on a
    CPU `SCREEN_BLOCK`, `RANK_BLOCK`, `REFINE_BLOCK`; on a GPU `ACCEL_BLOCKS`), the same block
    whatever the number of devices and processes (`where`,
    default `spread.layout()`), and is called on whole batches (`spread.Blocked`).
    `timed`: a timed target's two programs (`_screen_timed`, `_refine_timed`; no rank: `rank` None)
    and its polish (`polish.program_timed` for `polish_points` points). `bounded`: the programs
    that keep a design within a size (`size`; their last argument the bound, unused without it).
    `blocks`: other caps (screen, rank, refinement) than the platform's (`block_caps`).
    `deadline` (a `time.perf_counter()` time; one process): a wait for a program still compiling
    past it raises `spread.OutOfTime` (the search stops there; XLA's compiling threads cannot be
    stopped, and the process waits for them at its exit)."""
    keep = min(screen_keep, samples * len(_subarcs(closed)))
    sizes: tuple[int, ...] = (samples, keep * n_topos, min(refine, keep) * n_topos)
    given = checked_blocks(blocks)
    caps: tuple[int, ...] = default_blocks(quick) if given is None else given
    jobs = [("screen", n_dyads, closed, 0, quick and closed, sliders, bounded),
            ("rank", n_dyads, False, 0, True, sliders, bounded),
            ("refine", n_dyads, False, steps, False, sliders, bounded)]
    if timed:
        sizes = (samples, min(refine, samples * _STARTS) * n_topos)
        caps = (caps[0], caps[2])
        jobs = [("screen-timed", n_dyads, False, 0, quick, sliders, bounded),
                ("refine-timed", n_dyads, False, steps, False, sliders, bounded)]
    x64 = bool(jax.config.read("jax_enable_x64"))  # the traced program's default dtypes depend on it
    where = _spread.layout() if where is None else where
    if where.devices > len(jax.local_devices()):
        raise ValueError(f"{where.devices} devices asked for, {len(jax.local_devices())} here")
    block = [_spread.blocks(n, cap)[1] for n, cap in zip(sizes, caps)]
    tasks = [(job, b, d) for job, b in zip(jobs, block) for d in range(where.devices)]
    ex = ThreadPoolExecutor(len(tasks) + (polish_points > 0))
    pol = (None if polish_points <= 0
           else ex.submit(_polish_program_timed, n_dyads, polish_points, sliders, bounded) if timed
           else ex.submit(_polish_program, n_dyads, polish_points, sliders, bounded))
    futures = [ex.submit(_compiled, t[0][0], t[1], *t[0][1:], x64, t[2]) for t in tasks]
    ex.shutdown(wait=False)  # the threads end with their compiling

    def wait(f: Future):
        if deadline is None:
            return f.result()
        try:
            return f.result(timeout=max(0.0, deadline - time.perf_counter()))
        except FutureTimeout:
            raise _spread.OutOfTime("the programs were still compiling at the time limit") from None

    def ready(fs: list, also=None) -> list:
        """The programs of `fs` once compiled (and `also`, the polish's)."""
        out = [wait(f) for f in fs]
        if also is not None:
            wait(also)
        return out

    # the screen and the rank are waited for here; the refinement (and the polish) go on compiling
    # while the first round screens and ranks, and are waited for at the refinement's first call
    # (`spread.Blocked`): the same programs, the same bits, compiled at once
    per: list = []
    for i, job in enumerate(jobs):
        fs = futures[i * where.devices:(i + 1) * where.devices]
        per.append(functools.partial(ready, fs, pol) if job[0].startswith("refine") else ready(fs))
    rows: tuple[tuple[int, ...], ...] = ((1, 2, 3), (0, 1, 2, 3, 4), (0, 1, 2, 3, 4))
    keyed: tuple[int | None, ...] = (0, None, None)
    if timed:
        rows, keyed = ((1, 2, 3), (0, 1, 2, 3, 4)), (0, None)
    out = [_spread.Blocked(c, r, k, where, n, b) for c, r, k, n, b in zip(per, rows, keyed, sizes, block)]
    return Programs(out[0], None, out[1]) if timed else Programs(*out)


@functools.lru_cache(maxsize=32)
def _compiled(which: str, b: int, n_dyads: int, closed: bool, steps: int, quick: bool, sliders: bool,
              bounded: bool, x64: bool, device: int = 0):
    """One program of `programs` for a block of `b` rows on this process's `device`-th device (kept
    for the process, keyed by every static input and the x64 mode; the dynamic data are arguments
    of the program: a second search of the same shapes compiles nothing; the rank's and the
    refinement's serve open and closed targets). Every device's program is compiled from the same
    program for the same block: the same code."""
    nj = CRANK + 1 + n_dyads
    i32, f32 = np.int32, np.float32
    options = _QUICK if quick else None
    on = jax.sharding.SingleDeviceSharding(jax.local_devices()[device])

    def arg(shape, dtype=f32):
        return jax.ShapeDtypeStruct(shape, dtype, sharding=on)

    topo = arg((b, n_dyads, 2), i32), arg((b, n_dyads), bool), arg((b,), i32)
    if which == "screen":
        return compiled("synthesis-screen", _screen_of, (arg((2,), np.uint32), *topo, arg((DESC_N,)), arg((2,))),
                        (closed, sliders, bounded), options)
    if which == "screen-timed":
        return compiled("synthesis-screen-timed", _screen_timed_of,
                        (arg((2,), np.uint32), *topo, arg((TIMED_SCREEN_T, 2)), arg((TIMED_SCREEN_T,)),
                         arg((TIMED_SCREEN_T,)), arg(()), arg((2,))), (sliders, bounded), options)
    poses, arcs = arg((b, nj, 2)), arg((b, 2))
    if which == "refine-timed":
        return compiled("synthesis-refine-timed", _refine_timed_of,
                        (*topo, poses, arcs, arg((REFINE_T, 2)), arg((REFINE_T,)), arg(()), arg((REFINE_T,)),
                         arg((2,))), (steps, sliders, bounded), options)
    if which == "rank":
        return compiled("synthesis-rank", _rank_of, (*topo, poses, arcs, arg((RANK_T, 2)), arg(()), arg((RANK_T,)),
                                                     arg((2,))), (sliders, bounded), options)
    return compiled("synthesis-refine", _refine_of, (*topo, poses, arcs, arg((TARGET_N, 2)), arg(()), arg(()),
                                                     arg((REFINE_T,)), arg((2,))), (steps, sliders, bounded), options)


def _screen_of(key, parents, active, traced, target_desc, bounds, closed, sliders, bounded):
    """`_screen` with its static options last (a stored program's signature: `cache.compiled`)."""
    return _screen(key, parents, active, traced, target_desc, bounds, closed=closed, sliders=sliders, bounded=bounded)


def _rank_of(parents, active, traced, poses, arcs, target, closed, u, bounds, sliders, bounded):
    """`_rank` with its static options last (`cache.compiled`)."""
    return _rank(parents, active, traced, poses, arcs, target, closed, u, bounds, sliders=sliders, bounded=bounded)


def _screen_timed_of(key, parents, active, traced, target, w, u, span, bounds, sliders, bounded):
    """`_screen_timed` with its static options last (`cache.compiled`)."""
    return _screen_timed(key, parents, active, traced, target, w, u, span, bounds, sliders=sliders, bounded=bounded)


def _refine_timed_of(parents, active, traced, poses, arcs, target, w, lr, u, bounds, steps, sliders, bounded):
    """`_refine_timed` with its static options last (`cache.compiled`)."""
    return _refine_timed(parents, active, traced, poses, arcs, target, w, lr, u, bounds, steps=steps, sliders=sliders,
                         bounded=bounded)


def _refine_of(parents, active, traced, poses, arcs, target, lr, closed, u, bounds, steps, sliders, bounded):
    """`_refine` with its static options last (`cache.compiled`)."""
    return _refine(parents, active, traced, poses, arcs, target, lr, closed, u, bounds, steps=steps, sliders=sliders,
                   bounded=bounded)


class Candidate(NamedTuple):
    """A scored mechanism: its `topology`, `pose` (joint positions at input offset 0, the search's
    own coordinates), input offsets `start`, `span` (rad) of the traced interval, the exact
    `match` (distance and placement), the `assembly` check, when it was found (s), whether it
    is the result of the float64 `polish`, and its `size` (`size.design_size`: in the target's extents)."""

    topology: Topology
    pose: np.ndarray
    start: float
    span: float
    match: _dist.Match
    assembly: Assembly
    found_s: float
    polished: bool = False
    size: float = float("nan")


def _radii(curve, closed: bool, frame: bool = False):
    """The descriptor before sorting: distances from the centroid of the arclength-resampled,
    normalised curve (`_screen` sorts them, `sortnet.sort_first`). `frame`: also that centroid and
    the RMS radius (`size`)."""
    seg = jnp.sqrt(jnp.sum(jnp.diff(curve, axis=0) ** 2, axis=-1) + 1e-12)
    s = jnp.concatenate([jnp.zeros(1, curve.dtype), jnp.cumsum(seg)])
    q = s[-1] * (jnp.arange(DESC_N) / (DESC_N if closed else DESC_N - 1))
    c = jnp.stack([jnp.interp(q, s, curve[:, 0]), jnp.interp(q, s, curve[:, 1])], axis=-1)
    mean = c.mean(0)
    c = c - mean
    r = jnp.sqrt(jnp.sum(c * c, axis=-1) + 1e-12)
    rms = jnp.sqrt(jnp.mean(r * r))
    return (r / rms, mean, rms) if frame else r / rms


def _desc(points: np.ndarray, closed: bool) -> np.ndarray:
    """The sorted `_radii` in NumPy (the target's descriptor)."""
    c = arclength_resample(points, DESC_N, closed)
    c = c - c.mean(0)
    r = np.sqrt(np.sum(c * c, axis=-1) + 1e-12)
    return np.sort(r / np.sqrt(np.mean(r * r))).astype(np.float32)


def _subarcs(closed: bool):
    if closed:
        return np.array([[0.0, 2 * np.pi]], np.float32)
    return np.array([[2 * np.pi * i / _STARTS, 2 * np.pi * f] for i in range(_STARTS) for f in _SPANS], np.float32)


def _subarc_slices(closed: bool) -> list[tuple[int, int, int]]:
    """Each sub-arc of `_subarcs` as a strided slice (start, step, count) of the screen's curve at half
    samples (`_half_samples`): its starts are whole samples and its points, 33 evenly spaced over the
    span (a closed target: the whole turn's `SCREEN_T` + 1 samples), fall on whole and half samples."""
    out = []
    for start, span in _subarcs(closed).astype(np.float64):
        k = SCREEN_T + 1 if closed else 33
        x2 = 2 * SCREEN_T * (start + span * np.linspace(0.0, 1.0, k)) / (2 * np.pi)
        idx = np.rint(x2).astype(int)
        step = int(idx[1] - idx[0])
        if not (np.allclose(x2, idx, atol=1e-6) and np.all(np.diff(idx) == step)):
            raise AssertionError("a sub-arc's points are not on the half samples")  # a change of the constants
        out.append((int(idx[0]), step, k))
    return out


def _half_samples(curve, ok, reach: int):
    """The curve (T + 1 samples over a turn, the last = the first) and its dyads' closing (T + 1,) at
    every half sample, the midpoints linear (closing where both ends close), extended periodically
    to `reach` + 1 points."""
    mid = 0.5 * (curve[:-1] + curve[1:])
    c2 = jnp.stack([curve[:-1], mid], 1).reshape(2 * SCREEN_T, 2)
    o2 = jnp.stack([ok[:-1], ok[:-1] & ok[1:]], 1).reshape(2 * SCREEN_T)
    reps = reach // (2 * SCREEN_T) + 1
    return jnp.concatenate([c2] * reps + [c2[:1]]), jnp.concatenate([o2] * reps + [o2[:1]])


@functools.partial(jax.jit, static_argnames=("closed", "sliders", "bounded"))
def _screen(key, parents, active, traced, target_desc, bounds=(np.inf, 0.0), *, closed: bool, sliders: bool = False,
            bounded: bool = False):
    """Descriptor distances (B, S) of random poses (B, J, 2) over the sub-arcs; inf where a dyad does
    not close at a sample of the sub-arc (or, `bounded`, where the design is larger than `bounds`:
    `size`). Each sub-arc's points are a static strided slice of the curve at half samples
    (`_subarc_slices`: no gathers)."""
    b = parents.shape[0]
    poses = jax.random.uniform(key, (b, CRANK + 1 + parents.shape[1], 2), _DT, -1.0, 1.0)
    th = jnp.asarray(2 * np.pi * np.arange(SCREEN_T + 1) / SCREEN_T, _DT)
    pos, marg = jax.vmap(functools.partial(trace, sliders=sliders), in_axes=(0, 0, 0, None))(parents, active, poses, th)
    curves = pos[jnp.arange(b), :, traced]                    # (B, T+1, 2), the last = the first
    if bounded:  # every dyad's margin above its floor (`transmission`: 0 without one)
        thr = jax.vmap(lambda par: _tm.thresholds(par, bounds[1], sliders))(parents)
        ok = jnp.min(marg - thr[:, None, :], axis=-1) > 0
    else:
        ok = jnp.min(marg, axis=-1) > 0                        # (B, T+1)
    slices = _subarc_slices(closed)
    reach = max(st + step * (k - 1) for st, step, k in slices)

    def per_candidate(curve, okk, par, act, pose):
        c2, o2 = _half_samples(curve, okk, reach)
        pts = jnp.stack([jax.lax.slice(c2, (st, 0), (st + step * (k - 1) + 1, 2), (step, 1))
                         for st, step, k in slices])
        valid = jnp.stack([jnp.all(jax.lax.slice(o2, (st,), (st + step * (k - 1) + 1,), (step,)))
                           for st, step, k in slices])
        if not bounded:
            return jax.vmap(lambda p: _radii(p, closed))(pts), valid
        r, mean, rms = jax.vmap(lambda p: _radii(p, closed, frame=True))(pts)
        fits = jax.vmap(lambda m, s: _size.within(par, act, pose, m, s, bounds[0], sliders))(mean, rms)
        return r, valid & fits

    r, valid = jax.vmap(per_candidate)(curves, ok, parents, active, poses)  # (B, S, DESC_N), (B, S)
    desc = sort_first(jnp.moveaxis(r, -1, 0))                # sorted along the leading axis: no gathers
    d = jnp.mean(jnp.abs(desc - target_desc[:, None, None]), axis=0)
    return poses, jnp.where(valid, d, jnp.inf)


def _normalised(c, w):
    mean = jnp.sum(w[:, None] * c, axis=0)
    c = c - mean
    return c / jnp.sqrt(jnp.sum(w * jnp.sum(c * c, axis=1)) + 1e-30)


def _u(n: int, closed: bool) -> np.ndarray:
    """Fractions of the interval sampled: a closed turn without its end, an open one with both."""
    return (np.arange(n) / (n if closed else n - 1)).astype(np.float32)


@functools.partial(jax.jit, static_argnames=("sliders", "bounded"))
def _rank(parents, active, traced, poses, arcs, target, closed, u, bounds=(np.inf, 0.0), *, sliders: bool = False,
          bounded: bool = False):
    """(chamfer at the best of `_ROT` rotations, that rotation) of each candidate over its sub-arc.
    `closed` a 0/1 array (one program for open and closed targets), `u` from `_u`; inf where a dyad
    does not close at a sample (or, `bounded`, where the design is larger than `bounds`: `size`)."""

    def one(par, act, tr, pose, arc):
        pos, marg = trace(par, act, pose, arc[0] + arc[1] * u, sliders)
        c = pos[:, tr]
        w = _dist.arclength_weights(c, closed)
        fits = True
        if bounded:  # within the size, every dyad's margin above its floor
            fits = _size.within(par, act, pose, *_size.weighted_frame(c, w), bounds[0], sliders) & (
                jnp.min(marg - _tm.thresholds(par, bounds[1], sliders)) > 0)
        c = _normalised(c, w)
        phis = 2 * np.pi * jnp.arange(_ROT, dtype=_DT) / _ROT
        rot = jnp.stack([jnp.stack([jnp.cos(phis), -jnp.sin(phis)], -1),
                         jnp.stack([jnp.sin(phis), jnp.cos(phis)], -1)], -2)  # (R, 2, 2)
        rc = jnp.einsum("rij,tj->rti", rot, c)
        d = jnp.sqrt(jnp.sum((rc[:, :, None] - target[None, None]) ** 2, -1) + 1e-12)
        val = jnp.sum(w * d.min(2), axis=1) + d.min(1).mean(1)
        k = jnp.argmin(val)
        return jnp.where((jnp.min(marg) > 0) & fits, val[k], jnp.inf), phis[k]

    return jax.vmap(one)(parents, active, traced, poses, arcs)


def _loss(params, par, act, tr, target, closed, u, sliders, bounds=(np.inf, 0.0), bounded=False):
    pose, arc = params
    start, span = arc[0], jnp.where(closed > 0, jnp.asarray(2 * np.pi, arc.dtype), arc[1])
    pos, marg = trace(par, act, pose, start + span * u, sliders)
    fit = _dist.soft_chamfer(pos[:, tr], target, closed, tau=0.01)
    floor = jnp.maximum(MARGIN_FLOOR, _tm.AIM * _tm.thresholds(par, bounds[1], sliders)) if bounded else MARGIN_FLOOR
    pen = jnp.mean(jnp.sum(jax.nn.relu(floor - marg) ** 2, axis=-1))
    shorter = (1 - closed) * (jax.nn.relu(span - 2 * np.pi) ** 2 + jax.nn.relu(0.05 - span) ** 2)
    out = fit + 100.0 * pen + 100.0 * shorter
    if bounded:  # the size penalty (`size`), in the surrogate's normalisation of the curve
        frame = _size.weighted_frame(pos[:, tr], _dist.arclength_weights(pos[:, tr], closed))
        out = out + _size.WEIGHT * _size.penalty(par, act, pose, *frame, bounds[0], sliders)
    return out


@functools.partial(jax.jit, static_argnames=("steps", "sliders", "bounded"))
def _refine(parents, active, traced, poses, arcs, target, lr, closed, u, bounds=(np.inf, 0.0), *, steps: int,
            sliders: bool = False, bounded: bool = False):
    """Each candidate's pose and arc after `steps` Adam steps (`_adam`) on `_loss`: (poses, arcs, losses).
    `bounded`: with the size penalty for the bound `bounds` (`size`)."""
    return jax.vmap(lambda par, act, tr, pose, arc: _adam(
        _loss, (pose, arc), (par, act, tr, target, closed, u, sliders, bounds, bounded), lr, steps))(
        parents, active, traced, poses, arcs)


def _adam(loss, params, args, lr, steps: int):
    """(pose, arc, the last loss) after `steps` Adam steps on `loss(params, *args)` from `params`
    = (pose, arc): the step size falls from lr to lr / 10 along a half cosine (long strides first, a
    fine fit at the end); a non-finite gradient component counts as 0."""
    import optax  # here: importing it costs every command 0.05 s

    opt = optax.adam(lambda k: lr * (0.55 + 0.45 * jnp.cos(np.pi * jnp.minimum(k, steps) / steps)))
    g = jax.value_and_grad(loss)

    def step(carry, _):
        params, state = carry
        v, grads = g(params, *args)
        grads = jax.tree_util.tree_map(lambda x: jnp.where(jnp.isfinite(x), x, 0.0), grads)
        upd, state = opt.update(grads, state, params)
        return (optax.apply_updates(params, upd), state), v

    (params, _), vals = jax.lax.scan(step, (params, opt.init(params)), None, length=steps)
    return params[0], params[1], vals[-1]


def timed_samples(target: Target, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A timed target as `n` samples: (points (n, 2) normalised with the weights, weights (n,) summing
    to 1 — 0 on padding —, input fractions u (n,) of the span, the span S = t_last − t_0, signed):
    the point i at the input offset start + S u_i. More than `n` points: `n` of them evenly by index
    (the first and last kept); fewer: all, then padding (u = 0, weight 0)."""
    t = np.asarray(target.inputs, float)
    pts = np.asarray(target.points, float)
    idx = np.arange(len(t)) if len(t) <= n else np.unique(np.rint(np.linspace(0, len(t) - 1, n)).astype(int))
    m = len(idx)
    span = float(t[-1] - t[0])
    w = np.zeros(n)
    w[:m] = 1.0 / m
    u = np.zeros(n)
    u[:m] = (t[idx] - t[0]) / span
    p = np.zeros((n, 2))
    p[:m] = _dist.normalise(pts[idx])[0]
    return p, w, u, span


@functools.partial(jax.jit, static_argnames=("sliders", "bounded"))
def _screen_timed(key, parents, active, traced, target, w, u, span, bounds=(np.inf, 0.0), *, sliders: bool = False,
                  bounded: bool = False):
    """A timed target's screen: random poses (B, J, 2), each traced from `_STARTS` starts over a turn
    at the target's inputs (start + span u), and the square of the ordered distance at each start
    (`distance.ordered_sq`: the target's own measure, no descriptor) (B, `_STARTS`); inf where a
    dyad does not close at a sample."""
    b = parents.shape[0]
    poses = jax.random.uniform(key, (b, CRANK + 1 + parents.shape[1], 2), _DT, -1.0, 1.0)
    starts = jnp.asarray(2 * np.pi * np.arange(_STARTS) / _STARTS, _DT)
    th = (starts[:, None] + span * u[None, :]).reshape(-1)

    def one(par, act, tr, pose):
        pos, marg = trace(par, act, pose, th, sliders)
        c = pos[:, tr].reshape(_STARTS, -1, 2)
        thr = _tm.thresholds(par, bounds[1], sliders) if bounded else 0.0
        ok = jnp.all((jnp.min(marg - thr, axis=-1) > 0).reshape(_STARTS, -1) | (w[None, :] == 0), axis=1)
        if bounded:  # within the size (`size`) at each start
            ok = ok & jax.vmap(lambda cc: _size.within(par, act, pose, *_size.weighted_frame(cc, w), bounds[0],
                                                       sliders))(c)
        d = jax.vmap(lambda cc: _dist.ordered_sq(cc, target, w))(c)
        return jnp.where(ok, d, jnp.inf)

    return poses, jax.vmap(one)(parents, active, traced, poses)


def _loss_timed(params, par, act, tr, target, w, u, sliders, bounds=(np.inf, 0.0), bounded=False):
    pose, arc = params
    span = jax.lax.stop_gradient(arc[1])  # the target's: fixed
    um = jnp.asarray(np.linspace(0.0, 1.0, _TIMED_MARGIN_T), u.dtype)
    pos, marg = trace(par, act, pose, arc[0] + span * jnp.concatenate([u, um]), sliders)
    fit = _dist.ordered_sq(pos[:u.shape[0], tr], target, w)
    floor = jnp.maximum(MARGIN_FLOOR, _tm.AIM * _tm.thresholds(par, bounds[1], sliders)) if bounded else MARGIN_FLOOR
    pen = jnp.mean(jnp.sum(jax.nn.relu(floor - marg) ** 2, axis=-1))
    out = fit + 100.0 * pen
    if bounded:  # the size penalty (`size`), the curve at the target's inputs with its weights
        frame = _size.weighted_frame(pos[:u.shape[0], tr], w)
        out = out + _size.WEIGHT * _size.penalty(par, act, pose, *frame, bounds[0], sliders)
    return out


@functools.partial(jax.jit, static_argnames=("steps", "sliders", "bounded"))
def _refine_timed(parents, active, traced, poses, arcs, target, w, lr, u, bounds=(np.inf, 0.0), *, steps: int,
                  sliders: bool = False, bounded: bool = False):
    """`_refine` for a timed target: Adam on the pose and the interval's start (its span the
    target's) against the square of the ordered distance at the target's inputs (`timed_samples`),
    plus the margin penalty at those and at `_TIMED_MARGIN_T` inputs across the interval."""
    return jax.vmap(lambda par, act, tr, pose, arc: _adam(
        _loss_timed, (pose, arc), (par, act, tr, target, w, u, sliders, bounds, bounded), lr, steps))(
        parents, active, traced, poses, arcs)


def _rotate(poses, phi):
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    x, y = poses[..., 0], poses[..., 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=-1)


def interval_offsets(start: float, span: float, n: int, closed: bool) -> np.ndarray:
    """The input offsets of the scored trace: a closed curve n inputs over a turn (the last one
    before the first again), an open one n inputs from start to start + span, both ends included."""
    if closed:
        return start + 2 * np.pi * np.arange(n) / n
    return start + span * np.linspace(0.0, 1.0, n)


def score(topo: Topology, pose: np.ndarray, start: float, span: float, target: Target, *,
          n_trace: int, n_points: int) -> tuple[_dist.Match, Assembly]:
    """The exact distance and the assembly check of one candidate (float64): the phase-free distance
    (`distance.match`, at `distance.N_FINE` points whatever `n_points`, the surrogate's count) of the
    path traced at `n_trace` inputs. A timed target: the ordered distance (`distance.match_ordered`)
    of the traced point at start + (t_i − t_0) to point i, the check over that interval (a closed
    target: the whole turn). A candidate whose file would hold a value outside its domain
    (`in_domain`) does not pass the check (`asm.ok` False)."""
    m, asm = _scored(topo, pose, start, span, target, n_trace=n_trace, n_points=n_points)
    if asm.ok and np.isfinite(m.distance) and not in_domain(topo, pose, start, m, target):
        asm = asm._replace(ok=False)
    return m, asm


def in_domain(topo: Topology, pose: np.ndarray, start: float, m: _dist.Match, target: Target) -> bool:
    """Whether the candidate placed onto the target (`mechanism.placed_pose`, in the target's unit,
    as its file writes it: mm when the target names none) holds values a file can
    (`jaxlink.model.domains.joints_inside`: no link shorter than a nanometre, nothing beyond 1000 km)."""
    unit = {"m": 1.0, "mm": 1e-3, "cm": 1e-2}.get(target.unit, 1e-3)
    return joints_inside(placed_pose(topo, pose, start, m) * unit, bodies(topo))


def _scored(topo: Topology, pose: np.ndarray, start: float, span: float, target: Target, *,
            n_trace: int, n_points: int) -> tuple[_dist.Match, Assembly]:
    asm = certify(topo, pose, *certified_interval(start, span, target))
    if target.timed:
        t = np.asarray(target.inputs, float)
        pos, marg = trace_exact(topo, pose, start + (t - t[0]))
        if not np.all(marg > 0):
            return _dist.Match(np.inf, 0.0, 1.0, np.zeros(2)), asm
        return _dist.match_ordered(pos[:, topo.traced], target.points), asm
    th = interval_offsets(start, span, n_trace, target.closed)
    pos, marg = trace_exact(topo, pose, th)
    if not np.all(marg > 0):
        return _dist.Match(np.inf, 0.0, 1.0, np.zeros(2)), asm
    return _dist.match(pos[:, topo.traced], target.points, closed=target.closed), asm


def certified_interval(start: float, span: float, target: Target) -> tuple[float, float]:
    """(start, span) of the interval a candidate is certified over (`score`): a closed target's whole
    turn, a timed one's from its first input to its last (either way), an open one's sub-interval."""
    if target.timed:
        t = np.asarray(target.inputs, float)
        sp = float(t[-1] - t[0])
        return (start if sp >= 0 else start + sp), (2 * np.pi if target.closed else abs(sp))
    return start, (2 * np.pi if target.closed else span)


def keeps_transmission(topo: Topology, pose, start: float, span: float, target: Target, floor: float) -> bool:
    """Whether a candidate's least transmission angle over its interval (`transmission.least`) has a
    margin sin² of at least `floor`."""
    return bool(_tm.least(topo, pose, *certified_interval(start, span, target)).margin >= floor)


def size_of(topo: Topology, pose, m: _dist.Match, target: Target, n_points: int = _dist.N_POINTS,
            frame: tuple | None = None) -> float:
    """The size of a scored design (`size.design_size`), in the target's extents; nan without a match.
    `frame`: the target's `size.target_frame`, if known."""
    if not np.isfinite(m.distance):
        return float("nan")
    centre, _, ext = _size.target_frame(target, n_points) if frame is None else frame
    return _size.design_size(topo, pose, m, centre, ext)


def _full_slots(prog, key, arr, samples, screen_keep, refine, tdesc, trank, flag, arcs_all, closed, elites,
                jitter, rng, bounds, clock=None):
    """A full round's refinement slots: screen, rank, the best `refine` per topology rotated to their
    best angle; the last half of each topology's slots restart from its best refined so far, jittered.
    `clock` (a dict): the seconds of the screen and of the rank are written there."""
    t0 = time.perf_counter()
    n_topos = arr.parents.shape[0]
    picks_pose, picks_arc, picks_topo = [], [], []
    for ti in range(n_topos):
        sub = jax.random.fold_in(key, ti)
        par = np.repeat(arr.parents[ti:ti + 1], samples, 0)
        act = np.repeat(arr.active[ti:ti + 1], samples, 0)
        trc = np.repeat(arr.traced[ti:ti + 1], samples, 0)
        poses, d = prog.screen(sub, par, act, trc, tdesc, bounds)
        d = np.asarray(d)
        flat = np.argsort(d, axis=None)[:screen_keep]  # a fixed count: the same shapes every round
        ci, ai = np.unravel_index(flat, d.shape)
        picks_pose.append(np.asarray(poses)[ci])
        picks_arc.append(arcs_all[ai])
        picks_topo.append(np.full(len(ci), ti))
    pose = np.concatenate(picks_pose)
    arc = np.concatenate(picks_arc)
    tix = np.concatenate(picks_topo)
    t1 = time.perf_counter()
    val, phi = prog.rank(arr.parents[tix], arr.active[tix], arr.traced[tix], pose, arc, trank, flag,
                         _u(RANK_T, closed), bounds)
    val, phi = np.asarray(val), np.asarray(phi)
    if clock is not None:
        clock.update(screen=t1 - t0, rank=time.perf_counter() - t1)
    # `refine` per topology (the same shapes every round); the inf ones are dropped after
    sel = np.concatenate([np.flatnonzero(tix == ti)[np.argsort(val[tix == ti], kind="stable")][:refine]
                          for ti in range(n_topos)])
    # rotate each pose so that its curve is near the target's orientation; the offsets stay
    poses0 = _rotate(pose[sel], phi[sel]).astype(np.float32)
    arcs0 = arc[sel].copy()
    rank_ok = np.isfinite(val[sel])
    stix = tix[sel]
    for ti, el in elites.items():
        slots = np.flatnonzero(stix == ti)[refine - refine // 2:]
        for k, slot in enumerate(slots):
            poses0[slot], arcs0[slot] = _jittered(el[k % len(el)], jitter * (k > 0), closed, rng)
            rank_ok[slot] = True
    return stix, poses0, arcs0, rank_ok


def _full_slots_timed(prog, key, arr, refine, screen_target, elites, jitter, rng, bounds):
    """A timed target's full round's slots: the screen's best `refine` (pose, start) per topology
    (its span the target's), the last half of each topology's slots its best refined so far, jittered."""
    n_topos = arr.parents.shape[0]
    tt, tw, tu, span = screen_target
    picks = []
    for ti in range(n_topos):
        sub = jax.random.fold_in(key, ti)
        par, act, trc = (np.repeat(x[ti:ti + 1], prog.screen.n, 0) for x in (arr.parents, arr.active, arr.traced))
        poses, d = prog.screen(sub, par, act, trc, tt, tw, tu, np.float32(span), bounds)
        d = np.asarray(d)
        flat = np.argsort(d, axis=None)[:refine]
        ci, si = np.unravel_index(flat, d.shape)
        picks.append((np.asarray(poses)[ci], si, np.isfinite(d[ci, si]), np.full(len(ci), ti)))
    poses0 = np.concatenate([p[0] for p in picks]).astype(np.float32)
    arcs0 = np.stack([2 * np.pi * np.concatenate([p[1] for p in picks]) / _STARTS,
                      np.full(len(poses0), span)], axis=1).astype(np.float32)
    rank_ok = np.concatenate([p[2] for p in picks])
    stix = np.concatenate([p[3] for p in picks])
    for ti, el in elites.items():
        slots = np.flatnonzero(stix == ti)[refine - refine // 2:]
        for k, slot in enumerate(slots):
            poses0[slot], arcs0[slot] = _jittered(el[k % len(el)], jitter * (k > 0), True, rng)
            rank_ok[slot] = True
    return stix, poses0, arcs0, rank_ok


def _jittered(elite, jitter, closed, rng):
    ep, ea = elite
    scale = np.sqrt(np.mean(np.sum((ep - ep.mean(0)) ** 2, -1)))
    return (ep + rng.normal(0.0, jitter * scale, ep.shape),
            ea + (rng.normal(0.0, jitter, 2) if not closed else 0.0))


def _polish_slots(elites, elite_vals, n_slots, jitter, closed, rng):
    """A polishing round's slots (the same count as a full round's): every slot on one of the three
    topologies whose best refined value is lowest, evenly; on each, its two best refined as they are,
    the others jittered by 0.25–2 × `jitter`."""
    best = sorted(elites, key=lambda ti: elite_vals[ti][0][0])[:3]
    stix = np.array([best[i % len(best)] for i in range(n_slots)])
    poses0, arcs0 = [], []
    for i, ti in enumerate(stix):
        k = i // len(best)
        el = elites[ti]
        amp = 0.0 if k < len(el) else jitter * (0.25, 0.5, 1.0, 2.0)[k % 4]
        p, a = _jittered(el[k % len(el)], amp, closed, rng)
        poses0.append(p)
        arcs0.append(a)
    return stix, np.asarray(poses0, np.float32), np.asarray(arcs0, np.float32)


def search(target: Target, topos: list[Topology], *, time_limit: float | None = None, seed: int = 0,
           rounds: int | None = None, samples: int = 8192, screen_keep: int = 128, refine: int = 8,
           steps: int = 300, n_trace: int = 1000, n_points: int = _dist.N_POINTS, per_topology: int = 2,
           lr: float = 0.01, jitter: float = 0.02, quick: bool | None = None, t0: float | None = None,
           finish: int | None = None, max_size: float | None = None, min_transmission: float | None = None,
           log=None, checkpoint=None, resume: bool = False, fingerprint: str = "",
           blocks: tuple[int, int, int] | None = None, status: dict | None = None) -> list[Candidate]:
    """Rounds of screen → rank → refine → score: `rounds` of them, or until `time_limit` seconds.
    `rounds` (default `DEFAULT_ROUNDS` when no `time_limit` is given): that many rounds (the
    polishing ones counted), full and polishing alternating: the same result on any machine, any
    number of devices or processes. `time_limit` (seconds, compiling included; default none): a
    cap. With `rounds` too, a round starts only if `ROUND_MARGIN` times the last one of its kind
    fits in the time left; alone, the rounds go on while one fits (after each full round, and
    whenever the time left is too short for another full round but not for a refinement, a
    polishing round refines the best found again, `_polish_slots`). In one process a round still
    running at `ABANDON_AT` times the limit is abandoned between two blocks (the rounds done are
    the answer; none done: no answer). A search stopped by its limit depends on the machine's
    speed. `status` (a dict, if given) receives `rounds` (the rounds done) and `stopped_by`:
    "rounds" (they were done) or "time_limit" (the limit stopped a round, its scoring or a polish),
    and `outside`: the scored candidates that assemble but break `max_size` or `min_transmission`
    (not in the checkpoint: a resumed search's are its own rounds').
    `quick` (`programs`; default: when a `time_limit` ≤ 15 s is given) trades run time for compile
    time. Several processes (`jax.distributed`): each computes its share of every batch, all hold
    the same results, process 0's clock decides the rounds (`spread`).
    `finish` (default 4, 0 when `quick`: a short search has no time to compile the polish): after
    every round that round's best candidate, and after the last round up to `finish` more
    (`_to_polish`), are polished in float64 (`polish`) while the time limit leaves room
    (`_polish_starts`: in one process each polish stops at the limit, so the time a slow round
    leaves is spent polishing; without a time limit: always, each to its end); in one process,
    with a time limit and no `rounds`, while time is left after those, the next best (within
    twice the best unpolished distance) too.
    Each polished candidate is scored like the others and added beside its original.
    `max_size` K: every answer's size (`size.design_size`) at most K — its links at most K times the
    target's extent, its frame pivots within K times it of the target's centre —, the screen, the
    rank, the refinements and the polish kept within it (`size`); default: no bound (each answer's
    size is reported either way). `min_transmission` μ (degrees): every answer's least transmission
    angle over its interval (`transmission.least`, located between samples) at least μ, the screen,
    the rank, the refinements and the polish kept above it (`transmission`).
    `checkpoint` (a path): the whole state written there after every round and every final polish
    (`checkpoint.save`, with `fingerprint`); `resume`: continue from the state saved there
    (`checkpoint.load`; none: from the start). With `rounds` a resumed search ends with exactly the
    uninterrupted one's candidates; with a time limit the time spent before counts against it.
    `blocks`: the caps (screen, rank, refinement) of the batches' blocks (`programs`; default the
    platform's, `block_caps`: the answer's bits depend on them).
    Returns every scored candidate that assembles (and is within `max_size`, and keeps
    `min_transmission`), best first."""
    if rounds is not None and (isinstance(rounds, bool) or not isinstance(rounds, (int, np.integer)) or rounds < 1):
        raise ValueError(f"rounds = {rounds!r}: a whole number of rounds, at least 1")
    if time_limit is not None and (isinstance(time_limit, bool) or not isinstance(
            time_limit, (int, float, np.integer, np.floating)) or not 0 < time_limit < np.inf):
        raise ValueError(f"time_limit = {time_limit!r}: a finite number of seconds above 0, or None")
    if rounds is None and time_limit is None:
        rounds = DEFAULT_ROUNDS
    capped = time_limit is not None
    limit = float(time_limit) if time_limit is not None else np.inf  # the cap (s)
    status = {} if status is None else status
    status.update(rounds=0, stopped_by="rounds", outside=[])
    outside: list[Candidate] = status["outside"]  # the scored candidates that assemble outside the bounds
    if finish is not None and (isinstance(finish, bool) or not isinstance(finish, (int, np.integer)) or finish < 0):
        raise ValueError(f"finish = {finish!r}: a whole number of candidates to polish, at least 0")
    if isinstance(per_topology, bool) or not isinstance(per_topology, (int, np.integer)) or per_topology < 1:
        raise ValueError(f"per_topology = {per_topology!r}: a whole number of candidates scored per topology "
                         "and round, at least 1")
    if max_size is not None and not (isinstance(max_size, (int, float, np.integer, np.floating))
                                     and not isinstance(max_size, bool) and max_size > 0):
        raise ValueError(f"max_size = {max_size!r}: a positive number of target extents")
    if min_transmission is not None and not (isinstance(min_transmission, (int, float, np.integer, np.floating))
                                             and not isinstance(min_transmission, bool)
                                             and 0 < min_transmission < 90):
        raise ValueError(f"min_transmission = {min_transmission!r}: an angle in degrees between 0 and 90")
    began: float = time.perf_counter() if t0 is None else t0  # the search's clock starts
    path = None if checkpoint is None else Path(checkpoint)
    saved = _ckpt.load(path, fingerprint) if resume and path is not None else None  # before any compiling
    closed = target.closed
    timed = target.timed
    arr = as_arrays(topos)
    sized = max_size is not None and bool(np.isfinite(max_size))
    bounded = sized or min_transmission is not None  # the programs that keep designs within bounds
    frame = _size.target_frame(target, n_points)
    bound = float(max_size) if max_size is not None and sized else np.inf  # in target extents
    floor = _tm.floor_of(min_transmission)  # sin² μ of the least transmission angle (0: none)
    bounds = np.array([_size.limit(bound, frame[2], frame[1]), floor], np.float32)
    quick = quick_of(time_limit, quick)
    blocks = checked_blocks(blocks)
    finish = (0 if quick else 4) if finish is None else finish
    sliders = any(t.sliders or t.levers for t in topos)  # the programs that trace both kinds
    polish_points = (len(target.points) if timed else n_points) if finish > 0 else 0
    # a time limit in one process: a compile still running at `ABANDON_AT` times it ends the search
    start = began if saved is None else time.perf_counter() - saved["elapsed"]
    compile_by = start + ABANDON_AT * limit if capped and jax.process_count() == 1 else None
    try:
        prog = programs(len(topos), arr.parents.shape[1], closed, samples=samples, screen_keep=screen_keep,
                        refine=refine, steps=steps, quick=quick, polish_points=polish_points,
                        sliders=sliders, timed=timed, bounded=bounded, blocks=blocks, deadline=compile_by)
    except _spread.OutOfTime:
        status.update(stopped_by="time_limit", rounds=int(saved["rnd"]) if saved is not None else 0)
        if log is not None:
            log(f"the programs were still compiling at {time.perf_counter() - start:.1f} s (the time limit: "
                f"{limit:g} s)")
        return sorted(saved["found"], key=lambda c: c.match.distance) if saved is not None else []
    if timed:  # the screen's and the refinement's samples of the target; `jitter` leaves the span alone
        ts = timed_samples(target, TIMED_SCREEN_T)
        screen_target = (*(np.asarray(x, np.float32) for x in ts[:3]), ts[3])
        rt, rw, ru, _ = (np.asarray(x, np.float32) for x in timed_samples(target, REFINE_T))
    else:
        tpts = _dist.normalise(arclength_resample(target.points, TARGET_N, closed))[0]
        tdesc = _desc(target.points, closed)
        trank = jnp.asarray(_dist.normalise(arclength_resample(target.points, RANK_T, closed))[0], _DT)
        ttarget = jnp.asarray(tpts, _DT)
    arcs_all = _subarcs(closed)
    flag = np.float32(closed)
    key = jax.random.PRNGKey(seed)
    found: list[Candidate] = []
    rnd = 0
    round_start = time.perf_counter()
    rng = np.random.default_rng(seed)
    elites: dict[int, list] = {}       # per topology: the best two refined (pose, arc) so far
    elite_vals: dict[int, list] = {}
    nsl = (min(refine, samples * _STARTS) if timed else
           min(refine, min(screen_keep, samples * len(arcs_all))))  # refinement slots per topology
    stix = np.repeat(np.arange(len(topos)), nsl)  # the topology of each slot (a full round)
    polish = False
    t_polish = None  # the seconds one float64 polish took (the time kept free for the last ones)

    origins: set[int] = set()  # the candidates polished (by id)
    # a time-limited search in one process: its polishes stop at the limit, a round still running at
    # `ABANDON_AT` times it is abandoned, and without `rounds` the time left after the final polishes
    # polishes further candidates (several processes must polish alike: `_polish_starts`)
    cut = capped and jax.process_count() == 1

    def save(stage: str, **extra) -> None:
        if path is None:
            return
        index = {id(c): i for i, c in enumerate(found)}
        _ckpt.save(path, fingerprint, dict(
            stage=stage, rnd=rnd, key=np.asarray(key), rng=rng.bit_generator.state, elites=elites,
            elite_vals=elite_vals, found=found, origins=sorted(index[i] for i in origins if i in index),
            polish=polish, t_polish=t_polish, stix=stix, full_dur=full_dur, polish_dur=polish_dur,
            elapsed=time.perf_counter() - began, **extra))

    full_dur = polish_dur = 0.0
    if saved is not None:
        rnd, polish, t_polish, stix = saved["rnd"], saved["polish"], saved["t_polish"], saved["stix"]
        key = jnp.asarray(saved["key"])
        rng.bit_generator.state = saved["rng"]
        elites, elite_vals, found = saved["elites"], saved["elite_vals"], saved["found"]
        origins = {id(found[i]) for i in saved["origins"]}
        full_dur, polish_dur = saved["full_dur"], saved["polish_dur"]
        began = time.perf_counter() - saved["elapsed"]  # the time spent before counts
        if log is not None:
            log(f"resumed after round {rnd} ({saved['stage']}): {len(found)} candidates, "
                f"{saved['elapsed']:.1f} s spent before")

    def polish_one(c: Candidate) -> None:
        nonlocal t_polish
        # the polish's program compiles beside the refinement's and is waited for with it (`programs`):
        # a search resumed at its final polish has not called the refinement yet
        _ = prog.refine.programs
        t1 = time.perf_counter()
        origins.add(id(c))
        ti = topos.index(c.topology)
        deadline = began + limit - SCORE_RESERVE_S if cut else None
        new = _polished(c, arr.parents[ti], arr.active[ti], int(arr.traced[ti]), target, n_trace, n_points, began,
                        sliders, max_size if sized else None, min_transmission, deadline)
        if new is not None:
            found.append(new)
        t_polish = time.perf_counter() - t1  # the estimate of the next one
        if log is not None:
            log(f"polished {c.topology.name}: {c.match.distance:.4f} -> "
                f"{new.match.distance if new is not None else float('nan'):.4f}, {time.perf_counter() - began:.1f} s")

    def last_round(now: float) -> bool:
        """After a round (at `now`): whether it was the last; else `polish` says what the next is."""
        nonlocal polish
        if rounds is not None:
            polish = bool(elites) and not polish  # as below when time is no limit
            if rnd >= rounds:
                return True
            # with a time limit too: the next round only if 1.25 times its kind's last fits (process 0's clock)
            if capped and _spread.agreed(int(ROUND_MARGIN * (polish_dur if polish else full_dur)
                                             > limit - (now - began))):
                status["stopped_by"] = "time_limit"
                return True
            return False
        nxt = _spread.agreed(_next_round(limit - (now - began), full_dur, polish_dur, bool(elites), polish))
        # process 0's clock decides for all
        polish = nxt == 1
        if nxt < 0:
            status["stopped_by"] = "time_limit"
        return nxt < 0

    done = saved is not None and (saved["stage"] != "rounds" or last_round(time.perf_counter()))
    if cut:  # a round still running at `ABANDON_AT` times the limit is abandoned (`spread.Blocked`)
        for blocked in prog:
            if blocked is not None:
                blocked.deadline = began + ABANDON_AT * limit
    round_start = time.perf_counter()
    while not done:
        try:
            rnd += 1
            n_before = len(found)
            clock: dict[str, float] = {}  # the round's phases (s), for the log
            if polish:
                stix, poses0, arcs0 = _polish_slots(elites, elite_vals, len(stix), jitter, closed or timed, rng)
                rank_ok = np.ones(len(stix), bool)
            elif timed:
                t_screen = time.perf_counter()
                stix, poses0, arcs0, rank_ok = _full_slots_timed(prog, key, arr, nsl, screen_target, elites, jitter,
                                                                 rng, bounds)
                clock["screen"] = time.perf_counter() - t_screen
                key = jax.random.fold_in(key, rnd)
            else:
                stix, poses0, arcs0, rank_ok = _full_slots(prog, key, arr, samples, screen_keep, refine, tdesc,
                                                           trank, flag, arcs_all, closed, elites, jitter, rng, bounds,
                                                           clock)
                key = jax.random.fold_in(key, rnd)
            t_ref = time.perf_counter()
            if timed:
                p, a, v = prog.refine(arr.parents[stix], arr.active[stix], arr.traced[stix], poses0, arcs0, rt, rw,
                                      np.float32(lr), ru, bounds)
            else:
                p, a, v = prog.refine(arr.parents[stix], arr.active[stix], arr.traced[stix], poses0,
                                      arcs0, ttarget, np.float32(lr), flag, _u(REFINE_T, closed), bounds)
            p, a, v = np.asarray(p, float), np.asarray(a, float), np.asarray(v)
            t_score = time.perf_counter()
            clock["refine"] = t_score - t_ref
            for ti in range(len(topos)):
                idx = np.flatnonzero((stix == ti) & np.isfinite(v) & rank_ok)
                pool = [(v[i], p[i].astype(np.float32), a[i].astype(np.float32)) for i in idx]
                pool += elite_vals.get(ti, [])
                pool.sort(key=lambda e: e[0])
                if pool:
                    elite_vals[ti] = pool[:2]
                    elites[ti] = [(e[1], e[2]) for e in pool[:2]]
            # the exact scoring after the search's first design stops at the time limit (one process)
            stop = began + limit - SCORE_RESERVE_S if cut and found else None

            def scored(ti: int, stop=stop) -> list[Candidate]:
                """Topology `ti`'s refined candidates scored in the surrogate's order until `per_topology`
                pass, trying at most SCORE_TRIES times as many: the best by the surrogate can all fail
                the exact check (a four-bar pushed to a dead centre on letter R's corners), the next
                ones not; none after `stop` (a `time.perf_counter()` time)."""
                idx = np.flatnonzero(stix == ti)
                idx = idx[np.isfinite(v[idx]) & rank_ok[idx]]
                kept: list[Candidate] = []
                for i in idx[np.argsort(v[idx])][:SCORE_TRIES * per_topology]:
                    if len(kept) >= per_topology:
                        break
                    if stop is not None and time.perf_counter() >= stop:
                        status["stopped_by"] = "time_limit"  # the scoring stopped by the limit
                        break
                    start = float(a[i, 0])
                    span = (float(target.inputs[-1] - target.inputs[0]) if target.inputs is not None
                            else 2 * np.pi if closed else float(a[i, 1]))
                    m, asm = score(topos[ti], p[i], start, span, target, n_trace=n_trace, n_points=n_points)
                    sz = size_of(topos[ti], p[i], m, target, n_points, frame)
                    if np.isfinite(m.distance) and asm.ok and (not sized or sz <= bound) and (
                            floor == 0 or keeps_transmission(topos[ti], p[i], start, span, target, floor)):
                        kept.append(Candidate(topos[ti], p[i], start, span, m, asm, time.perf_counter() - began,
                                              size=sz))
                    elif np.isfinite(m.distance) and asm.ok:  # assembles, outside the bounds: set aside
                        outside.append(Candidate(topos[ti], p[i], start, span, m, asm, time.perf_counter() - began,
                                                 size=sz))
                return kept

            # the topologies side by side (NumPy and SciPy's k-d trees release the interpreter), the most
            # promising first (the least surrogate value: what a stop at the time limit keeps); the
            # candidates added in topology order (each topology's the same whatever the threads)
            ok_v = np.where(np.isfinite(v) & rank_ok, v, np.inf)
            first = sorted(range(len(topos)), key=lambda ti: float(np.min(ok_v[stix == ti], initial=np.inf)))
            with ThreadPoolExecutor(SCORE_THREADS) as ex:
                futures = {ti: ex.submit(scored, ti) for ti in first}
                for ti in range(len(topos)):
                    found.extend(futures[ti].result())
            if log is not None:
                best = min((c.match.distance for c in found), default=float("inf"))
                clock["score"] = time.perf_counter() - t_score
                phases = ", ".join(f"{what} {sec:.1f} s" for what, sec in clock.items())
                log(f"round {rnd}{' (polish)' if polish else ''}: {len(found)} candidates, best distance {best:.4f}, "
                    f"{time.perf_counter() - began:.1f} s ({phases})")
            now = time.perf_counter()
            dur = now - round_start
            if polish:
                polish_dur = dur
            else:
                full_dur, polish_dur = dur, now - t_ref  # the compiling is done before the first round
            if finish > 0:  # this round's best, polished in float64 if time is left (`_polish_starts`)
                mine = _to_polish(found[n_before:], origins, 1, min((c.match.distance for c in found), default=np.inf))
                guess = polish_dur if t_polish is None else t_polish  # before the first: the round's refinement
                if mine and _polish_starts(limit - (now - began), guess, not capped):
                    polish_one(mine[0])
            save("rounds")
            now = round_start = time.perf_counter()
            done = last_round(now)
        except _spread.OutOfTime:
            # abandoned at `ABANDON_AT` times the limit, in its screen, rank or refinement (before it
            # changed the candidates or the elites): the rounds done are the answer
            status["stopped_by"] = "time_limit"
            if log is not None:
                log(f"round {rnd} abandoned at {time.perf_counter() - began:.1f} s (the time limit: {limit:g} s)")
            rnd -= 1
            break
    if saved is not None and saved["stage"] != "rounds":  # resumed in the final polish (or after it)
        last, n_done = saved["last"], saved["n_done"]
    else:
        where = {id(c): i for i, c in enumerate(found)}
        last = [where[id(c)] for c in _to_polish(found, origins, finish)] if finish > 0 and t_polish is not None \
            else []
        n_done = 0
        save("finish", last=last, n_done=0)
    for k in range(n_done, len(last)):
        if not _polish_starts(limit - (time.perf_counter() - began), t_polish or 0.0, not capped):
            break
        polish_one(found[last[k]])
        save("finish", last=last, n_done=k + 1)
    while finish > 0 and cut and rounds is None and _polish_starts(
            limit - (time.perf_counter() - began), 0.0, False):  # time left: the next candidates too
        more = _to_polish(found, origins, 1, min((c.match.distance for c in found if not c.polished), default=np.inf))
        if not more:
            break
        polish_one(more[0])
        save("finish", last=last, n_done=len(last))
    found.sort(key=lambda c: c.match.distance)
    status["rounds"] = rnd
    return found


#: a time-limited search starts another round only if this many times the last one of its kind
#: fits in the time left: a round's time varies (the slots grow with the elites; on a GPU shared by
#: 5 processes a round took up to 2x the one before it, and three letters of 26 passed their limit
#: of 58 s by 0.6-9 s)
ROUND_MARGIN = 1.25


def _next_round(left: float, full_dur: float, polish_dur: float, elites: bool, after_polish: bool) -> int:
    """A time-limited search's next round with `left` seconds of its limit left, after a full round
    of `full_dur` s and a polishing one of `polish_dur` s (before any: the first round's refinement),
    `after_polish` when the round just done was a polishing one: 1 a polishing round (after each full
    one, and while a full one no longer fits), 0 a full round, -1 none (stop); a round starts only
    if `ROUND_MARGIN` times its kind's last time fits."""
    can_polish = elites and ROUND_MARGIN * polish_dur <= left
    if can_polish and not after_polish:
        return 1  # after each full round one polishing round: the best found refined again
    if ROUND_MARGIN * full_dur <= left:
        return 0  # another full round
    return 1 if can_polish else -1  # polishing again: a full round no longer fits


#: the least time left (s) for which a time-limited search starts a float64 polish in one process
POLISH_MIN_S = 1.0
#: the time (s) a polish leaves before the time limit for its scoring (`_polished`: the trace, the
#: certificate and up to `polish.BACK` points back)
SCORE_RESERVE_S = 0.5


def _polish_starts(left: float, guess: float, exact: bool) -> bool:
    """Whether a float64 polish starts with `left` seconds of the time limit left: without a time
    limit (`exact`) always; in one process when at least `POLISH_MIN_S` is left (the polish stops at the
    time limit less `SCORE_RESERVE_S`, `polish.polish`'s deadline, whatever it was expected to
    take); in several processes, which must polish alike, when one as long as `guess` (the last
    polish's time; before the first, the round's refinement) fits, as process 0's clock says."""
    if exact:
        return True
    if jax.process_count() == 1:
        return left >= POLISH_MIN_S
    return bool(_spread.agreed(int(guess <= left)))


def _to_polish(found: list[Candidate], origins: set[int], n: int, best: float | None = None) -> list[Candidate]:
    """Up to `n` candidates of `found` to polish: not polished before and not a polish's result,
    within twice the `best` distance (default: the best of `found`), best first; the best of each
    topology first, then the second best of each."""
    if not found:
        return []
    limit = 2.0 * (min(c.match.distance for c in found) if best is None else best)
    pool = sorted((c for c in found if not c.polished and id(c) not in origins and c.match.distance <= limit),
                  key=lambda c: c.match.distance)
    taken: list[Candidate] = []
    for per in (1, 2):
        for c in pool:
            if len(taken) == n:
                return taken
            if all(t is not c for t in taken) and sum(t.topology.name == c.topology.name for t in taken) < per:
                taken.append(c)
    return taken


def _polished(c: Candidate, parents, active, traced: int, target: Target, n_trace: int, n_points: int,
              t0: float, sliders: bool = False, max_size: float | None = None,
              min_transmission: float | None = None, deadline: float | None = None) -> Candidate | None:
    """`c` polished (`polish.polish`, stopped at `deadline` if given) and scored; if it does not
    assemble (or is larger than `max_size`, or its least transmission angle below `min_transmission`),
    the first point back towards `c` (`polish.BACK`) that does; None if none does."""
    pose, start, span = _polish(parents, active, traced, c.pose, c.start, c.span, target, n_points=n_points,
                                sliders=sliders, max_size=max_size, min_transmission=min_transmission,
                                deadline=deadline)
    floor = _tm.floor_of(min_transmission)
    frame = _size.target_frame(target, n_points)
    for f in BACK:
        p = c.pose + f * (pose - c.pose)
        st, sp = c.start + f * (start - c.start), c.span + f * (span - c.span)
        m, asm = score(c.topology, p, st, sp, target, n_trace=n_trace, n_points=n_points)
        sz = size_of(c.topology, p, m, target, n_points, frame)
        if np.isfinite(m.distance) and asm.ok and (max_size is None or sz <= max_size) and (
                floor == 0 or keeps_transmission(c.topology, p, st, sp, target, floor)):
            return Candidate(c.topology, p, st, sp, m, asm, time.perf_counter() - t0, True, sz)
    return None
