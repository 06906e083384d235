"""Formatting of the Morris, regression and DGSM studies (`jaxlink.study.morris`, `regression`,
`dgsm`) and of the stopping rule: indices.csv, the JSON manifest, the printed summaries and the
plots (Morris μ*–σ, bars of the coefficients or bounds). Computes nothing.

**indices.csv** (long form, one row per output, position, parameter and index): `output`
(`feasible` for the indicator — Morris and regression —, `P.x`, `P.y`, a metric,
`deviation(P)`), `input (<input unit>)` (the position's input; empty for a scalar), `parameter`
(the factor; empty for `R2`, `rank_R2`), `method`, `unit` (the unit of the row's value columns),
`value (unit)`, `low (unit)`, `high (unit)` (the interval at `confidence`; empty where none),
`conditional` (1: over the feasible designs only; 0 for the `feasible` rows and where every
design is feasible). Methods: Morris `mu`, `mu_star`, `sigma` (the output's unit); regression
`pearson`, `spearman`, `src`, `srrc`, `pcc`, `prcc`, `R2`, `rank_R2` (1); DGSM `nu` ((output /
parameter unit)²) and `ST_bound` (1). No cell is ever `nan`.
"""

from __future__ import annotations

import csv
import json
import pathlib
from typing import Any

import numpy as np

from ..study.dgsm import DGSMReport
from ..study.morris import MorrisReport
from ..study.regression import COEFFICIENTS, RegressionIndices, RegressionReport
from .sampling import _base_manifest, _g, _input_unit


def _rows(mech, rep):
    """(output, input, parameter, method, unit, value, low, high, conditional) of every index."""
    units = dict(zip(rep.inputs.parameters, _param_units(mech, rep.inputs)))
    cond = "1" if _conditional(rep) else "0"
    out = []

    def pos(k):
        return "" if k is None else _g(rep.input_values[k])

    if isinstance(rep, MorrisReport):
        blocks = [((("feasible", "1", None),), rep.feasibility, "0")] + [(rep.labels, rep.indices, cond)]
        for labels, ind, c in blocks:
            for i, (name, unit, k) in enumerate(labels):
                for j, f in enumerate(rep.factors):
                    for m in ("mu", "mu_star", "sigma"):
                        v, lo, hi = (getattr(ind, m)[i, j], getattr(ind, m + "_low")[i, j],
                                     getattr(ind, m + "_high")[i, j])
                        out.append([name, pos(k), f, m, unit, _g(v), _g(lo), _g(hi), c])
    elif isinstance(rep, RegressionReport):
        blocks = [((("feasible", "1", None),), rep.feasibility, "0")]
        if rep.indices is not None:
            blocks.append((rep.labels, rep.indices, cond))
        for labels, ind, c in blocks:
            for i, (name, _unit, k) in enumerate(labels):
                for j, f in enumerate(rep.factors):
                    for m in COEFFICIENTS:
                        out.append([name, pos(k), f, m, "1", _g(ind.values[m][i, j]), _g(ind.low[m][i, j]),
                                    _g(ind.high[m][i, j]), c])
                out.append([name, pos(k), "", "R2", "1", _g(ind.r2[i]), "", "", c])
                out.append([name, pos(k), "", "rank_R2", "1", _g(ind.rank_r2[i]), "", "", c])
    elif isinstance(rep, DGSMReport):
        ind = rep.indices
        if ind is not None:
            for i, (name, unit, k) in enumerate(rep.labels):
                for j, f in enumerate(rep.inputs.factors):
                    pu = units[f.parameters[0]]
                    out.append([name, pos(k), f.name, "nu", f"({unit}/{pu})^2", _g(ind.nu[i, j]), _g(ind.nu_low[i, j]),
                                _g(ind.nu_high[i, j]), cond])
                    out.append([name, pos(k), f.name, "ST_bound", "1", _g(ind.bound[i, j]), _g(ind.bound_low[i, j]),
                                _g(ind.bound_high[i, j]), cond])
    else:
        raise TypeError(f"not a Morris, regression or DGSM report: {type(rep).__name__}")
    return out


def _param_units(mech, inputs) -> tuple:
    from ..study.responses import unit_names

    lu, au = unit_names(mech)
    return tuple({"length": lu, "angle": au}.get(mech.kinds[p], "1") for p in inputs.parameters)


