"""Formatting of the design-space studies (`jaxlink.study.sample`, `sensitivity`): study.csv,
indices.csv, the JSON manifest, the printed summaries and the plots (Sobol' bars, indices against
the input, the grid's heat maps). Computes nothing.

**study.csv** (`sample`, `grid`; one row per design, in the order drawn, infeasible ones kept):
`sample`, one column `NAME (unit)` per studied parameter, `feasible` (1 or 0), one column
`OUTPUT (unit)` per scalar response (empty where infeasible, never `nan`), and with the
robust-design map its columns (`sigma_rss(OUTPUT) (unit)`, `worst_case_linear(OUTPUT) (unit)`,
`cpk(OUTPUT) (1)`, `jaxlink.study.robust`).

**indices.csv** (`sensitivity`; long form): `output`, `input (<input unit>)` (the position's
input for a point's x or y, empty for a scalar), `parameter` (the factor; for `S2` the pair
`a,b`, in the factors' order), `method` (`S1`, `ST`, and `S2` with `[study] second_order`),
`value (1)`, `low (1)`, `high (1)` (the bootstrap interval), `conditional` (1: over the wholly
feasible base samples only; 0 for the `feasible` output itself, over all).
"""

from __future__ import annotations

import csv
import hashlib
import json
import pathlib

import numpy as np

from ..study.inputs import GIVEN, Range
from ..study.responses import unit_names
from ..study.sampling import SampleReport, SensitivityReport
from ..study.sobol import pairs


def _g(v) -> str:
    return f"{float(v):.10g}"


def _input_unit(mech) -> str:
    lu, au = unit_names(mech)
    return au if mech.input_kind == "angle" else lu


def write_study_csv(path, rep: SampleReport) -> None:
    rob = rep.robust
    rlabels = () if rob is None else rob.labels
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["sample"] + [f"{p} ({u})" for p, u in zip(rep.parameters, rep.units)] + ["feasible"]
                   + [f"{name} ({unit})" for name, unit in rep.labels]
                   + [f"{name} ({unit})" for name, unit in rlabels])
        for i in range(len(rep.feasible)):
            ok = bool(rep.feasible[i])
            w.writerow([str(i)] + [_g(v) for v in rep.values[i]] + [str(int(ok))]
                       + [_g(v) if ok else "" for v in rep.responses[i]]
                       + ([] if rob is None else [_g(v) if ok else "" for v in rob.values[i]]))


def write_indices_csv(path, mech, rep: SensitivityReport) -> None:
    iu = _input_unit(mech)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["output", f"input ({iu})", "parameter", "method", "value (1)", "low (1)", "high (1)",
                    "conditional"])
        rows: list = [[(("feasible", "1", None),), rep.feasibility, "0"]]
        if rep.indices is not None:
            rows.append([rep.labels, rep.indices, "1"])
        for labels, ind, cond in rows:
            for i, (name, _unit, k) in enumerate(labels):
                x = "" if k is None else _g(rep.input_values[k])
                for j, f in enumerate(rep.factors):
                    for m in ("S1", "ST"):
                        v, lo, hi = (getattr(ind, m)[i, j], getattr(ind, m + "_low")[i, j],
                                     getattr(ind, m + "_high")[i, j])
                        w.writerow([name, x, f, m, _g(v), _g(lo), _g(hi), cond])
                if ind.S2 is not None:
                    for c, (j, k) in enumerate(pairs(len(rep.factors))):
                        w.writerow([name, x, f"{rep.factors[j]},{rep.factors[k]}", "S2", _g(ind.S2[i, c]),
                                    _g(ind.S2_low[i, c]), _g(ind.S2_high[i, c]), cond])


def _base_manifest(mech, inputs, method: str) -> dict:
    from .. import __version__

    lu, au = unit_names(mech)
    src = pathlib.Path(mech.file)
    factors = []
    for f in inputs.factors:
        if isinstance(f, Range):
            factors.append({"name": f.name, "parameters": list(f.parameters), "kind": f.kind, "range": [f.low, f.high],
                            "levels": f.levels if method == "grid" else None})
        else:
            factors.append({"name": f.name, "parameters": list(f.parameters), "kind": f.kind,
                            "distribution": f.distribution, "half_width": f.half_width, "sigma": f.sigma,
                            "zone": "circle" if f.zone else ("box " + f.box if getattr(f, "box", "") else None)})
    return {
        "method": method, "file": str(mech.file),
        "file_sha256": hashlib.sha256(src.read_bytes()).hexdigest() if src.is_file() else None,
        "jaxlink_version": __version__, "seed": inputs.seed,
        "sampler": None if method == "grid" else inputs.sampler,
        "units": {"length": lu, "angle": au, "input": _input_unit(mech)},
        "positions": inputs.positions, "points": list(inputs.points), "metrics": list(inputs.metrics),
        "factors": factors,
    }


