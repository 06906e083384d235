"""Formatting of a tolerance study (`jaxlink.study.tolerance`): the CSV files, the JSON manifest,
the printed summary and the tolerance band around the coupler curves. Computes nothing but the
band's geometry (the 2 × 2 covariance of each point from the first-order Jacobian).

**tolerance.csv** (long form, one row per response and position): `output`, `unit` (the unit of
every value column of the row, marked `(unit)`: the file's length unit for a point's x, y, the
angle unit for a rocker's swing, …), `input (<input unit>)` (empty for a scalar metric),
`nominal (unit)`, `sigma_rss (unit)`, `worst_case_linear (unit)`, with second order
`mean_shift2 (unit)` and `std2 (unit)` (the second-order mean shift and σ from the exact Hessian),
and with Monte Carlo
`mc_mean_shift (unit)`, `mc_std (unit)`, `mc_std_error (unit)`, `mc_p0.135 (unit)`,
`mc_p99.865 (unit)` (deviations from the nominal), `mc_max_abs_deviation (unit)`, `agree` (1, or 0
where first order and Monte Carlo disagree beyond the sampling error), with `[study] limits` and
Monte Carlo `spec_low (unit)`, `spec_high (unit)`, `mc_percent_out_of_spec (%)` (of the feasible
samples), `mc_cp (1)` (empty for a one-sided limit) and `mc_cpk (1)` on the limited responses'
rows (empty on the others), and with the worst case
`worst_case (unit)` (the largest deviation over the tolerance box, computed exactly) and
`worst_case_status` ("enumerated" | "found"). The rows `deviation(P.x)`, `deviation(P.y)` (the
largest |change| of the coordinate over the cycle) and `deviation(P)` (the largest distance of P's
path from the nominal over the cycle) give `worst_case_linear` (the linear bound), the Monte Carlo
mean (of `deviation(P)`) and largest value, and the worst case; a metric's row its worst case; a cell
that has no value is empty.

**importance.csv**: `output`, `input (<input unit>)`, `parameter`, `factor (1)`: (J σ)² / σ_RSS²
(with `[study.correlation]` J_j (Σ J)_j / σ_RSS², `FirstOrder.importance`).
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import pathlib

import numpy as np

from ..study.responses import unit_names
from ..study.tolerance import QUANTILES, ToleranceReport
from ..study.worstcase import monte_carlo_objectives


def _g(v) -> str:
    return "" if v is None else f"{float(v):.10g}"


def write_tolerance_csv(path, mech, rep: ToleranceReport) -> None:
    _, au = unit_names(mech)
    iu = au if mech.input_kind == "angle" else unit_names(mech)[0]
    mc = rep.monte_carlo
    f = rep.first_order
    head = ["output", "unit", f"input ({iu})", "nominal (unit)", "sigma_rss (unit)", "worst_case_linear (unit)"]
    so = rep.second_order
    if so is not None:
        head += ["mean_shift2 (unit)", "std2 (unit)"]
    if mc is not None:
        head += ["mc_mean_shift (unit)", "mc_std (unit)", "mc_std_error (unit)",
                 f"mc_p{100 * QUANTILES[0]:g} (unit)", f"mc_p{100 * QUANTILES[1]:g} (unit)",
                 "mc_max_abs_deviation (unit)", "agree"]
    spec = {} if mc is None else {i: q for q, (*_, i) in enumerate(mc.limits)}
    if spec:
        head += ["spec_low (unit)", "spec_high (unit)", "mc_percent_out_of_spec (%)", "mc_cp (1)", "mc_cpk (1)"]
    wc = rep.worst
    if wc is not None:
        head += ["worst_case (unit)", "worst_case_status"]
    worst = {} if wc is None else {n: (wc.value[q], wc.status[q]) for q, n in enumerate(wc.names)}
    N = rep.inputs.positions

    def cap(i):
        if not spec:
            return []
        if i not in spec:
            return [""] * 5
        assert mc is not None
        q = spec[i]
        _, lo, hi, _ = mc.limits[q]
        return [_g(lo) if math.isfinite(lo) else "", _g(hi) if math.isfinite(hi) else "", _g(mc.percent_out[q]),
                _g(mc.cp[q]) if math.isfinite(mc.cp[q]) else "", _g(mc.cpk[q])]

    def tail(name):
        if wc is None:
            return []
        if name not in worst:
            return ["", ""]
        value, status = worst[name]
        return ["" if status == "none feasible" else _g(value), status]

    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(head)
        for i, (name, unit, k) in enumerate(rep.labels):
            row = [name, unit, "" if k is None else _g(rep.input_values[k]), _g(rep.nominal[i]),
                   _g(f.sigma_rss[i]), _g(f.worst_case[i])]
            if so is not None:
                row += [_g(so.mean_shift[i]), _g(so.std[i])]
            if mc is not None:
                row += [_g(mc.mean_shift[i]), _g(mc.std[i]), _g(mc.std_error[i]), _g(mc.low[i]), _g(mc.high[i]),
                        _g(mc.max_abs[i]), str(int(mc.agree[i]))]
            row += cap(i)
            w.writerow(row + tail(name) if k is None else row + tail(None))
        lu = unit_names(mech)[0]
        for j, p in enumerate(rep.inputs.points):
            for c, a in (("x", 2 * N * j), ("y", 2 * N * j + N)):
                row = [f"deviation({p}.{c})", lu, "", "0", "", _g(f.worst_case[a:a + N].max())]
                row += ["", ""] if so is not None else []
                if mc is not None:
                    row += ["", "", "", "", "", _g(mc.max_abs[a:a + N].max()), ""] + cap(-1)
                w.writerow(row + tail(f"deviation({p}.{c})"))
            row = [f"deviation({p})", lu, "", "0", "", _g(rep.deviation_bound[j])]
            row += ["", ""] if so is not None else []
            if mc is not None:
                row += [_g(mc.deviation_mean[j]), "", "", "", "", _g(mc.deviation_max[j]), ""] + cap(-1)
            w.writerow(row + tail(f"deviation({p})"))



def write_importance_csv(path, mech, rep: ToleranceReport) -> None:
    _, au = unit_names(mech)
    iu = au if mech.input_kind == "angle" else unit_names(mech)[0]
    imp = rep.first_order.importance
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["output", f"input ({iu})", "parameter", "factor (1)"])
        for i, (name, _unit, k) in enumerate(rep.labels):
            x = "" if k is None else _g(rep.input_values[k])
            for j, p in enumerate(rep.parameters):
                w.writerow([name, x, p, _g(imp[i, j])])


def manifest(mech, rep: ToleranceReport, *, wall_time: float, files: list) -> dict:
    """The JSON manifest: what was computed, from what, how long it took."""
    from .. import __version__

    lu, au = unit_names(mech)
    src = pathlib.Path(mech.file)
    digest = hashlib.sha256(src.read_bytes()).hexdigest() if src.is_file() else None
    mc = rep.monte_carlo
    inp = rep.inputs
    out = {
        "method": "tolerance",
        "file": str(mech.file),
        "file_sha256": digest,
        "jaxlink_version": __version__,
        "seed": inp.seed,
        "units": {"length": lu, "angle": au, "input": au if mech.input_kind == "angle" else lu},
        "positions": inp.positions,
        "points": list(inp.points),
        "metrics": list(inp.metrics),
        "responses": len(rep.labels),
        "tolerances": [{"name": t.name, "parameters": list(t.parameters), "kind": t.kind,
                        "distribution": t.distribution, "half_width": t.half_width, "sigma": t.sigma,
                        "zone": "circle" if t.zone else ("box " + t.box if t.box else None)} for t in inp.tolerances],
        "certificate": rep.certificate,
        "margin": rep.margin,
        "margin_drop_linear": (rep.margin_drop if rep.margin_drop is not None and math.isfinite(rep.margin_drop)
                               else None),
        "monte_carlo": None if mc is None else {"samples": mc.samples, "feasible": mc.feasible,
                                                "infeasible": mc.infeasible, "outside_domain": mc.outside,
                                                "disagree": int(np.count_nonzero(~mc.agree)),
                                                "capability": capability_json(mc)},
        "worst_case": worst_case_json(rep),
        "second_order": None if rep.second_order is None else {
            "method": "second-order Taylor moments from the exact Hessian (docs/methods/tolerance.md)",
            "largest_mean_shift": float(np.abs(rep.second_order.mean_shift).max(initial=0.0)),
            "largest_std_change": float(np.abs(rep.second_order.std - rep.first_order.sigma_rss).max(initial=0.0))},
        "warnings": list(rep.warnings),
        "timings_s": {k: round(v, 4) for k, v in rep.timings.items()},
        "wall_time_s": round(wall_time, 3),
        "files": files,
    }
    return out


def _mc_objectives(rep: ToleranceReport):
    n_curve = sum(1 for lab in rep.labels if lab[2] is not None)
    return monte_carlo_objectives(rep.monte_carlo, len(rep.inputs.points), rep.inputs.positions, n_curve)


def capability_json(mc) -> list:
    """The manifest's `monte_carlo.capability`: per limited response its limits (None: open side),
    the feasible samples out of spec (count and percent), Cp (None for a one-sided limit), Cpk."""
    def num(v):
        return float(v) if math.isfinite(v) else None

    return [{"output": name, "low": num(lo), "high": num(hi), "out_of_spec": int(mc.out_of_spec[q]),
             "percent_out_of_spec": float(mc.percent_out[q]), "cp": num(mc.cp[q]), "cpk": num(mc.cpk[q])}
            for q, (name, lo, hi, _i) in enumerate(mc.limits)]


def worst_case_json(rep: ToleranceReport):
    """The manifest's `worst_case` (None when not searched)."""
    wc = rep.worst
    if wc is None:
        return None
    mcq = None if rep.monte_carlo is None else _mc_objectives(rep)
    return {"corners_enumerated": wc.corners, "candidates": wc.candidates, "infeasible": wc.infeasible,
            "ascent_evaluations": wc.evaluations,
            "outputs": [{"name": n, "unit": wc.units[q],
                         "worst": None if wc.status[q] == "none feasible" else float(wc.value[q]),
                         "status": wc.status[q],
                         "linear": float(wc.linear[q]), "mc_max": None if mcq is None else float(mcq[q]),
                         "design": {p: float(d) for p, d in zip(rep.parameters, wc.design[q])}}
                        for q, n in enumerate(wc.names)]}


