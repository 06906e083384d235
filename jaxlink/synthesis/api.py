"""`jaxlink.synthesize`: a linkage whose point traces a target path — topology and dimensions."""

from __future__ import annotations

import functools
import math
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Callable, NamedTuple

import jax
import numpy as np

from ..errors import MechanismError
from ..model.sketch import Sketch
from . import bounds as _bounds
from . import checkpoint as _checkpoint
from . import distance as _dist
from . import pareto as _pareto
from . import progress as _progress
from . import size as _size
from . import transmission as _tm
from .mechanism import crank_angle, placed_pose, to_sketch
from .search import (
    SCORE_THREADS,
    Candidate,
    certified_interval,
    checked_blocks,
    default_blocks,
    interval_offsets,
    quick_of,
    search,
)
from .target import Target, load_target, make_target
from .topology import MAX_DYADS, Topology
from .topology import topologies as builtin_topologies
from .tracer import lengths


class Design(NamedTuple):
    """One answer, in the target's coordinates and unit.

    - `topology`: its name; `joints`, `links` (the frame counted as a link);
    - `distance`: the phase-free distance to the target (`jaxlink.synthesis.distance.match`: each
      point of either curve to the other's polyline, 2000 points; it does not depend on where the
      crank's turn starts), what the designs are ranked by;
    - `link_chamfer_2000`: LInK's metric of the same curve (`distance.link_chamfer`: the point
      chamfer of both curves resampled to 2000 points, at the best rotation), to compare with
      LInK's published numbers; nan for a timed target;
    - `start_deg`, `stop_deg`: the crank's angle (the file's input, degrees) at the traced interval's
      ends (a closed target: a whole turn, `stop_deg` = `start_deg` + 360); `n_inputs`: the inputs
      the distance was computed at (a closed target: `n_inputs` steps of 360/n_inputs degrees from
      `start_deg`; an open one: `n_inputs` inputs from `start_deg` to `stop_deg`, both included);
    - `scale`, `rotation_deg`, `translation`: the placement of the search's normalised mechanism
      onto the target (x ↦ k R(φ) x + t);
    - `margin`: the smallest reach margin of its dyads over the interval (`assembly`);
    - `size`: its longest link, or its frame pivot furthest from the target's centre, over the
      target's extent (its largest distance between two points): `size.design_size`, the larger of
      `link_size` (its longest link) and `pivot_size` (its frame pivot furthest from the centre);
    - `transmission_deg`: its least transmission angle over the interval (degrees, 0–90: the angle
      between the two links of a revolute dyad, between a slider's link and its guide's normal;
      located between samples, `transmission.least`);
    - `lengths`: the crank's and every dyad link's length (target unit);
    - `sketch`: the mechanism (`jaxlink.Sketch`), `curve`: the traced path (n_inputs, 2);
    - `found_s`: seconds from the start of the search to this answer; `pareto`: it is on the Pareto
      front of the answers' distance, joints, least transmission angle and size (`pareto.front`: no
      other answer is as good on each and better on one);
    - `violates`: the bounds in force it breaks, in words (`bounds.violations`; empty: it meets them
      all, `meets`);
    - `inputs_deg`: a timed target's crank angles (the file's input, degrees) at which its points are
      matched, (N,); `distance` is then the ordered distance (`distance.match_ordered`) of the
      traced point there to the target's points, and `curve` the path over the interval; else None;
    - `at_inputs`: a timed target's traced points at `inputs_deg` (N, 2), else None.
    """

    topology: str
    joints: int
    links: int
    distance: float
    start_deg: float
    stop_deg: float
    n_inputs: int
    scale: float
    rotation_deg: float
    translation: tuple[float, float]
    margin: float
    lengths: dict
    sketch: Sketch
    curve: np.ndarray
    found_s: float
    pareto: bool
    inputs_deg: np.ndarray | None = None
    at_inputs: np.ndarray | None = None
    size: float = float("nan")
    transmission_deg: float = float("nan")
    link_chamfer_2000: float = float("nan")
    link_size: float = float("nan")
    pivot_size: float = float("nan")
    violates: tuple[str, ...] = ()

    @property
    def meets(self) -> bool:
        """Whether it meets every bound in force (`Synthesis.bounds`)."""
        return not self.violates


