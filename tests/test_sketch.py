"""The sketch form (joints and links, `[sketch]`) and its Python builder `jl.Sketch`.

References are independent of the sketch translator: the loop-form scenes (solved by the loop
files, written by hand), and for the textbook six-bars the geometry itself — each joint the
intersection of two circles (numpy, branch held from the sketch's pose).
"""

from __future__ import annotations

import functools
import math
import pathlib

import jax
import numpy as np
import pytest

import jaxlink as jl
from jaxlink.solvers import dyads
from jaxlink.solvers.closed_form import method_for
from jaxlink.solvers.options import NewtonOptions

jax.config.update("jax_enable_x64", True)
pytestmark = pytest.mark.xdist_group("sketch")

SCENES = pathlib.Path(jl.__file__).parent / "scenes"
DATA = pathlib.Path(__file__).parent / "data"
TURN = np.linspace(0.0, 2 * np.pi, 73)


def _joints_of(scene: str, exprs: dict, phi: float) -> dict:
    """Joint positions (file units) of a loop-form scene at input `phi` (SI): its file with the
    joints added as [points] (`exprs`: name -> list of terms), solved by the loop form."""
    text = (SCENES / f"{scene}.toml").read_text()
    extra = "\n".join(f"J_{n} = {terms!r}".replace("'", '"') for n, terms in exprs.items())
    text = text.replace("[points]\n", "[points]\n" + extra + "\n", 1)
    mech = jl.loads(text)
    sol = jl.solve(mech, np.asarray([phi]))
    assert bool(sol.converged[0])
    pts = np.asarray(sol.points[0]) / mech.units.length
    return {n: tuple(map(float, pts[mech.point_names.index(f"J_{n}")])) for n in exprs}


def _compare(loop_mech, sketch_mech, names, phis=TURN, tol=1e-12):
    """Positions of `names` (points of both) agree to `tol` relative to the largest, over `phis`."""
    a = jl.solve(loop_mech, phis)
    b = jl.solve(sketch_mech, phis)  # both inputs are the crank's angle from the x axis
    assert bool(np.all(a.converged)) and bool(np.all(b.converged))
    ia = [loop_mech.point_names.index(n) for n in names]
    ib = [sketch_mech.point_names.index(n) for n in names]
    pa, pb = np.asarray(a.points)[:, ia], np.asarray(b.points)[:, ib]
    err = np.max(np.abs(pa - pb)) / np.max(np.abs(pa))
    assert err < tol, err
    return err


def _closed_form(mech) -> bool:
    return method_for(mech, NewtonOptions()) == "closed_form"


# ----------------------------------------------------------------------------- the scenes


@functools.lru_cache(maxsize=None)  # one build per module run: the tests share it
def _four_bar_sketch():
    j = _joints_of("four-bar", {"A": ["a @ phi2"], "B": ["a @ phi2", "b @ phi3"]}, 0.0)
    p = _joints_of("four-bar", {"P": ["a @ phi2", "cx @ phi3", "cy @ phi3 + 90"]}, 0.0)["P"]
    sk = (jl.Sketch("four-bar", length_unit="mm", angle_unit="deg")
          .frame("A0", 0, 0).frame("B0", 55, 0)
          .joint("A", *j["A"]).joint("B", *j["B"]).joint("P", *p)
          .link("crank", "A0", "A").link("coupler", "A", "B", "P").link("rocker", "B0", "B")
          .crank("crank", name="phi2"))
    return sk


def test_four_bar_sketch_equals_loop_form_and_file_equals_builder():
    loop = jl.load("four-bar")
    sk = _four_bar_sketch()
    mech = sk.mechanism()
    assert mech.point_names == ("A", "B", "P")  # every moving joint by default
    assert mech.unknown_names == ("theta_coupler", "theta_rocker")
    assert mech.input_name == "phi2" and mech.input_start == pytest.approx(0.0, abs=1e-15)
    # the sketch's dimensions: lengths from the coordinates, in the file unit
    for name, value in {"crank": 20, "coupler": 60, "rocker": 45, "B0_x": 55,
                        "coupler_P": math.hypot(30, 15)}.items():
        assert mech.from_si(name, float(mech.parameters[mech.parameter_index(name)])) == pytest.approx(value, 1e-13)
    assert mech.from_si("coupler_P_angle", float(mech.parameters[mech.parameter_index("coupler_P_angle")])) \
        == pytest.approx(math.degrees(math.atan2(15, 30)), 1e-12)
    assert _closed_form(mech) and [d.kind for d in dyads.classify(mech)] == ["RRR"]
    _compare(loop, mech, ["P"])
    # the file and the builder are the same mechanism (same structure, same numbers)
    from_file = jl.loads(sk.toml())
    assert from_file.structure == mech.structure
    np.testing.assert_array_equal(from_file.parameters, mech.parameters)
    np.testing.assert_array_equal(from_file.guess, mech.guess)
    # --set reaches a derived dimension: a longer crank is the loop form's longer crank
    longer = sk.mechanism(overrides={"crank": 22.0})
    _compare(jl.load("four-bar", overrides={"a": 22.0}), longer, ["P"])


@functools.lru_cache(maxsize=None)  # one build per module run: the tests share it
def _slider_crank_sketch(scene):
    start = math.radians(30.0)
    j = _joints_of(scene, {"A": ["h2 @ psi12"], "B": ["h1 @ alpha1", "p14 @ alpha4"]}, start)
    sk = (jl.Sketch("slider-crank", length_unit="mm", angle_unit="deg")
          .frame("O1", 0, 0).joint("A", *j["A"]).joint("B", *j["B"])
          .link("crank", "O1", "A").link("rod", "A", "B")
          .slider("B", on="frame", along=(1, 0)).crank("crank"))
    return sk


