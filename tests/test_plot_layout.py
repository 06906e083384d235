"""The plots read cleanly (issue 48: "histograms.png's title and legend cut off; the tornado is
titled 'at 379 deg'"). conftest.py checks every figure the suite saves in-process with
tests/layout.py; here the checker's own teeth, and the tornado's crank angle against an
independent numpy four-bar."""

import math

import numpy as np
import pytest
from layout import problems

import jaxlink as jl
from jaxlink import study as st

FILE = """
[mechanism]
length_unit = "mm"
angle_unit = "deg"

[parameters]
a = 20.0
b = 60.0
c = 45.0
d = 55.0
cx = 30.0
cy = 15.0

[input]
name = "phi2"
body = "crank"
start = 30

[unknowns]
phi3 = 30.0
phi4 = 80.0

[loops]
main = ["a @ phi2", "b @ phi3", "-c @ phi4", "-d @ 0"]

[points]
P = ["a @ phi2", "cx @ phi3", "cy @ phi3 + 90"]

[study]
positions = 72
samples = 0
points = ["P"]
metrics = ["deviation"]

[study.tolerances]
a = 0.05
b = 0.02
c = 0.03
d = 0.04
cx = 0.05
cy = 0.01
"""


def _coupler_point(x, phi, pick):
    """P of the four-bar (a, b, c, d, cx, cy) = x at crank angles phi (rad), numpy: B on the circle
    of radius b about A and c about B0 = (d, 0), the intersection `pick` (±1)."""
    a, b, c, d, cx, cy = x
    A = np.stack([a * np.cos(phi), a * np.sin(phi)], -1)
    v = np.array([d, 0.0]) - A
    L = np.hypot(v[:, 0], v[:, 1])
    along = (b * b - c * c + L * L) / (2 * L)
    h = np.sqrt(b * b - along * along)
    u = v / L[:, None]
    n = np.stack([-u[:, 1], u[:, 0]], -1)
    B = A + along[:, None] * u + pick * h[:, None] * n
    e = (B - A) / b
    return A + cx * e + cy * np.stack([-e[:, 1], e[:, 0]], -1)


def test_tornado_names_a_crank_angle_within_one_turn():
    """The cycle runs from 30° to 30° + 355°: the input where the deviation bound Σ t_j ‖∂P/∂x_j‖
    is largest (located here with central differences of a numpy four-bar) is named reduced to
    [0°, 360°) — on main the title said 'at 378 deg'."""
    from jaxlink.report.tolerance import tornado_rows

    mech = jl.loads(FILE)
    rep = st.tolerance(mech, study=st.Study(mech, st.read_study(mech)), samples=0, worst=False)
    phi = np.deg2rad(rep.input_values)
    x0 = np.array([20.0, 60.0, 45.0, 55.0, 30.0, 15.0])
    t = np.array([0.05, 0.02, 0.03, 0.04, 0.05, 0.01])
    ix = [i for i, lab in enumerate(rep.labels) if lab[0] == "P.x"]
    nominal = np.asarray(rep.nominal)[ix]
    pick = min((1, -1), key=lambda s: np.abs(_coupler_point(x0, phi, s)[:, 0] - nominal).max())
    bound = np.zeros(len(phi))
    for j in range(6):
        dx = np.zeros(6)
        dx[j] = 1e-6
        dP = (_coupler_point(x0 + dx, phi, pick) - _coupler_point(x0 - dx, phi, pick)) / 2e-6
        bound += t[j] * np.hypot(dP[:, 0], dP[:, 1])
    k = int(np.argmax(bound))
    assert np.sort(bound)[-2] < bound[k] * (1 - 1e-6)  # no near tie: the argmax is the argmax
    assert rep.input_values[k] >= 360  # the case of the issue: past one turn as sampled
    title = next(r[0] for r in tornado_rows(mech, rep) if r[0].startswith("deviation(P)"))
    assert title == f"deviation(P) at {math.fmod(rep.input_values[k], 360.0):.4g} deg"


