"""Command `jaxlink optimize`: design search over the file's `[optimize]` section."""

from __future__ import annotations

import contextlib
import math
import os
import sys

from ..errors import MechanismError

#: the method without --method: the gradient search, the one that needs no budget (it sizes its
#: presample and starts from the problem and stops by itself; docs/methods/optimize.md "Methods")
DEFAULT_METHOD = "gradient"


def register(sub) -> None:
    from .mechanism import add_mechanism_arguments

    p = sub.add_parser(
        "optimize", help="design search: uniform, Monte Carlo or gradient (the file's [optimize])",
        description=(
            "Search the variables of the file's [optimize] section (bounds in file units) for the "
            "lowest objective. All methods use one batched, jitted evaluator sharded over all JAX "
            "devices. --budget counts mechanism evaluations: one design solved over its revolution "
            "(per circuit); a value-and-gradient counts 2. With --out, the state is checkpointed "
            "after every chunk (OUT.state.npz, OUT.log.jsonl, OUT rewritten with the best so far); "
            "--resume continues an interrupted search and ends with the same result. Same seed, "
            "same result. See docs/methods/optimize.md."
        ),
    )
    add_mechanism_arguments(p, positions=False)
    p.add_argument("--method", default=None, choices=("uniform", "montecarlo", "gradient"),
                   help=f"search method (default {DEFAULT_METHOD}: it sizes its search from the problem and stops "
                        "when no start improves, docs/methods/optimize.md)")
    p.add_argument("--budget", type=int, default=None,
                   help="mechanism evaluations allowed (default: [optimize] budget; else the gradient search "
                        "chooses its sizes from the problem and stops when no start improves or after 400000, "
                        "the others 10000): a count, the same result on any machine")
    p.add_argument("--time", type=float, default=None, metavar="SECONDS",
                   help="a cap on the search's wall time, compilation and the final report included: a chunk "
                        "starts only if one as long as the last fits (default: [optimize] time, else none). "
                        "When it stops the search, the summary and the JSON (stopped_by) say so, and the result "
                        "depends on the machine's speed")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: [optimize] seed, else 0)")
    p.add_argument("--out", metavar="OUT.json", help="write the result JSON here (and checkpoint beside it)")
    p.add_argument("--resume", action="store_true", help="continue the interrupted search of --out")
    p.add_argument("--uniform", choices=("grid", "coordinate"), default=None,
                   help="uniform search: full grid, or parameter-by-parameter stepping (as the feed study did) "
                        "(default: [optimize] uniform, else grid)")
    p.add_argument("--starts", type=int, default=None, help="gradient: parallel starts (default 16)")
    p.add_argument("--chunk", type=int, default=None,
                   help="designs per batch (default: [optimize] chunk, else from the device and the problem's "
                        "size: 4096 designs of 36 samples on a CPU)")
    p.add_argument("--progress", choices=("auto", "on", "off"), default="auto",
                   help="progress bar (auto: when stderr is a terminal)")
    add_distributed_arguments(p, "spread the search over N processes (hosts, or several on one host) with "
                                 "jax.distributed: start the same command N times, with --process-id 0 … N-1 and "
                                 "the same --coordinator; same result as one process; process 0 writes --out "
                                 "(docs/methods/optimize.md)")
    p.set_defaults(func=cmd_optimize)


def add_distributed_arguments(p, description: str) -> None:
    """The options of a command spread over several processes (`_distributed` reads them)."""
    d = p.add_argument_group("several processes", description)
    d.add_argument("--coordinator", metavar="HOST:PORT", default=None,
                   help="address of process 0, which coordinates (a free port on its host)")
    d.add_argument("--num-processes", type=int, default=None, metavar="N", help="number of processes")
    d.add_argument("--process-id", type=int, default=None, metavar="I", help="this process's index, 0 … N-1")


def _distributed(args) -> bool:
    """Join the group of processes the options name (before any JAX work); whether this process
    prints (process 0, or a single process)."""
    given = [args.coordinator is not None, args.num_processes is not None, args.process_id is not None]
    if not any(given):
        return True
    if not all(given):
        raise MechanismError("--coordinator, --num-processes and --process-id go together (all three or none)")
    if args.num_processes < 1:
        raise MechanismError(f"--num-processes must be at least 1, got {args.num_processes}")
    if not 0 <= args.process_id < args.num_processes:
        raise MechanismError(f"--process-id must be in 0 … {args.num_processes - 1}, got {args.process_id}")
    host, _, port = args.coordinator.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise MechanismError(f"--coordinator must be HOST:PORT, got {args.coordinator!r}")
    from ..optimize import initialize_distributed

    index, _ = initialize_distributed(args.coordinator, args.num_processes, args.process_id)
    return index == 0


_STOPPED = {"budget": "at the budget (the evaluations allowed)", "iterations": "after its iterations",
            "converged": "by itself: no start improves",
            "interrupted": "interrupted (Ctrl-C): the best design found so far, not the search's end"}


