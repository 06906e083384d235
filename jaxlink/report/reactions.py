"""Tables, CSV and plots of the joint reactions and the driving torque (`jaxlink reactions`).

CSV columns: `input_deg`; for each joint J (file order) `J_Fx_N`, `J_Fy_N`, the force on the
joint's second listed body from its first; `drive_torque_N_m`, the torque the drive applies to the
input body (counter-clockwise positive). Rows where the kinematics did not converge or the
kinetostatic system is singular hold `nan`.
"""

from __future__ import annotations

import csv
import dataclasses

import numpy as np


@dataclasses.dataclass
class ReactionsTable:
    """One row per input position; `columns` name the columns of `data` (units in the names)."""

    columns: list
    data: np.ndarray  # (N, 2 J + 2)
    ok: np.ndarray  # (N,) bool
    result: np.ndarray  # (N,) RESULTS codes
    joint_names: tuple
    omega: float

    def column(self, name: str) -> np.ndarray:
        return self.data[:, self.columns.index(name)]

    def magnitudes(self) -> np.ndarray:
        """(N, J) |F| of each joint, N."""
        f = self.data[:, 1:-1].reshape(len(self.data), -1, 2)
        return np.hypot(f[..., 0], f[..., 1])


def reactions_table(mech, phis, *, omega: float, p=None, dtype=np.float64, degrees=None) -> ReactionsTable:
    """Solve positions at `phis` (rad) and the reactions at input speed `omega` (rad/s). `degrees`:
    the input angles as given (the `input_deg` column; default `phis` converted)."""
    from ..analysis.kinetostatics import rigidity_errors, solve_reactions
    from ..errors import MechanismError
    from ..model import bodies as _bodies
    from ..results import RESULTS

    mdl = _bodies.model(mech)
    p = np.asarray(mech.parameters if p is None else p, dtype=dtype)
    sol, r = solve_reactions(mech, np.asarray(phis, dtype=dtype), p, omega=omega)
    conv = np.asarray(sol.converged)
    if conv.sum() >= 2:
        errors = rigidity_errors(mech, np.asarray(sol.q)[conv], np.asarray(phis)[conv], p)
        if errors:
            raise MechanismError("the bodies do not move rigidly with the kinematics: " + "; ".join(errors),
                                 file=mech.file, key="bodies")
    res = np.asarray(r.result)
    ok = res == RESULTS.converged
    force = np.where(ok[:, None, None], np.asarray(r.force, dtype=float), np.nan)
    torque = np.where(ok, np.asarray(r.torque, dtype=float), np.nan)
    cols = ["input_deg"]
    data = [np.rad2deg(np.asarray(phis, dtype=float)) if degrees is None else np.asarray(degrees, dtype=float)]
    for k, name in enumerate(mdl.joint_names):
        cols += [f"{name}_Fx_N", f"{name}_Fy_N"]
        data += [force[:, k, 0], force[:, k, 1]]
    cols.append("drive_torque_N_m")
    data.append(torque)
    return ReactionsTable(cols, np.stack(data, axis=1), ok, res, mdl.joint_names, float(omega))


def write_csv(path: str, table: ReactionsTable) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(table.columns)
        for row in table.data:
            w.writerow(["nan" if np.isnan(x) else repr(float(x)) for x in row])


def print_summary(table: ReactionsTable, out) -> None:
    n = len(table.data)
    out.write(f"{n} positions, {int(table.ok.sum())} solved, ω = {table.omega:g} rad/s\n")
    if not table.ok.any():
        return
    mags = table.magnitudes()
    ang = table.data[:, 0]
    width = max(len(j) for j in table.joint_names + ("drive torque",))
    out.write(f"{'joint':<{width}}  {'max |F| (N)':>14} {'at input (deg)':>15}\n")
    for k, name in enumerate(table.joint_names):
        i = int(np.nanargmax(mags[:, k]))
        out.write(f"{name:<{width}}  {mags[i, k]:14.6g} {ang[i]:15.6g}\n")
    t = table.column("drive_torque_N_m")
    i = int(np.nanargmax(np.abs(t)))
    out.write(f"{'drive torque':<{width}}  {t[i]:14.6g} {ang[i]:15.6g}   (N·m, largest |τ|)\n")
    out.write("(use --csv OUT to write every row)\n")


def plot(path: str, mech, table: ReactionsTable) -> None:
    """Reaction magnitudes over the input angle (as in the feed-mechanism thesis, Fig. 15.1) and the drive torque."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ang = table.data[:, 0]
    mags = table.magnitudes()
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 7), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    styles = ("-", "--", "-.", ":")  # two-force members give equal curves: keep them visible
    for k, name in enumerate(table.joint_names):
        ax.plot(ang, mags[:, k], styles[k % 4], label=name, lw=1.6)
    ax.set_ylabel("reaction |F| (N)")
    ax.set_title(f"{mech.name}: joint reactions, ω = {table.omega:g} rad/s")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncol=2)
    ax2.plot(ang, table.column("drive_torque_N_m"), color="k")
    ax2.set_ylabel("drive torque (N·m)")
    ax2.set_xlabel("input angle (deg)")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
