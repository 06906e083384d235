"""Tables, CSV and plots of the joint reactions and the driving torque (`jaxlink reactions`).

CSV columns: `input_deg` (as asked for; `input_m` for a length input); for each joint J (file order)
`J_Fx_N`, `J_Fy_N`, the force on the joint's second listed body from its first; `drive_torque_N_m`,
the torque the drive applies to the input body (counter-clockwise positive), or for a length input
`drive_force_N`, the actuator's force along `[input] axis` (positive pushes towards a larger input);
`result`, the name of
the code of the row (`converged`; the position solve's code, e.g. `cannot_assemble`, where the
kinematics did not converge; `singular` where the kinetostatic system is singular). Rows that are
not `converged` hold `nan`: they are left out of the summary and are gaps in the plot. Where a
change point was located between two rows, `change_point_deg` (`_m` for a length input) comes
before `result`, as in `jaxlink kinematics` (`report/kinematics.py`); where a gap was (both rows
assembled, the linkage not between them), `gap_from_deg` and `gap_to_deg`. With `units` (`--units file`,
`report/units.py`) the CSV and the summary are in the file's units: `input_deg` (`input_rad` in a
file in radians), the forces in N, `drive_torque_N_mm` (N·cm, N·m: force × the file's length unit).
"""

from __future__ import annotations

import csv
import dataclasses
import sys

import numpy as np

from ..results import RESULTS
from . import grid as _grid
from .units import FileUnits, convert


@dataclasses.dataclass
class ReactionsTable:
    """One row per input position; `columns` name the columns of `data` (units in the names)."""

    columns: list
    data: np.ndarray  # (N, 2 J + 3); the last column is the result code
    ok: np.ndarray  # (N,) bool
    result: np.ndarray  # (N,) RESULTS codes
    joint_names: tuple
    omega: float
    input_kind: str = "angle"
    periodic: bool = False
    rpm: float | None = None
    branch_points: list = dataclasses.field(default_factory=list)
    change_points: str = "keep"

    def column(self, name: str) -> np.ndarray:
        return self.data[:, self.columns.index(name)]

    @property
    def drive_column(self) -> str:
        """`drive_torque_N_m` (an angle input) or `drive_force_N` (a length input)."""
        return "drive_torque_N_m" if self.input_kind == "angle" else "drive_force_N"

    def magnitudes(self) -> np.ndarray:
        """(N, J) |F| of each joint, N."""
        f = self.data[:, 1:1 + 2 * len(self.joint_names)].reshape(len(self.data), -1, 2)
        return np.hypot(f[..., 0], f[..., 1])

    def speed_text(self, units: FileUnits | None = None) -> str:
        unit, factor = ("rad/s" if self.input_kind == "angle" else "m/s", 1.0) if units is None \
            else units.speed(self.input_kind)
        if self.input_kind != "angle":
            return f"v = {self.omega * factor:g} {unit}"
        if self.rpm is not None:
            return f"{self.rpm:g} rpm (ω = {self.omega * factor:.4g} {unit})"
        return f"ω = {self.omega * factor:g} {unit}"


def reactions_table(mech, phis, *, omega: float, p=None, dtype=np.float64, input_values=None,
                    rpm: float | None = None, change_points: str = "keep") -> ReactionsTable:
    """Solve positions at `phis` (SI) and the reactions at input speed `omega` (rad/s). `input_values`:
    the input column as asked for (degrees for an angle input, metres for a length input; default
    `phis` converted); `rpm`: the speed as given, for the labels; `change_points`: `"keep"` or
    `"smooth"` (`NewtonOptions.change_points`). The branch points located between consecutive rows
    are in `branch_points` (`kinematics.located_branch_points`)."""
    from ..analysis.kinetostatics import rigidity_errors, solve_reactions
    from ..errors import MechanismError
    from ..model import bodies as _bodies
    from ..solvers.options import NewtonOptions
    from .kinematics import _branch_point_columns, located_branch_points

    mdl = _bodies.model(mech)
    p = np.asarray(mech.parameters if p is None else p, dtype=dtype)
    opts = None if change_points == "keep" else NewtonOptions(change_points=change_points)
    sol, r = solve_reactions(mech, np.asarray(phis, dtype=dtype), p, omega=omega, options=opts)
    conv = np.asarray(sol.converged)
    if conv.sum() >= 2:
        errors = rigidity_errors(mech, np.asarray(sol.q)[conv], np.asarray(phis)[conv], p)
        if errors:
            raise MechanismError("the bodies do not move rigidly with the kinematics: " + "; ".join(errors),
                                 file=mech.file, key="bodies")
    # the position solve's code where it did not converge (more telling than `not_assembled`)
    res = np.where(conv, np.asarray(r.result), np.asarray(sol.result)).astype(np.int8)
    ok = res == RESULTS.converged
    force = np.where(ok[:, None, None], np.asarray(r.force, dtype=float), np.nan)
    torque = np.where(ok, np.asarray(r.torque, dtype=float), np.nan)
    angle = mech.input_kind == "angle"
    if input_values is None:
        input_values = np.rad2deg(np.asarray(phis, dtype=float)) if angle else np.asarray(phis, dtype=float)
    cols = ["input_deg" if angle else "input_m"]
    data = [np.asarray(input_values, dtype=float)]
    for k, name in enumerate(mdl.joint_names):
        cols += [f"{name}_Fx_N", f"{name}_Fy_N"]
        data += [force[:, k, 0], force[:, k, 1]]
    cols += ["drive_torque_N_m" if angle else "drive_force_N"]
    data += [torque]
    located = located_branch_points(mech, np.asarray(phis, dtype=dtype), np.asarray(sol.q), np.asarray(sol.result),
                                    p, np.asarray(input_values, dtype=float))
    cols, data = _branch_point_columns(mech, located, cols, data)  # before `result`, the last column
    cols += ["result"]
    data += [res.astype(float)]
    return ReactionsTable(cols, np.stack(data, axis=1), ok, res, mdl.joint_names, float(omega), mech.input_kind,
                          _grid.full_turn(phis, mech.input_kind), rpm, located, change_points)