def cmd_optimize(args) -> int:
    import time

    # a --time limit counts from the process's start: importing JAX, loading the file and building the evaluator too
    started = getattr(args, "started", None) or time.perf_counter()
    from .mechanism import enable_dtype, load_from_args

    printer = _distributed(args)
    enable_dtype(args.dtype)
    from ..optimize import Evaluator, problem_from, run
    from ..optimize.problem import INTEGER_DOMAINS, check_size
    from .mechanism import check_output, writing

    # the options (the [optimize] keys they stand for are checked, naming the file, by problem_from)
    for option in ("budget", "seed", "starts", "chunk"):
        value = getattr(args, option)
        lo, hi = INTEGER_DOMAINS[option]
        if value is not None and not lo <= value <= hi:
            raise MechanismError(f"--{option} {value}: must be an integer from {lo} to {hi}")
    if args.out is not None:
        from ..optimize.checkpoint import paths

        for path in paths(args.out):  # the result and the checkpoint files beside it
            check_output("--out", str(path))
        folder = os.path.realpath(os.path.dirname(os.path.abspath(args.out)))
        if folder.split(os.sep)[1:2] in (["dev"], ["proc"], ["sys"]):
            raise MechanismError(f"--out {args.out}: the checkpoint files (OUT.state.npz, OUT.log.jsonl) are "
                                 f"written beside OUT, and {folder} is no place for them; give a file (or a named "
                                 "pipe) in an ordinary folder")
        check_output("--out", args.out, ("json",))
    mech = load_from_args(args)
    problem = problem_from(mech)
    budget = args.budget if args.budget is not None else problem.option("budget")
    seed = args.seed if args.seed is not None else problem.option("seed", 0)
    if args.time is not None and not (math.isfinite(args.time) and 0 < args.time <= 1e7):
        raise MechanismError(f"--time {args.time!r}: must be a number of seconds, more than 0 and at most 1e7")
    time_s = args.time if args.time is not None else problem.option("time")  # the key: checked by problem_from
    chunk = args.chunk if args.chunk is not None else problem.option("chunk", None)
    progress = sys.stderr.isatty() if args.progress == "auto" else args.progress == "on"
    default = args.method is None
    if default and args.uniform:
        raise MechanismError(f"--uniform {args.uniform}: an option of --method uniform (without --method the search "
                             f"is {DEFAULT_METHOD}); give --method uniform")
    if default:
        args.method = DEFAULT_METHOD
    knobs = {}
    if args.method == "uniform":
        knobs["uniform"] = args.uniform or problem.option("uniform", "grid")
        if knobs["uniform"] not in ("grid", "coordinate"):
            raise MechanismError(f"[optimize] uniform must be \"grid\" or \"coordinate\", got {knobs['uniform']!r}",
                                 file=mech.file, key="optimize.uniform")
    if args.method == "gradient" and args.starts:
        knobs["starts"] = args.starts
    ev = Evaluator(problem, chunk=chunk)  # chunk None: from the device and the problem's size
    check_size(problem, ev.chunk, "--chunk" if args.chunk is not None else "chunk")
    with writing("--out", args.out) if args.out and printer else contextlib.nullcontext():
        result = run(ev, args.method, budget=budget, seed=seed, out=args.out, resume=args.resume,
                     progress=progress and printer, time=time_s, started=started, **knobs)
    if not printer:
        return 0 if result.parameters else 1
    print(f"method      {result.method}" + (f" ({knobs['uniform']})" if "uniform" in knobs else "")
          + (" (the default; --method uniform or montecarlo for the others)" if default else ""))
    if result.parameters:
        print("best        " + ", ".join(f"{k} = {v:.6g}" for k, v in result.parameters.items()))
        print(f"objective   {result.value:.10g}" if result.value is not None else "objective   -")
        if result.metrics:
            print("metrics     " + ", ".join(f"{k} = {v:.6g}" for k, v in result.metrics.items() if v is not None))
        if result.fallback:
            print(f"certified   fell back to the {result.fallback + 1}. best design: the {result.fallback} better "
                  "one(s) cannot be assembled between two checked positions")
    else:
        print(f"best        none: {result.reason}")
        print(f"error: {result.reason}", file=sys.stderr)
    print(f"evaluations {result.evaluations} ({result.designs} designs, "
          f"{100 * result.infeasible_fraction:.1f} % infeasible), {result.wall_s:.2f} s "
          f"({result.search_wall_s:.2f} s searching, {result.compile_s:.2f} s compiling)")
    stopped_by = result.extra.get("stopped_by")
    if stopped_by == "time_limit":
        print(f"stopped     at the time limit ({result.extra['time_limit_s']:g} s): the result depends on the "
              "machine's speed; a --budget (or no --time) for one that does not")
    elif stopped_by is not None:
        print(f"stopped     {_STOPPED.get(stopped_by, stopped_by)}")
    if args.out:
        print(f"wrote {args.out}" + (f" and {result.best_file} (the best design: jaxlink kinematics "
                                     f"{result.best_file})" if result.best_file else ""))
    if stopped_by == "interrupted":
        print(_interrupted(args, result), file=sys.stderr)
        return 130
    return 0 if result.parameters else 1


def _interrupted(args, result) -> str:
    """What a Ctrl-C saved and how to go on."""
    head = f"jaxlink optimize: interrupted after {result.evaluations} evaluations"
    if not args.out:
        return (f"{head}: the best design so far is printed above; nothing was written (no --out). With --out "
                "OUT.json the search writes its best so far and its state as it goes, and --resume continues an "
                "interrupted one to the uninterrupted result")
    from ..optimize.checkpoint import paths

    state = paths(args.out)[1]
    best = f" and the best design as a file in {result.best_file}" if result.best_file else ""
    return (f"{head}: saved the best so far in {args.out} (\"complete\": false){best}, the search's state in "
            f"{state}; the same command with --resume continues it to the result of an uninterrupted search: "
            f"jaxlink optimize {args.file} --method {args.method} --out {args.out} --resume (and the same "
            "--set, --budget, --seed and other options)")
