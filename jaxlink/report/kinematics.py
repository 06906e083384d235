"""Tables, CSV files, plots and animations of solved kinematics (the command line's output)."""

from __future__ import annotations

import csv
import dataclasses
from typing import TextIO

import jax
import jax.numpy as jnp
import numpy as np

from ..files import expr as _expr
from ..solvers.assemble import solve
from ..analysis.transfer import time_derivatives, transfer
from ..model.mechanism import Mechanism
from ..results import RESULTS


@dataclasses.dataclass
class KinematicsTable:
    """One row per input position; `columns` name the columns of `data` (units in the names)."""

    columns: list
    data: np.ndarray
    converged: np.ndarray
    result: np.ndarray
    inputs: np.ndarray  # SI
    q: np.ndarray
    points: np.ndarray  # (N, n_points, 2)
    velocities: np.ndarray | None
    accelerations: np.ndarray | None
    omega: float
    parameters: np.ndarray

    def column(self, name: str) -> np.ndarray:
        return self.data[:, self.columns.index(name)]


def kinematics_table(mech: Mechanism, phis, *, omega: float = 1.0, order: int = 2, p=None,
                     dtype=np.float64) -> KinematicsTable:
    """Solve positions at `phis` (SI) and, up to `order`, point velocities/accelerations at ω."""
    p = np.asarray(mech.parameters if p is None else p, dtype=dtype)
    sol = solve(mech, np.asarray(phis, dtype=dtype), jnp.asarray(p))
    tr = transfer(mech, jnp.asarray(phis, dtype=dtype), sol.q, jnp.asarray(p), order=order)
    _, _, v, a = time_derivatives(tr, omega)
    conv = np.asarray(sol.converged)
    # the residual at the returned q (the solver reports the one before its last correction)
    resid = jax.jit(jax.vmap(lambda qq, ph: jnp.max(jnp.abs(mech.residual(qq, ph, jnp.asarray(p))))))(
        sol.q, jnp.asarray(phis, dtype=dtype))
    q = np.asarray(sol.q, dtype=float)
    pts = np.asarray(tr.points, dtype=float)
    v = None if v is None else np.where(conv[:, None, None], np.asarray(v, dtype=float), np.nan)
    a = None if a is None else np.where(conv[:, None, None], np.asarray(a, dtype=float), np.nan)

    if mech.input_kind == "angle":
        cols, data = ["input_deg"], [np.rad2deg(np.asarray(phis, dtype=float))]
    else:
        cols, data = ["input_m"], [np.asarray(phis, dtype=float)]
    for j, (n, k) in enumerate(zip(mech.unknown_names, mech.unknown_kinds)):
        cols.append(f"{n}_rad" if k == "angle" else f"{n}_m")
        data.append(q[:, j])
    for i, pn in enumerate(mech.point_names):
        cols += [f"{pn}_x_m", f"{pn}_y_m"]
        data += [pts[:, i, 0], pts[:, i, 1]]
        if v is not None:
            cols += [f"{pn}_vx_m_s", f"{pn}_vy_m_s"]
            data += [v[:, i, 0], v[:, i, 1]]
        if a is not None:
            cols += [f"{pn}_ax_m_s2", f"{pn}_ay_m_s2"]
            data += [a[:, i, 0], a[:, i, 1]]
    cols += ["converged", "residual_m"]
    data += [conv.astype(float), np.asarray(resid, dtype=float)]
    return KinematicsTable(cols, np.stack(data, axis=1), conv, np.asarray(sol.result), np.asarray(phis),
                           q, pts, v, a, omega, p)


def write_csv(path: str, table: KinematicsTable) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(table.columns)
        for row in table.data:
            out = []
            for name, x in zip(table.columns, row):
                if name == "converged":
                    out.append(str(int(x)))
                elif np.isnan(x):
                    out.append("nan")
                else:
                    out.append(repr(float(x)))
            w.writerow(out)


def failure_summary(table: KinematicsTable) -> str:
    codes, counts = np.unique(table.result[~table.converged], return_counts=True)
    parts = []
    for c, n in zip(codes, counts):
        where = table.column(table.columns[0])[table.result == c]
        parts.append(f"{n} × {RESULTS.names[int(c)]} (first at {table.columns[0]} = {where[0]:g}): "
                     f"{RESULTS.messages[int(c)]}")
    return "; ".join(parts)