def summary(mech, rep: ToleranceReport) -> str:
    """A table per output (the largest value over the cycle for a curve) and the counts."""
    mc = rep.monte_carlo
    f = rep.first_order
    groups: dict = {}
    for i, (name, unit, _k) in enumerate(rep.labels):
        groups.setdefault((name, unit), []).append(i)
    so = rep.second_order
    head = f"{'output':<22} {'unit':<8} {'σ_RSS max':>11} {'worst lin.':>11}"
    head += f" {'σ₂ max':>11} {'shift₂':>11}" if so is not None else ""
    head += f" {'MC σ max':>11} {'MC shift':>11}" if mc is not None else ""
    head += "  most important"
    lines = [head]
    for (name, unit), idx in groups.items():
        idx = np.asarray(idx)
        j = idx[np.argmax(f.sigma_rss[idx])]
        top = int(np.argmax(f.importance[j])) if f.sigma_rss[j] > 0 else None
        row = f"{name:<22} {unit:<8} {f.sigma_rss[j]:11.4g} {f.worst_case[idx].max():11.4g}"
        if so is not None:
            row += f" {so.std[idx].max():11.4g} {so.mean_shift[idx][np.argmax(np.abs(so.mean_shift[idx]))]:11.4g}"
        if mc is not None:
            row += f" {mc.std[idx].max():11.4g} {mc.mean_shift[idx][np.argmax(np.abs(mc.mean_shift[idx]))]:11.4g}"
        if top is not None:
            row += f"  {rep.parameters[top]} ({100 * f.importance[j, top]:.0f} %)"
        lines.append(row)
    lu = unit_names(mech)[0]
    for j, p in enumerate(rep.inputs.points):
        row = f"{'deviation(' + p + ')':<22} {lu:<8} {'':>11} {rep.deviation_bound[j]:11.4g}"
        row += f" {'':>11} {'':>11}" if so is not None else ""
        if mc is not None:
            row += f" {'max ' + format(mc.deviation_max[j], '.4g'):>11} {'':>11}"
        lines.append(row)
    wc = rep.worst
    if wc is not None:
        mcq = None if mc is None else _mc_objectives(rep)
        lines.append(f"worst case over the tolerance box ({wc.candidates} "
                     f"{'corners, every one' if wc.corners else 'candidate corners'} + gradient ascent; "
                     "Monte Carlo's largest is a sample's, not a worst case):")
        lines.append(f"{'output':<22} {'unit':<8} {'linear':>11} {'worst':>11}" + (f" {'MC max':>11}" if mc else "")
                     + "  status")
        for q, n in enumerate(wc.names):
            value = f"{'—':>11}" if wc.status[q] == "none feasible" else f"{wc.value[q]:11.4g}"
            lines.append(f"{n:<22} {wc.units[q]:<8} {wc.linear[q]:11.4g} {value}"
                         + (f" {mcq[q]:11.4g}" if mcq is not None else "") + f"  {wc.status[q]}")
    if mc is not None:
        lines.append(f"Monte Carlo: {mc.samples} samples, {mc.feasible} feasible, {mc.infeasible} infeasible "
                     + (f"({mc.outside} with a value outside its domain) " if mc.outside else "")
                     + f"(feasibility: {rep.certificate})")
        for q, (name, lo, hi, _i) in enumerate(mc.limits):
            cp = f"Cp {mc.cp[q]:.3g}, " if math.isfinite(mc.cp[q]) else ""
            lines.append(f"  {name} in [{lo:g}, {hi:g}]: {mc.percent_out[q]:.3g} % of the feasible samples out of "
                         f"spec, {cp}Cpk {mc.cpk[q]:.3g}")
    return "\n".join(lines)