@pytest.mark.parametrize("scene", ["slider-crank", "slider-crank-mass"])
def test_slider_crank_sketch_equals_loop_form(scene):
    loop = jl.load(scene)
    start = math.radians(30.0)
    mech = _slider_crank_sketch(scene).mechanism()
    assert mech.input_start == pytest.approx(start, 1e-14)
    assert set(mech.unknown_names) == {"theta_rod", "s_B"}
    assert _closed_form(mech) and [d.kind for d in dyads.classify(mech)] == ["RRP"]
    # the guide's offset is a parameter: 12 mm above the crank pivot
    assert mech.from_si("B_offset", float(mech.parameters[mech.parameter_index("B_offset")])) \
        == pytest.approx(12.0, 1e-13)
    _compare(loop, mech, ["A", "B"], phis=TURN + start)


@pytest.mark.parametrize("scene", ["sewing-feed", "sewing-feed-opt"])
def test_sewing_feed_sketch_equals_loop_form(scene):
    """The seed's bottom-feed six-bar: a crank plate with two arms, a lever plate pivoted between
    its ends, a collinear carrier plate; two dyads."""
    loop = jl.load(scene)
    mech = _sewing_feed_sketch(scene).mechanism()
    assert _closed_form(mech) and [d.kind for d in dyads.classify(mech)] == ["RRR", "RRR"]
    _compare(loop, mech, ["Z"], phis=TURN + loop.input_start)


@functools.lru_cache(maxsize=None)  # one build per module run: the tests share it
def _sewing_feed_sketch(scene):
    start = jl.load(scene).input_start
    j = _joints_of(scene, {
        "B": ["l2 @ phi2"], "C": ["-l22 @ phi2 + gamma"], "D": ["l2 @ phi2", "l3 @ phi3"],
        "E": ["l2 @ phi2", "l3 @ phi3", "l44 @ phi4"],  # the lever's frame pivot: (l8, l7)
        "F": ["l2 @ phi2", "l3 @ phi3", "l4 @ phi4"],
        "H": ["l2 @ phi2", "l3 @ phi3", "l4 @ phi4", "l6 @ phi6"],
        "Z": ["l2 @ phi2", "l3 @ phi3", "l4 @ phi4", "(l6 + l66) @ phi6"],
    }, start)
    sk = jl.Sketch("sewing-feed", length_unit="mm", angle_unit="deg").frame("A", 0, 0).frame("E", *j["E"])
    for n in ("B", "C", "D", "F", "H", "Z"):
        sk.joint(n, *j[n])
    sk.link("crank", "A", "B", "C").link("coupler", "B", "D").link("lever", "E", "D", "F")
    sk.link("link5", "H", "C").link("carrier", "F", "H", "Z").crank("crank", name="phi2").points("Z", "D")
    return sk


@pytest.mark.parametrize("scene", ["needle-arachne", "needle-dwell", "needle-arachne-unit"])
def test_needle_arachne_sketch_equals_loop_form(scene):
    """The ARACHNE needle six-bar: a bell crank (plate C0, C, D) and a vertical needle slider."""
    loop = jl.load(scene)
    mech = _needle_sketch(scene).mechanism()
    assert _closed_form(mech) and [d.kind for d in dyads.classify(mech)] == ["RRR", "RRP"]
    _compare(loop, mech, ["B"])


@functools.lru_cache(maxsize=None)  # one build per module run: the tests share it
def _needle_sketch(scene):
    j = _joints_of(scene, {
        "A": ["l2 @ phi2"], "C0": ["(l1, 0)"], "C": ["(l1, 0)", "l4r @ psi"], "D": ["(l1, 0)", "l4a @ psi - beta"],
        "B2": ["(l1 + l7, 0)", "s @ 90"]}, 0.0)
    lu = "m" if scene.endswith("unit") else "mm"
    sk = (jl.Sketch("needle", length_unit=lu, angle_unit="deg")
          .frame("A0", 0, 0).frame("C0", *j["C0"])
          .joint("A", *j["A"]).joint("C", *j["C"]).joint("D", *j["D"]).joint("B", *j["B2"])
          .link("crank", "A0", "A").link("coupler", "A", "C").link("bellcrank", "C0", "C", "D")
          .link("rod", "D", "B").slider("B", on="frame", along=(0, 1)).crank("crank", name="phi2"))
    return sk


def test_needle_arachne_original_sketch_equals_loop_form():
    """The thesis's original needle drive: the rocker itself drives the rod; frame pivot C0 off
    the crank's axis."""
    loop = jl.load("needle-arachne-original")
    mech = _needle_original_sketch().mechanism()
    assert _closed_form(mech) and [d.kind for d in dyads.classify(mech)] == ["RRR", "RRP"]
    _compare(loop, mech, ["B"])


@functools.lru_cache(maxsize=None)  # one build per module run: the tests share it
def _needle_original_sketch():
    j = _joints_of("needle-arachne-original", {
        "A": ["l2 @ phi2"], "C0": ["(l1, l6)"], "C": ["l2 @ phi2", "l3 @ phi3"],
        "B2": ["(l1, l6)", "l4 @ psi", "l5 @ phi5"]}, 0.0)
    sk = (jl.Sketch("needle-original", length_unit="mm", angle_unit="deg")
          .frame("A0", 0, 0).frame("C0", *j["C0"])
          .joint("A", *j["A"]).joint("C", *j["C"]).joint("B", *j["B2"])
          .link("crank", "A0", "A").link("coupler", "A", "C").link("rocker", "C0", "C")
          .link("rod", "C", "B").slider("B", on="frame", along=(0, 1)).crank("crank", name="phi2"))
    return sk