def print_summary(table: KinematicsTable, out: TextIO, every_row_hint: bool = True) -> None:
    n = len(table.data)
    speed = f" at ω = {table.omega:g} rad/s" if table.velocities is not None else ""
    out.write(f"{n} positions{speed}, {int(table.converged.sum())} converged, "
              f"max residual {np.nanmax(table.column('residual_m')):.2e} m\n")
    width = max(len(c) for c in table.columns)
    out.write(f"{'column':<{width}}  {'min':>14} {'max':>14}\n")
    for j, c in enumerate(table.columns[:-2]):
        col = table.data[:, j]
        out.write(f"{c:<{width}}  {np.nanmin(col):14.6g} {np.nanmax(col):14.6g}\n")
    if every_row_hint:
        out.write("(use --csv OUT to write every row)\n")


# ----------------------------------------------------------------------------- drawing


def chains(mech: Mechanism, q, phis, p):
    """Polylines of every loop and point sum (partial sums of their vectors), shape
    (N, n_chains, max_len + 1, 2), per chain the number of vertices and its name. A loop's
    polyline starts at the origin and closes on itself; its vertices are the joints."""
    groups = list(mech.loops) + list(mech.points)
    max_len = max(len(t) for _, t in groups)

    def one(qk, phik):
        env = mech.env(qk, phik, jnp.asarray(p))
        out = []
        for _, terms in groups:
            pts = [jnp.zeros(2, dtype=qk.dtype)]
            for term in terms:
                x, y = mech.term_vector(term, env)
                pts.append(pts[-1] + jnp.stack([jnp.asarray(x, qk.dtype), jnp.asarray(y, qk.dtype)]))
            pts += [pts[-1]] * (max_len + 1 - len(pts))
            out.append(jnp.stack(pts))
        return jnp.stack(out)

    arr = jax.jit(jax.vmap(one))(jnp.asarray(q), jnp.asarray(phis, dtype=jnp.asarray(q).dtype))
    return np.asarray(arr), [len(t) + 1 for _, t in groups], [n for n, _ in groups]


def ground_terms(mech: Mechanism):
    """Per loop, per term: True when the vector is fixed (no input, no unknown): a frame vector."""
    moving = set(mech.unknown_names) | {mech.input_name}
    return [[not any(n.name in moving for node in t.nodes() for n in _expr.names_in(node)) for t in terms]
            for _, terms in mech.loops]


def _draw_linkage(ax, mech, ch, lens, k, color="0.45"):
    """The linkage at position k: moving links solid with joints, frame vectors dashed, and thin
    lines from the last joint of each point's chain to the point."""
    ground = ground_terms(mech)
    for c in range(len(mech.loops)):
        poly = ch[k, c, : lens[c]]
        for j, fixed in enumerate(ground[c]):
            seg = poly[j: j + 2]
            if fixed:
                ax.plot(seg[:, 0], seg[:, 1], "--", color="0.7", lw=1.0)
            else:
                ax.plot(seg[:, 0], seg[:, 1], "-o", color=color, lw=1.6, ms=3)
    for i in range(len(mech.points)):
        c = len(mech.loops) + i
        poly = ch[k, c, : lens[c]]
        ax.plot(poly[-2:, 0], poly[-2:, 1], "-", color=color, lw=0.8)
        ax.plot(poly[-1, 0], poly[-1, 1], "s", color=f"C{i}", ms=5)