def _two_ranges(rep: SampleReport) -> bool:
    return rep.grid_shape is not None and sum(n > 1 for n in rep.grid_shape) == 2


def draw_sample_plots(d: pathlib.Path, mech, rep: SampleReport) -> list:
    """grid.png (a grid over two ranges) and robust.png (with the robust-design map), scatter.png (a
    `sample`: `plot_scatter`), or the plot of a vector, list or centered study
    (`parameter_studies.py`: vector.png, list.png, centered.png) into `d`;
    their paths. `mech` needs only its names (`study_files.MechanismNames`)."""
    from .parameter_studies import plot_parameter_study

    files = []
    if rep.inputs.method in GIVEN and plot_parameter_study(d / f"{rep.inputs.method}.png", mech, rep):
        files.append(d / f"{rep.inputs.method}.png")
    if rep.grid_shape is None and rep.inputs.method not in GIVEN and plot_scatter(d / "scatter.png", mech, rep):
        files.append(d / "scatter.png")
    if _two_ranges(rep) and rep.labels:
        files.append(d / "grid.png")
        plot_grid(files[-1], mech, rep)
    rob = rep.robust
    if _two_ranges(rep) and rob is not None and rob.labels:
        # the metrics' columns and each path's deviation bound (not the per-coordinate ones)
        keep = [j for j, (name, _u) in enumerate(rob.labels)
                if not (name.endswith(".x)") or name.endswith(".y)"))]
        files.append(d / "robust.png")
        plot_grid(files[-1], mech, rep, labels=tuple(rob.labels[j] for j in keep), values=rob.values[:, keep],
                  title="robust-design map")
    return files


def draw_sensitivity_plots(d: pathlib.Path, mech, rep: SensitivityReport) -> list:
    """sobol.png and sobol_curves.png (with points) into `d`; their paths."""
    files = [d / "sobol.png"]
    plot_bars(files[-1], mech, rep)
    if rep.indices is not None and rep.inputs.points:
        files.append(d / "sobol_curves.png")
        plot_curves(files[-1], mech, rep)
    return files