# ----------------------------------------------------------------------------- textbook six-bars


def _circle(p, q, r1, r2, sigma):
    """The intersection X of |X − p| = r1 and |X − q| = r2 on the side sigma (+1: left of p → q)."""
    d = q - p
    dist = np.hypot(d[..., 0], d[..., 1])[..., None]
    e = d / dist
    a = (r1**2 - r2**2 + dist**2) / (2 * dist)
    h = np.sqrt(r1**2 - a**2)
    perp = np.stack([-e[..., 1], e[..., 0]], axis=-1)
    return p + a * e + sigma * h * perp


def _side(p, q, x):
    d, w = q - p, x - p
    return 1.0 if d[0] * w[1] - d[1] * w[0] > 0 else -1.0


def _reference(frame, crank, dyads_, phis, pose_phi):
    """Positions over `phis` of a linkage made of RRR dyads: `dyads_` = [(X, P, Q, rP, rQ, side)]
    with side a function of the positions at the sketch's pose; plates as extra dyads."""
    def at(phi, sides=None):
        pos = {k: np.asarray(v, float) for k, v in frame.items()}
        piv, name, r = crank
        pos[name] = pos[piv] + r * np.array([np.cos(phi), np.sin(phi)])
        out_sides = {}
        for x, p, q, rp, rq, pick in dyads_:
            if sides is None:
                cands = [_circle(pos[p], pos[q], rp, rq, s) for s in (1.0, -1.0)]
                s = 1.0 if pick(cands[0], cands[1], pos) else -1.0
            else:
                s = sides[x]
            out_sides[x] = s
            pos[x] = _circle(pos[p], pos[q], rp, rq, s)
        return pos, out_sides

    pose, sides = at(pose_phi)
    return pose, [at(phi, sides)[0] for phi in phis]


def _check_sixbar(sk_builder, pose, ref, phis, names):
    mech = sk_builder.mechanism()
    assert _closed_form(mech), "a dyadic linkage takes the closed form"
    sol = jl.solve(mech, phis)
    assert bool(np.all(sol.converged))
    got = np.asarray(sol.points) / mech.units.length
    want = np.asarray([[r[n] for n in names] for r in ref])
    idx = [mech.point_names.index(n) for n in names]
    err = np.max(np.abs(got[:, idx] - want)) / np.max(np.abs(want))
    assert err < 1e-12, err
    return mech


def test_jansen_leg_sketch_matches_circle_intersections():
    """Theo Jansen's leg with his eleven numbers (a = 38, l = 7.8, m = 15, b … k): two plates,
    seven moving links, four dyads, a full turn."""
    a, l_, m, b, c, d, e, f, g, h, i, j, k = 38, 7.8, 15, 41.5, 39.3, 40.1, 55.8, 39.4, 36.7, 65.7, 49, 50, 61.9
    frame = {"O": (0.0, 0.0), "Z": (-a, -l_)}
    up = lambda c1, c2, pos: c1[1] > c2[1]  # noqa: E731
    down = lambda c1, c2, pos: c1[1] < c2[1]  # noqa: E731
    left = lambda c1, c2, pos: c1[0] < c2[0]  # noqa: E731
    dy = [("P1", "M", "Z", j, b, up), ("P2", "M", "Z", k, c, down), ("P3", "Z", "P1", d, e, left),
          ("P4", "P3", "P2", f, g, down), ("P5", "P4", "P2", h, i, down)]
    phis = np.linspace(0, 2 * np.pi, 61)
    pose, ref = _reference(frame, ("O", "M", m), dy, phis, 0.0)
    sk = jl.Sketch("jansen", length_unit="cm", angle_unit="rad").frame("O", 0, 0).frame("Z", -a, -l_)
    for n in ("M", "P1", "P2", "P3", "P4", "P5"):
        sk.joint(n, *pose[n])
    sk.link("crank", "O", "M").link("j", "M", "P1").link("k", "M", "P2").link("bde", "Z", "P1", "P3")
    sk.link("c", "Z", "P2").link("f", "P3", "P4").link("ghi", "P2", "P4", "P5").crank("crank")
    mech = _check_sixbar(sk, pose, ref, phis, ["P1", "P2", "P3", "P4", "P5"])
    assert [d.kind for d in dyads.classify(mech)] == ["RRR"] * 3  # P3 and P5 are on plates


