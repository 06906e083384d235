"""Plots and animations of a kinematics table (`jaxlink kinematics --plot / --animate`).

The linkage is drawn where `jaxlink/report/drawing.py` places it: joints as white pins with their
names, ground pivots with a ground symbol, a sketch's links as bars and its plates as shaded
polygons labelled with their names, a sketch's joints on one body as dots; a loop file's links as
bars labelled with their length, frame vectors dashed, its `[joints]` bodies of three or more
joints as shaded plates; sliders as a block on their guide line (a loop's own slider vector
dotted), each point's arm from its last joint, the input marked (an arc arrow about the crank's
pivot, or an actuator drawn as a cylinder), and the traced point paths. Lengths are shown in the
file's length unit; the titles give the input as asked for (`grid.format_input`).

Curves over the input: positions, and |v|, |a| (thick, one colour per point) with their x and y
components (thin: solid x, dashed y). Positions that did not assemble are gaps in every line and
shaded ranges; over one full revolution each curve is closed (the last position joined to the
first). An axis whose extremes lie far outside the bulk of its values (the spike of a toggle) is
limited to the bulk (the 5–95 % range widened by half its span) and says so with the true extremes.
"""

from __future__ import annotations

import numpy as np

from ..results import RESULTS
from . import grid as _grid
from .drawing import LinkageDrawing, drawing
from .units import file_units

UNITS = {1.0: "m", 1e-2: "cm", 1e-3: "mm"}


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def wrapped(fig, text: str, fontsize: float, width: float = 0.96) -> str:
    """`text` broken at spaces into lines that each fit in `width` of the figure's width when drawn
    at `fontsize` (measured with the figure's renderer, not guessed from a character count)."""
    r = fig.canvas.get_renderer()
    limit = width * fig.bbox.width
    probe = fig.text(0, 0, "", fontsize=fontsize)
    lines: list[str] = []
    for para in text.split("\n"):
        line = ""
        for word in para.split(" "):
            trial = f"{line} {word}" if line else word
            probe.set_text(trial)
            if line and probe.get_window_extent(r).width > limit:
                lines.append(line)
                line = word
            else:
                line = trial
        lines.append(line)
    probe.remove()
    return "\n".join(lines)


def legend_below(fig, handles, labels, ncol: int, fontsize: float = 8):
    """A figure legend centred below the panels, in at most `ncol` columns and as few fewer as it
    takes to fit in the figure's width; the legend (None without handles)."""
    if not handles:
        return None
    r = fig.canvas.get_renderer()
    for n in range(max(1, min(ncol, len(labels))), 0, -1):
        leg = fig.legend(handles, labels, loc="lower center", ncol=n, fontsize=fontsize, frameon=False)
        if n == 1 or leg.get_window_extent(r).width <= 0.98 * fig.bbox.width:
            return leg
        leg.remove()
    return None


def finish(fig, path, *, title: str | None = None, legend=None, title_size: float = 10, dpi: int = 120) -> None:
    """Lay out and write a figure of panels: the title wrapped to the figure's width above the
    panels, `legend` = (handles, labels, columns) centred below them (`legend_below`), the panels
    fitted between the two (`tight_layout` with the measured heights of title and legend), then
    the figure written to `path` at `dpi` and closed. Every text stays inside the figure."""
    r = fig.canvas.get_renderer()
    H = fig.bbox.height
    if title:  # tight_layout leaves room for it
        fig.suptitle(wrapped(fig, title, title_size), fontsize=title_size)
    bottom = 0.0
    if legend is not None:
        leg = legend_below(fig, *legend)
        if leg is not None:
            bottom = (leg.get_window_extent(r).height + 4) / H
    fig.tight_layout(rect=(0, bottom, 1, 1))
    fig.savefig(path, dpi=dpi)
    pyplot().close(fig)


def length_unit(mech) -> tuple:
    """(factor from metres to the file's length unit, its name)."""
    u = float(mech.units.length)
    name = UNITS.get(u)
    return (1.0 / u, name) if name else (1e3, "mm")


def linkage_drawing(mech, table) -> LinkageDrawing:
    """The placed linkage of a kinematics table (positions where it assembled)."""
    return drawing(mech, table.q, table.inputs, table.parameters, table.assembled)