def _finish(d: pathlib.Path, mech, rep, data: dict, files: list, sizes: dict, extra: dict | None) -> list:
    from .study_files import write_archive

    data["sizes"] = sizes
    data.update(extra or {})
    data["files"] = [f.name for f in files]
    write_archive(d, mech, rep, data)
    files[-1].write_text(json.dumps(data, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    return [str(f) for f in files]


def write_sample_all(out_dir, mech, rep: SampleReport, *, wall_time: float, plot: bool = True,
                     extra: dict | None = None) -> list:
    """study.csv, grid.png and robust.png (a grid over two ranges), study.npz and study.json into
    `out_dir`; `extra`: more manifest keys."""
    d = pathlib.Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    files = [d / "study.csv"]
    write_study_csv(files[0], rep)
    method = "grid" if rep.grid_shape is not None else rep.inputs.method if rep.inputs.method in GIVEN else "sample"
    if plot:
        files += draw_sample_plots(d, mech, rep)
    files += [d / "study.npz", d / "study.json"]
    data = _base_manifest(mech, rep.inputs, method)
    n = len(rep.feasible)
    rob = rep.robust
    data.update({"samples": n, "grid_shape": None if rep.grid_shape is None else list(rep.grid_shape),
                 "feasible": int(rep.feasible.sum()), "infeasible": int(n - rep.feasible.sum()),
                 "certificate": rep.certificate, "responses": [f"{a} ({b})" for a, b in rep.labels],
                 "robust": None if rob is None else {"tolerances": list(rob.tolerances),
                                                     "columns": [f"{a} ({b})" for a, b in rob.labels],
                                                     "limits": [[nm, _lim(lo), _lim(hi)] for nm, lo, hi in rob.limits]},
                 "warnings": list(rep.warnings), "timings_s": {k: round(v, 4) for k, v in rep.timings.items()},
                 "wall_time_s": round(wall_time, 3)})
    sizes = {"designs": n, "parameters": len(rep.parameters), "positions": rep.inputs.positions,
             "scalar_responses": len(rep.labels), "robust_columns": 0 if rob is None else len(rob.labels)}
    return _finish(d, mech, rep, data, files, sizes, extra)


def _lim(v):
    return v if np.isfinite(v) else ("inf" if v > 0 else "-inf")


def write_sensitivity_all(out_dir, mech, rep: SensitivityReport, *, wall_time: float, plot: bool = True,
                          extra: dict | None = None) -> list:
    """indices.csv, sobol.png, sobol_curves.png (with points), study.npz and study.json into
    `out_dir`; `extra`: more manifest keys."""
    d = pathlib.Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    files = [d / "indices.csv"]
    write_indices_csv(files[0], mech, rep)
    if plot:
        files += draw_sensitivity_plots(d, mech, rep)
    files += [d / "study.npz", d / "study.json"]
    data = _base_manifest(mech, rep.inputs, "sensitivity")
    data.update({"samples": rep.samples, "evaluations": rep.evaluations, "bootstrap": rep.inputs.bootstrap,
                 "confidence": rep.inputs.confidence, "second_order": rep.inputs.second_order,
                 "feasible_fraction": rep.feasible_fraction,
                 "complete_samples": rep.complete, "conditional": rep.complete < rep.samples,
                 "certificate": rep.certificate, "responses": len(rep.labels),
                 "warnings": list(rep.warnings), "timings_s": {k: round(v, 4) for k, v in rep.timings.items()},
                 "wall_time_s": round(wall_time, 3)})
    sizes = {"base_samples": rep.samples, "designs": rep.evaluations, "factors": len(rep.factors),
             "positions": rep.inputs.positions, "responses": len(rep.labels)}
    return _finish(d, mech, rep, data, files, sizes, extra)


def sample_summary(rep: SampleReport) -> str:
    """Per scalar response: the nominal, least, mean and largest over the feasible designs."""
    ok = rep.feasible
    lines = [f"{len(ok)} designs, {int(ok.sum())} feasible, {int((~ok).sum())} infeasible "
             f"(feasibility: {rep.certificate})"]
    if ok.any() and rep.labels:
        lines.append(f"{'output':<22} {'unit':<8} {'nominal':>11} {'least':>11} {'mean':>11} {'largest':>11}")
        v = rep.responses[ok]
        for j, (name, unit) in enumerate(rep.labels):
            lines.append(f"{name:<22} {unit:<8} {rep.nominal[j]:11.4g} {v[:, j].min():11.4g} {v[:, j].mean():11.4g} "
                         f"{v[:, j].max():11.4g}")
    rob = rep.robust
    if rob is not None and ok.any() and rob.labels:
        lines.append(f"robust-design map (first order, tolerances of {', '.join(rob.tolerances)}), over the feasible "
                     "designs:")
        lines.append(f"{'column':<34} {'unit':<8} {'least':>11} {'mean':>11} {'largest':>11}")
        r = rob.values[ok]
        for j, (name, unit) in enumerate(rob.labels):
            lines.append(f"{name:<34} {unit:<8} {r[:, j].min():11.4g} {r[:, j].mean():11.4g} {r[:, j].max():11.4g}")
    return "\n".join(lines)


def sensitivity_summary(rep: SensitivityReport) -> str:
    """S1 and ST per factor of the feasibility and every scalar response, and of each curve its
    indices averaged over the cycle."""
    head = f"{'output':<22} " + " ".join(f"{f[:9] + ' S1/ST':>19}" for f in rep.factors)
    lines = [f"Sobol' indices, {rep.samples} base samples ({rep.evaluations} designs), "
             f"{100 * rep.inputs.confidence:g} % bootstrap intervals of {rep.inputs.bootstrap} resamples; "
             f"feasible fraction {rep.feasible_fraction:.4g}", head]

    def row(name, s1, st):
        return f"{name:<22} " + " ".join(f"{a:9.3f}/{b:<9.3f}" for a, b in zip(s1, st))

    lines.append(row("feasible", rep.feasibility.S1[0], rep.feasibility.ST[0]))
    ind = rep.indices
    if ind is None:
        return "\n".join(lines)
    groups: dict = {}
    for i, (name, _u, _k) in enumerate(rep.labels):
        groups.setdefault(name, []).append(i)
    for name, idx in groups.items():
        if len(idx) == 1:
            lines.append(row(name, ind.S1[idx[0]], ind.ST[idx[0]]))
        else:
            lines.append(row(name + " (cycle mean)", ind.S1[idx].mean(0), ind.ST[idx].mean(0)))
    return "\n".join(lines)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_bars(path, mech, rep: SensitivityReport) -> None:
    """S1 and ST of each factor with their bootstrap intervals, one panel per scalar output (the
    feasibility first); with the second order, each pair's S2 after them."""
    plt = _plt()
    panels = [("feasible (indicator)" + (": every design feasible" if rep.feasibility.constant[0] else ""),
               rep.feasibility, 0)]
    if rep.indices is not None:
        panels += [(f"{name} ({unit})", rep.indices, i) for i, (name, unit, k) in enumerate(rep.labels) if k is None]
    D = len(rep.factors)
    cols = min(3, len(panels))
    rows = -(-len(panels) // cols)
    wide = 1.0 + (0.0 if rep.feasibility.S2 is None else 0.5 * len(pairs(D)) / max(D, 1))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols * wide, 3.0 * rows), squeeze=False)
    x = np.arange(D)
    for ax, (title, ind, i) in zip(axes.ravel(), panels):
        for off, m, c in ((-0.2, "S1", "C0"), (0.2, "ST", "C1")):
            v = getattr(ind, m)[i]
            err = np.stack([v - getattr(ind, m + "_low")[i], getattr(ind, m + "_high")[i] - v])
            ax.bar(x + off, v, 0.4, yerr=np.maximum(err, 0.0), color=c, capsize=3, label=m)
        ticks = list(rep.factors)
        s2, s2_low, s2_high = ind.S2, ind.S2_low, ind.S2_high
        if s2 is not None and s2_low is not None and s2_high is not None and s2.shape[1]:  # the pairs' S2 last
            v = s2[i]
            err = np.stack([v - s2_low[i], s2_high[i] - v])
            ax.bar(D + np.arange(len(v)), v, 0.4, yerr=np.maximum(err, 0.0), color="C2", capsize=3, label="S2")
            ticks += [f"{rep.factors[j]},{rep.factors[k]}" for j, k in pairs(D)]
        ax.set_xticks(np.arange(len(ticks)), ticks, rotation=30, ha="right", fontsize=8)
        ax.set_title(title, fontsize=9)
        ax.set_ylim(min(0.0, ax.get_ylim()[0]), max(1.05, ax.get_ylim()[1]))
        ax.axhline(0, color="k", lw=0.5)
        ax.grid(True, axis="y", lw=0.3)
    for ax in axes.ravel()[len(panels):]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"{mech.name}: Sobol' indices, {rep.samples} base samples, "
                 f"{100 * rep.inputs.confidence:g} % bootstrap intervals", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_curves(path, mech, rep: SensitivityReport) -> None:
    """S1 (dashed) and ST (solid, its interval shaded) of every factor against the input, for each
    studied point's x and y."""
    plt = _plt()
    ind = rep.indices
    assert ind is not None
    pts = rep.inputs.points
    fig, axes = plt.subplots(len(pts), 2, figsize=(11, 3.2 * len(pts)), squeeze=False)
    xs = rep.input_values
    lu, _ = unit_names(mech)
    for r, p in enumerate(pts):
        for c, comp in enumerate(("x", "y")):
            ax = axes[r, c]
            idx = np.asarray([i for i, (name, _u, k) in enumerate(rep.labels) if name == f"{p}.{comp}"])
            for j, f in enumerate(rep.factors):
                line, = ax.plot(xs, ind.ST[idx, j], lw=1.2, label=f"{f} ST")
                ax.fill_between(xs, ind.ST_low[idx, j], ind.ST_high[idx, j], color=line.get_color(), alpha=0.2, lw=0)
                ax.plot(xs, ind.S1[idx, j], lw=0.9, ls="--", color=line.get_color(), label=f"{f} S1")
            ax.set_title(f"{p}.{comp} ({lu})", fontsize=9)
            ax.set_xlabel(f"{mech.input_name} ({_input_unit(mech)})")
            ax.set_ylim(-0.05, 1.05)
            ax.grid(True, lw=0.3)
    axes[0, 1].legend(fontsize=7, ncol=2)
    fig.suptitle(f"{mech.name}: Sobol' indices along the cycle (ST solid with its interval, S1 dashed)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_scatter(path, mech, rep: SampleReport, *, most: int = 20000) -> bool:
    """scatter.png of a `sample` study: every scalar response (rows) against every studied
    parameter (columns), one dot per feasible design, the file's design marked; the designs that
    do not assemble as red crosses on the bottom edge of each panel (they have no response). At
    most `most` designs are drawn (the first ones: a sequence's first points cover the space).
    False (nothing drawn) without designs or scalar responses."""
    n, T = rep.values.shape
    S = len(rep.labels)
    if not n or not S or not T:
        return False
    plt = _plt()
    k = min(n, most)
    x, ok, y = rep.values[:k], np.asarray(rep.feasible[:k], bool), rep.responses[:k]
    fig, axes = plt.subplots(S, T, figsize=(2.6 * T + 0.8, 2.2 * S + 0.8), squeeze=False, sharex="col", sharey="row")
    ms = 4.0 if k <= 500 else 1.0
    for i, (name, unit) in enumerate(rep.labels):
        for j in range(T):
            ax = axes[i, j]
            ax.plot(x[ok, j], y[ok, i], ".", ms=ms, alpha=0.5, color="tab:blue", rasterized=True)
            ax.plot(rep.nominal_x[j], rep.nominal[i], "k*", ms=8)
            if (~ok).any():
                ax.plot(x[~ok, j], np.zeros(int((~ok).sum())), "x", ms=3, color="tab:red",
                        transform=ax.get_xaxis_transform(), clip_on=False)
            if i == S - 1:
                ax.set_xlabel(f"{rep.parameters[j]} ({rep.units[j]})", fontsize=8)
            if j == 0:
                ax.set_ylabel(f"{name}\n({unit})", fontsize=8)
            ax.tick_params(labelsize=7)
    bad = int((~ok).sum())
    fig.suptitle(f"{mech.name}: {k} designs{' (the first ' + str(k) + ' of ' + str(n) + ')' if k < n else ''}, "
                 f"{bad} do not assemble (red crosses); ★ the file's design", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.96))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def plot_grid(path, mech, rep: SampleReport, *, labels=None, values=None, title: str | None = None) -> None:
    """A heat map of every scalar response (or of the columns `values` (n, C) named by `labels`:
    the robust-design map's) over a grid of two ranges (the others at one level), the infeasible
    designs masked (grey, hatched)."""
    plt = _plt()
    assert rep.grid_shape is not None
    a, b = [i for i, n in enumerate(rep.grid_shape) if n > 1]
    n1, n2 = rep.grid_shape[a], rep.grid_shape[b]
    xv = rep.values[:, a].reshape(n1, n2)
    yv = rep.values[:, b].reshape(n1, n2)
    bad = ~rep.feasible.reshape(n1, n2)
    labels = rep.labels if labels is None else labels
    values = rep.responses if values is None else values
    S = len(labels)
    cols = min(3, S)
    rows = -(-S // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.8 * rows), squeeze=False)
    for j, (name, unit) in enumerate(labels):
        ax = axes.ravel()[j]
        z = np.ma.masked_array(values[:, j].reshape(n1, n2), bad | ~np.isfinite(values[:, j].reshape(n1, n2)))
        ax.set_facecolor("0.8")
        m = ax.pcolormesh(xv, yv, z, shading="nearest", cmap="viridis")
        if bad.any():
            ax.contourf(xv, yv, bad.astype(float), levels=[0.5, 1.5], colors="none", hatches=["//"])
        fig.colorbar(m, ax=ax, label=unit)
        ax.set_title(name + (" (grey: does not assemble)" if bad.any() else ""), fontsize=9)
        ax.set_xlabel(f"{rep.parameters[a]} ({rep.units[a]})")
        ax.set_ylabel(f"{rep.parameters[b]} ({rep.units[b]})")
    for ax in axes.ravel()[S:]:
        ax.axis("off")
    fig.suptitle(f"{mech.name}: {title + ', ' if title else ''}grid of {n1} × {n2} designs, "
                 f"{int(rep.feasible.sum())} feasible", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(path, dpi=120)
    plt.close(fig)