def test_stephenson_iii_and_klann_type_sketches_match_circle_intersections():
    """Stephenson III: a four-bar whose coupler point drives a second dyad to the frame. Klann
    type: two ternary plates (the coupler, the leg) and two rockers."""
    phis = np.linspace(0, 2 * np.pi, 61)
    # Stephenson III: O2 A (crank 1), A B (coupler 3.5, plate with C), O4 B (rocker 3), O2 O4 = 4
    frame = {"O2": (0.0, 0.0), "O4": (4.0, 0.0), "O6": (1.0, 4.5)}
    up = lambda c1, c2, pos: c1[1] > c2[1]  # noqa: E731
    right = lambda c1, c2, pos: c1[0] > c2[0]  # noqa: E731
    dy = [("B", "A", "O4", 3.5, 3.0, up), ("C", "A", "B", 2.0, 2.2, up), ("D", "C", "O6", 2.5, 2.0, right)]
    pose, ref = _reference(frame, ("O2", "A", 1.0), dy, phis + 0.3, 0.3)
    sk = jl.Sketch("stephenson3").frame("O2", 0, 0).frame("O4", 4, 0).frame("O6", 1.0, 4.5)
    for n in ("A", "B", "C", "D"):
        sk.joint(n, *pose[n])
    sk.link("crank", "O2", "A").link("coupler", "A", "B", "C").link("rocker", "O4", "B")
    sk.link("link5", "C", "D").link("output", "O6", "D").crank("crank")
    _check_sixbar(sk, pose, ref, phis + 0.3, ["A", "B", "C", "D"])

    # Klann type: crank M A; coupler plate A B C; rocker O1 B; leg plate C D F; rocker O2 D
    frame = {"M": (0.0, 0.0), "O1": (-2.0, 1.5), "O2": (-3.5, -0.5)}
    dy = [("B", "A", "O1", 3.0, 1.8, up), ("C", "A", "B", 4.2, 2.6, lambda c1, c2, pos: c1[0] < c2[0]),
          ("D", "C", "O2", 1.6, 2.2, up), ("F", "C", "D", 4.5, 5.0, lambda c1, c2, pos: c1[1] < c2[1])]
    pose, ref = _reference(frame, ("M", "A", 0.8), dy, phis, 0.0)
    sk = jl.Sketch("klann").frame("M", 0, 0).frame("O1", -2.0, 1.5).frame("O2", -3.5, -0.5)
    for n in ("A", "B", "C", "D", "F"):
        sk.joint(n, *pose[n])
    sk.link("crank", "M", "A").link("coupler", "A", "B", "C").link("r1", "O1", "B")
    sk.link("leg", "C", "D", "F").link("r2", "O2", "D").crank("crank")
    _check_sixbar(sk, pose, ref, phis, ["B", "C", "D", "F"])


# ----------------------------------------------------------------------------- the file and its errors

FOUR_BAR = """\
[mechanism]
length_unit = "mm"
angle_unit = "deg"

[sketch]
frame = ["A0", "B0"]
points = ["P"]

[sketch.input]
crank = "crank"

[sketch.joints]
A0 = [0, 0]
B0 = [55, 0]
A = [20, 0]
B = [48.0, 44.44]
P = [30.0, 30.0]

[sketch.links]
crank = ["A0", "A"]
coupler = ["A", "B", "P"]
rocker = ["B0", "B"]
"""


@pytest.mark.parametrize("old,new,words,line", [
    ('rocker = ["B0", "B"]\n', "", ["mobility 2 by Grübler", "missing link"], 5),
    ('rocker = ["B0", "B"]', 'rocker = ["B0", "Bx"]', ["'Bx' is not a joint", "did you mean 'B'"], 22),
    ('crank = "crank"', 'crank = "coupler"', ["no frame joint"], 10),
    ('A = [20, 0]', 'A = [20]', ["must be [x, y]"], 15),
    ('[sketch.links]', '[loops]\nx = ["a @ b"]\n\n[sketch.links]', ["derives [loops]"], 19),
    ('rocker = ["B0", "B"]', 'rocker = ["B0", "B"]\nbase = ["A0", "B0"]', ["two frame joints"], 23),
    ('points = ["P"]', 'points = ["P"]\nsliders = 3', ["[sketch.sliders] must be a table"], 8),
    ('crank = "crank"', 'link = "cuopler"', ["'cuopler' is not a link", "did you mean 'coupler'"], 10),
    ('crank = "crank"', 'crank = "crank"\nlink = "coupler"', ["needs one of crank", "slider = "], 9),
    ('crank = "crank"', 'slider = "B"', ["'B' is not a slider of [sketch.sliders]"], 10),
])
def test_bad_sketches_name_the_line_and_the_reason(old, new, words, line):
    assert old in FOUR_BAR
    with pytest.raises(jl.MechanismError) as info:
        jl.loads(FOUR_BAR.replace(old, new, 1), file="fb.toml")
    msg = str(info.value)
    for w in words:
        assert w in msg, (w, msg)
    assert msg.startswith(f"fb.toml:{line}"), msg


def test_sketch_file_checks_and_prints_its_loops(tmp_path, capsys):
    from jaxlink.cli import main

    path = tmp_path / "fb.toml"
    path.write_text(FOUR_BAR)
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "loop_A_B_B0: (A0_x, A0_y) + crank @ theta_crank + coupler @ theta_coupler" in out
    assert "P = (A0_x, A0_y) + crank @ theta_crank + coupler_P @ theta_coupler + coupler_P_angle" in out
    assert "frame A0, B0; links crank (A0 A), coupler (A B P: a plate), rocker (B0 B); input: theta_crank, " \
           "the angle of link crank about A0" in out