class Synthesis(NamedTuple):
    """`target`; `designs`: the best answer of each topology, those that meet the bounds first, each
    part best first (a topology with no answer within the bounds: its best outside them, with what it
    `violates`); `wall_s`: the search's time;
    `max_size`: the bound on the designs' longest link (extents; None: none); `extent`: the target's
    extent (its largest distance between two points, in its unit: the size's unit); `min_transmission`:
    the least transmission angle asked for (degrees; None: none); `max_pivot`: the bound on the frame
    pivots' distance from the target's centre (extents; None: none); `simplest`: the index in
    `designs` of the simplest answer (`pareto.simplest`: the fewest joints within 10 % of the best
    distance, of those meeting the bounds; None: no design); `interrupted`: the search was stopped
    (Ctrl-C) and these are the designs of its rounds until then (`synthesize(checkpoint=...)`);
    `rounds`: the rounds done; `stopped_by`: "rounds" (the rounds asked for, or the default
    `search.DEFAULT_ROUNDS`, were done: the designs do not depend on the machine) or "time_limit"
    (the time limit stopped the search: they do); `time_limit`: the limit given (s; None: none)."""

    target: Target
    designs: list[Design]
    wall_s: float
    max_size: float | None = None
    extent: float = float("nan")
    min_transmission: float | None = None
    interrupted: bool = False
    rounds: int = 0
    stopped_by: str = "rounds"
    time_limit: float | None = None
    max_pivot: float | None = None
    simplest: int | None = None

    @property
    def best(self) -> Design:
        return self.designs[0]

    @property
    def bounds(self) -> _bounds.Bounds:
        """The bounds in force (`bounds.Bounds`)."""
        return _bounds.Bounds(self.min_transmission, self.max_size, self.max_pivot)

    @property
    def meets(self) -> bool:
        """Whether some design meets every bound in force (then the best does)."""
        return any(d.meets for d in self.designs)


def _design(c: Candidate, target: Target, n_trace: int, name: str, frame: tuple | None = None,
            bnds: _bounds.Bounds = _bounds.OFF) -> Design:
    """The answer of a candidate; `frame`: the target's `size.target_frame` (the search's; default
    at `distance.N_POINTS`), `bnds`: the bounds it is checked against (`Design.violates`)."""
    frame = _size.target_frame(target, _dist.N_POINTS) if frame is None else frame
    m = c.match
    placed = placed_pose(c.topology, c.pose, c.start, m)
    a0 = crank_angle(placed)
    start = math.degrees(a0)
    span = 2 * math.pi if target.closed and not target.timed else c.span
    th = interval_offsets(c.start, c.span, n_trace, target.closed and not target.timed)
    from .tracer import trace_exact

    curve = _dist.place(trace_exact(c.topology, c.pose, th)[0][:, c.topology.traced], m)
    sk = to_sketch(c.topology, placed, name=name, unit=target.unit,
                   description=f"{c.topology.name}, synthesized for {target.source} (distance {m.distance:.6g})")
    inputs_deg, at_inputs = _timed_points(c, target, m, start)
    # the least transmission angle: the assembly check's least margin (the same certificate over
    # the same interval) unless slotted levers' margins count there and not here
    mu = (_tm.least(c.topology, c.pose, *certified_interval(c.start, c.span, target)) if c.topology.levers
          else c.assembly)
    mu_deg = _tm.angle_deg(mu.margin) if np.isfinite(mu.margin) else float("nan")
    link_size, pivot_size = _size.design_sizes(c.topology, c.pose, m, frame[0], frame[2])
    return Design(c.topology.name, c.topology.n_joints, c.topology.n_links, float(m.distance), start,
                  start + math.degrees(span), n_trace, float(m.scale), math.degrees(m.rotation),
                  (float(m.translation[0]), float(m.translation[1])), float(c.assembly.margin),
                  {k: v * m.scale for k, v in lengths(c.topology, c.pose).items()}, sk, curve, c.found_s, False,
                  inputs_deg, at_inputs, float(c.size), mu_deg,
                  float("nan") if target.timed else _dist.link_chamfer(curve, target.points, closed=target.closed),
                  link_size, pivot_size, _bounds.violations(bnds, float(mu.margin), link_size, pivot_size))


def _timed_points(c: Candidate, target: Target, m: _dist.Match, start_deg: float):
    """(inputs_deg, at_inputs) of a timed target's design, (None, None) otherwise."""
    if target.inputs is None:
        return None, None
    from .tracer import trace_exact

    t = np.asarray(target.inputs, float)
    dt = t - t[0]
    at = _dist.place(trace_exact(c.topology, c.pose, c.start + dt)[0][:, c.topology.traced], m)
    return start_deg + np.degrees(dt), at