def test_the_layout_check_finds_cut_and_crossed_text():
    """The checker's teeth: a title past the figure's edge, a legend below it and tick labels set
    on top of each other are each reported; the same figure laid out cleanly is not."""
    from jaxlink.report.plot import pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(3, 2))
    ax.plot([0, 1], [0, 1], label="a line")
    fig.tight_layout()
    fig.canvas.draw()
    assert problems(fig) == []
    fig.suptitle("a title much too long to fit in a figure only three inches wide at all")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.6))
    ax.set_xticks([0.0, 0.01], ["zero point zero", "zero point zero one"])
    fig.canvas.draw()
    found = problems(fig)
    plt.close(fig)
    assert any(f.startswith("text 'a title") for f in found)
    assert any(f.startswith("legend outside") for f in found)
    assert any("tick labels 'zero point zero' and 'zero point zero one' overlap" in f for f in found)


@pytest.mark.parametrize("ncol", [3, 1])
def test_finish_keeps_title_and_legend_inside(ncol):
    """`plot.finish` (the study plots' layout): a title and a three-entry legend wider than a
    one-panel figure are wrapped and folded into the figure."""
    from jaxlink.report.plot import finish, pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(4.8, 3.5), squeeze=False)
    for i in range(3):
        ax[0, 0].plot([0, 1], [i, i + 1], label=f"a rather long legend entry number {i}")
    seen = {}
    orig = fig.savefig

    def save(path, **kw):
        fig.canvas.draw()
        seen["problems"] = problems(fig)

    fig.savefig = save
    finish(fig, "unused.png", title="four-bar: Monte Carlo of 2000 samples (red: the specification limits)",
           legend=(*ax[0, 0].get_legend_handles_labels(), ncol))
    fig.savefig = orig
    assert seen["problems"] == []


def test_a_one_response_study_draws_its_plots_inside_the_figure(tmp_path):
    """The issue's histograms.png: one scalar response (the rocker's swing) with specification
    limits makes a one-panel figure whose title and three-entry legend were wider than it (on main:
    'nominal' and the legend past the right edge); tolerance.png and tornado.png too."""
    from layout import Watch

    from jaxlink.report.tolerance import draw_plots

    mech = jl.loads(FILE)
    inputs = st.read_study(mech, metrics=["stroke"], samples=512, limits={"swing(phi4)": [59.9, 60.1]})
    rep = st.tolerance(mech, study=st.Study(mech, inputs), worst=False)
    with Watch() as w:
        files = draw_plots(tmp_path, mech, rep)
    assert [f.name for f in files] == ["tolerance.png", "tornado.png", "histograms.png"]
    assert w.found == []


@pytest.mark.parametrize("rpm", [None, 300.0])
def test_kinematics_plot_rates_in_the_file_unit(tmp_path, rpm):
    """The issue: 'plots show positions in mm and velocities in m/s'. The velocity panel of a
    file in mm is in mm/s at a given speed and in mm/rad (the transfer function) without one, its
    |v| line that of an independent numpy four-bar's central differences in φ (× ω with a speed)."""
    from matplotlib.figure import Figure

    from jaxlink.report.kinematics import kinematics_table
    from jaxlink.report.plot import plot_kinematics

    mech = jl.loads(FILE)
    deg = np.arange(30.0, 390.0, 10.0)
    omega = 1.0 if rpm is None else rpm * 2 * math.pi / 60
    table = kinematics_table(mech, np.deg2rad(deg), omega=omega, rpm=rpm, input_values=deg)
    grabbed = []
    orig = Figure.savefig

    def grab(fig, *a, **k):
        grabbed.append(fig)
        return orig(fig, *a, **k)

    Figure.savefig = grab
    try:
        plot_kinematics(str(tmp_path / "k.png"), mech, table)
    finally:
        Figure.savefig = orig
    ax = next(a for a in grabbed[0].axes if a.get_ylabel().startswith("velocity"))
    assert ax.get_ylabel() == ("velocity (mm/rad)" if rpm is None else "velocity (mm/s)")
    line = next(ln for ln in ax.get_lines() if ln.get_label() == "|v| P")
    phi = np.deg2rad(deg)
    x0 = np.array([20.0, 60.0, 45.0, 55.0, 30.0, 15.0])
    nominal = table.points[:, 0, 0] * 1e3
    pick = min((1, -1), key=lambda s: np.abs(_coupler_point(x0, phi, s)[:, 0] - nominal).max())
    h = 1e-6
    dP = (_coupler_point(x0, phi + h, pick) - _coupler_point(x0, phi - h, pick)) / (2 * h)
    want = np.hypot(dP[:, 0], dP[:, 1]) * omega
    np.testing.assert_allclose(line.get_ydata()[: len(deg)], want, rtol=1e-6)
