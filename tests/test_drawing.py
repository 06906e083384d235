"""What the linkage drawing is made of (issue 24 item 5): the joints it draws as pins and their
names, the ground symbols, bars, plates and points — from a sketch file's joints and links, and
from a loop file's vectors without a joint where no joint is — and the input as given in titles.
The data of the drawing (`jaxlink.report.drawing.drawing(...).describe()`), not pixels; positions
against closed forms (Freudenstein's four-bar, circle intersections written here)."""

import math

import matplotlib
import numpy as np
import pytest
from closed_forms import fourbar_freudenstein

import jaxlink as jl
from jaxlink.report import export, grid, plot
from jaxlink.report.drawing import drawing
from jaxlink.report.kinematics import kinematics_table

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PHIS = np.deg2rad(np.arange(-100.0, 260.0, 30.0))


def drawn(mech, phis=PHIS, q=None):
    """The drawing at the unknowns `q` (N, n) (default: solved)."""
    if q is None:
        sol = jl.solve(mech, phis)
        assert bool(np.all(sol.converged))
        q = np.asarray(sol.q)
    return drawing(mech, np.asarray(q), phis, mech.parameters, np.ones(len(phis), bool))


def angle(v):
    return np.arctan2(v[..., 1], v[..., 0])


def e(t):
    return np.stack([np.cos(t), np.sin(t)], axis=-1)


def circles(c1, r1, c2, r2, left):
    """The intersection of two circles (N, 2) on the left (`left`) or right of c1 → c2."""
    d = c2 - c1
    dist = np.linalg.norm(d, axis=-1, keepdims=True)
    a = (r1 * r1 - r2 * r2 + dist * dist) / (2 * dist)
    h = np.sqrt(r1 * r1 - a * a)
    n = np.stack([-d[..., 1], d[..., 0]], axis=-1) / dist
    return c1 + a * d / dist + (h if left else -h) * n


