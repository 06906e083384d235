"""Command `jaxlink study`: parameter studies of the file's `[study]` table — the tolerance
analysis (docs/methods/tolerance.md), sampling and grids over `[study.ranges]` and Sobol' global
sensitivity (docs/methods/sensitivity.md)."""

from __future__ import annotations

import sys
import time


def register(sub) -> None:
    from .mechanism import add_mechanism_arguments

    p = sub.add_parser(
        "study", help="parameter studies of the file's [study] table: tolerance, sample, grid, sensitivity",
        description=(
            "Parameter studies of the file's [study] table (docs/reference/file-format.md §17), in the file's "
            "units. tolerance: exact first order (RSS σ, linear worst case, importance factors) from the exact "
            "Jacobian and Monte Carlo with the tolerances' distributions (tolerance.csv, importance.csv, "
            "tolerance.png). sample: designs drawn over [study.ranges] by a scrambled Sobol', Halton, Latin "
            "hypercube or random sampler; grid: the full factorial over the ranges (study.csv; grid.png for two "
            "ranges). sensitivity: Sobol' S1 and ST with bootstrap intervals of every response along the cycle "
            "and of the feasibility (indices.csv, sobol.png, sobol_curves.png). --robust (sample, grid): the "
            "first-order tolerance report at every design (study.csv columns, robust.png). Infeasible designs are "
            "kept and flagged. Every method writes study.json and study.npz (--replot redraws from them) and, "
            "with --out, a checkpoint chunk by chunk (--resume)."
        ),
    )
    add_mechanism_arguments(p, positions=False)
    p.add_argument("--method", default=None, choices=("tolerance", "sample", "grid", "sensitivity", "morris",
                                                      "regression", "dgsm", "vector", "list", "centered"),
                   help="the study (default: [study] method, else tolerance); morris, regression, dgsm: Morris "
                        "elementary effects, correlation/regression coefficients, derivative-based indices "
                        "(indices.csv); vector, list, centered: Dakota's parameter studies (study.csv)")
    p.add_argument("--samples", type=int, default=None, metavar="N",
                   help="tolerance: Monte Carlo samples (default 10000; 0: first order only); sample: designs "
                        "(default 1024); sensitivity: base samples N, N (D + 2) designs (default 1024); "
                        "default: [study] samples")
    p.add_argument("--sampler", default=None, choices=("sobol", "lhs", "halton", "random"),
                   help="the sequence of sample and sensitivity (default: [study] sampler, else sobol)")
    p.add_argument("--bootstrap", type=int, default=None, metavar="R",
                   help="bootstrap resamples of the Sobol' intervals (default: [study] bootstrap, else 100)")
    p.add_argument("--second-order", action="store_true", default=None,
                   help="sensitivity: the second-order Sobol' indices S2 too, N (2D + 2) designs; tolerance: the "
                        "second-order mean shift and sigma from the exact Hessian (one more compile, ~5 s) "
                        "(default: [study] second_order)")
    p.add_argument("--positions", type=int, default=None, metavar="N",
                   help="input positions over the cycle (default: [study] positions, else 360)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: [study] seed, else 0)")
    p.add_argument("--chunk", type=int, default=None,
                   help="designs per batch (default: [study] chunk, else about 2^21 positions)")
    p.add_argument("--robust", action="store_true", default=None,
                   help="sample, grid: the robust-design map, the first-order tolerance report ([study.tolerances]) "
                        "at every design (default: [study] robust)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="write the files into this folder (and, chunk by chunk, the checkpoint DIR/checkpoint/)")
    p.add_argument("--resume", action="store_true",
                   help="continue the interrupted study of --out DIR from its checkpoint (the same result as an "
                        "uninterrupted run; every method, the --precision rule too: it resumes in the round it was "
                        "killed in; refused when the file or the study's inputs differ)")
    p.add_argument("--replot", metavar="DIR", default=None,
                   help="redraw every plot of the study written into DIR (study.json, study.npz) without "
                        "computing anything")
    p.add_argument("--precision", type=float, default=None, metavar="EPS",
                   help="tolerance (Monte Carlo) and sensitivity: double the samples until the largest interval "
                        "half-width is at most EPS (default: [study] precision, else no rule)")
    p.add_argument("--max-samples", type=int, default=None, metavar="N",
                   help="the stopping rule's cap on the samples (default: [study] max_samples, else 65536)")
    p.add_argument("--tol", action="append", default=[], metavar="NAME=T",
                   help="set a tolerance of [study.tolerances], in the file's units (repeatable): NAME=T (±t; a "
                        "zone's radius where the file gives one), NAME=sigma:S, NAME=radius:R, NAME=box:WX,WY; the "
                        "entry's distribution and k are kept. A file without [study] is studied with these")
    p.add_argument("--dist", action="append", default=[], metavar="D|NAME=D",
                   help="D: [study] distribution, that of the tolerances without their own; NAME=D: NAME's own "
                        "(uniform, normal, triangular, truncated-normal; repeatable)")
    p.add_argument("--limits", action="append", default=[], metavar="OUTPUT=LOW,HIGH",
                   help="a specification limit of a scalar response, file units, as [study] limits (repeatable; "
                        "-inf or inf for a one-sided limit), e.g. --limits 'stroke(s_B)=4.9,5.1'")
    p.add_argument("--no-plot", action="store_true", help="do not draw the plots")
    p.add_argument("--progress", choices=("auto", "on", "off"), default="auto",
                   help="progress bar of the sampled designs (auto: when stderr is a terminal)")
    p.set_defaults(func=cmd_study)


def cmd_study(args) -> int:
    from ..errors import MechanismError
    from .mechanism import enable_dtype, load_from_args

    t0 = time.perf_counter()
    if args.replot:
        return _replot(args)
    if args.resume and not args.out:
        raise MechanismError("--resume continues the study of --out DIR: give --out")
    enable_dtype(args.dtype)
    mech = load_from_args(args)
    from ..report import tolerance as _report
    from ..study import read_study, tolerance
    from ..study.tolerance import study_for

    for opt, v, lo in (("--samples", args.samples, 0), ("--positions", args.positions, 8), ("--seed", args.seed, 0),
                       ("--chunk", args.chunk, 1), ("--bootstrap", args.bootstrap, 0)):
        if v is not None and v < lo:
            raise MechanismError(f"{opt} must be at least {lo}, got {v}")
    from ..files.overrides import blamed, study_table
    from ..study.tolerance import limited_responses

    table, blame = study_table(mech.tables.get("study"), tol=args.tol, dist=args.dist, limits=args.limits)
    try:
        inputs = read_study(mech, table, method=args.method, samples=args.samples, positions=args.positions,
                            seed=args.seed, chunk=args.chunk, sampler=args.sampler, bootstrap=args.bootstrap,
                            robust=args.robust, precision=args.precision, max_samples=args.max_samples,
                            second_order=args.second_order)
        study = study_for(mech, inputs)  # in one process (tests, scripts calling `main`): compiled once per key
        if inputs.limits and inputs.method == "tolerance":
            limited_responses(mech, inputs, study.responses.labels)  # the names, before any work
    except MechanismError as e:
        raise blamed(e, blame) from None
    extra = {"chunk": study.chunk, "command_line": {"set": list(args.set), "dtype": args.dtype,
                                                    "resume": bool(args.resume), "tol": list(args.tol),
                                                    "dist": list(args.dist), "limits": list(args.limits)}}
    show = sys.stderr.isatty() if args.progress == "auto" else args.progress == "on"
    from . import study_methods

    if study_methods.handles(inputs):  # morris, regression, dgsm, Dakota's studies, the stopping rule
        return study_methods.run(args, mech, study, show, t0, checkpoint=_checkpoint(args, mech, study, inputs.method))
    if inputs.method != "tolerance":
        return _design_space(args, mech, study, show, t0, extra)
    bar = None
    if show and inputs.samples > 0:
        from tqdm import tqdm

        bar = tqdm(total=inputs.samples, desc="Monte Carlo", unit="sample", leave=False, file=sys.stderr)
    try:
        rep = tolerance(mech, study=study, progress=None if bar is None else bar.update,
                        second_order=inputs.second_order,
                        checkpoint=_checkpoint(args, mech, study, "monte_carlo"))
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
        files = _report.write_all(args.out, mech, rep, wall_time=time.perf_counter() - t0, plot=not args.no_plot,
                                  extra=extra)
        print("wrote " + ", ".join(files))
    return 0


def _checkpoint(args, mech, study, what: str):
    """The checkpoint of `--out DIR` (DIR/checkpoint/), resumed with `--resume`; None without --out."""
    import pathlib

    from ..study.checkpoint import Checkpoint, resume_key

    if not args.out:
        return None
    inputs = study.inputs
    if what == "sample" and inputs.sampler != "lhs":
        # a sequence's first n points are the same whatever n: a resumed sample may ask for more
        # (incremental refinement) or fewer samples; its chunks done are reused where they are whole
        inputs = inputs._replace(samples=0)
    key = resume_key(mech, inputs, chunk=study.chunk, what=what)
    return Checkpoint(pathlib.Path(args.out) / "checkpoint", key, resume=args.resume)


def _replot(args) -> int:
    """`--replot DIR`: every plot redrawn from DIR's study.json and study.npz (nothing computed)."""
    import hashlib
    import pathlib

    from ..report.replot import read, replot

    data = read(args.replot)[0]
    src = pathlib.Path(args.file)
    if src.is_file() and data.get("file_sha256") not in (None, hashlib.sha256(src.read_bytes()).hexdigest()):
        print(f"warning: {src} has changed since the study in {args.replot}: the plots are the study's",
              file=sys.stderr)
    files = replot(args.replot)
    print("redrew " + (", ".join(files) if files else "nothing (this study has no plot)"))
    return 0


def _design_space(args, mech, study, show: bool, t0: float, extra: dict) -> int:
    """`sample`, `grid` and `sensitivity`."""
    import numpy as np

    from ..report import sampling as _report
    from ..study.design import grid_shape
    from ..study.sampling import sample, sensitivity

    inputs = study.inputs
    D = len(inputs.factors)
    total = {"sample": inputs.samples, "grid": int(np.prod(grid_shape(inputs))) if inputs.ranges else 0,
             "sensitivity": inputs.samples * ((2 * D if inputs.second_order else D) + 2)}[inputs.method]
    bar = None
    if show and total > 0:
        from tqdm import tqdm

        bar = tqdm(total=total, desc=inputs.method, unit="design", leave=False, file=sys.stderr)
    progress = None if bar is None else bar.update
    srep = rep = None
    try:
        ck = _checkpoint(args, mech, study, inputs.method)
        if inputs.method == "sensitivity":
            srep = sensitivity(mech, study=study, progress=progress, checkpoint=ck)
        else:
            rep = sample(mech, study=study, grid=inputs.method == "grid", progress=progress, checkpoint=ck)
    finally:
        if bar is not None:
            bar.close()
    done = srep if srep is not None else rep
    assert done is not None
    print(f"{inputs.method} study of {mech.name}: {len(inputs.factors)} factors "
          f"({', '.join(f.name for f in inputs.factors)}), {inputs.positions} positions; "
          f"{done.timings['total']:.3g} s")
    if srep is not None:
        print(_report.sensitivity_summary(srep))
    else:
        assert rep is not None
        print(_report.sample_summary(rep))
    for w in done.warnings:
        print(f"warning: {w}", file=sys.stderr)
    if args.out:
        wall = time.perf_counter() - t0
        if srep is not None:
            files = _report.write_sensitivity_all(args.out, mech, srep, wall_time=wall, plot=not args.no_plot,
                                                  extra=extra)
        else:
            assert rep is not None
            files = _report.write_sample_all(args.out, mech, rep, wall_time=wall, plot=not args.no_plot, extra=extra)
        print("wrote " + ", ".join(files))
    return 0