def _write_best(path: Path, target: Target, n_trace: int, name: str, c: Candidate) -> None:
    """The design of candidate `c` written to `path` as a sketch file, atomically."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(_design(c, target, n_trace, name).sketch.toml())
    tmp.replace(path)


def _blocks_of(options: dict, time_limit: float | None) -> tuple[int, ...]:
    """The blocks' caps a search with these `search.search` options and time limit takes."""
    given = checked_blocks(options.get("blocks"))
    return default_blocks(quick_of(time_limit, options.get("quick"))) if given is None else given


def synthesize(target: Any, *, closed: bool | None = None, time_limit: float | None = None, seed: int = 0,
               rounds: int | None = None, max_links: int = 8, sliders: bool = False, levers: bool = False,
               topologies: list[str | Topology] | None = None,
               n_points: int = _dist.N_POINTS, count: int = 1000, samples: int = 8192, name: str = "synthesized",
               max_size: float | None = _bounds.MAX_SIZE, min_transmission: float | None = _bounds.MIN_TRANSMISSION,
               max_pivot: float | None = _bounds.MAX_PIVOT, log: Callable[[str], None] | None = None,
               checkpoint: str | Path | None = None, resume: bool = False, started: float | None = None,
               progress: Callable[[_progress.Progress], None] | None = None, best_file: str | Path | None = None,
               **search_options) -> Synthesis:
    """Find linkages whose traced point follows `target` (a path to a .csv/.npy/.svg file, an
    (N, 2) array or a `Target`), up to `max_links` links, in `rounds` search rounds or within
    `time_limit` seconds.
    `closed`: match a closed loop over a whole crank turn, or an open path over a sub-interval
    (default: from the target, `jaxlink.synthesis.target`). `topologies`: the topologies to search, each
    the name of a built-in one (`jaxlink.synthesis.topology.topologies`) or a `Topology` (e.g. one
    grown by `topology.grow` or `topology.slide`, at most `topology.MAX_DYADS` dyads, every name
    distinct); default the built-ins up to `max_links`, with their slider variants when `sliders`
    (`topology.with_sliders`: the slider-crank, …), and with their slotted-lever variants when
    `levers` (`topology.with_levers`: a lever turning about a frame pivot, the block pinned at a
    moving joint sliding in its slot, as in the Whitworth quick return).
    Returns the best design of each topology, best first (`Synthesis.best`); `seed` makes it
    repeatable for a given number of rounds: `rounds` = N runs exactly N rounds (the polishing
    rounds counted, `search.search`; default `search.DEFAULT_ROUNDS` = 2 when no `time_limit` is
    given), so that the result is the same on any machine, any number of devices, any number of
    processes. `time_limit` (seconds, compiling included; default none) is a cap: with `rounds`,
    a round starts only if 1.25 times the last one of its kind fits in the time left; alone, the
    rounds go on while one fits; in one process a round is abandoned before a turn of its blocks
    when the turns left would not end by the limit (the rounds done are the answer: none done,
    none), and programs whose compile would not fit (as measured on this machine before:
    `compiling`) are not compiled — the log says so. `started` (a `time.perf_counter()` time,
    default this call's): when the limit's clock started (the command line's: its start, so that
    loading and importing count). `progress` (a function, if given): called with a
    `jaxlink.synthesis.progress.Progress` at every stage of the search (compiling, each round's start,
    each topology scored, each float64 polish, the end), with the best design so far. `best_file`
    (a path, if given): the best design so far written there as a sketch file after every round and
    every polish where it changed (replaced whole: a reader never sees half a file). When it stops the search,
    `Synthesis.stopped_by` is "time_limit" and the designs depend on the machine's speed. A limit
    of at most 15 s also chooses the quick programs (`search.quick_of`). Spread over this
    process's devices, and over the processes of a `jax.distributed` group
    (`jaxlink.optimize.initialize_distributed`, called first in every process): every process
    returns the same designs (`search`).
    The bounds a designer builds to, on by default (`jaxlink.synthesis.bounds`), each off with None:
    `min_transmission` μ (degrees, default 30; 0 too: none): designs whose transmission angle stays
    at least μ over their interval (`jaxlink.synthesis.transmission`, located between samples);
    `max_size` K (default 3): designs whose links are at most K times the target's extent (its
    largest distance between two points); `max_pivot` P (default 3): designs whose frame pivots are
    within P times it of the target's centre (`jaxlink.synthesis.size`). The search keeps to them
    (to the larger of K and P for both when they differ, the exact check then marking the others);
    each design's `transmission_deg`, `link_size`, `pivot_size` are reported either way, and what it
    `violates`. The designs meeting them come first; a topology with none within them is shown by its
    best outside them (so when none meets them, `Synthesis.meets` is False and the best shown breaks
    them: its `violates` says how). Every design is marked on the Pareto front or not
    (`Design.pareto`), and `Synthesis.simplest` names the simplest within 10 % of the best distance
    (`jaxlink.synthesis.pareto`).
    `checkpoint` (a file path): the search's whole state written there after every round, so that
    an interrupted search loses at most a round (an earlier state there is removed first, unless
    `resume`); stopped by Ctrl-C (KeyboardInterrupt) after a round, it returns the designs of the
    rounds done (`Synthesis.interrupted`); `resume`: continue the search whose state is
    there (`jaxlink.synthesis.checkpoint`: refused if it belongs to another target, topologies, seed
    or options). With `rounds` a resumed search returns exactly the uninterrupted one's designs; with
    a time limit the time spent before counts against it. One process only.
    Computes in float64 for the answers (NumPy) whatever JAX's x64 setting."""
    if rounds is not None and (isinstance(rounds, bool) or not isinstance(rounds, (int, np.integer)) or rounds < 1):
        raise MechanismError(f"rounds = {rounds!r}: the number of rounds must be a whole number, at least 1")
    if time_limit is not None and (isinstance(time_limit, bool) or not isinstance(
            time_limit, (int, float, np.integer, np.floating)) or not 0 < time_limit < np.inf):
        raise MechanismError(f"time_limit = {time_limit!r}: a finite number of seconds above 0, or None for no "
                             "limit (the search then runs `rounds` rounds, by default 2)")
    if isinstance(max_links, bool) or not isinstance(max_links, (int, np.integer)) or max_links < 4:
        raise MechanismError(f"max_links = {max_links!r}: a whole number of links, at least 4 (the four-bar, "
                             "the frame counted)")
    if not isinstance(sliders, (bool, np.bool_)):
        raise MechanismError(f"sliders = {sliders!r}: True (also the slider variants) or False")
    if not isinstance(levers, (bool, np.bool_)):
        raise MechanismError(f"levers = {levers!r}: True (also the slotted-lever variants) or False")
    try:
        bnds = _bounds.checked(min_transmission, max_size, max_pivot)
    except ValueError as e:
        raise MechanismError(str(e)) from None
    fin = search_options.get("finish")
    if fin is not None and (isinstance(fin, bool) or not isinstance(fin, (int, np.integer)) or fin < 0):
        raise MechanismError(f"finish = {fin!r}: the number of candidates polished at the end must be a whole "
                             "number, at least 0 (0: no polish)")
    per = search_options.get("per_topology")
    if per is not None and (isinstance(per, bool) or not isinstance(per, (int, np.integer)) or per < 1):
        raise MechanismError(f"per_topology = {per!r}: the number of candidates of a topology kept by a round must "
                             "be a whole number, at least 1")
    try:
        checked_blocks(search_options.get("blocks"))
    except ValueError as e:
        raise MechanismError(str(e)) from None
    t0 = time.perf_counter() if started is None else float(started)
    if isinstance(target, Target):
        tgt = target if closed is None else target._replace(closed=bool(closed))
    elif isinstance(target, (str, Path)):
        tgt = load_target(target, closed=closed)
    else:
        tgt = make_target(target, closed=closed)
    topos = builtin_topologies(max_links, sliders=bool(sliders), levers=bool(levers))
    if topologies is not None:
        known = {t.name: t for t in builtin_topologies(99, sliders=True, levers=True)}
        bad = [n for n in topologies if not isinstance(n, Topology) and n not in known]
        if bad:
            raise MechanismError(f"unknown topology {bad[0]!r}; the topologies are {', '.join(known)}")
        topos = [n if isinstance(n, Topology) else known[n] for n in topologies]
        big = [t.name for t in topos if len(t.dyads) > MAX_DYADS]
        if big:
            raise MechanismError(f"topology {big[0]!r} has more than {MAX_DYADS} dyads")
        names = [t.name for t in topos]
        if len(set(names)) < len(names):
            raise MechanismError(f"two topologies named {next(n for n in names if names.count(n) > 1)!r}: "
                                 "name each (`grow(..., name=...)`); the answers are keyed by name")
    if not isinstance(resume, (bool, np.bool_)):
        raise MechanismError(f"resume = {resume!r}: True (continue the search saved at `checkpoint`) or False")
    if resume and checkpoint is None:
        raise MechanismError("resume = True needs the `checkpoint` file of the search to continue")
    if checkpoint is not None and jax.process_count() > 1:
        raise MechanismError("a checkpoint (and --resume) is for a search in one process; with several "
                             "processes run without it")
    fp = _checkpoint.fingerprint(tgt, topos, seed=seed, rounds=rounds, samples=samples, count=count,
                                 n_points=n_points, max_size=bnds.search_size,
                                 min_transmission=bnds.min_transmission,
                                 time_limit=time_limit if rounds is None else quick_of(time_limit, None),
                                 cap=time_limit is not None and rounds is not None,
                                 options=sorted(search_options.items()),
                                 # the blocks' caps (the platform's unless given): the answer's bits depend on them
                                 blocks=_blocks_of(search_options, time_limit)) if checkpoint is not None else ""
    if checkpoint is not None and not resume:
        Path(checkpoint).unlink(missing_ok=True)  # an earlier search's state is never this one's
    interrupted = False
    status: dict = {}
    try:
        found = search(tgt, topos, time_limit=time_limit, seed=seed, rounds=rounds, samples=samples,
                       n_trace=count, n_points=n_points, t0=t0, log=log, status=status,
                       max_size=bnds.search_size, min_transmission=bnds.min_transmission,
                       checkpoint=checkpoint, resume=bool(resume), fingerprint=fp,
                       progress=None if progress is None and best_file is None else _progress.relay(
                           progress, tgt, None if best_file is None else functools.partial(
                               _write_best, Path(best_file), tgt, count, name)), **search_options)
    except KeyboardInterrupt:
        # stopped: the candidates of the rounds done, as saved after the last one (none saved: stop)
        saved = _checkpoint.load(Path(checkpoint), fp) if checkpoint is not None else None
        if saved is None:
            raise
        found = sorted(saved["found"], key=lambda c: c.match.distance)
        interrupted = True
        status = {"rounds": int(saved["rnd"]), "stopped_by": "interrupted"}
        if log is not None:
            log(f"interrupted: the designs of the {saved['rnd']} rounds done")
    frame = _size.target_frame(tgt, n_points)
    chosen = _each_topology(found, sorted(status.get("outside", []), key=lambda c: c.match.distance), bnds, frame)
    with ThreadPoolExecutor(SCORE_THREADS) as ex:  # the designs side by side (NumPy), in order
        designs = list(ex.map(lambda c: _design(c, tgt, count, name, frame, bnds), chosen))
    designs.sort(key=lambda d: (not d.meets, d.distance))
    on = _pareto.front([d.distance for d in designs], [d.joints for d in designs],
                       [d.transmission_deg for d in designs], [d.size for d in designs])
    designs = [d._replace(pareto=bool(p)) for d, p in zip(designs, on)]
    simplest = _pareto.simplest([d.distance for d in designs], [d.joints for d in designs],
                                [d.links for d in designs], [d.meets for d in designs])
    return Synthesis(tgt, designs, time.perf_counter() - t0, bnds.max_size, _size.extent(tgt.points),
                     bnds.min_transmission, interrupted, int(status.get("rounds", 0)),
                     str(status.get("stopped_by", "rounds")), None if time_limit is None else float(time_limit),
                     bnds.max_pivot, simplest)


def _each_topology(found: list[Candidate], outside: list[Candidate], bnds: _bounds.Bounds,
                   frame: tuple) -> list[Candidate]:
    """Each topology's answer: its best candidate of `found` (the search's, within its bounds) that
    is within the link and pivot bounds one by one (they differ from the search's one bound only when
    the two differ), else its best of `found`, else its best of `outside` (both best first)."""
    def within(c: Candidate) -> bool:
        if bnds.max_size is None and bnds.max_pivot is None:
            return True
        link, pivot = _size.design_sizes(c.topology, c.pose, c.match, frame[0], frame[2])
        return not _bounds.violations(bnds._replace(min_transmission=None), 0.0, link, pivot)

    best: dict[str, Candidate] = {}
    for c in found:
        if c.topology.name not in best and within(c):
            best[c.topology.name] = c
    for c in [*found, *outside]:
        best.setdefault(c.topology.name, c)
    return list(best.values())