def test_four_bar_sketch_is_drawn_from_its_joints_and_links():
    """The scene four-bar-sketch: its frame joints A0, B0 with ground symbols, the pins A and B, P a
    point of the coupler (no pin), the coupler a plate A-B-P, crank and rocker bars, the crank
    marked as the input — where Freudenstein's closed form puts them."""
    mech = jl.load("four-bar-sketch")
    a, b, c, dd = 0.020, 0.060, 0.045, 0.055
    phi3, phi4 = fourbar_freudenstein(a, b, c, dd, PHIS, -1)
    d = drawn(mech, q=np.stack([phi3, phi4], axis=1))  # theta_coupler, theta_rocker
    got = d.describe()
    assert got["joints"] == ["A0", "B0", "A", "B"]
    assert got["ground"] == ["A0", "B0"]
    assert got["marks"] == ["P"] and got["points"] == ["P"]
    assert got["plates"] == {"coupler": ["A", "B", "P"]} and got["bars"] == ["crank", "rocker"]
    assert got["drive"] == ("crank", "crank") and d.loops == []
    # a = 20, b = 60, c = 45, d = 55 mm; P 30 mm along AB and 15 mm to its left (the scene's comment)
    A = a * e(PHIS)
    B = A + b * e(phi3)
    P = A + 0.030 * e(phi3) + 0.015 * e(phi3 + np.pi / 2)
    want = np.stack([0 * A, 0 * A + [dd, 0.0], A, B], axis=1)
    np.testing.assert_allclose(d.joints, want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(d.marks[:, 0], P, rtol=0, atol=1e-12)
    coupler = d.bodies[[x.name for x in d.bodies].index("coupler")]
    assert coupler.plate and coupler.outline.shape[1] == 3
    corners = np.stack([A, B, P], axis=1)
    for k in range(3):  # every corner of the plate is A, B or P
        assert np.min(np.abs(corners - coupler.outline[:, k:k + 1]).max(axis=(0, 2))) < 1e-12
    np.testing.assert_allclose(d.drive.ends[:, 0], 0 * A, atol=1e-15)
    np.testing.assert_allclose(d.drive.ends[:, 1], A, atol=1e-12)
    # the plot's artists: ground symbols at A0 and B0, the file's names as labels
    fig, ax = plt.subplots()
    s, _ = plot.length_unit(mech)
    art = plot.LinkageArtist(ax, d, s)
    art.update(0)
    np.testing.assert_allclose(art.ground_xy / s, [[0, 0], [dd, 0]], atol=1e-12)
    assert [t.get_text() for t in art.labels] == ["A0", "B0", "A", "B"]
    assert [t.get_text() for t in art.body_labels] == ["crank", "coupler", "rocker"]
    plt.close(fig)


STEPHENSON = dict(O2=(0.0, 0.0), O4=(4.0, 0.0), O6=(1.0, 4.5))


def stephenson_joints(phi):
    """Stephenson III by circle intersections (m): crank O2 A = 1, coupler A B = 3.5, rocker O4 B = 3,
    coupler point C 2 from A and 2.2 from B, link C D = 2.5, output O6 D = 2 (B left of A → O4, C left
    of A → B, D right
    of C → O6)."""
    o2, o4, o6 = (np.broadcast_to(np.array(v), (len(phi), 2)) for v in STEPHENSON.values())
    A = o2 + e(phi)
    B = circles(A, 3.5, o4, 3.0, left=True)
    C = circles(A, 2.0, B, 2.2, left=True)
    D = circles(C, 2.5, o6, 2.0, left=False)
    return {"O2": o2, "O4": o4, "O6": o6, "A": A, "B": B, "C": C, "D": D}


# the same linkage in loop form, the coupler point C written as offsets p along A B and q across
# it: the vertex where the two offsets meet is no joint
P_ALONG = (4.0 - 2.2 ** 2 + 3.5 ** 2) / 7.0
Q_ACROSS = math.sqrt(4.0 - P_ALONG ** 2)
STEPHENSON_LOOPS = f"""\
[mechanism]
name = "stephenson3-loops"
angle_unit = "deg"
[parameters]
p = {P_ALONG!r}
q = {Q_ACROSS!r}
[input]
name = "phi2"
start = 17.188733853924695
[unknowns]
phi3 = 48.386
phi4 = 103.892
phi5 = 44.738
phi6 = -13.194
[loops]
four_bar = ["1 @ phi2", "3.5 @ phi3", "-3 @ phi4", "-(4, 0)"]
second = ["1 @ phi2", "p @ phi3", "q @ phi3 + 90", "2.5 @ phi5", "-2 @ phi6", "-(1, 4.5)"]
[points]
C = ["1 @ phi2", "p @ phi3", "q @ phi3 + 90"]
"""

# an oscillating cylinder in loop form: its trunnion (60, 0) is the foot of the turning guide
CYLINDER = """\
[mechanism]
name = "oscillating-cylinder"
length_unit = "mm"
angle_unit = "deg"
[parameters]
a = 20.0
[input]
name = "phi2"
[unknowns]
s = 40.0
theta3 = 180.0
[loops]
main = ["a @ phi2", "-s @ theta3", "-(60, 0)"]
[points]
A = ["a @ phi2"]
"""


def test_stephenson_iii_has_no_joint_at_its_coupler_point_offsets():
    """The issue's J1: drawn where the coupler point's two offset vectors meet. The sketch draws its
    seven joints (C a pin: the coupler and link 5 meet there) and the coupler as a plate; the loop
    form draws the same seven pins and nothing at A + p e(phi3)."""
    phis = PHIS + 0.3
    want = stephenson_joints(phis)
    pose = {n: v[0] for n, v in stephenson_joints(np.array([0.3])).items()}
    sk = jl.Sketch("stephenson3")
    for n in ("O2", "O4", "O6"):
        sk.frame(n, *pose[n])
    for n in ("A", "B", "C", "D"):
        sk.joint(n, *pose[n])
    sk.link("crank", "O2", "A").link("coupler", "A", "B", "C").link("rocker", "O4", "B")
    sk.link("link5", "C", "D").link("output", "O6", "D").crank("crank")
    angles = np.stack([angle(want["B"] - want["A"]), angle(want["B"] - want["O4"]), angle(want["D"] - want["C"]),
                       angle(want["D"] - want["O6"])], axis=1)  # the unknowns of both forms, in this order
    d = drawn(sk.mechanism(), phis, angles)
    got = d.describe()
    assert got["joints"] == ["O2", "O4", "O6", "A", "B", "C", "D"] and got["marks"] == []
    assert got["ground"] == ["O2", "O4", "O6"]
    assert got["plates"] == {"coupler": ["A", "B", "C"]}
    np.testing.assert_allclose(d.joints, np.stack([want[n] for n in got["joints"]], axis=1), atol=1e-12)

    d = drawn(jl.loads(STEPHENSON_LOOPS), phis, angles)
    assert len(d.joint_names) == 7, d.joint_names
    assert sorted(d.describe()["ground"]) == ["O1", "O2", "O3"]
    for n, xy in want.items():  # every joint drawn where it is, and only those
        assert np.min(np.abs(d.joints - xy[:, None]).max(axis=(0, 2))) < 1e-12, n
    offset = want["A"] + P_ALONG * e(angles[:, 0])  # where p and q meet
    assert np.min(np.linalg.norm(d.joints - offset[:, None], axis=-1).max(axis=0)) > 0.1


def test_oscillating_cylinder_trunnion_has_a_ground_symbol():
    rel = 0.020 * e(PHIS) - [0.060, 0.0]  # s e(theta3): from the trunnion to the crank pin
    d = drawn(jl.loads(CYLINDER), q=np.stack([np.linalg.norm(rel, axis=-1), angle(rel)], axis=1))
    got = d.describe()
    ground = d.joints[0, d.ground]
    assert len(got["ground"]) == 2 and np.allclose(sorted(ground[:, 0]), [0.0, 0.060], atol=1e-12)
    assert got["drive"] == ("crank", "phi2") and len(got["sliders"]) == 1


def test_loop_file_draws_its_joints_tables():
    """sewing-feed: the pins are its [joints] tables, in their order with their names, A and E
    the frame's; the crank (A, B, C) is a plate; the lever's D, E, F lie on one line: no plate."""
    mech = jl.load("sewing-feed")
    d = drawn(mech)
    got = d.describe()
    assert got["joints"] == ["A", "B", "C", "D", "E", "F", "H"]
    assert got["ground"] == ["A", "E"]
    assert got["plates"] == {"crank": ["A", "B", "C"]}
    assert got["drive"] == ("crank", "phi2")
    v = dict(zip(mech.parameter_names, np.asarray(mech.parameters)))
    np.testing.assert_allclose(d.joints[:, 1], v["l2"] * e(PHIS), atol=1e-12)
    np.testing.assert_allclose(d.joints[:, 2], -v["l22"] * e(PHIS + v["gamma"]), atol=1e-12)
    np.testing.assert_allclose(d.joints[:, 4], np.broadcast_to([v["l8"], v["l7"]], (len(PHIS), 2)), atol=1e-12)


def test_titles_show_the_input_as_given(tmp_path, monkeypatch):
    """A run starting at −100° is titled −100°, not 260° (plot, geometry export)."""
    assert grid.format_input(-100.0, "angle") == "-100°" and grid.format_value(-100.0, "angle") == "260°"
    mech = jl.load("four-bar-sketch")
    phis = np.deg2rad(np.arange(-100.0, 260.0, 30.0))
    table = kinematics_table(mech, phis, outputs=("position",), input_values=np.arange(-100.0, 260.0, 30.0))
    assert export.geometry(mech, table).title == "four-bar-sketch at input -100°"
    real = plot.pyplot()
    figs = []

    class Pyplot:
        def __getattr__(self, name):
            return getattr(real, name)

        def close(self, fig):
            figs.append(fig)
            real.close(fig)

    monkeypatch.setattr(plot, "pyplot", lambda: Pyplot())
    plot.plot_kinematics(str(tmp_path / "x.png"), mech, table)
    assert figs[0].axes[0].get_title() == "four-bar-sketch: linkage at -100° and point paths"


@pytest.mark.parametrize("name", ["four-bar-sketch"])
def test_export_follows_the_drawing(name):
    """The geometry export names the joints as the drawing does and outlines the plate."""
    mech = jl.load(name)
    table = kinematics_table(mech, PHIS, outputs=("position",))
    geo = export.geometry(mech, table)
    assert [t.text for t in geo.labels] == ["A0", "B0", "A", "B", "P"]
    assert [c.layer for c in geo.circles[:4]] == ["GROUND", "GROUND", "JOINTS", "JOINTS"]
    plates = [p for p in geo.layer("LINKAGE") if p.closed]
    assert len(plates) == 1 and len(plates[0].xy) == 3
    assert {p.layer for p in geo.polylines if p.layer.startswith("JOINT_PATH_")} == {"JOINT_PATH_A", "JOINT_PATH_B"}