def band(rep: ToleranceReport, j: int):
    """The nominal path (N, 2), the per-position covariance (N, 2, 2) and the normal standard
    deviation σ_n (N,) of studied point `j` (file units)."""
    n = rep.inputs.positions
    a = 2 * n * j
    J = rep.first_order.jacobian
    jx, jy = J[a:a + n], J[a + n:a + 2 * n]
    s2 = rep.first_order.sigma ** 2
    cov = np.empty((n, 2, 2))
    cov[:, 0, 0] = (jx * jx * s2).sum(1)
    cov[:, 1, 1] = (jy * jy * s2).sum(1)
    cov[:, 0, 1] = cov[:, 1, 0] = (jx * jy * s2).sum(1)
    xy = np.stack([rep.nominal[a:a + n], rep.nominal[a + n:a + 2 * n]], axis=1)
    tan = np.roll(xy, -1, 0) - np.roll(xy, 1, 0)
    norm = np.hypot(tan[:, 0], tan[:, 1])
    nrm = np.stack([-tan[:, 1], tan[:, 0]], axis=1) / np.where(norm > 0, norm, 1.0)[:, None]
    sn = np.sqrt(np.maximum(np.einsum("ni,nij,nj->n", nrm, cov, nrm), 0.0))
    return xy, cov, sn, nrm


