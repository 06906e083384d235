"""The plot of Dakota's parameter studies (`jaxlink.study.parameter_study`: `vector`, `list`,
`centered`), one panel per scalar response, drawn from the `SampleReport` alone (so `--replot`
redraws it). Computes nothing.

- `vector.png`: each response against the step k = 0 … n along the line from the file's design
  (k = 0) to the final design (k = n), the parameters' start and final values in the title;
- `centered.png`: each response against the offset i = −k … k of one parameter at a time (one
  line per parameter, its step Δ in the legend; i = 0 is the file's design, shared by all lines);
- `list.png`: each response against the design's row (1 … n).

A design that does not assemble over its cycle has no response: its place is left empty and
marked by a grey band (vector, list) or a cross on the axis (centered), never drawn as 0.
"""

from __future__ import annotations

import numpy as np

from ..study.sampling import SampleReport


def centered_offsets(rep: SampleReport) -> tuple[int, list]:
    """(k, rows): the study's steps k and, per parameter, the rows of its designs in the order of the
    offsets −k … −1, 0, 1 … k (row 0, the file's design, at offset 0)."""
    n, T = rep.values.shape
    k = (n - 1) // (2 * max(T, 1))
    rows = []
    for j in range(T):
        first = 1 + 2 * k * j
        rows.append(list(range(first, first + k)) + [0] + list(range(first + k, first + 2 * k)))
    return k, rows


def plot_parameter_study(path, mech, rep: SampleReport) -> bool:
    """Draw the plot of a vector, list or centered study (module doc) into `path`; False (nothing
    drawn) for another method or a study without scalar responses."""
    method = rep.inputs.method
    if method not in ("vector", "list", "centered") or not rep.labels or not len(rep.values):
        return False
    from .plot import pyplot

    plt = pyplot()
    S = len(rep.labels)
    cols = min(3, S)
    rows_ = -(-S // cols)
    fig, axes = plt.subplots(rows_, cols, figsize=(4.6 * cols, 3.4 * rows_), squeeze=False)
    ok = np.asarray(rep.feasible, bool)
    n = len(ok)
    y_all = np.where(ok[:, None], rep.responses, np.nan)
    if method == "centered":
        k, rows = centered_offsets(rep)
        x = np.arange(-k, k + 1)
        step = {p: rep.values[r[k + 1], j] - rep.values[0, j] for j, (p, r) in enumerate(zip(rep.parameters, rows))}
    else:
        x = np.arange(n) if method == "vector" else np.arange(1, n + 1)
    for s, (name, unit) in enumerate(rep.labels):
        ax = axes.ravel()[s]
        if method == "centered":
            for j, (p, r) in enumerate(zip(rep.parameters, rows)):
                y = y_all[r, s]
                (line,) = ax.plot(x, y, "o-", ms=3, label=f"{p} (Δ = {step[p]:.4g} {rep.units[j]})")
                bad = ~ok[r]
                if bad.any():  # on the axis, in the parameter's colour
                    ax.plot(x[bad], np.full(int(bad.sum()), 0.0), "x", ms=7, mew=1.5, color=line.get_color(),
                            transform=ax.get_xaxis_transform(), clip_on=False)
            ax.set_xticks(x)
            ax.axvline(0, color="0.7", lw=0.8)
            ax.set_xlabel("offset i (steps of Δ; 0: the file's design)")
        else:
            ax.plot(x, y_all[:, s], "o-", ms=3)
            for i in np.flatnonzero(~ok):
                ax.axvspan(x[i] - 0.5, x[i] + 0.5, color="0.85", lw=0)
            if n <= 12:
                ax.set_xticks(x)
            ax.set_xlabel("step k (0: the file's design)" if method == "vector" else "design (row of the list)")
        ax.set_ylabel(unit)
        ax.set_title(name, fontsize=9)
    handles, labels = axes.ravel()[0].get_legend_handles_labels()
    if method == "centered" and handles:
        fig.legend(handles, labels, loc="lower center", ncol=min(4, len(labels)), fontsize=8)
    for ax in axes.ravel()[S:]:
        ax.axis("off")
    bad = int((~ok).sum())
    note = f"; {bad} do not assemble ({'crosses' if method == 'centered' else 'grey'})" if bad else ""
    if method == "vector":
        ends = ", ".join(f"{p} {rep.values[0, j]:.4g} → {rep.values[-1, j]:.4g} {rep.units[j]}"
                         for j, p in enumerate(rep.parameters))
        title = f"{mech.name}: vector study, {n} designs ({ends}){note}"
    elif method == "centered":
        title = f"{mech.name}: centered study, {n} designs, one parameter at a time{note}"
    else:
        title = f"{mech.name}: list study, {n} designs ({', '.join(rep.parameters)}){note}"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0.06 if method == "centered" else 0, 1, 0.95))
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return True
