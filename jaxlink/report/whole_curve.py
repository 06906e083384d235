"""The whole closed curve (`jaxlink.analysis.whole_curve`) as the `kinematics --whole-curve`
command writes it: a CSV (one row per position along the curve, its segment and every column with
its unit), a summary of the segments, and a picture of the points' closed paths."""

from __future__ import annotations

import csv
import sys

import numpy as np

from .units import FileUnits, convert


def table(mech, wc) -> tuple[list, np.ndarray]:
    """(columns, data) of the curve, SI (the input in degrees for an angle, as the kinematics CSV):
    `segment`, `input_deg`, every unknown, every point's x and y."""
    cols = ["segment", "input_deg"]
    data = [wc.segment.astype(float), np.rad2deg(wc.input)]
    for j, (n, k) in enumerate(zip(mech.unknown_names, mech.unknown_kinds)):
        cols.append(f"{n}_{'rad' if k == 'angle' else 'm'}")
        data.append(wc.q[:, j])
    for i, pn in enumerate(mech.point_names):
        cols += [f"{pn}_x_m", f"{pn}_y_m"]
        data += [wc.points[:, i, 0], wc.points[:, i, 1]]
    return cols, np.stack(data, axis=1)


def write_csv(out: str, mech, wc, units: FileUnits | None = None) -> None:
    """The curve as CSV to `out` (a path or `-`), exact numbers (shortest round trip)."""
    cols, data = table(mech, wc)
    cols, data = convert(cols, data, units)
    fh = sys.stdout if out == "-" else open(out, "w", newline="")
    try:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(cols)
        for row in data:
            w.writerow([str(int(row[0])), *(repr(float(x)) for x in row[1:])])
    finally:
        if fh is not sys.stdout:
            fh.close()


def summary(mech, wc) -> list:
    """One line per segment: where the input runs and on which sides the dyads are."""
    deg = mech.units.angle != 1.0

    def ang(x):
        return f"{np.degrees(x):.10g}°" if deg else f"{x:.10g} rad"

    if wc.full_turn:
        head = f"whole curve {mech.input_name} turns fully: one segment, a full turn ({len(wc.input)} positions)"
    else:
        head = (f"whole curve {len(wc.segments)} segments, the input turning back at its limit positions "
                f"({len(wc.input)} positions)")
    out = [head]
    for i, (a, b, sigma) in enumerate(wc.segments):
        sides = " ".join("+" if s > 0 else "−" for s in sigma)
        out.append(f"            segment {i}: {mech.input_name} from {ang(a)} to {ang(b)}, dyad sides {sides}")
    return out


def plot(path: str, mech, wc) -> None:
    """The points' closed paths, one colour per segment, the limit positions marked."""
    from .plot import length_unit, pyplot

    plt = pyplot()
    scale, lu = length_unit(mech)  # file units per metre
    fig, ax = plt.subplots(figsize=(7, 6))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k in range(len(wc.segments)):
        sel = wc.segment == k
        for i, pn in enumerate(mech.point_names):
            ax.plot(wc.points[sel, i, 0] * scale, wc.points[sel, i, 1] * scale, color=colors[k % len(colors)],
                    ls=("-", "--", ":", "-.")[i % 4], lw=1.5, label=f"{pn}, segment {k}")
            ax.plot(wc.points[sel, i, 0][-1:] * scale, wc.points[sel, i, 1][-1:] * scale, "o",
                    color=colors[k % len(colors)], ms=4)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"x ({lu})")
    ax.set_ylabel(f"y ({lu})")
    ax.grid(True, alpha=0.3)
    ax.set_title(f"{mech.name}: the whole curve ({len(wc.segments)} segment{'s' if len(wc.segments) > 1 else ''})")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
