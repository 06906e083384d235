"""The `jaxlink study` methods of jaxlink/study/morris.py, regression.py, dgsm.py,
parameter_studies.py and the stopping rule (convergence.py): run, print and write their files
(`jaxlink.cli.study` dispatches here)."""

from __future__ import annotations

import sys
import time
from typing import Any

SCREENING = ("morris", "regression", "dgsm")
GIVEN = ("vector", "list", "centered")


def handles(inputs) -> bool:
    """Whether this module runs the study of `inputs`."""
    return inputs.method in SCREENING + GIVEN or (
        inputs.precision is not None and inputs.method in ("tolerance", "sensitivity"))


def _bar(show: bool, total: int | None, desc: str, unit: str = "design"):
    """A progress bar on standard error (None when not shown); `total` None: of unknown length
    (the stopping rule's rounds: the designs or samples done so far, and their rate)."""
    if not show or (total is not None and total <= 0):
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit=unit, leave=False, file=sys.stderr)


def run(args, mech, study, show: bool, t0: float, checkpoint=None) -> int:
    """Run the study of `args`; `checkpoint`: the checkpoint of --out (None without it)."""
    from ..report import screening as _screening

    inputs = study.inputs
    D = len(inputs.factors)
    total = {"morris": inputs.samples * (D + 1), "regression": inputs.samples, "dgsm": inputs.samples,
             "sensitivity": 0, "tolerance": 0}.get(inputs.method, len(inputs.designs))
    rule = inputs.method in ("sensitivity", "tolerance")  # the precision stopping rule: rounds until it holds
    bar = (_bar(show, None, f"{inputs.method} (rounds to precision {inputs.precision:g})",
                "sample" if inputs.method == "tolerance" else "design")
           if rule else _bar(show, total, inputs.method))
    progress = None if bar is None else bar.update
    conv = None
    rep: Any
    try:
        if inputs.method == "morris":
            from ..study.morris import morris

            rep = morris(mech, study=study, progress=progress, checkpoint=checkpoint)
        elif inputs.method == "regression":
            from ..study.regression import regression

            rep = regression(mech, study=study, progress=progress, checkpoint=checkpoint)
        elif inputs.method == "dgsm":
            from ..study.dgsm import dgsm

            rep = dgsm(mech, study=study, progress=progress, checkpoint=checkpoint)
        elif inputs.method in GIVEN:
            from ..study.parameter_studies import parameter_study

            rep = parameter_study(mech, study=study, progress=progress, checkpoint=checkpoint)
        elif inputs.method == "sensitivity":
            from ..study.convergence import converged_sensitivity

            rep, conv = converged_sensitivity(mech, study=study, progress=progress, checkpoint=checkpoint)
        else:
            from ..study.convergence import converged_tolerance

            rep, conv = converged_tolerance(mech, study=study, progress=progress, checkpoint=checkpoint)
    finally:
        if bar is not None:
            bar.close()
    if inputs.method == "tolerance":
        from ..report import tolerance as _tol

        print(f"tolerance study of {mech.name}: {len(inputs.parameters)} toleranced parameters, "
              f"{inputs.positions} positions, {len(rep.labels)} responses")
        print(_tol.summary(mech, rep))
    else:
        print(f"{inputs.method} study of {mech.name}: {len(inputs.factors)} factors "
              f"({', '.join(f.name for f in inputs.factors)}), {inputs.positions} positions; "
              f"{rep.timings['total']:.3g} s")
        if inputs.method in SCREENING:
            print(_screening.summary(rep))
        else:
            from ..report import sampling as _sampling

            print(_sampling.sensitivity_summary(rep) if inputs.method == "sensitivity"
                  else _sampling.sample_summary(rep))
    if conv is not None:
        print(_screening.convergence_line(conv))
    for w in rep.warnings:
        print(f"warning: {w}", file=sys.stderr)
    if args.out:
        wall = time.perf_counter() - t0
        plot = not args.no_plot
        if inputs.method in SCREENING:
            files = _screening.write_all(args.out, mech, rep, wall_time=wall, plot=plot)
        elif inputs.method == "tolerance":
            from ..report import tolerance as _tol

            files = _tol.write_all(args.out, mech, rep, wall_time=wall, plot=plot)
        else:
            from ..report import sampling as _sampling

            files = (_sampling.write_sensitivity_all(args.out, mech, rep, wall_time=wall, plot=plot)
                     if inputs.method == "sensitivity" else
                     _sampling.write_sample_all(args.out, mech, rep, wall_time=wall, plot=plot))
        if conv is not None:
            _screening.add_convergence(next(f for f in files if f.endswith("study.json")), conv)
        print("wrote " + ", ".join(files))
    return 0
