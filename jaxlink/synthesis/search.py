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
   the most promising first; in a time-limited search in one process, once a design is kept (in
   a round before, or in this one by any topology), no score starts past the time limit (less
   `SCORE_RESERVE_S`).

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

import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from . import checkpoint as _ckpt
from . import compiling as _compiling
from . import distance as _dist
from . import size as _size
from . import spread as _spread
from . import transmission as _tm
from .polish import BACK
from .polish import polish as _polish
from .programs import ACCEL_BLOCKS as ACCEL_BLOCKS
from .programs import RANK_BLOCK as RANK_BLOCK
from .programs import REFINE_BLOCK as REFINE_BLOCK
from .programs import REFINE_BLOCK_QUICK as REFINE_BLOCK_QUICK
from .programs import SCREEN_BLOCK as SCREEN_BLOCK
from .programs import _compiled as _compiled
from .programs import _platform as _platform
from .programs import _rank_of as _rank_of
from .programs import _refine_of as _refine_of
from .programs import _refine_timed_of as _refine_timed_of
from .programs import _screen_of as _screen_of
from .programs import _screen_timed_of as _screen_timed_of
from .programs import block_caps as block_caps
from .programs import checked_blocks, compile_key, programs, quick_of
from .programs import default_blocks as default_blocks
from .ranking import RANK_T, _u
from .refinement import REFINE_T, TARGET_N
from .scheduling import (
    ABANDON_AT,
    DEFAULT_ROUNDS,
    ROUND_MARGIN,
    SCORE_RESERVE_S,
    _full_slots,
    _full_slots_timed,
    _next_round,
    _polish_slots,
    _polish_starts,
    _to_polish,
)
from .scheduling import POLISH_MIN_S as POLISH_MIN_S
from .scoring import SCORE_THREADS, SCORE_TRIES, Candidate, keeps_transmission, score, size_of
from .scoring import certified_interval as certified_interval
from .scoring import in_domain as in_domain
from .scoring import interval_offsets as interval_offsets
from .screening import _DT, _STARTS, TIMED_SCREEN_T, _desc, _subarcs, timed_samples
from .screening import DESC_N as DESC_N
from .screening import _screen_timed as _screen_timed
from .target import Target, arclength_resample
from .topology import CRANK as CRANK
from .topology import Topology, as_arrays