def plot_kinematics(path: str, mech: Mechanism, table: KinematicsTable) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x_in = table.data[:, 0]
    xlabel = "input angle (deg)" if table.columns[0] == "input_deg" else "input (m)"
    npts = len(mech.point_names)
    rows = 1 + (table.velocities is not None) + (table.accelerations is not None)
    fig = plt.figure(figsize=(12, 3.2 * max(rows, 2)))
    ax_path = fig.add_subplot(1, 2, 1)
    ch, lens, _ = chains(mech, table.q, table.inputs, table.parameters)
    k0 = int(np.argmax(table.converged)) if table.converged.any() else 0
    _draw_linkage(ax_path, mech, ch * 1e3, lens, k0)
    for i, pn in enumerate(mech.point_names):
        xy = table.points[:, i] * 1e3
        ok = table.converged
        ax_path.plot(xy[ok, 0], xy[ok, 1], "-", lw=1.5, label=f"path of {pn}")
        if (~ok).any():
            ax_path.plot(xy[~ok, 0], xy[~ok, 1], "x", color="red", label=f"{pn}: not converged")
    ax_path.set_aspect("equal", adjustable="datalim")
    ax_path.set_xlabel("x (mm)")
    ax_path.set_ylabel("y (mm)")
    ax_path.set_title(f"{mech.name}: linkage at {x_in[k0]:g}° and point paths")
    ax_path.grid(alpha=0.3)
    if npts:
        ax_path.legend(fontsize=8)
    r = 0
    ax = fig.add_subplot(rows, 2, 2)
    for i, pn in enumerate(mech.point_names):
        ax.plot(x_in, table.points[:, i, 0] * 1e3, label=f"{pn} x")
        ax.plot(x_in, table.points[:, i, 1] * 1e3, "--", label=f"{pn} y")
    ax.set_ylabel("position (mm)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    for arr, lab, unit in ((table.velocities, "velocity", "m/s"), (table.accelerations, "acceleration", "m/s²")):
        if arr is None:
            continue
        r += 1
        ax = fig.add_subplot(rows, 2, 2 + 2 * r)
        for i, pn in enumerate(mech.point_names):
            ax.plot(x_in, arr[:, i, 0], label=f"{pn} {lab[0]}x")
            ax.plot(x_in, arr[:, i, 1], "--", label=f"{pn} {lab[0]}y")
            ax.plot(x_in, np.hypot(arr[:, i, 0], arr[:, i, 1]), ":", color="k", label=f"|{lab[0]}| {pn}")
        ax.set_ylabel(f"{lab} ({unit})")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    ax.set_xlabel(xlabel + (f", ω = {table.omega:g} rad/s" if rows > 1 else ""))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def animate(path: str, mech: Mechanism, table: KinematicsTable, fps: int = 15) -> None:
    """GIF of the moving linkage (loop polygons = links and joints; traced point paths)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    ch, lens, names = chains(mech, table.q, table.inputs, table.parameters)
    ch = ch * 1e3
    ok = table.converged
    allxy = ch[ok].reshape(-1, 2) if ok.any() else ch.reshape(-1, 2)
    pad = 0.05 * np.ptp(allxy, axis=0).max()
    fig, ax = plt.subplots(figsize=(6, 6))
    ax.set_xlim(allxy[:, 0].min() - pad, allxy[:, 0].max() + pad)
    ax.set_ylim(allxy[:, 1].min() - pad, allxy[:, 1].max() + pad)
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    nl = len(mech.loops)
    ground = ground_terms(mech)
    # one line per vector of every loop: moving links solid with joints, frame vectors dashed
    seg_lines = [[ax.plot([], [], "--", color="0.7", lw=1.0)[0] if fixed else ax.plot([], [], "-o", lw=2, ms=4)[0]
                  for fixed in ground[c]] for c in range(nl)]
    arm_lines = [ax.plot([], [], "-", color="0.4", lw=1.0)[0] for _ in mech.point_names]
    for i, pn in enumerate(mech.point_names):
        xy = table.points[ok, i] * 1e3
        ax.plot(xy[:, 0], xy[:, 1], ":", lw=1, color="0.5")
    point_marks = [ax.plot([], [], "s", ms=6, label=n)[0] for n in mech.point_names]
    title = ax.set_title("")
    if mech.point_names:
        ax.legend(loc="upper right", fontsize=8)

    def draw(k):
        for c in range(nl):
            poly = ch[k, c, : lens[c]]
            for j, line in enumerate(seg_lines[c]):
                line.set_data(poly[j: j + 2, 0], poly[j: j + 2, 1])
                if not ground[c][j]:
                    line.set_color("C0" if ok[k] else "red")
        for i, m in enumerate(point_marks):
            c = nl + i
            arm = ch[k, c, lens[c] - 2: lens[c]]
            arm_lines[i].set_data(arm[:, 0], arm[:, 1])
            m.set_data([table.points[k, i, 0] * 1e3], [table.points[k, i, 1] * 1e3])
        title.set_text(f"{mech.name}   {table.columns[0]} = {table.data[k, 0]:.1f}"
                       + ("" if ok[k] else "  (not converged)"))
        return [ln for row in seg_lines for ln in row] + arm_lines + point_marks + [title]

    anim = FuncAnimation(fig, draw, frames=len(table.data), blit=False)
    anim.save(path, writer=PillowWriter(fps=fps))
    plt.close(fig)