def test_sketch_masses_give_the_reactions_of_the_loop_file():
    """slider-crank-mass written as a sketch with [sketch.masses] and the same loads: the drive
    torque and every joint force equal the loop file's (its bodies and joints written by hand)."""
    loop = jl.load("slider-crank-mass")
    start = 0.0
    j = _joints_of("slider-crank-mass", {"A": ["h2 @ psi12"], "B": ["h1 @ alpha1", "p14 @ alpha4"]}, start)
    sk = (jl.Sketch("slider-crank-mass", length_unit="mm", angle_unit="deg")
          .frame("O", 0, 0).joint("A", *j["A"]).joint("B", *j["B"])
          .link("crank", "O", "A").link("rod", "A", "B")
          .slider("B", on="frame", along=(1, 0)).crank("crank"))
    sk.table("environment", {"gravity": [0.0, -9.81]})
    sk.table("loads", {
        "work": {"kind": "force", "body": "B_block", "at": "B", "force": [-200.0, 0.0]},
        "rod_moment": {"kind": "torque", "body": "rod", "torque": 2.0},
        "return_spring": {"kind": "spring", "bodies": ["ground", "B_block"], "from": ["(200, 12)"], "to": "B",
                          "stiffness": 500.0, "length": 60.0, "preload": 10.0}})
    text = sk.toml().replace("[sketch.links]", "[sketch.masses]\n"
                             "crank = { mass = 0.3, centroid = [%r, %r], inertia = 2.0e-4 }\n"
                             "rod = { mass = 0.5, inertia = 2.6667e-4 }\n"
                             "B = { mass = 0.8 }\n\n[sketch.links]" % (j["A"][0] / 3, j["A"][1] / 3))
    mech = jl.loads(text)
    phis = np.radians(np.arange(0.0, 360.0, 15.0))
    _, ra = jl.solve_reactions(loop, phis, omega=30.0, alpha=5.0)
    _, rb = jl.solve_reactions(mech, phis, omega=30.0, alpha=5.0)
    assert bool(np.all(np.asarray(ra.result) == jl.RESULTS.converged))
    assert bool(np.all(np.asarray(rb.result) == jl.RESULTS.converged))
    scale = float(np.abs(np.asarray(ra.torque)).max())
    np.testing.assert_allclose(np.asarray(rb.torque), np.asarray(ra.torque), rtol=0, atol=1e-12 * scale)
    names_a, names_b = loop.bodies.joint_names, mech.bodies.joint_names
    pairs = {"O": "O", "A": "A", "B": "B", "guide": "B_slide"}
    fa, fb = np.asarray(ra.force), np.asarray(rb.force)
    for na, nb in pairs.items():
        a, b = fa[:, names_a.index(na)], fb[:, names_b.index(nb)]
        fscale = float(np.abs(a).max())
        # the same joint may be written with its two bodies the other way round: force or its opposite
        assert min(np.abs(a - b).max(), np.abs(a + b).max()) < 1e-11 * fscale, (na, nb)


def test_whitworth_sketch_equals_loop_form():
    """The Whitworth quick-return as a sketch: the crank pin A slides in the lever's slot through
    its pivot O2 (an RPR dyad), the ram C on a horizontal guide (RRP); both in closed form."""
    loop = jl.load("whitworth")
    mech = _whitworth_sketch().mechanism()
    assert _closed_form(mech) and [d.kind for d in dyads.classify(mech)] == ["RPR", "RRP"]
    _compare(loop, mech, ["A", "B", "C"])


@functools.lru_cache(maxsize=None)  # one build per module run: the tests share it
def _whitworth_sketch():
    j = _joints_of("whitworth", {"A": ["(0, d)", "r @ phi"], "B": ["l @ theta"], "C": ["(0, H)", "x @ 0"]}, 0.0)
    sk = (jl.Sketch("whitworth", length_unit="mm", angle_unit="deg")
          .frame("O2", 0, 0).frame("O1", 0, 300)
          .joint("A", *j["A"]).joint("B", *j["B"]).joint("C", *j["C"])
          .link("crank", "O1", "A").link("lever", "O2", "B").link("rod", "B", "C")
          .slider("A", on="lever", through="O2").slider("C", on="frame", along=(1, 0))
          .crank("crank", name="phi"))
    return sk


def test_a_triad_is_closed_by_newton_and_matches_scipy():
    """A class-III group (a ternary link held by three binary links: no dyad to split off): the
    sketch closes it by the fundamental cycles of what is left, Newton solves it, and its joints
    match scipy's fsolve on the joints' distance equations, continued from the sketch's pose."""
    from scipy.optimize import fsolve

    pos = {"O": (0.0, 0.0), "E": (3.0, 2.5), "F": (4.0, -0.5), "A": (1.0, 0.0), "B": (2.0, 1.2),
           "C": (2.6, 1.6), "D": (3.0, 0.6)}
    sk = jl.Sketch("triad").frame("O", *pos["O"]).frame("E", *pos["E"]).frame("F", *pos["F"])
    for n in "ABCD":
        sk.joint(n, *pos[n])
    sk.link("crank", "O", "A").link("ab", "A", "B").link("tri", "B", "C", "D").link("ec", "E", "C")
    sk.link("fd", "F", "D").crank("crank")
    mech = sk.mechanism()
    assert dyads.classify(mech) is None and len(mech.loops) == 2
    p = {k: np.asarray(v) for k, v in pos.items()}
    bars = [("A", "B"), ("B", "C"), ("B", "D"), ("C", "D"), ("E", "C"), ("F", "D")]
    length = {b: np.linalg.norm(p[b[0]] - p[b[1]]) for b in bars}
    r = np.linalg.norm(p["A"])
    phis = np.arctan2(p["A"][1], p["A"][0]) + np.linspace(0.0, 0.8, 9)

    def equations(x, phi):
        at = {"A": r * np.array([np.cos(phi), np.sin(phi)]), "E": p["E"], "F": p["F"],
              "B": x[0:2], "C": x[2:4], "D": x[4:6]}
        return [np.linalg.norm(at[u] - at[v]) - length[(u, v)] for u, v in bars]

    x = np.concatenate([p["B"], p["C"], p["D"]])
    ref = []
    for phi in phis:
        x = fsolve(equations, x, args=(phi,), xtol=1e-12)
        assert np.abs(equations(x, phi)).max() < 1e-12
        ref.append(x.copy())
    sol = jl.solve(mech, phis)
    assert bool(np.all(sol.converged))
    got = np.asarray(sol.points)[:, [mech.point_names.index(n) for n in "BCD"]].reshape(len(phis), 6)
    assert np.abs(got - np.asarray(ref)).max() < 1e-10