def search(target: Target, topos: list[Topology], *, time_limit: float | None = None, seed: int = 0,
           rounds: int | None = None, samples: int = 8192, screen_keep: int = 128, refine: int = 8,
           steps: int = 300, n_trace: int = 1000, n_points: int = _dist.N_POINTS, per_topology: int = 2,
           lr: float = 0.01, jitter: float = 0.02, quick: bool | None = None, t0: float | None = None,
           finish: int | None = None, max_size: float | None = None, min_transmission: float | None = None,
           log=None, checkpoint=None, resume: bool = False, fingerprint: str = "",
           blocks: tuple[int, int, int] | None = None, status: dict | None = None,
           progress=None) -> list[Candidate]:
    """Rounds of screen → rank → refine → score: `rounds` of them, or until `time_limit` seconds.
    `rounds` (default `DEFAULT_ROUNDS` when no `time_limit` is given): that many rounds (the
    polishing ones counted), full and polishing alternating: the same result on any machine, any
    number of devices or processes. `time_limit` (seconds, compiling included; default none): a
    cap. With `rounds` too, a round starts only if `ROUND_MARGIN` times the last one of its kind
    fits in the time left; alone, the rounds go on while one fits (after each full round, and
    whenever the time left is too short for another full round but not for a refinement, a
    polishing round refines the best found again, `_polish_slots`). In one process a round is
    abandoned before a turn of blocks when its batch's turns left would not end by the limit
    (`spread.Blocked`, at the time its turns took; the rounds done are the answer; none done: no
    answer), and programs whose compile would not end by it (`compiling.estimate`: measured here
    before) are not compiled: the search says so and ends. A search stopped by its limit depends on the machine's
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
    platform's, `block_caps`: the answer's bits depend on them). `progress` (a function, if given)
    is called with a dict as the search goes: `stage` ("compiling" before the programs are
    compiled, "round" when a round starts, "scored" after each topology's scoring — `scored` of
    `topologies` done —, "polished" after each float64 polish, "done"), `round`, `polish` (a
    polishing round), `best` (the best `Candidate` so far, or None), `elapsed` and `left` (seconds
    since the search's clock started, and of the time limit left; None without one).
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
    if progress is not None:
        progress(dict(stage="compiling", round=0, polish=False, scored=0, topologies=len(topos), best=None,
                      elapsed=time.perf_counter() - began,
                      left=limit - (time.perf_counter() - began) if capped else None))
    # a time limit in one process: a compile that would not end by `ABANDON_AT` times it is not
    # started, and one still running then ends the search
    start = began if saved is None else time.perf_counter() - saved["elapsed"]
    compile_by = start + ABANDON_AT * limit if capped and jax.process_count() == 1 else None
    if compile_by is not None:
        need = _compiling.estimate(compile_key(len(topos), arr.parents.shape[1], closed, samples=samples,
                                               screen_keep=screen_keep, refine=refine, steps=steps, quick=quick,
                                               polish_points=polish_points, sliders=sliders, timed=timed,
                                               bounded=bounded, blocks=blocks))
        left = compile_by - time.perf_counter()
        if left <= 0 or (need is not None and need > left):
            status.update(stopped_by="time_limit", rounds=int(saved["rnd"]) if saved is not None else 0)
            if log is not None:
                log(f"the programs were not compiled: {'no time was left' if left <= 0 else ''}"
                    + (f"their compile would take about {need:.1f} s (as measured here before), more than "
                       f"the {left:.1f} s left" if left > 0 else "")
                    + f" of the time limit ({limit:g} s, counted from {time.perf_counter() - start:.1f} s ago)")
            return sorted(saved["found"], key=lambda c: c.match.distance) if saved is not None else []
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
    # a time-limited search in one process: its polishes stop at the limit, a round whose batch would
    # not end by `ABANDON_AT` times it is abandoned, and without `rounds` the time left after the final polishes
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
        tell("polished")
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
    if cut:  # a round whose batch would not end by `ABANDON_AT` times the limit is abandoned (`spread.Blocked`)
        for blocked in prog:
            if blocked is not None:
                blocked.deadline = began + ABANDON_AT * limit
    def tell(stage: str, scored: int = 0) -> None:
        """`progress` told where the search is (`stage`, `scored` topologies of this round's scoring)."""
        if progress is not None:
            now = time.perf_counter()
            progress(dict(stage=stage, round=rnd, polish=polish, scored=scored, topologies=len(topos),
                          best=min(found, key=lambda c: c.match.distance, default=None), elapsed=now - began,
                          left=limit - (now - began) if capped else None))

    round_start = time.perf_counter()
    while not done:
        try:
            rnd += 1
            tell("round")
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
            # the exact scoring after the search's first design (found in a round before, or in this
            # one by any topology's thread) stops at the time limit (one process)
            stop = began + limit - SCORE_RESERVE_S if cut else None
            any_kept = [bool(found)]

            def scored(ti: int, stop=stop) -> list[Candidate]:
                """Topology `ti`'s refined candidates scored in the surrogate's order until `per_topology`
                pass, trying at most SCORE_TRIES times as many: the best by the surrogate can all fail
                the exact check (a four-bar pushed to a dead centre on letter R's corners), the next
                ones not; none after `stop` (a `time.perf_counter()` time) once a design is kept."""
                idx = np.flatnonzero(stix == ti)
                idx = idx[np.isfinite(v[idx]) & rank_ok[idx]]
                kept: list[Candidate] = []
                for i in idx[np.argsort(v[idx])][:SCORE_TRIES * per_topology]:
                    if len(kept) >= per_topology:
                        break
                    if stop is not None and any_kept[0] and time.perf_counter() >= stop:
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
                        any_kept[0] = True
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
                    tell("scored", ti + 1)
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
        except _spread.OutOfTime as why:
            # abandoned before `ABANDON_AT` times the limit, in its screen, rank or refinement (before it
            # changed the candidates or the elites): the rounds done are the answer
            status["stopped_by"] = "time_limit"
            if log is not None:
                log(f"round {rnd} abandoned at {time.perf_counter() - began:.1f} s (the time limit: {limit:g} s): "
                    f"{why}")
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
    tell("done")
    return found


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