def write_csv(out, table: ReactionsTable, units: FileUnits | None = None) -> None:
    """The table as CSV to `out`: a path, `-` (standard output) or an open text file; `units`: in
    the file's units (default SI)."""
    if isinstance(out, str) and out != "-":
        with open(out, "w", newline="") as fh:
            _write_rows(fh, table, units)
    else:
        _write_rows(sys.stdout if out == "-" else out, table, units)


def _write_rows(fh, table: ReactionsTable, units: FileUnits | None = None) -> None:
    columns, data = convert(table.columns, table.data, units)
    w = csv.writer(fh, lineterminator="\n")
    w.writerow(columns)
    for row in data:
        out = ["nan" if np.isnan(x) else repr(float(x)) for x in row[:-1]]
        w.writerow(out + [RESULTS.name(int(row[-1]))])


def failure_summary(table: ReactionsTable) -> str:
    """`19 × cannot_assemble at 135°–225°: <what to do>` for every code other than converged."""
    return _grid.failure_text(table.result, table.data[:, 0], table.input_kind, table.periodic)


def print_summary(table: ReactionsTable, out, units: FileUnits | None = None) -> None:
    """The largest |F| of every joint and the largest |τ| (|F| of the drive force of a length
    input), with the input where they occur (an angle reduced to [0, 360°) or [0, 2π)), over the
    solved rows; `units`: the input and the torque in the file's units (default: degrees or
    metres, N·m)."""
    n = len(table.data)
    out.write(f"{n} positions, {int(table.ok.sum())} solved, {table.speed_text(units)}\n")
    if not table.ok.any():
        return
    mags = table.magnitudes()
    columns, data = convert(table.columns, table.data, units)
    ang = data[:, 0]
    angle = table.input_kind == "angle"
    in_unit = columns[0].split("_", 1)[1]  # deg, rad, m, mm, …
    at = (_grid.reduce_deg(ang) if in_unit == "deg" else np.mod(ang, 2 * np.pi)) if angle else ang
    head = f"at input ({in_unit})"
    width = max(len(j) for j in table.joint_names + ("drive torque",))
    what, unit, sym = ("drive torque", "N·m", "τ") if angle else ("drive force", "N", "F")
    out.write(f"{'joint':<{width}}  {'max |F| (N)':>14} {head:>15}\n")
    for k, name in enumerate(table.joint_names):
        i = int(np.nanargmax(mags[:, k]))
        out.write(f"{name:<{width}}  {mags[i, k]:14.6g} {at[i]:15.6g}\n")
    lu = "m" if units is None else units.length
    column = f"drive_torque_N_{lu}" if angle else table.drive_column
    t = data[:, columns.index(column)]
    i = int(np.nanargmax(np.abs(t)))
    unit = f"N·{lu}" if angle else "N"
    out.write(f"{what:<{width}}  {t[i]:14.6g} {at[i]:15.6g}   ({unit}, largest |{sym}|)\n")
    from .kinematics import branch_point_text

    for line in branch_point_text(table, table.input_kind, table.change_points, units):
        out.write(line + "\n")
    out.write("(use --csv OUT to write every row)\n")


def plot(path: str, mech, table: ReactionsTable) -> None:
    """Reaction magnitudes over the input (as in the feed-mechanism thesis, Fig. 15.1) and the drive
    torque: gaps and shaded ranges where not solved, closed over a full revolution, axes limited to
    the bulk of the values when a spike (a toggle) would flatten them (`jaxlink/report/plot.py`)."""
    from .plot import closed_curve, limit_axis, pyplot

    plt = pyplot()
    ang = table.data[:, 0]
    mags = table.magnitudes()
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(10, 7), sharex=True, gridspec_kw={"height_ratios": [2, 1]},
                                  layout="constrained")
    styles = ("-", "--", "-.", ":")  # two-force members give equal curves: keep them visible
    for k, name in enumerate(table.joint_names):
        ax.plot(*closed_curve(ang, mags[:, k], table.periodic), styles[k % 4], color=f"C{k % 10}", label=name, lw=1.6)
    ax.set_ylabel("reaction |F| (N)")
    ax.set_title(f"{mech.name}: joint reactions at {table.speed_text()}")
    angle = table.input_kind == "angle"
    torque = table.column(table.drive_column)
    ax2.plot(*closed_curve(ang, torque, table.periodic), color="k", label="drive torque" if angle else "drive force")
    ax2.set_ylabel("drive torque (N·m)" if angle else "drive force (N)")
    ax2.set_xlabel("input angle (deg)" if table.input_kind == "angle" else "input (m)")
    for a, arrays, unit in ((ax, [mags], "N"), (ax2, [torque], "N·m" if angle else "N")):
        bad = ~table.ok
        h = (ang[1] - ang[0]) if len(ang) > 1 else 1.0
        for i, (lo, hi) in enumerate(_grid.runs(bad)):
            a.axvspan(ang[lo] - h / 2, ang[hi] + h / 2, color="red", alpha=0.08, lw=0,
                      label="not solved" if i == 0 else None)
        limit_axis(a, arrays, unit)
        a.grid(alpha=0.3)
        a.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    if table.periodic:
        ax.set_xlim(ang[0], ang[0] + 360.0 * np.sign(ang[1] - ang[0]))
    fig.savefig(path, dpi=110)
    plt.close(fig)
