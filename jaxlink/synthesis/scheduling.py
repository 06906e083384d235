"""The search's rounds: what a full round and a polishing round refine (`_full_slots`,
`_polish_slots`), and the time decisions of a time-limited search — the next round
(`_next_round`), whether a float64 polish starts (`_polish_starts`), which candidates are polished
(`_to_polish`)."""

from __future__ import annotations

import time

import jax
import numpy as np

from . import spread as _spread
from .ranking import RANK_T, _rotate, _u
from .scoring import Candidate
from .screening import _STARTS

#: the rounds of a search given neither `rounds` nor a time limit: a full round and a polishing
#: round (then the final polishes), about what the former default limit of 60 s ran on a quiet
#: 2-core CPU with the 16 topologies up to eight links; a count, the same designs on any machine
DEFAULT_ROUNDS = 2


#: a time-limited search in one process abandons a round before a turn of blocks (`spread.Blocked`'s
#: deadline) whose batch would not end by this many times its limit, at the time its turns took,
#: keeping the rounds done; and stops waiting for programs still compiling there, and starts none
#: whose compile (as measured here before, `compiling.estimate`) would not end by then: what
#: follows (the round's scoring until a design passes, the designs, the files) takes the rest of
#: the 10 % + 2 s a run may overrun its limit by
ABANDON_AT = 1.0


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
