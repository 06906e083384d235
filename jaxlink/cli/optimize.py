"""Command `jaxlink optimize`: design search over the file's `[optimize]` section."""

from __future__ import annotations

import sys

from ..errors import MechanismError


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
    p.add_argument("--method", required=True, choices=("uniform", "montecarlo", "gradient"),
                   help="search method")
    p.add_argument("--budget", type=int, default=None,
                   help="mechanism evaluations allowed (default: [optimize] budget; else the gradient search "
                        "chooses its sizes from the problem and stops when no start improves, the others 10000)")
    p.add_argument("--time", type=float, default=None, metavar="SECONDS",
                   help="stop the search after this wall time, compilation included (default: [optimize] time, "
                        "else none)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: [optimize] seed, else 0)")
    p.add_argument("--out", metavar="OUT.json", help="write the result JSON here (and checkpoint beside it)")
    p.add_argument("--resume", action="store_true", help="continue the interrupted search of --out")
    p.add_argument("--uniform", choices=("grid", "coordinate"), default=None,
                   help="uniform search: full grid, or parameter-by-parameter stepping (as the feed study did) "
                        "(default: [optimize] uniform, else grid)")
    p.add_argument("--starts", type=int, default=None, help="gradient: parallel starts (default 16)")
    p.add_argument("--chunk", type=int, default=None, help="designs per batch (default 256)")
    p.add_argument("--progress", choices=("auto", "on", "off"), default="auto",
                   help="progress bar (auto: when stderr is a terminal)")
    p.set_defaults(func=cmd_optimize)


def cmd_optimize(args) -> int:
    from .mechanism import enable_dtype, load_from_args

    enable_dtype(args.dtype)
    from ..optimize import Evaluator, problem_from, run

    mech = load_from_args(args)
    problem = problem_from(mech)
    budget = args.budget if args.budget is not None else problem.option("budget")
    seed = args.seed if args.seed is not None else problem.option("seed", 0)
    for name, v in (("--budget", budget), ("--seed", seed)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int)):
            raise MechanismError(f"{name} must be an integer, got {v!r}")
    if budget is not None and budget < 1:
        raise MechanismError("--budget must be at least 1")
    time_s = args.time if args.time is not None else problem.option("time")
    if time_s is not None and (isinstance(time_s, bool) or not isinstance(time_s, (int, float)) or not time_s > 0):
        raise MechanismError(f"--time must be a positive number of seconds, got {time_s!r}")
    if args.starts is not None and args.starts < 1:
        raise MechanismError("--starts must be at least 1")
    chunk = args.chunk or problem.option("chunk", 256)
    if not isinstance(chunk, int) or chunk < 1:
        raise MechanismError(f"--chunk must be a positive integer, got {chunk!r}")
    progress = sys.stderr.isatty() if args.progress == "auto" else args.progress == "on"
    knobs = {}
    if args.method == "uniform":
        knobs["uniform"] = args.uniform or problem.option("uniform", "grid")
        if knobs["uniform"] not in ("grid", "coordinate"):
            raise MechanismError(f"[optimize] uniform must be \"grid\" or \"coordinate\", got {knobs['uniform']!r}",
                                 file=mech.file, key="optimize.uniform")
    if args.method == "gradient" and args.starts:
        knobs["starts"] = args.starts
    ev = Evaluator(problem, chunk=chunk)
    result = run(ev, args.method, budget=budget, seed=seed, out=args.out, resume=args.resume,
                 progress=progress, time=time_s, **knobs)
    print(f"method      {result.method}" + (f" ({knobs['uniform']})" if "uniform" in knobs else ""))
    if result.parameters:
        print("best        " + ", ".join(f"{k} = {v:.6g}" for k, v in result.parameters.items()))
        print(f"objective   {result.value:.10g}" if result.value is not None else "objective   -")
        if result.metrics:
            print("metrics     " + ", ".join(f"{k} = {v:.6g}" for k, v in result.metrics.items() if v is not None))
    else:
        print("best        none: no feasible design found: every design tried failed to assemble over its "
              "revolution (widen the bounds, check the file's design, or give more --budget / --time)")
    print(f"evaluations {result.evaluations} ({result.designs} designs, "
          f"{100 * result.infeasible_fraction:.1f} % infeasible), {result.wall_s:.2f} s "
          f"({result.search_wall_s:.2f} s searching, {result.compile_s:.2f} s compiling)")
    if args.out:
        print(f"wrote {args.out}" + (f" and {result.best_file} (the best design: jaxlink kinematics "
                                     f"{result.best_file})" if result.best_file else ""))
    return 0 if result.parameters else 1