def plot_band(path, mech, rep: ToleranceReport, *, k: float = 3.0, ellipses: int = 12) -> None:
    """The tolerance band of every studied point: the nominal path, the ±kσ envelope (along the
    path's normal, σ_n² = nᵀ C n with C = J Σ Jᵀ the point's first-order covariance) and the kσ
    ellipses of C at `ellipses` positions."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lu = unit_names(mech)[0]
    fig, ax = plt.subplots(figsize=(8, 6.5))
    t = np.linspace(0, 2 * np.pi, 64)
    bands = [band(rep, j) for j in range(len(rep.inputs.points))]
    extent = max(float(np.ptp(b[0], axis=0).max()) for b in bands)
    widest = max(float(k * b[2].max()) for b in bands)
    # tolerances are small against the mechanism: magnify the deviations (a round factor, said in the title)
    mag = 1.0
    if widest > 0 and 0.03 * extent / widest >= 2.0:  # a band narrower than 3 % of the figure
        target = 0.03 * extent / widest
        decade = 10.0 ** math.floor(math.log10(target))
        mag = max(m * decade for m in (1.0, 2.0, 5.0) if m * decade <= target)
    circle = np.stack([np.cos(t), np.sin(t)])
    for j, p in enumerate(rep.inputs.points):
        xy, cov, sn, nrm = bands[j]
        sn, cov = mag * sn, mag * mag * cov
        line, = ax.plot(xy[:, 0], xy[:, 1], lw=1.2, label=f"{p} nominal")
        c = line.get_color()
        for s in (1, -1):
            e = xy + s * k * sn[:, None] * nrm
            ax.plot(np.append(e[:, 0], e[0, 0]), np.append(e[:, 1], e[0, 1]), lw=0.7, ls="--", color=c,
                    label=f"{p} ±{k:g}σ envelope" if s == 1 else None)
        for i in np.linspace(0, len(xy), ellipses, endpoint=False).astype(int):
            w, v = np.linalg.eigh(cov[i])
            pts = v @ (k * np.sqrt(np.maximum(w, 0.0))[:, None] * circle)
            ax.fill(xy[i, 0] + pts[0], xy[i, 1] + pts[1], color=c, alpha=0.35, lw=0)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"x ({lu})")
    ax.set_ylabel(f"y ({lu})")
    ax.set_title(f"{mech.name}: first-order {k:g}σ tolerance band, ellipses at {ellipses} input positions"
                 + (f"\n(deviations magnified ×{mag:g})" if mag != 1 else ""), fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(True, lw=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def _finish(fig, axes, used: int, path, title: str, legend_cols: int | None) -> None:
    """The unused panels off, the first panel's legend below the figure (at most `legend_cols`
    columns; None: no legend), the title, and the figure written to `path` and closed
    (`plot.finish`: every text inside the figure)."""
    from .plot import finish

    for ax in axes.ravel()[used:]:
        ax.axis("off")
    legend = (*axes.ravel()[0].get_legend_handles_labels(), legend_cols) if legend_cols else None
    finish(fig, path, title=title, legend=legend)


def _input_text(mech, x: float) -> str:
    """An input value of the study (file units) as a designer names it: a crank angle reduced to
    one turn (a cycle from 19° has its last position at 19° + 359°, named 18°), a length as is."""
    lu, au = unit_names(mech)
    if mech.input_kind != "angle":
        return f"{x:.4g} {lu}"
    turn = 360.0 if au == "deg" else 2 * math.pi
    r = float(np.mod(x, turn))
    return f"{0.0 if math.isclose(r, turn, rel_tol=0, abs_tol=1e-9) else r:.4g} {au}"


def tornado_rows(mech, rep: ToleranceReport) -> list:
    """The tornado's panels: per scalar response `(title, unit, low (T,), high (T,))`, the first-order
    change of the response with each parameter alone at −t and +t (J_j · ∓t_j, t_j its half-width);
    per studied point `(title, unit, 0, c (T,))`, each parameter's share t_j ‖∂P/∂x_j‖ of the linear
    bound of the path deviation at the input where that bound is largest."""
    f = rep.first_order
    t = np.asarray(f.half_width, float)
    out = []
    for i, (name, unit, k) in enumerate(rep.labels):
        if k is None:
            out.append((name, unit, -np.asarray(f.jacobian[i]) * t, np.asarray(f.jacobian[i]) * t))
    lu = unit_names(mech)[0]
    for p in rep.inputs.points:
        rx = [i for i, (nm, _u, k) in enumerate(rep.labels) if nm == f"{p}.x" and k is not None]
        ry = [i for i, (nm, _u, k) in enumerate(rep.labels) if nm == f"{p}.y" and k is not None]
        if not rx or len(rx) != len(ry):
            continue
        c = t[None, :] * np.hypot(f.jacobian[rx], f.jacobian[ry])  # (N, T)
        k = int(np.argmax(c.sum(axis=1)))
        out.append((f"deviation({p}) at {_input_text(mech, rep.input_values[rep.labels[rx[k]][2]])}", lu,
                    np.zeros(len(t)), c[k]))
    return out


def plot_tornado(path, mech, rep: ToleranceReport) -> bool:
    """tornado.png: one panel per scalar response and studied point (`tornado_rows`), the
    parameters sorted by their effect, the largest on top; False (nothing drawn) without rows."""
    rows = tornado_rows(mech, rep)
    if not rows or not len(rep.parameters):
        return False
    from .plot import pyplot

    plt = pyplot()
    T = len(rep.parameters)
    cols = min(2, len(rows))
    nr = -(-len(rows) // cols)
    fig, axes = plt.subplots(nr, cols, figsize=(5.6 * cols, 0.9 + 0.32 * T * nr + 0.6 * nr), squeeze=False)
    for ax, (title, unit, lo, hi) in zip(axes.ravel(), rows):
        order = np.argsort(np.maximum(np.abs(lo), np.abs(hi)))  # the largest last: on top
        y = np.arange(T)
        if np.any(lo != 0):
            ax.barh(y, lo[order], color="tab:blue", label="parameter at −t")
            ax.barh(y, hi[order], color="tab:orange", label="parameter at +t")
        else:  # a point: each parameter's share of the deviation bound
            ax.barh(y, hi[order], color="0.5")
        ax.set_yticks(y)
        ax.set_yticklabels([rep.parameters[j] for j in order], fontsize=8)
        ax.axvline(0, color="k", lw=0.8)
        ax.set_xlabel(f"change ({unit})" if np.any(lo != 0) else f"share of the deviation bound ({unit})")
        ax.set_title(title, fontsize=9)
        ax.grid(True, axis="x", lw=0.3)
    _finish(fig, axes, len(rows), path, f"{mech.name}: first-order effect of each tolerance (±t, one at a time)",
            2 if any(np.any(r[2] != 0) for r in rows) else None)
    return True


def plot_histograms(path, mech, rep: ToleranceReport, *, bins: int = 64) -> bool:
    """histograms.png: the Monte Carlo distribution of every scalar response (its streamed
    histogram, `MonteCarlo.histogram`, merged into `bins` bars), the nominal, the first-order
    normal density (σ_RSS), and the specification limits of `[study] limits` with the percent out
    of spec and Cpk; False (nothing drawn) without Monte Carlo or scalar responses."""
    mc = rep.monte_carlo
    if mc is None or mc.histogram is None or not mc.feasible:
        return False
    scalar = [i for i, (_n, _u, k) in enumerate(rep.labels) if k is None]
    hist, width = np.asarray(mc.histogram), np.asarray(mc.histogram_width, float)
    from .plot import pyplot

    plt = pyplot()
    cols = min(3, len(scalar))
    nr = -(-len(scalar) // cols)
    fig, axes = plt.subplots(nr, cols, figsize=(4.8 * cols, 3.5 * nr), squeeze=False)
    limits = {idx: (lo, hi, q) for q, (_nm, lo, hi, idx) in enumerate(mc.limits)}
    for s, (ax, i) in enumerate(zip(axes.ravel(), scalar)):
        name, unit, _k = rep.labels[i]
        inner = hist[s, 1:-1]  # equal bins over [−w, w]
        group = max(1, len(inner) // bins)
        kept = len(inner) // group * group  # whole groups (the rest, if any, is left out of the plot)
        counts = inner[:kept].reshape(-1, group).sum(axis=1)
        edges = rep.nominal[i] - width[s] + (2 * width[s] / len(inner)) * np.arange(0, kept + 1, group)
        dens = counts / max(mc.feasible, 1) / np.diff(edges)
        ax.stairs(dens, edges, fill=True, alpha=0.6, label=f"Monte Carlo ({mc.feasible} feasible)")
        sig = float(rep.first_order.sigma_rss[i])
        if sig > 0:
            xs = np.linspace(edges[0], edges[-1], 400)
            ax.plot(xs, np.exp(-0.5 * ((xs - rep.nominal[i]) / sig) ** 2) / (sig * math.sqrt(2 * math.pi)),
                    color="k", lw=1, label="first order (normal, σ_RSS)")
        ax.axvline(rep.nominal[i], color="k", ls=":", lw=1, label="nominal")
        note = ""
        if i in limits:
            lo, hi, q = limits[i]
            for v in (lo, hi):
                if np.isfinite(v):
                    ax.axvline(v, color="tab:red", lw=1.5)
            note = f"\n{mc.percent_out[q]:.3g} % out of spec, Cpk {mc.cpk[q]:.3g}"
        outside = int(hist[s, 0] + hist[s, -1] + inner[kept:].sum())
        if outside:
            note += f"\n{outside} samples beyond the plotted range"
        ax.set_title(name + note, fontsize=9)
        ax.set_xlabel(unit)
        ax.set_ylabel(f"density (1/{unit})")
    _finish(fig, axes, len(scalar), path,
            f"{mech.name}: Monte Carlo of {mc.samples} samples (red: the specification limits)", 3)
    return True


def draw_plots(d: pathlib.Path, mech, rep: ToleranceReport) -> list:
    """The study's plots into folder `d`: tolerance.png (where there are points), tornado.png
    (`plot_tornado`), histograms.png (with Monte Carlo and scalar responses, `plot_histograms`);
    their paths. `mech` needs only its names (`study_files.MechanismNames`)."""
    files = []
    if rep.inputs.points:
        files.append(d / "tolerance.png")
        plot_band(files[-1], mech, rep)
    if plot_tornado(d / "tornado.png", mech, rep):
        files.append(d / "tornado.png")
    if plot_histograms(d / "histograms.png", mech, rep):
        files.append(d / "histograms.png")
    return files


def write_all(out_dir, mech, rep: ToleranceReport, *, wall_time: float, plot: bool = True,
              extra: dict | None = None) -> list:
    """Write tolerance.csv, importance.csv, tolerance.png (when there are points), study.npz and
    study.json into `out_dir` (created); returns the paths written. `extra`: more manifest keys
    (the command line's options, the chunk)."""
    from .study_files import write_archive

    d = pathlib.Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    files = [d / "tolerance.csv", d / "importance.csv"]
    write_tolerance_csv(files[0], mech, rep)
    write_importance_csv(files[1], mech, rep)
    if plot:
        files += draw_plots(d, mech, rep)
    files += [d / "study.npz", d / "study.json"]
    data = manifest(mech, rep, wall_time=wall_time, files=[f.name for f in files])
    mc = rep.monte_carlo
    data["sizes"] = {"parameters": len(rep.parameters), "positions": rep.inputs.positions,
                     "responses": len(rep.labels), "monte_carlo_samples": 0 if mc is None else mc.samples}
    data.update(extra or {})
    write_archive(d, mech, rep, data)
    files[-1].write_text(json.dumps(data, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    return [str(f) for f in files]