class LinkageArtist:
    """The matplotlib artists of a linkage drawing on `ax`, scaled by `scale` (metres → shown
    unit); `update(k)` shows position k (nothing where it did not assemble). The joint circles are
    one line (`joint_marks`, gid "joints"), the ground symbols sit at `ground_xy` (shown unit)."""

    def __init__(self, ax, d: LinkageDrawing, scale: float, color: str = "0.25", labels: bool = True):
        from matplotlib.patches import Polygon

        self.d, self.s, self.ax = d, scale, ax
        size = d.extent * scale
        self.size = size
        self.segments = []
        for kinds in d.kinds:
            row = []
            for kind in kinds:
                if kind == "link":
                    ln, = ax.plot([], [], "-", color=color, lw=2.4, solid_capstyle="round", zorder=3)
                elif kind == "frame":
                    ln, = ax.plot([], [], "--", color="0.6", lw=1.0, zorder=2)
                elif kind == "slider":  # the loop's vector of a slider: a construction line
                    ln, = ax.plot([], [], ":", color="0.6", lw=0.9, zorder=2)
                else:
                    ln, = ax.plot([], [], "-", color="0.5", lw=1.0, zorder=2)
                row.append(ln)
            self.segments.append(row)
        # the bodies of a sketch (bars, plates), the plates of a loop file's [joints]
        self.bodies = []
        for b in d.bodies:
            if b.plate:
                self.bodies.append(ax.add_patch(Polygon(
                    np.zeros((len(b.joints), 2)), closed=True, facecolor=(0.79, 0.85, 0.92, 0.6), edgecolor=color,
                    lw=2.0, joinstyle="round", zorder=2.5)))
            else:
                self.bodies.append(ax.plot([], [], "-", color=color, lw=2.6, solid_capstyle="round", zorder=3)[0])
        self.marks = ax.plot([], [], "o", ms=3.5, color=color, zorder=5)[0]
        self.drive_lines: list = []
        if d.drive is not None and d.drive.kind == "actuator":  # a cylinder: its barrel, its rod
            self.drive_lines = [ax.plot([], [], "-", color="0.6", lw=8.0, solid_capstyle="butt", zorder=3)[0],
                                ax.plot([], [], "-", color=color, lw=2.4, solid_capstyle="round", zorder=3.5)[0]]
            lengths = np.linalg.norm(d.drive.ends[:, 1] - d.drive.ends[:, 0], axis=-1)
            self.barrel = 0.6 * float(np.nanmin(lengths[d.shown])) if d.shown.any() else 0.0
            self.drive_lines.append(ax.annotate("input", (0, 0), xytext=(0, 0), textcoords="offset points",
                                                fontsize=7, color="C3", ha="center", va="center", zorder=7))
        self.arms = [ax.plot([], [], "-", color=color, lw=1.2, alpha=0.8, zorder=3)[0] for _ in d.arms]
        self.guides = [ax.plot([], [], "-", color="0.55", lw=4.0, alpha=0.45, solid_capstyle="butt", zorder=1)[0]
                       for _ in d.sliders]
        self.blocks = [ax.add_patch(Polygon(np.zeros((4, 2)), closed=True, facecolor="0.85", edgecolor=color,
                                            lw=1.4, zorder=4)) for _ in d.sliders]
        # ground pivots do not move: their symbols are drawn once, at the first shown position
        rows = np.flatnonzero(d.shown)
        k0 = int(rows[0]) if rows.size else 0
        self.ground_xy = d.joints[k0, d.ground] * scale if d.joints.size else np.zeros((0, 2))
        g = 0.035 * size
        for x, y in self.ground_xy:
            ax.add_patch(Polygon([[x, y], [x - g, y - 1.5 * g], [x + g, y - 1.5 * g]], closed=True,
                                 facecolor="0.8", edgecolor="0.3", lw=1.0, zorder=2.7))
            ax.plot([x - 1.5 * g, x + 1.5 * g], [y - 1.5 * g] * 2, "-", color="0.3", lw=1.4, zorder=2.7)
            for t in np.linspace(-1.2, 1.2, 5):
                ax.plot([x + t * g, x + (t - 0.4) * g], [y - 1.5 * g, y - 2.0 * g], "-", color="0.3", lw=0.8,
                        zorder=2.7)
        if d.drive is not None and d.drive.kind == "crank" and d.shown.any():
            self._crank_arrow(ax, d.drive, k0, scale, 0.08 * size)
        self.joint_marks, = ax.plot([], [], "o", ms=5.5, mfc="white", mec=color, mew=1.4, zorder=5, gid="joints")
        # a point at a joint: its colour behind the pin; elsewhere a square
        self.point_marks = [ax.plot([], [], "s", color=f"C{i}", ms=8 if n in d.joint_names else 6,
                                    zorder=4.9 if n in d.joint_names else 6)[0] for i, n in enumerate(d.point_names)]
        self.labels = []
        self.link_labels = []
        if labels:
            seen = set()  # a link in two loops is labelled once
            for kinds, texts in zip(d.kinds, d.labels):
                row = []
                for kind, t in zip(kinds, texts):
                    row.append(ax.annotate(t, (0, 0), xytext=(0, 0), textcoords="offset points", fontsize=7,
                                           color="0.45", style="italic", ha="center", va="center", zorder=7)
                               if kind == "link" and t not in seen else None)
                    seen.add(t)
                self.link_labels.append(row)
            self.labels = [ax.annotate(n, (0, 0), xytext=(5, 5), textcoords="offset points", fontsize=8,
                                       color="0.15", zorder=7) for n in d.joint_names]
            taken = set(d.joint_names)
            self.body_labels = [ax.annotate(b.name, (0, 0), xytext=(0, 0), textcoords="offset points", fontsize=7.5,
                                            color="0.35", style="italic", ha="center", va="center", zorder=7)
                                for b in d.bodies]
            self.mark_labels = [None if n in d.point_names else
                                ax.annotate(n, (0, 0), xytext=(4, 4), textcoords="offset points", fontsize=8,
                                            color="0.15", zorder=7) for n in d.mark_names]
            self.point_labels = [None if n in taken else
                                 ax.annotate(n, (0, 0), xytext=(5, -11), textcoords="offset points", fontsize=8,
                                             color=f"C{i}", fontweight="bold", zorder=7)
                                 for i, n in enumerate(d.point_names)]
        else:
            self.point_labels = [None] * len(d.point_names)
            self.body_labels, self.mark_labels = [], []

    @staticmethod
    def _crank_arrow(ax, drive, k0: int, scale: float, radius: float) -> None:
        """The input's mark: an arc arrow about the crank's pivot in the input's sense of turning."""
        cx, cy = drive.ends[k0, 0] * scale
        a = np.deg2rad(np.linspace(150.0, 240.0, 24))[:: int(drive.sense) or 1]
        x, y = cx + radius * np.cos(a), cy + radius * np.sin(a)
        ax.plot(x[:-1], y[:-1], "-", color="C3", lw=1.3, zorder=4)
        ax.annotate("", xy=(x[-1], y[-1]), xytext=(x[-3], y[-3]), zorder=4,
                    arrowprops=dict(arrowstyle="-|>", color="C3", lw=1.3, mutation_scale=10))
        ax.annotate("input", (cx - radius, cy), xytext=(-4, 0), textcoords="offset points", fontsize=7,
                    color="C3", ha="right", va="center", zorder=7)

    def bounds(self) -> tuple:
        """(xmin, xmax, ymin, ymax) of everything drawn over all shown positions, padded."""
        d, shown = self.d, self.d.shown
        pieces = [v[shown].reshape(-1, 2) for v in d.loops] + [d.points[shown].reshape(-1, 2)]
        pieces += [a[shown].reshape(-1, 2) for a in d.arms] + [sl.guide[shown].reshape(-1, 2) for sl in d.sliders]
        pieces += [b.outline[shown].reshape(-1, 2) for b in d.bodies] + [d.joints[shown].reshape(-1, 2)]
        xy = np.concatenate(pieces) * self.s if shown.any() else np.zeros((1, 2))
        xy = xy[np.isfinite(xy).all(axis=1)]
        if not xy.size:
            xy = np.zeros((1, 2))
        pad = 0.06 * max(float(np.ptp(xy, axis=0).max()), 1e-12)
        ground = 0.035 * self.size * 2.2 if self.ground_xy.size else 0.0
        return (xy[:, 0].min() - pad, xy[:, 0].max() + pad, xy[:, 1].min() - max(pad, ground),
                xy[:, 1].max() + pad)

    def artists(self) -> list:
        out = [ln for row in self.segments for ln in row] + self.bodies + self.drive_lines + self.arms + self.guides
        out += self.blocks + [self.joint_marks, self.marks] + self.point_marks + self.labels + self.body_labels
        out += [t for t in self.point_labels + self.mark_labels if t is not None]
        out += [t for row in self.link_labels for t in row if t is not None]
        return out

    def update(self, k: int) -> list:
        d, s = self.d, self.s
        show = bool(d.shown[k])
        for c, row in enumerate(self.segments):
            v = d.loops[c][k] * s
            n = len(row)
            for j, ln in enumerate(row):
                seg = np.stack([v[j], v[(j + 1) % n]])
                ln.set_data(seg[:, 0], seg[:, 1])
                label = self.link_labels[c][j] if self.link_labels else None
                if label is not None:  # beside the middle of the bar, on its left
                    t = seg[1] - seg[0]
                    t = t / max(float(np.hypot(*t)), 1e-300)
                    label.xy = tuple(seg.mean(axis=0))
                    label.set_position((-7 * t[1], 7 * t[0]))
                    label.set_visible(show)
        for b, art, label in zip(d.bodies, self.bodies, self.body_labels or [None] * len(d.bodies)):
            xy = b.outline[k] * s
            if b.plate:
                art.set_xy(xy)
                art.set_visible(show)
            else:
                art.set_data(xy[:, 0], xy[:, 1])
            if label is not None:  # a plate's name in it, a bar's beside its middle on its left
                label.xy = tuple(xy.mean(axis=0))
                t = xy[-1] - xy[0]
                t = t / max(float(np.hypot(*t)), 1e-300)
                label.set_position((0, 0) if b.plate else (-8 * t[1], 8 * t[0]))
                label.set_visible(show)
        if self.drive_lines and d.drive is not None:
            a, b = d.drive.ends[k] * s
            u = (b - a) / max(float(np.hypot(*(b - a))), 1e-300)
            barrel = a + self.barrel * s * u
            self.drive_lines[0].set_data([a[0], barrel[0]], [a[1], barrel[1]])
            self.drive_lines[1].set_data([a[0], b[0]], [a[1], b[1]])
            self.drive_lines[2].xy = tuple(0.5 * (a + barrel))  # beside the barrel, on its right
            self.drive_lines[2].set_position((14 * u[1], -14 * u[0]))
            self.drive_lines[2].set_visible(show)
        mk = d.marks[k] * s
        self.marks.set_data(mk[:, 0], mk[:, 1])
        for t, p in zip(self.mark_labels, mk):
            if t is not None:
                t.xy = tuple(p)
                t.set_visible(show)
        for arm, ln in zip(d.arms, self.arms):
            ln.set_data(arm[k, :, 0] * s, arm[k, :, 1] * s)
        h, w = 0.05 * self.size, 0.032 * self.size
        for sl, ln, patch in zip(d.sliders, self.guides, self.blocks):
            ln.set_data(sl.guide[k, :, 0] * s, sl.guide[k, :, 1] * s)
            u = sl.axis[k]
            n_ = np.array([-u[1], u[0]])
            b = sl.block[k] * s
            patch.set_xy(np.array([b - h * u - w * n_, b + h * u - w * n_, b + h * u + w * n_, b - h * u + w * n_]))
            patch.set_visible(show)
        xy = d.joints[k] * s
        self.joint_marks.set_data(xy[:, 0], xy[:, 1])
        for i, m in enumerate(self.point_marks):
            m.set_data([d.points[k, i, 0] * s], [d.points[k, i, 1] * s])
        for t, p in zip(self.labels, xy):
            t.xy = tuple(p)
            t.set_visible(show)
        for t, p in zip(self.point_labels, d.points[k] * s):
            if t is not None:
                t.xy = tuple(p)
                t.set_visible(show)
        return self.artists()


