"""Command `jaxlink study`: parameter studies of the file's `[study]` table (this step: the
tolerance analysis, docs/methods/tolerance.md)."""

from __future__ import annotations

import sys
import time


def register(sub) -> None:
    from .mechanism import add_mechanism_arguments

    p = sub.add_parser(
        "study", help="parameter studies: the tolerance analysis of the file's [study] table",
        description=(
            "Tolerance analysis around the file's design: exact first order (RSS σ, linear worst case, "
            "importance factors) of the studied points' paths and cycle metrics from the exact Jacobian, and "
            "Monte Carlo with the tolerances' distributions (seeded, streamed; infeasible samples counted). "
            "The tolerances are the file's [study.tolerances] (docs/reference/file-format.md §17). Writes "
            "tolerance.csv, importance.csv, tolerance.png and study.json into --out, in the file's units."
        ),
    )
    add_mechanism_arguments(p, positions=False)
    p.add_argument("--method", default=None, choices=("tolerance",),
                   help="the study (default: [study] method, else tolerance)")
    p.add_argument("--samples", type=int, default=None, metavar="N",
                   help="Monte Carlo samples (default: [study] samples, else 10000; 0: first order only)")
    p.add_argument("--positions", type=int, default=None, metavar="N",
                   help="input positions over the cycle (default: [study] positions, else 360)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: [study] seed, else 0)")
    p.add_argument("--chunk", type=int, default=None,
                   help="Monte Carlo designs per batch (default: [study] chunk, else about 2^21 positions)")
    p.add_argument("--out", metavar="DIR", default=None, help="write the files into this folder")
    p.add_argument("--no-plot", action="store_true", help="do not draw tolerance.png")
    p.add_argument("--progress", choices=("auto", "on", "off"), default="auto",
                   help="progress bar of the Monte Carlo run (auto: when stderr is a terminal)")
    p.set_defaults(func=cmd_study)


def cmd_study(args) -> int:
    from ..errors import MechanismError
    from .mechanism import enable_dtype, load_from_args

    t0 = time.perf_counter()
    enable_dtype(args.dtype)
    mech = load_from_args(args)
    from ..report import tolerance as _report
    from ..study import Study, read_study, tolerance

    for opt, v, lo in (("--samples", args.samples, 0), ("--positions", args.positions, 8), ("--seed", args.seed, 0),
                       ("--chunk", args.chunk, 1)):
        if v is not None and v < lo:
            raise MechanismError(f"{opt} must be at least {lo}, got {v}")
    inputs = read_study(mech, method=args.method, samples=args.samples, positions=args.positions, seed=args.seed,
                        chunk=args.chunk)
    study = Study(mech, inputs)
    show = sys.stderr.isatty() if args.progress == "auto" else args.progress == "on"
    bar = None
    if show and inputs.samples > 0:
        from tqdm import tqdm

        bar = tqdm(total=inputs.samples, desc="Monte Carlo", unit="sample", leave=False, file=sys.stderr)
    try:
        rep = tolerance(mech, study=study, progress=None if bar is None else bar.update)
    finally:
        if bar is not None:
            bar.close()
    print(f"tolerance study of {mech.name}: {len(inputs.parameters)} toleranced parameters, "
          f"{inputs.positions} positions, {len(rep.labels)} responses; "
          f"first order in {rep.timings['first_order']:.3g} s"
          + (f", Monte Carlo in {rep.timings['monte_carlo']:.3g} s" if "monte_carlo" in rep.timings else ""))
    print(_report.summary(mech, rep))
    for w in rep.warnings:
        print(f"warning: {w}", file=sys.stderr)
    if args.out:
        files = _report.write_all(args.out, mech, rep, wall_time=time.perf_counter() - t0, plot=not args.no_plot)
        print("wrote " + ", ".join(files))
    return 0