def _conditional(rep) -> bool:
    return rep.feasible_fraction < 1.0


def write_indices_csv(path, mech, rep) -> None:
    """indices.csv of a Morris, regression or DGSM study (see the module doc)."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["output", f"input ({_input_unit(mech)})", "parameter", "method", "unit", "value (unit)",
                    "low (unit)", "high (unit)", "conditional"])
        w.writerows(_rows(mech, rep))


def _method(rep) -> str:
    return {MorrisReport: "morris", RegressionReport: "regression", DGSMReport: "dgsm"}[type(rep)]


def write_all(out_dir, mech, rep, *, wall_time: float, plot: bool = True) -> list:
    """indices.csv, the plot (morris.png, regression.png or dgsm.png; with a scalar response or
    the feasibility to show), study.npz and study.json into `out_dir` (`--replot` redraws the
    plot from the last two)."""
    d = pathlib.Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    method = _method(rep)
    files = [d / "indices.csv"]
    write_indices_csv(files[0], mech, rep)
    if plot:
        files.append(d / f"{method}.png")
        if not plot_indices(files[-1], mech, rep):
            files.pop()
    files += [d / "study.npz", d / "study.json"]
    data = _base_manifest(mech, rep.inputs, method)
    extra: dict = {"feasible_fraction": rep.feasible_fraction, "certificate": rep.certificate,
                   "responses": len(rep.labels), "bootstrap": rep.inputs.bootstrap,
                   "confidence": rep.inputs.confidence}
    if isinstance(rep, MorrisReport):
        extra.update({"trajectories": rep.trajectories, "evaluations": rep.evaluations, "levels": rep.levels})
    else:
        extra.update({"samples": rep.samples, "evaluations": rep.samples})
    if isinstance(rep, DGSMReport):
        extra["poincare_constants"] = [float(c) for c in rep.constants]
    data.update(extra)
    data.update({"warnings": list(rep.warnings), "timings_s": {k: round(v, 4) for k, v in rep.timings.items()},
                 "wall_time_s": round(wall_time, 3), "files": [f.name for f in files]})
    from .study_files import write_archive

    write_archive(d, mech, rep, data)  # study.npz and the report's tree: --replot redraws from them
    files[-1].write_text(json.dumps(data, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    return [str(f) for f in files]


def add_convergence(manifest, conv) -> None:
    """Add the stopping rule's `convergence` (`samples`, `converged`, `precision`, `max_samples`,
    `history`: [samples, largest half-width] per round) to a written study.json."""
    p = pathlib.Path(manifest)
    data = json.loads(p.read_text(encoding="utf-8"))
    data["convergence"] = {"samples": conv.samples, "converged": conv.converged, "precision": conv.precision,
                           "max_samples": conv.max_samples,
                           "history": [[int(n), float(h) if np.isfinite(h) else None] for n, h in conv.history]}
    p.write_text(json.dumps(data, indent=2, allow_nan=False) + "\n", encoding="utf-8")


def convergence_line(conv) -> str:
    rounds = ", ".join(f"{n}: {h:.3g}" for n, h in conv.history)
    return (f"precision {conv.precision:g}: {'reached' if conv.converged else 'NOT reached'} at {conv.samples} samples "
            f"(largest half-width per round: {rounds})")


def summary(rep) -> str:
    """Per factor, the main index of the feasibility and of every scalar response (a curve's
    averaged over the cycle): Morris μ*/σ, regression SRC (and R²), DGSM ST bound."""
    main: list[Any]
    ind: Any
    if isinstance(rep, MorrisReport):
        title = (f"Morris elementary effects, {rep.trajectories} trajectories ({rep.evaluations} designs), "
                 f"{rep.levels} levels; μ*/σ in the output's unit per range")
        main = [("feasible", rep.feasibility, 0, "mu_star", "sigma")]
        ind, a, b = rep.indices, "mu_star", "sigma"
    elif isinstance(rep, RegressionReport):
        title = (f"standardized regression (SRC) and partial rank (PRCC) coefficients, {rep.samples} designs; "
                 f"feasible fraction {rep.feasible_fraction:.4g}")
        ind, a, b = rep.indices, "src", "prcc"
        main = [("feasible", rep.feasibility, 0, a, b)]
    else:
        title = (f"DGSM from the exact gradients, {rep.samples} designs: ν and the ST bound C ν / V; "
                 f"feasible fraction {rep.feasible_fraction:.4g}")
        ind, a, b = rep.indices, "nu", "bound"
        main = []

    def get(ind, m):
        return ind.values[m] if isinstance(ind, RegressionIndices) else getattr(ind, m)

    factors = rep.factors
    lines = [title, f"{'output':<24} " + " ".join(f"{f[:9] + ' ' + a[:6] + '/' + b[:6]:>24}" for f in factors)]

    def row(name, x, y):
        return f"{name:<24} " + " ".join(f"{p:11.4g}/{q:<12.4g}" for p, q in zip(x, y))

    for name, src, i, ma, mb in main:
        lines.append(row(name, get(src, ma)[i], get(src, mb)[i]))
    if ind is None:
        return "\n".join(lines)
    groups: dict = {}
    for i, (name, _u, _k) in enumerate(rep.labels):
        groups.setdefault(name, []).append(i)
    for name, idx in groups.items():
        x, y = get(ind, a)[idx], get(ind, b)[idx]
        lines.append(row(name if len(idx) == 1 else name + " (mean)", x.mean(0), y.mean(0)))
    return "\n".join(lines)


def plot_indices(path, mech, rep) -> bool:
    """Morris: μ* against σ per factor, one panel per scalar output (the feasibility first);
    regression: SRC and PRCC bars with their intervals; DGSM: the ST bound's bars. False (nothing
    drawn) where there is no panel."""
    from .plot import finish
    from .sampling import _plt

    panels: list[Any] = []
    every = rep.feasible_fraction >= 1.0  # the indicator is constant: its panel would be one point
    if isinstance(rep, (MorrisReport, RegressionReport)) and not every:
        panels.append(("feasible (indicator)", rep.feasibility, 0))
    if rep.indices is not None:
        panels += [(f"{name} ({unit})", rep.indices, i) for i, (name, unit, k) in enumerate(rep.labels) if k is None]
    if not panels:
        return False
    plt = _plt()
    cols = min(3, len(panels))
    rows = -(-len(panels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    x = np.arange(len(rep.factors))
    for ax, (title, ind, i) in zip(axes.ravel(), panels):
        if isinstance(rep, MorrisReport):
            ax.errorbar(ind.mu_star[i], ind.sigma[i], xerr=np.maximum(ind.mu_star_high[i] - ind.mu_star[i], 0),
                        fmt="o", capsize=3)
            for j, f in enumerate(rep.factors):
                ax.annotate(f, (ind.mu_star[i, j], ind.sigma[i, j]), fontsize=7, xytext=(3, 3),
                            textcoords="offset points")
            ax.set_xlabel("μ*")
            ax.set_ylabel("σ")
        else:
            series = ((("src", "SRC"), ("prcc", "PRCC")) if isinstance(rep, RegressionReport)
                      else (("bound", "ST bound"),))
            wdt = 0.8 / len(series)
            for s, (m, lab) in enumerate(series):
                if isinstance(rep, RegressionReport):
                    v, lo, hi = ind.values[m][i], ind.low[m][i], ind.high[m][i]
                else:
                    v, lo, hi = ind.bound[i], ind.bound_low[i], ind.bound_high[i]
                err = np.maximum(np.stack([v - lo, hi - v]), 0.0)
                ax.bar(x + (s - (len(series) - 1) / 2) * wdt, v, wdt, yerr=err, capsize=3, label=lab)
            ax.set_xticks(x, rep.factors, rotation=30, ha="right", fontsize=8)
            ax.axhline(0, color="k", lw=0.5)
            ax.legend(fontsize=7)
        ax.set_title(title, fontsize=9)
        ax.grid(True, lw=0.3)
    for ax in axes.ravel()[len(panels):]:
        ax.axis("off")
    what = {MorrisReport: "Morris elementary effects (μ* against σ)", RegressionReport:
            "standardised regression (SRC) and partial rank correlation (PRCC) coefficients",
            DGSMReport: "derivative-based upper bounds of ST"}[type(rep)]
    n = f"{rep.evaluations if isinstance(rep, MorrisReport) else rep.samples} designs"
    feas = ("every design assembles" if every else
            f"{100 * (1 - rep.feasible_fraction):.3g} % of the designs do not assemble")
    finish(fig, path, title=f"{mech.name}: {what}; {n}, {feas}")
    return True
