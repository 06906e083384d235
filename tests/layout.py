"""What a reader of a figure would see cut or crossed out: every visible text (titles, labels,
tick labels, legends) inside the figure, and no two tick labels of one axis overlapping.

`problems(fig)` measures the texts of a drawn figure with its renderer (matplotlib's own text
extents, not a guess from character counts). conftest.py checks every figure the suite's tests
save in their own process (a wrapper around `Figure.savefig`); tests/test_plot_layout.py draws
each plot of `study`, `kinematics`, `reactions` and `synthesize` on purpose."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

from matplotlib.figure import Figure  # noqa: E402
from matplotlib.text import Text  # noqa: E402

SLACK = 1.0
"""Pixels a text may reach past the figure's edge (anti-aliasing)."""


def _shown_ticks(axis) -> list:
    """The tick labels of `axis` that are drawn: visible, not empty, their tick within the view."""
    lo, hi = sorted(axis.get_view_interval())
    eps = 1e-9 * max(1.0, abs(hi - lo))
    out = []
    for tk in axis.get_major_ticks() + axis.get_minor_ticks():
        if lo - eps <= tk.get_loc() <= hi + eps:
            out += [lab for lab in (tk.label1, tk.label2) if lab.get_visible() and lab.get_text().strip()]
    return out


def problems(fig: Figure) -> list[str]:
    """What is cut off or overlapping in `fig` (drawn): one line per text outside the figure and per
    pair of overlapping tick labels of one axis; empty when the figure reads cleanly."""
    r = fig.canvas.get_renderer()
    W, H = fig.bbox.width, fig.bbox.height
    hidden = set()  # tick labels whose tick is outside the view: not drawn
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            shown = {id(lab) for lab in _shown_ticks(axis)}
            for tk in axis.get_major_ticks() + axis.get_minor_ticks():
                hidden |= {id(lab) for lab in (tk.label1, tk.label2) if id(lab) not in shown}
    out = []

    def outside(bb) -> bool:
        return bb.x0 < -SLACK or bb.y0 < -SLACK or bb.x1 > W + SLACK or bb.y1 > H + SLACK

    for t in fig.findobj(Text):
        if id(t) in hidden or not t.get_visible() or not t.get_text().strip():
            continue
        bb = t.get_window_extent(r)
        if outside(bb):
            out.append(f"text {t.get_text()[:50]!r} outside the figure: {tuple(round(v) for v in bb.extents)} "
                       f"in {W:.0f} x {H:.0f}")
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    for lg in legends:
        bb = lg.get_window_extent(r)
        if outside(bb):
            out.append(f"legend outside the figure: {tuple(round(v) for v in bb.extents)} in {W:.0f} x {H:.0f}")
    for ax in fig.axes:
        for name, axis in (("x", ax.xaxis), ("y", ax.yaxis)):
            labs = _shown_ticks(axis)
            bbs = [lab.get_window_extent(r) for lab in labs]
            for i in range(len(bbs)):
                for j in range(i + 1, len(bbs)):
                    if bbs[i].overlaps(bbs[j]):
                        out.append(f"{name} tick labels {labs[i].get_text()!r} and {labs[j].get_text()!r} overlap "
                                   f"(panel {ax.get_title()!r})")
    return out


class Watch:
    """Every figure saved while installed is drawn and checked just before it is written (after it
    a legend's or an annotation's boxes hold the pixels of the saved dpi, not the figure's):
    `found` holds `path: problem` lines."""

    def __init__(self):
        self.found: list[str] = []
        self._orig = None

    def __enter__(self):
        self._orig = orig = Figure.savefig
        watch = self

        def savefig(fig, fname, *args, **kwargs):
            if kwargs.get("bbox_inches") is None:  # a tight box would move the edges measured against
                fig.canvas.draw()  # at the figure's dpi: the layout savefig draws, in other pixels
                watch.found += [f"{fname}: {p}" for p in problems(fig)]
            return orig(fig, fname, *args, **kwargs)

        Figure.savefig = savefig
        return self

    def __exit__(self, *exc):
        Figure.savefig = self._orig
        return False
