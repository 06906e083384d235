"""`jaxlink synthesize`: a linkage whose point follows a target path (jaxlink/synthesis/)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any


def _extents(text: str) -> float | None:
    """A bound in target extents: a positive number, or "none" (no bound)."""
    import argparse
    import math

    if text.strip().lower() in ("none", "off"):
        return None
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: a positive number of target extents, or none") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"{text!r}: a positive number of target extents, or none")
    return v


def register(sub) -> None:
    from ..synthesis.bounds import MAX_PIVOT, MAX_SIZE, MIN_TRANSMISSION
    from .optimize import add_distributed_arguments

    p = sub.add_parser(
        "synthesize", help="find a linkage (topology and dimensions) whose point traces a target path",
        description=(
            "Path synthesis: one-degree-of-freedom revolute linkages grown by dyads (the four-bar, the Watt and "
            "Stephenson six-bars, eight-bars; with --sliders also their variants with sliders on frame guides, "
            "the slider-crank first; with --levers their variants with a slotted lever) whose traced point "
            "follows TARGET (a .csv of x, y, a .npy (N, 2) "
            "array or an .svg path) up to translation, rotation and scale, ranked by the symmetric chamfer "
            "distance of the normalised curves' points to each other's polyline (independent of where the crank's "
            "turn starts), LInK's 2000-point metric beside it (docs/methods/synthesis.md). By default only "
            "designs a designer can build: a transmission angle of at least 30 degrees, links at most 3 times the "
            "target's extent, frame pivots within 3 times it of its centre (--min-transmission 0 --max-size none "
            "--max-pivot none: no bound). Writes the best "
            "mechanism as a sketch file that "
            "`jaxlink kinematics` replays, every topology's best, a JSON of the ranked designs and a plot."
        ),
    )
    p.add_argument("target", metavar="TARGET",
                   help="the target path: .csv, .npy or .svg; a CSV column theta_deg (or theta_rad) makes it timed: "
                        "each point reached at its crank angle, matched by the ordered distance")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--closed", dest="closed", action="store_const", const=True, default=None,
                   help="a closed loop, matched by a whole crank turn")
    g.add_argument("--open", dest="closed", action="store_const", const=False,
                   help="an open path, matched by a sub-interval of the crank turn")
    p.add_argument("--time-limit", type=float, default=None, metavar="S",
                   help="a cap on the command's seconds, from its start, compiling included (default: none). A "
                        "round starts only if 1.25 times the last one's time fits, a round is abandoned before a "
                        "block whose batch would not end by the limit (the rounds done are the answer), programs "
                        "whose compile would not fit (as measured here before) are not compiled, and the float64 "
                        "polishes stop at the limit: the command overruns it by at most 10 %% + 2 s; alone, "
                        "rounds go on while one fits. When it stops the search the summary and the JSON "
                        "(stopped_by) say so: the designs then depend on the machine's speed")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--rounds", type=int, default=None, metavar="N",
                   help="search rounds, full and polishing alternating (default 2 without --time-limit: a full "
                        "round and a polishing one): designs that do not depend on the machine's speed unless a "
                        "--time-limit stops the search first")
    p.add_argument("--quick", action="store_true", default=None,
                   help="the quick programs: a closed or timed target's screen compiled at XLA's lowest level, no "
                        "final float64 polish, the refinement in blocks of 64 (less compiling, longer rounds: for "
                        "short searches; default: when a --time-limit of at most 15 s is given)")
    p.add_argument("--max-links", type=int, default=8,
                   help="most links, the frame counted (default 8: the eight-bars too; 6: the four-bar and "
                        "six-bars, a round about half as long; 10: the 27 ten-bars too, 12 joints, a round "
                        "about 2.7 times as long)")
    p.add_argument("--sliders", action="store_true",
                   help="also search the variants with sliders: a dyad between a moving joint and a frame pivot "
                        "used by nothing else becomes a slider on a frame guide (the four-bar's rocker a "
                        "slider: the slider-crank); 18 more topologies up to 8 links, 39 up to 10")
    p.add_argument("--levers", action="store_true",
                   help="also search the variants with a slotted lever: a dyad between a moving joint and a frame "
                        "pivot (not the crank's) becomes a lever turning about the pivot, the moving joint's pin "
                        "sliding in its slot (the Whitworth quick return, the oscillating cylinder); 10 more "
                        "topologies up to 8 links, 25 more up to 10")
    p.add_argument("--topologies", default=None, metavar="NAMES",
                   help="comma-separated topology names to search (default: all up to --max-links; the "
                        "slider and lever topologies by name without --sliders or --levers too)")
    p.add_argument("--max-size", type=_extents, default=MAX_SIZE, metavar="K",
                   help=f"keep every link at most K times the target's extent (the largest distance between two of "
                        f"its points; default {MAX_SIZE:g}; none: no bound). Each design's size, in extents, is in "
                        "the table and the JSON either way")
    p.add_argument("--max-pivot", type=_extents, default=MAX_PIVOT, metavar="P",
                   help=f"keep every frame pivot within P times the target's extent of the target's centre "
                        f"(default {MAX_PIVOT:g}; none: no bound)")
    p.add_argument("--min-transmission", type=float, default=MIN_TRANSMISSION, metavar="DEG",
                   help="keep every design's transmission angle (between the two links of each revolute dyad, "
                        "between a slider's link and its guide's normal) at least DEG degrees over its whole "
                        f"interval, checked between samples (default {MIN_TRANSMISSION:g}; 0: no bound). Each "
                        "design's least angle is in the table (mu_deg) and the JSON either way; the table's "
                        "column `bounds` says which designs meet the bounds")
    p.add_argument("--samples", type=int, default=8192, metavar="N",
                   help="random candidates per topology and round (default 8192)")
    p.add_argument("--points", type=int, default=200, metavar="N",
                   help="points of the target's resampling in the float64 polish and the size's frame (default 200; "
                        "the reported distance and LInK's metric take 2000 of each curve)")
    p.add_argument("--count", type=int, default=1000, metavar="N",
                   help="crank positions the reported curve is traced at (default 1000)")
    p.add_argument("--flip-y", action="store_true", help="mirror the target's y (an SVG drawn with y down)")
    p.add_argument("--out", metavar="DIR", default="synthesis",
                   help="write the files into this folder (default synthesis)")
    p.add_argument("--no-plot", action="store_true", help="do not draw the plot")
    p.add_argument("--progress", choices=("auto", "on", "off"), default="auto",
                   help="a progress line on standard error from the start: the round, the topologies scored, the "
                        "best design so far (distance, topology, joints, least transmission angle; written to "
                        "OUT/synthesized.toml after every round where it changed), the time spent and left "
                        "(auto: when standard error is a terminal, updated in place; on: also a line per step "
                        "elsewhere)")
    p.add_argument("--quiet", action="store_true",
                   help="nothing on standard error but errors: no progress line, no line per round")
    p.add_argument("--resume", action="store_true",
                   help="continue the interrupted search of --out: the search writes its whole state to "
                        "DIR/synthesis.state after every round (one process), so Ctrl-C or a kill loses at most "
                        "a round; with --rounds the resumed search ends with exactly the uninterrupted one's "
                        "designs, with a time limit the time spent before counts. The same target and options "
                        "as the interrupted run (another search's state is refused)")
    add_distributed_arguments(p, "spread every round's candidates over N processes (hosts, or several on one "
                                 "host) with jax.distributed: start the same command N times, with --process-id "
                                 "0 … N-1 and the same --coordinator; process 0 decides the rounds and writes the "
                                 "files, the others print nothing (docs/methods/synthesis.md)")
    p.set_defaults(func=cmd_synthesize)


def cmd_synthesize(args) -> int:
    from ..errors import MechanismError
    from .optimize import _distributed

    if args.rounds is not None and args.rounds < 1:
        raise MechanismError(f"--rounds must be at least 1, got {args.rounds}")
    printer = _distributed(args)  # before any JAX work
    import jax

    jax.config.update("jax_enable_x64", True)
    from ..report.synthesis import table, write_all
    from ..synthesis.api import synthesize
    from ..synthesis.target import load_target

    if args.points < 8 or args.count < 8 or args.samples < 1:
        raise MechanismError("--points and --count must be >= 8, --samples >= 1")
    if args.time_limit is not None and not 0 < args.time_limit < float("inf"):  # nan too
        raise MechanismError(f"--time-limit {args.time_limit:g}: a finite number of seconds above 0 (or no "
                             "--time-limit: --rounds N, by default 2)")
    tgt = load_target(args.target, closed=args.closed, flip_y=args.flip_y)
    names = [n.strip() for n in args.topologies.split(",") if n.strip()] if args.topologies else None
    state = None
    if jax.process_count() == 1:
        state = Path(args.out) / "synthesis.state"
        if args.resume and not state.exists():
            raise MechanismError(f"--resume: {state} does not exist (no interrupted search in --out {args.out})")
        state.parent.mkdir(parents=True, exist_ok=True)
    elif args.resume:
        raise MechanismError("--resume is for a search in one process")
    quick: dict[str, Any] = {"quick": True} if args.quick else {}
    tty = sys.stderr.isatty()
    shown = printer and not args.quiet and (tty if args.progress == "auto" else args.progress == "on")
    best_file = Path(args.out) / "synthesized.toml" if printer else None
    status = _Status(sys.stderr, tty, None if best_file is None else str(best_file)) if shown else None
    log = None if not printer or args.quiet else (status.log if status is not None else
                                                  (lambda s: print(s, file=sys.stderr)))
    if best_file is not None:
        best_file.parent.mkdir(parents=True, exist_ok=True)
    try:
        res = synthesize(tgt, time_limit=args.time_limit, seed=args.seed, rounds=args.rounds,
                         max_links=args.max_links, topologies=names, n_points=args.points, count=args.count,
                         samples=args.samples, sliders=args.sliders, levers=args.levers,
                         max_size=args.max_size, max_pivot=args.max_pivot,
                         min_transmission=args.min_transmission, checkpoint=state, resume=args.resume,
                         started=getattr(args, "started", None), **quick, log=log,
                         progress=None if status is None else status.show, best_file=best_file)
    except KeyboardInterrupt:
        if status is not None:
            status.close()
        if state is not None and state.exists():
            print(f"synthesize: interrupted; the search's state after its last round is in {state}: the same "
                  "command with --resume continues it", file=sys.stderr)
            return 130
        raise
    if status is not None:
        status.close()
    if res.interrupted:  # Ctrl-C after a round: the designs until then are written, and the state kept
        print(f"synthesize: interrupted; writing the designs found until then. The search's state is in {state}: "
              "the same command with --resume continues it", file=sys.stderr)
    if not printer:
        return 0 if res.designs else 1
    if not res.designs:
        bounds = ([f"--max-size {args.max_size:g}"] if args.max_size is not None else []) + (
            [f"--max-pivot {args.max_pivot:g}"] if args.max_pivot is not None else []) + (
            [f"--min-transmission {args.min_transmission:g}"] if args.min_transmission else [])
        if res.stopped_by == "time_limit" and res.rounds == 0:
            print(f"no design: the time limit ({args.time_limit:g} s) ended the search before its first round "
                  f"ended ({res.wall_s:.1f} s since the command started, compiling included); give a longer "
                  "--time-limit, or none", file=sys.stderr)
            return 130 if res.interrupted else 1
        print("no design assembled over its interval" + (f" within {' and '.join(bounds)}" if bounds else "")
              + ": give more --rounds, --time-limit or --samples" + (", or looser bounds" if bounds else ""),
              file=sys.stderr)
        return 130 if res.interrupted else 1
    print(table(res))
    if not res.meets:
        print(f"synthesize: no design meets the bounds; the best found, {res.best.topology}, breaks them "
              f"({'; '.join(res.best.violates)}). It is written all the same: give more --rounds or --samples, "
              "or looser bounds", file=sys.stderr)
    for f in write_all(args.out, res, plot_it=not args.no_plot):
        print(f"wrote {f}")
    b = res.best
    span = (f"--start {b.start_deg!r} --step {360 / b.n_inputs!r} --count {b.n_inputs}"
            if res.target.closed and not res.target.timed
            else f"--start {b.start_deg!r} --stop {b.stop_deg!r} --count {b.n_inputs}")
    if res.target.timed:
        print(f"timed       the target's points are matched at the crank angles `inputs_deg` of {args.out}/"
              "synthesis.json")
    print(f"replay      jaxlink kinematics {args.out}/synthesized.toml {span} --outputs position")
    return 130 if res.interrupted else 0


class _Status:
    """The progress line on `stream` (`report.synthesis.progress_line`): on a terminal one line
    rewritten in place, the search's log lines printed above it; elsewhere a line per step."""

    def __init__(self, stream, tty: bool, best_file: str | None):
        self.stream, self.tty, self.best_file, self.line = stream, tty, best_file, ""

    def _write(self, text: str) -> None:
        self.stream.write(text)
        self.stream.flush()

    def show(self, p) -> None:
        from ..report.synthesis import progress_line

        self.line = progress_line(p, self.best_file)
        self._write(f"\r{self.line}\x1b[K" if self.tty else self.line + "\n")

    def log(self, text: str) -> None:
        self._write(f"\r{text}\x1b[K\n{self.line}" if self.tty else text + "\n")

    def close(self) -> None:
        if self.tty and self.line:
            self._write("\n")
        self.line = ""
