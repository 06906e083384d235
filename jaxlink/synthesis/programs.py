"""The search's compiled programs: the screen, the rank and the refinement of a batch's block,
compiled at once in threads (`programs`), kept for the process (`_compiled`, keyed by every static
input) and as stored traces beside the compilation cache (`cache.compiled`); the blocks' caps per
platform (`block_caps`) and the quick programs of a short search (`quick_of`)."""

from __future__ import annotations

import functools
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any, NamedTuple

import jax
import numpy as np

from ..cache import background as _background
from ..cache import compiled
from . import compiling as _compiling
from . import spread as _spread
from .polish import program as _polish_program
from .polish import program_timed as _polish_program_timed
from .ranking import RANK_T, _rank
from .refinement import REFINE_T, TARGET_N, _refine, _refine_timed
from .screening import _STARTS, DESC_N, TIMED_SCREEN_T, _screen, _screen_timed, _subarcs
from .topology import CRANK

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
    stopped: they are noted as such, `cache.background`, and the command line's process ends
    without waiting for them). The compile's seconds, from the start to the last program, are
    recorded (`compiling.record`, under `compile_key` of the same arguments)."""
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
    every = futures + ([pol] if pol is not None else [])
    for f in every:
        _background(f)
    _timed_compile(every, compile_key(n_topos, n_dyads, closed, samples=samples, screen_keep=screen_keep,
                                      refine=refine, steps=steps, quick=quick, where=where,
                                      polish_points=polish_points, sliders=sliders, timed=timed,
                                      bounded=bounded, blocks=blocks))

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


def compile_key(n_topos: int, n_dyads: int, closed: bool, *, samples: int, screen_keep: int, refine: int,
                steps: int, quick: bool = False, where: _spread.Layout | None = None, polish_points: int = 0,
                sliders: bool = False, timed: bool = False, bounded: bool = False,
                blocks: tuple[int, int, int] | None = None) -> str:
    """The key (`compiling.key`) under which the compile of `programs` with these arguments is
    recorded and estimated: its programs' blocks, options and devices."""
    keep = min(screen_keep, samples * len(_subarcs(closed)))
    given = checked_blocks(blocks)
    caps = default_blocks(quick) if given is None else given
    where = _spread.layout() if where is None else where
    sizes = (samples, keep * n_topos, min(refine, keep) * n_topos)
    return _compiling.key(blocks=[_spread.blocks(n, c)[1] for n, c in zip(sizes, caps)], n_dyads=n_dyads,
                          closed=closed, steps=steps, quick=quick, devices=where.devices,
                          polish_points=polish_points, sliders=sliders, timed=timed, bounded=bounded)


def _timed_compile(futures: list, key: str) -> None:
    """Record (`compiling.record`) the seconds from now until every one of `futures` is done, if
    all succeed."""
    t0 = time.perf_counter()
    left = [len(futures)]
    lock = threading.Lock()

    def one_done(f: Future) -> None:
        with lock:  # the futures end in their own threads
            left[0] -= 1
            last = left[0] == 0
        if last and all(g.exception() is None for g in futures):
            _compiling.record(key, time.perf_counter() - t0)

    for f in futures:
        f.add_done_callback(one_done)


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