def test_a_designs_sketch_file_moves_the_joints_and_reads_back_as_the_design():
    """The best file of a search on a sketch (`optimize.best_file.file_text`): the joints moved to
    where the design puts them at the start; read back, the same dimensions and branch."""
    from jaxlink.optimize.best_file import file_text

    text = (SCENES / "four-bar-sketch.toml").read_text()
    mech = jl.loads(text, file="fbs.toml")
    p = np.asarray(mech.with_parameters(coupler=64.0, coupler_P=40.0, coupler_P_angle=20.0, B0_y=3.0))
    q = np.asarray(jl.solve(mech, np.asarray([mech.input_start]), p).q[0])
    out = file_text(mech, p, q, text)
    assert "[parameters]" not in out and "# the coupler point" in out  # joints moved, comments kept
    back = jl.loads(out)
    np.testing.assert_allclose(back.parameters, p, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(back.guess, q, rtol=1e-12)
    phis = np.linspace(0.0, 2 * np.pi, 13)
    a, b = jl.solve(mech, phis, p).points, jl.solve(back, phis).points
    assert np.abs(np.asarray(a) - np.asarray(b)).max() < 1e-12 * 0.1


# ----------------------------------------------------------------------------- the designer's numbers
# A sketch's designer's numbers are those of its loop form (issue 48): the same outputs, classified
# by the mechanism's links (a coupler, a connecting rod is never a rocker), and the same Grashof
# lines — whatever the names of the joints, which decide where the derived loops start.


def _docs_sketch(name: str) -> str:
    """The ```toml block `# example: NAME` of docs/reference/file-format.md."""
    import re

    text = (pathlib.Path(__file__).resolve().parent.parent / "docs" / "reference" / "file-format.md").read_text()
    for m in re.finditer(r"^```toml\n(.*?)^```", text, re.S | re.M):
        if m.group(1).startswith(f"# example: {name}\n"):
            return m.group(1)
    raise LookupError(name)


def _klann_pose():
    """A Klann-type leg (crank M Q; arm plate Q B X on the rocker O1 B; leg plate X D F on the
    rocker O2 D) at the crank angle 0 by circle intersections (numpy), in m. Its joints are named
    so that the sketch closes its first loop from the rocker's pivot O1 (`O1` < `Q`)."""
    frame = {"M": (0.0, 0.0), "O1": (-2.0, 1.5), "O2": (-3.5, -0.5)}
    up = lambda c1, c2, pos: c1[1] > c2[1]  # noqa: E731
    dy = [("B", "Q", "O1", 3.0, 1.8, up), ("X", "Q", "B", 4.2, 2.6, lambda c1, c2, pos: c1[0] < c2[0]),
          ("D", "X", "O2", 1.6, 2.2, up), ("F", "X", "D", 4.5, 5.0, lambda c1, c2, pos: c1[1] < c2[1])]
    return _reference(frame, ("M", "Q", 0.8), dy, [], 0.0)[0]


@functools.lru_cache(maxsize=None)
def _klann_sketch():
    pose = _klann_pose()
    sk = jl.Sketch("klann").frame("M", 0, 0).frame("O1", -2.0, 1.5).frame("O2", -3.5, -0.5)
    for n in ("Q", "B", "X", "D", "F"):
        sk.joint(n, *pose[n])
    return (sk.link("crank", "M", "Q").link("arm", "Q", "B", "X").link("r1", "O1", "B")
            .link("leg", "X", "D", "F").link("r2", "O2", "D").crank("crank", name="phi"))


def _klann_loops() -> str:
    """The Klann leg in the loop form, written by hand around its polygons (M → Q → B → O1 → M and
    M → Q → X → D → O2 → M), its numbers from the pose (numpy)."""
    P = {k: np.asarray(v) for k, v in _klann_pose().items()}

    def ang(a, b):
        d = P[b] - P[a]
        return math.atan2(d[1], d[0])

    def dist(a, b):
        return float(np.linalg.norm(P[b] - P[a]))

    foot = math.remainder(ang("X", "F") - ang("X", "D"), 2 * math.pi)
    return f"""
[mechanism]
name = "klann-loops"
[parameters]
crank = {dist("M", "Q")!r}
arm = {dist("Q", "B")!r}
arm_x = {dist("Q", "X")!r}
gamma = {math.remainder(ang("Q", "X") - ang("Q", "B"), 2 * math.pi)!r}
r1 = {dist("O1", "B")!r}
leg = {dist("X", "D")!r}
r2 = {dist("O2", "D")!r}
o1x = -2.0
o1y = 1.5
o2x = -3.5
o2y = -0.5
[input]
name = "phi"
start = 0.0
[unknowns]
th_arm = {ang("Q", "B")!r}
th_r1 = {ang("O1", "B")!r}
th_leg = {ang("X", "D")!r}
th_r2 = {ang("O2", "D")!r}
[loops]
upper = ["crank @ phi", "arm @ th_arm", "-r1 @ th_r1", "-(o1x, o1y)"]
lower = ["crank @ phi", "arm_x @ th_arm + gamma", "leg @ th_leg", "-r2 @ th_r2", "-(o2x, o2y)"]
[points]
F = ["(o2x, o2y)", "r2 @ th_r2", "-leg @ th_leg", "{dist("X", "F")!r} @ th_leg + {foot!r}"]
"""


# (the sketch, its loop form, the sketch's unknowns by the loop form's names)
PAIRS = {
    "docs sketch-four-bar": (lambda: jl.loads(_docs_sketch("sketch-four-bar")), lambda: jl.load("four-bar"),
                             {"theta_coupler": "phi3", "theta_rocker": "phi4"}),
    "docs study-tolerance": (lambda: jl.loads(_docs_sketch("study-tolerance")), lambda: jl.load("four-bar"),
                             {"theta_coupler": "phi3", "theta_rocker": "phi4"}),
    "scene four-bar-sketch": (lambda: jl.load("four-bar-sketch"), lambda: jl.load("four-bar"),
                              {"theta_coupler": "phi3", "theta_rocker": "phi4"}),
    "four-bar": (lambda: _four_bar_sketch().mechanism(), lambda: jl.load("four-bar"),
                 {"theta_coupler": "phi3", "theta_rocker": "phi4"}),
    "docs sketch-slider-crank": (lambda: jl.loads(_docs_sketch("sketch-slider-crank")),
                                 lambda: jl.load("slider-crank"), {"theta_rod": "psi13", "s_B": "p14"}),
    "slider-crank": (lambda: _slider_crank_sketch("slider-crank").mechanism(), lambda: jl.load("slider-crank"),
                     {"theta_rod": "psi13", "s_B": "p14"}),
    "sewing-feed": (lambda: _sewing_feed_sketch("sewing-feed").mechanism(), lambda: jl.load("sewing-feed"),
                    {"theta_coupler": "phi3", "theta_lever": "phi4", "theta_link5": "phi5", "theta_carrier": "phi6"}),
    "needle-arachne": (lambda: _needle_sketch("needle-arachne").mechanism(), lambda: jl.load("needle-arachne"),
                       {"theta_coupler": "phi3", "theta_bellcrank": "psi", "theta_rod": "phi5", "s_B": "s"}),
    "needle-arachne-original": (lambda: _needle_original_sketch().mechanism(),
                                lambda: jl.load("needle-arachne-original"),
                                {"theta_coupler": "phi3", "theta_rocker": "psi", "theta_rod": "phi5", "s_B": "s"}),
    "whitworth": (lambda: _whitworth_sketch().mechanism(), lambda: jl.load("whitworth"),
                  {"theta_lever": "theta", "s_A": "s", "theta_rod": "psi", "s_C": "x"}),
    "luffing cylinder": (lambda: jl.Sketch("luffing", length_unit="mm", angle_unit="deg").frame("O", 0, 0)
                         .frame("C", 300, 0).joint("A", 0, 400).link("boom", "O", "A").actuator("C", "A", name="s")
                         .mechanism(), lambda: jl.load(DATA / "luffing-cylinder.toml"),
                         {"theta_boom": "theta", "theta_C_A": "psi"}),
    "klann": (lambda: _klann_sketch().mechanism(), lambda: jl.loads(_klann_loops()),
              {"theta_arm": "th_arm", "theta_r1": "th_r1", "theta_leg": "th_leg", "theta_r2": "th_r2"}),
}


@pytest.mark.parametrize("pair", list(PAIRS))
def test_a_sketchs_outputs_and_grashof_lines_are_its_loop_forms(pair):
    """For every sketch of the docs and the tests with a loop form: the same outputs, of the same
    kinds (the sketch's by its links, the loop form's by its loops), and the same four-bar loops
    with the same Grashof class, type, shortest link and lengths."""
    from jaxlink.analysis.grashof import four_bars
    from jaxlink.analysis.stroke import _kinds_of_loops, kinds

    make_sketch, make_loops, names = PAIRS[pair]
    sk, lp = make_sketch(), make_loops()
    assert set(sk.unknown_names) == set(names) and set(lp.unknown_names) == set(names.values())
    assert {names[n]: k for n, k in kinds(sk).items()} == kinds(lp)
    assert _kinds_of_loops(sk) == kinds(sk)  # the derived loops are the linkage's polygons
    a, b = four_bars(sk), four_bars(lp)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert (x.grashof, x.type, x.shortest) == (y.grashof, y.type, y.shortest)
        assert set(x.links) == set(y.links)
        for role in x.links:
            assert np.allclose(x.links[role], y.links[role], rtol=1e-12, atol=0), role
        assert np.allclose([x.s, x.longest, x.pq], [y.s, y.longest, y.pq], rtol=1e-12, atol=0)


def test_klann_sketch_designers_numbers_are_its_loop_forms():
    """The Klann leg: the outputs are the two rockers, never the arm or the leg (the couplers); the
    crank–arm–rocker loop is a Grashof crank-rocker (s + l = 0.8 + 3 < p + q = 1.8 + |M O1|, from
    the coordinates); swings, dead centres and transmission angles equal the loop form's."""
    from jaxlink.analysis.grashof import four_bars
    from jaxlink.analysis.motion import motion

    sk, lp = _klann_sketch().mechanism(), jl.loads(_klann_loops())
    (fb,) = four_bars(sk)
    lengths = sorted([0.8, 3.0, 1.8, math.hypot(2.0, 1.5)])
    assert fb.type == "crank-rocker" and lengths[0] + lengths[3] < lengths[1] + lengths[2]
    assert abs(fb.s + fb.longest - (lengths[0] + lengths[3])) < 1e-14
    assert abs(fb.pq - (lengths[1] + lengths[2])) < 1e-14
    ma, mb = motion(sk), motion(lp)
    assert ma.full_turn and mb.full_turn
    assert [(o["name"], o["kind"]) for o in ma.outputs] == [("theta_r1", "rocker"), ("theta_r2", "rocker")]
    assert [o["name"] for o in mb.outputs] == ["th_r1", "th_r2"]
    for x, y in zip(ma.outputs, mb.outputs):
        assert abs(x["stroke"] - y["stroke"]) < 1e-12 and abs(x["time_ratio"] - y["time_ratio"]) < 1e-9
        assert np.allclose(sorted(a for a, _ in x["dead_centres"]), sorted(a for a, _ in y["dead_centres"]),
                           atol=1e-9, rtol=0)
    assert len(ma.transmission) == len(mb.transmission) == 2
    for x, y in zip(ma.transmission, mb.transmission):
        assert abs(x["min"] - y["min"]) < 1e-10 and abs(x["max"] - y["max"]) < 1e-10


# ----------------------------------------------------------------------------- inputs a designer drives
# A floating link's angle and a slider's signed position on its guide as the sketch's input: the
# elliptic trammel (a bar AB, A on the x axis, B on the y axis) driven both ways. A point P of the
# bar at p from A: P = ((p − L) cos θ, p sin θ), on the ellipse x² / (L − p)² + y² / p² = 1.

TRAMMEL_L, TRAMMEL_P = 0.1, 0.03  # the bar's length, P's distance from A along it (m)


def _trammel(drive: str):
    L, p, th = TRAMMEL_L, TRAMMEL_P, math.radians(50.0)
    a, b = (-L * math.cos(th), 0.0), (0.0, L * math.sin(th))
    sk = (jl.Sketch("trammel").frame("O", 0, 0).joint("A", *a).joint("B", *b)
          .joint("P", a[0] + p * math.cos(th), p * math.sin(th)).link("bar", "A", "B", "P")
          .slider("A", on="frame", along=(1, 0)).slider("B", on="frame", along=(0, 1)).points("P"))
    if drive == "link":
        sk.link_angle("bar", name="theta")
    else:
        sk.slider_position("A", name="x")
    return sk.mechanism()


def _off_ellipse(P, a, b) -> float:
    """The largest distance (m) of the points P from the ellipse x²/a² + y²/b² = 1, to first order:
    |F| / |∇F| with F = x²/a² + y²/b² − 1."""
    F = (P[:, 0] / a) ** 2 + (P[:, 1] / b) ** 2 - 1
    return float(np.max(np.abs(F) / np.hypot(2 * P[:, 0] / a**2, 2 * P[:, 1] / b**2)))


def test_elliptic_trammel_driven_by_its_bars_angle_is_exact_on_the_ellipse():
    mech = _trammel("link")
    assert mech.input_name == "theta" and mech.input_kind == "angle"
    assert set(mech.unknown_names) == {"s_A", "s_B"}
    assert _closed_form(mech) and [d.kind for d in dyads.classify(mech)] == ["PP"]
    assert mech.input_start == pytest.approx(math.radians(50.0), abs=1e-15)
    phis = np.linspace(0.0, 2 * np.pi, 49)
    sol = jl.solve(mech, phis)
    assert bool(np.all(sol.converged))
    P = np.asarray(sol.points)[:, 0]
    L, p = TRAMMEL_L, TRAMMEL_P
    want = np.stack([(p - L) * np.cos(phis), p * np.sin(phis)], axis=1)
    assert np.abs(P - want).max() < 1e-15
    assert _off_ellipse(P, L - p, p) < 1e-15
    assert mech.sketch.input == ("link", "bar")


def test_elliptic_trammel_driven_by_a_sliders_signed_position_is_exact_on_the_ellipse():
    mech = _trammel("slider")
    assert mech.input_name == "x" and mech.input_kind == "length"
    assert set(mech.unknown_names) == {"theta_bar", "s_B"}
    assert _closed_form(mech) and [d.kind for d in dyads.classify(mech)] == ["RRP"]
    L, p = TRAMMEL_L, TRAMMEL_P
    assert mech.input_start == pytest.approx(-L * math.cos(math.radians(50.0)), abs=1e-16)  # 15 digits
    xs = np.linspace(-0.099, 0.099, 45)  # signed: A on either side of the origin, B stays above
    sol = jl.solve(mech, xs)
    assert bool(np.all(sol.converged))
    P = np.asarray(sol.points)[:, 0]
    yb = np.sqrt(L * L - xs * xs)  # B = (0, yb), the sketch's branch (above)
    want = np.stack([xs * (L - p) / L, p * yb / L], axis=1)  # P = A + p (B − A) / L
    assert np.abs(P - want).max() < 1e-15
    assert _off_ellipse(P, L - p, p) < 1e-15
    assert mech.sketch.input == ("slider", "A")
    # its range: signed, between the toggles where the bar lies on the x axis (B at the origin)
    m = jl.motion(mech)
    assert abs(m.lower + L) < 1e-15 and abs(m.upper - L) < 1e-15