def closed_curve(x, y, periodic: bool, step=None):
    """Append the first value at the end of one full revolution (x + one step)."""
    if not periodic or len(x) < 2:
        return x, y
    h = (x[1] - x[0]) if step is None else step
    return np.append(x, x[-1] + h), np.concatenate([y, y[:1]])


def _below(ax):
    """Axes coordinates shifted down past the tick labels and the x label (for a legend under the
    drawing, outside the point paths)."""
    from matplotlib.transforms import offset_copy

    return offset_copy(ax.transAxes, fig=ax.figure, y=-34, units="points")


def _loop(v, periodic: bool):
    """A path over one full revolution, closed: the first position again at the end."""
    return np.concatenate([v, v[:1]]) if periodic and len(v) > 1 else v


def robust_limits(values) -> tuple | None:
    """Limits for values whose extremes lie far outside their bulk: `(lo, hi, note)` or None.
    The bulk is the 5–95 % range; an extreme more than one bulk span beyond it is a spike (a
    toggle, a dead centre): the limits are then the bulk widened by half its span."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size < 10:
        return None
    lo, hi = np.percentile(v, [5, 95])
    span = hi - lo
    if span <= 0:
        return None
    vmin, vmax = v.min(), v.max()
    if vmax <= hi + span and vmin >= lo - span:
        return None
    return (max(vmin, lo - 0.5 * span), min(vmax, hi + 0.5 * span),
            f"clipped: the extremes are {vmin:.3g} … {vmax:.3g}")


def _shade_failures(ax, x, table, label=True):
    """Light red spans over the input ranges that did not assemble."""
    bad = ~table.assembled
    if not bad.any():
        return
    h = (x[1] - x[0]) if len(x) > 1 else 1.0
    first = True
    for a, b in _grid.runs(bad):
        ax.axvspan(x[a] - h / 2, x[b] + h / 2, color="red", alpha=0.08, lw=0,
                   label="not assembled" if (label and first) else None)
        first = False


def limit_axis(ax, arrays, unit_text):
    lim = robust_limits(np.concatenate([np.ravel(a) for a in arrays])) if arrays else None
    if lim is None:
        return
    lo, hi, note = lim
    pad = 0.05 * (hi - lo)
    ax.set_ylim(lo - pad, hi + pad)
    ax.text(0.01, 0.97, f"{note} {unit_text}", transform=ax.transAxes, fontsize=7, va="top", color="0.3",
            bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="0.8", alpha=0.85))


def plot_kinematics(path: str, mech, table) -> None:
    """The linkage and the point paths (left); positions, |v|, |a| over the input (right), in the
    file's length unit: per second at the speed given (`--rpm`, `--omega`, named under the axis),
    else per radian of the crank (per metre of a length input) — the transfer functions."""
    plt = pyplot()
    s, lu = length_unit(mech)
    x_in = table.input_values
    angle = table.input_kind == "angle"
    xlabel = "input angle (deg)" if angle else "input (m)"
    npts = len(mech.point_names)
    panels = [("position", None)]
    if table.velocities is not None:
        panels.append(("velocity", table.velocities))
    if table.accelerations is not None:
        panels.append(("acceleration", table.accelerations))
    rows = len(panels)
    # rates per second at a speed that was given; at the default unit speed they are the transfer
    # functions d/dφ, d²/dφ² (per radian of the crank; per metre of a length input) and say so
    given = table.rpm is not None or table.omega != 1.0
    per = "s" if given else ("rad" if angle else "m")
    fig = plt.figure(figsize=(13, 3.4 * max(rows, 2)), layout="constrained")
    gs = fig.add_gridspec(rows, 2, width_ratios=[1.0, 1.15])
    ax_path = fig.add_subplot(gs[:, 0])
    d = linkage_drawing(mech, table)
    ok = np.flatnonzero(table.converged)
    shown = np.flatnonzero(table.assembled)
    k0 = int(ok[0]) if ok.size else (int(shown[0]) if shown.size else 0)
    art = LinkageArtist(ax_path, d, s)
    art.update(k0)
    for i, pn in enumerate(mech.point_names):
        xy = table.points[:, i] * s
        ax_path.plot(_loop(xy[:, 0], table.periodic), _loop(xy[:, 1], table.periodic), "-", lw=1.4,
                     color=f"C{i}", label=f"path of {pn}", zorder=1)
    x0, x1, y0, y1 = art.bounds()
    ax_path.set_xlim(x0, x1)
    ax_path.set_ylim(y0, y1)
    ax_path.set_aspect("equal", adjustable="box")
    ax_path.set_xlabel(f"x ({lu})")
    ax_path.set_ylabel(f"y ({lu})")
    at = _grid.format_input(x_in[k0], table.input_kind) if len(x_in) else ""
    ax_path.set_title(f"{mech.name}: linkage at {at}" + (" and point paths" if npts else ""))
    ax_path.grid(alpha=0.3)
    if (~table.assembled).any():
        ax_path.plot([], [], " ", label="not assembled at " + _grid.format_runs(
            x_in, _grid.runs(~table.assembled, table.periodic), table.input_kind, limit=3))
    handles, _ = ax_path.get_legend_handles_labels()
    if handles:
        ax_path.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), bbox_transform=_below(ax_path), fontsize=8,
                       ncol=min(3, len(handles)), frameon=False)

    for r, (what, arr) in enumerate(panels):
        ax = fig.add_subplot(gs[r, 1])
        series: list = []
        for i, pn in enumerate(mech.point_names):
            col = f"C{i}"
            if what == "position":
                for comp, style in ((0, "-"), (1, "--")):
                    xx, yy = closed_curve(x_in, table.points[:, i, comp] * s, table.periodic)
                    ax.plot(xx, yy, style, color=col, lw=1.5, label=f"{pn} {'xy'[comp]}")
            else:
                assert arr is not None
                letter = what[0]
                shown = arr[:, i] * s  # the file's length unit
                mag = np.hypot(shown[:, 0], shown[:, 1])
                xx, yy = closed_curve(x_in, mag, table.periodic)
                ax.plot(xx, yy, "-", color=col, lw=2.4, label=f"|{letter}| {pn}")
                for comp, style in ((0, "-"), (1, "--")):
                    xx, yy = closed_curve(x_in, shown[:, comp], table.periodic)
                    ax.plot(xx, yy, style, color=col, lw=0.9, alpha=0.7, label=f"{pn} {letter}{'xy'[comp]}")
                series += [mag, shown[:, 0], shown[:, 1]]
        unit = {"position": lu, "velocity": f"{lu}/{per}", "acceleration": f"{lu}/{per}²"}[what]
        ax.set_ylabel(f"{what} ({unit})")
        _shade_failures(ax, x_in, table)
        if what != "position":
            limit_axis(ax, series, unit)
        ax.grid(alpha=0.3)
        if angle and table.periodic:
            ax.set_xlim(x_in[0], x_in[0] + 360.0 * np.sign(x_in[1] - x_in[0]))
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
        if r == rows - 1:
            speed = f", at {table.speed_text(file_units(mech))}" if rows > 1 and given else ""
            ax.set_xlabel(xlabel + speed)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def animate(path: str, mech, table, fps: int = 15, progress: bool = True, dpi: int = 90) -> None:
    """GIF of the moving linkage over the table's positions, with the traced point paths; a
    progress bar on standard error while the frames are drawn. The still parts (axes, grid, paths,
    ground symbols) are drawn once and every frame draws only the moving artists over them."""
    plt = pyplot()
    from PIL import Image
    from tqdm import tqdm

    s, lu = length_unit(mech)
    d = linkage_drawing(mech, table)
    fig, ax = plt.subplots(figsize=(6, 6), dpi=dpi)
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.set_xlabel(f"x ({lu})")
    ax.set_ylabel(f"y ({lu})")
    for i, pn in enumerate(mech.point_names):
        xy = table.points[:, i] * s
        ax.plot(_loop(xy[:, 0], table.periodic), _loop(xy[:, 1], table.periodic), ":", lw=1.2,
                color=f"C{i}", label=f"path of {pn}")
    art = LinkageArtist(ax, d, s)
    x0, x1, y0, y1 = art.bounds()
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    title = ax.set_title(f"{mech.name}   input 360°")  # room for the frames' titles
    if mech.point_names:
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), bbox_transform=_below(ax), fontsize=8,
                  frameon=False, ncol=min(3, len(mech.point_names)))
    fig.tight_layout()
    moving = sorted(art.artists() + [title], key=lambda a: a.get_zorder())
    for a in moving:
        a.set_animated(True)
    canvas = fig.canvas
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)
    x_in = table.input_values
    frames = []
    n = len(table.data)
    with tqdm(total=n, desc=f"drawing {path}", unit="frame", disable=not progress, leave=False,
              mininterval=0.5) as bar:
        for k in range(n):
            canvas.restore_region(background)
            art.update(k)
            text = f"{mech.name}   input {_grid.format_input(x_in[k], table.input_kind)}"
            if not table.assembled[k]:
                text += f"   ({RESULTS.name(table.result[k])}: not drawn)"
            title.set_text(text)
            title.set_color("black" if table.assembled[k] else "red")
            for a in moving:
                if a.get_visible():
                    ax.draw_artist(a)
            rgba = np.asarray(canvas.buffer_rgba())
            frames.append(Image.fromarray(rgba[..., :3].copy()).quantize(colors=64, method=Image.Quantize.MEDIANCUT))
            bar.update(1)
    plt.close(fig)
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=int(round(1000 / fps)), loop=0)
