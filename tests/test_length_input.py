"""A length as the input (a hydraulic cylinder, a driven slider), as first-class as an angle: the
command-line grid (--start/--step/--stop/--count, no default range, --rpm refused), the drive
force of `reactions` against closed forms (statics by virtual work, the power balance at speed, a
cylinder modelled as barrel and rod), and a design search over the stroke.

The file is tests/data/luffing-cylinder.toml: a boom pivoted at O = (0, 0) (angle θ), a cylinder
from the frame pivot C = (d, 0) to the boom's point A = r e(θ), of length s. From the triangle
OCA, cos θ = (r² + d² − s²) / (2 r d), so θ' = dθ/ds = s / (r d sin θ) and
θ'' = (1 − s cos θ θ' / sin θ) / (r d sin θ).
"""

from __future__ import annotations

import argparse
import math
import pathlib

import jax
import numpy as np
import pytest

import jaxlink as jl
from jaxlink.cli import main
from jaxlink.cli.mechanism import grid_values
from jaxlink.errors import MechanismError

jax.config.update("jax_enable_x64", True)

FILE = pathlib.Path(__file__).parent / "data" / "luffing-cylinder.toml"
R, D, G, L = 0.4, 0.3, 0.6, 1.2  # m (the file's r, d, g, L)
M, J, W, GRAV = 80.0, 12.0, 500.0, 9.81  # boom mass kg, inertia kg m², payload N, gravity m/s²


@pytest.fixture(scope="module")
def boom():
    return jl.load(FILE)


def closed_form(s):
    """θ, θ', θ'' of the boom at cylinder lengths s (m)."""
    th = np.arccos((R * R + D * D - s * s) / (2 * R * D))
    d1 = s / (R * D * np.sin(th))
    d2 = (1.0 - s * np.cos(th) * d1 / np.sin(th)) / (R * D * np.sin(th))
    return th, d1, d2


def cylinder_force(s, v):
    """The cylinder's force (N) at constant speed v (m/s), by the power balance
    F v = d/dt (T + V) + (the payload's power, negated): with G = g e(θ), T = ½ (m g² + J) θ̇²,
    V = m 9.81 g sin θ, the payload W at L e(θ): F = (m g² + J) θ' θ'' v² + (m 9.81 g + W L) cos θ θ'
    (v = 0: statics by virtual work, F δs = −Σ loads·δr)."""
    th, d1, d2 = closed_form(s)
    return (M * G * G + J) * d1 * d2 * v * v + (M * GRAV * G + W * L) * np.cos(th) * d1


S = np.linspace(0.2, 0.65, 10)  # the stroke (m), away from the toggles s = d ± r


# ----------------------------------------------------------------------------- the command line grid


def ns(**kw):
    base = {"start": None, "step": None, "stop": None, "count": None}
    return argparse.Namespace(**{**base, **kw})


def test_grid_of_a_length_and_of_an_angle_input(boom):
    four = jl.load("four-bar")
    # a length input has no default range (not 73 steps of 5 mm)
    with pytest.raises(MechanismError, match="no default range.*--stop"):
        grid_values(boom, ns())
    with pytest.raises(MechanismError, match="no default range"):
        grid_values(boom, ns(step=10.0))
    # --stop alone: 73 positions from [input] start (500 mm) to --stop
    g = grid_values(boom, ns(stop=644.0))
    assert len(g) == 73 and g[0] == 500.0 and g[-1] == 644.0 and np.allclose(np.diff(g), 2.0)
    # --stop with --step fixes the count (the last position at or before --stop), exact decimals
    assert grid_values(boom, ns(start=200.0, step=0.1, stop=200.35)).tolist() == [200.0, 200.1, 200.2, 200.3]
    assert grid_values(boom, ns(start=650.0, step=-50.0, stop=500.0)).tolist() == [650.0, 600.0, 550.0, 500.0]
    # --stop with --count gives the spacing, the last value exactly --stop
    assert grid_values(boom, ns(start=0.1, stop=0.3, count=3)).tolist() == [0.1, 0.2, 0.3]
    assert grid_values(boom, ns(start=200.0, step=25.0, count=3)).tolist() == [200.0, 225.0, 250.0]
    for bad, words in ((ns(step=5.0, stop=600.0, count=3), "not all three"),
                       (ns(start=600.0, step=5.0, stop=500.0), "runs away"),
                       (ns(start=600.0, stop=500.0, count=1), "--count 1")):
        with pytest.raises(MechanismError, match=words):
            grid_values(boom, bad)
    # an angle input: a revolution by default, --stop in degrees, 5° by default
    assert len(grid_values(four, ns())) == 72
    assert grid_values(four, ns(stop=20.0)).tolist() == [0.0, 5.0, 10.0, 15.0, 20.0]
    assert grid_values(four, ns(start=10.0, stop=-10.0)).tolist() == [10.0, 5.0, 0.0, -5.0, -10.0]
    assert grid_values(four, ns(stop=90.0, count=4)).tolist() == [0.0, 30.0, 60.0, 90.0]


def test_kinematics_and_reactions_commands_on_a_cylinder(capsys, tmp_path):
    code = main(["kinematics", str(FILE), "--rpm", "60", "--stop", "600"])
    err = capsys.readouterr().err
    assert code == 2 and "--rpm 60" in err and "--omega in m/s" in err
    assert main(["reactions", str(FILE)]) == 2
    assert "no default range" in capsys.readouterr().err
    out = tmp_path / "r.csv"
    code = main(["reactions", str(FILE), "--start", "200", "--stop", "650", "--count", "10", "--omega", "0",
                 "--csv", str(out)])
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert "input       s (length) from 200 mm to 650 mm, step 50 mm: 10 positions" in printed
    rows = [line.split(",") for line in out.read_text().splitlines()]
    assert rows[0] == ["input_m", "O_Fx_N", "O_Fy_N", "drive_force_N", "result"]
    data = np.array([r[:-1] for r in rows[1:]], dtype=float)
    assert np.allclose(data[:, 0], S, rtol=0, atol=1e-15)
    np.testing.assert_allclose(data[:, 3], cylinder_force(S, 0.0), rtol=1e-9, atol=1e-9)


# ----------------------------------------------------------------------------- the drive force


def test_cylinder_force_against_virtual_work_and_the_power_balance(boom):
    th = closed_form(S)[0]
    u = np.stack([R * np.cos(th) - D, R * np.sin(th)], axis=1) / S[:, None]  # C → A
    for v in (0.0, 0.8):
        sol, r = jl.solve_reactions(boom, S, omega=v)
        assert np.all(np.asarray(r.result) == jl.RESULTS.converged)
        np.testing.assert_allclose(np.asarray(sol.q)[:, 0], th, rtol=1e-12)
        F = np.asarray(r.drive)
        np.testing.assert_allclose(F, cylinder_force(S, v), rtol=1e-9)
        if v == 0.0:  # the pivot O holds the boom against the cylinder, its weight and the payload
            pivot = np.asarray(r.force)[:, 0]
            np.testing.assert_allclose(pivot + F[:, None] * u + [0.0, -M * GRAV - W], 0.0, atol=1e-9 * np.abs(F).max())


BARREL_ROD = """
[bodies.barrel]
angle = "psi"
[bodies.rod]
angle = "psi"
[joints.C]
bodies = ["ground", "barrel"]
at = ["(d, 0)"]
[joints.A]
bodies = ["rod", "boom"]
at = ["r @ theta"]
[joints.slide]
bodies = ["barrel", "rod"]
kind = "prismatic"
at = ["r @ theta"]
axis = "psi"
"""


def test_a_cylinder_as_barrel_and_rod_pushing_off_its_barrel():
    """The cylinder modelled as two massless bodies sliding in each other, the drive between them
    (`base = "barrel"`): the same force as the two-force member, the same pivot O, and the frame
    pivot C carrying the cylinder's force; an axis reversed is refused by the direction check."""
    text = FILE.read_text().replace('body = "boom"        # the cylinder pushes the boom',
                                    'body = "rod"\nbase = "barrel"')
    text = text.replace("[loads.payload]", BARREL_ROD + "\n[loads.payload]")
    mech = jl.loads(text)
    names = mech.bodies.body_names
    assert names[mech.bodies.input_base] == "barrel" and names[mech.bodies.input_body] == "rod"
    sol, r = jl.solve_reactions(mech, S, omega=0.0)
    F = np.asarray(r.drive)
    np.testing.assert_allclose(F, cylinder_force(S, 0.0), rtol=1e-9)
    th = closed_form(S)[0]
    u = np.stack([R * np.cos(th) - D, R * np.sin(th)], axis=1) / S[:, None]
    f = np.asarray(r.force)  # joints O, C, A, slide
    # the ground holds the barrel against the drive's reaction −F u: it pushes it with F u at C
    np.testing.assert_allclose(f[:, 1], F[:, None] * u, atol=1e-9 * np.abs(F).max())
    assert np.abs(np.asarray(r.moment)[:, 3]).max() < 1e-9 * np.abs(F).max() * R  # a two-force member
    from jaxlink.analysis.kinetostatics import drive_errors

    q = np.asarray(sol.q)
    assert drive_errors(mech, q, S) == []
    reversed_ = jl.loads(text.replace('axis = "psi"         # along', 'axis = "psi + 180"  # along'))
    msg = drive_errors(reversed_, q, S)
    assert len(msg) == 1 and "[input] axis" in msg[0] and "= -1, not 1" in msg[0]


@pytest.mark.parametrize("change,words", [
    (('at = ["r @ theta"]   # at A\n', ""), "needs 'at'"),
    (('axis = "psi"', 'axis = "r"'), "is a length where an angle is expected"),
    (('body = "boom"        # the cylinder pushes the boom', 'body = "boom"\nbase = "boom"'), "the driven body"),
])
def test_a_drive_force_needs_its_point_and_direction(change, words):
    with pytest.raises(MechanismError, match=words):
        jl.loads(FILE.read_text().replace(*change))


def test_an_angle_input_drive_takes_no_axis():
    text = jl.load("slider-crank-mass").file
    src = pathlib.Path(text).read_text().replace('body = "crank"', 'body = "crank"\naxis = "90"', 1)
    with pytest.raises(MechanismError, match="'axis' is for a length input"):
        jl.loads(src)


# ----------------------------------------------------------------------------- a design search


def test_design_search_over_the_stroke(boom):
    from jaxlink.optimize import problem_from, run
    from jaxlink.optimize.objectives.path import segment_distances2

    pr = problem_from(boom)
    assert not pr.periodic and pr.phis[0] == 0.3 and pr.phis[-1] == 0.6 and len(pr.phis) == 24
    for over, words in (({"stop": None}, "give 'stop'"), ({"objective": "ellipse", "axes": [1, 1]}, "open")):
        with pytest.raises(MechanismError, match=words):
            problem_from(boom, over)
    with pytest.raises(MechanismError, match="'stop' is for a length input"):
        problem_from(jl.load("sewing-feed-opt"), {"stop": 10.0})
    # the open path has no closing chord: a target on the chord of a half circle is far from it
    half = np.stack([np.cos(np.linspace(0, np.pi, 9)), np.sin(np.linspace(0, np.pi, 9))], axis=1)
    t = np.array([[0.0, 0.0]])
    assert float(np.min(segment_distances2(half, t))) < 1e-30
    assert float(np.min(segment_distances2(half, t, closed=False))) == pytest.approx(math.cos(math.pi / 16) ** 2)
    # the targets lie on the file's design (r = 400, d = 300), one point of the 3 × 3 grid
    res = run(pr, "uniform", budget=25)  # a 3 × 3 grid on both circuits
    assert res.parameters == {"r": 400.0, "d": 300.0}
    # on the path, up to the chords of the 240 positions of the report: the sagitta r Δθ²/8 (mm)
    th = closed_form(np.array([0.3, 0.6]))[0]
    sagitta = 400.0 * ((th[1] - th[0]) / 239) ** 2 / 8
    assert 0 < res.value <= 3 * sagitta**2
    assert res.certificate["certificate"] == "dense re-solve" and res.certificate["certified"]


def test_designers_numbers_of_an_oscillating_cylinder(capsys):
    """The cylinder from C = (d, 0) to the boom's point A (|OA| = r < d): its length runs between
    the toggles d − r (boom and cylinder in line, A between O and C) and d + r; over that range
    the boom swings π, the cylinder sin⁻¹(r/d) (its extreme where it is tangent to A's circle, at
    s = √(d² − r²), a dead centre), and the angle between them at A, cos μ = (r² + s² − d²) /
    (2 r s), runs from π to 0."""
    from jaxlink.analysis.motion import motion

    r, d = 0.25, 0.3
    mech = jl.load(FILE, overrides={"r": 250.0})
    m = motion(mech)
    assert abs(m.lower - (d - r)) < 1e-15 and abs(m.upper - (d + r)) < 1e-15
    assert (m.low, m.high) == (m.lower, m.upper)
    outs = {o["name"]: o for o in m.outputs}
    assert [(o["name"], o["kind"]) for o in m.outputs] == [("theta", "rocker"), ("psi", "rocker")]
    assert abs(outs["theta"]["stroke"] - math.pi) < 1e-7  # the root of a toggle: √ of a float's spacing
    psi = outs["psi"]
    assert abs(psi["stroke"] - math.asin(r / d)) < 1e-7
    ((at, value),) = psi["dead_centres"]
    assert abs(at - math.sqrt(d * d - r * r)) < 1e-12 and abs(value - (math.pi - math.asin(r / d))) < 1e-12
    (t,) = m.transmission
    assert t["kind"] == "RRR" and abs(t["min"]) < 1e-7 and abs(t["max"] - math.pi) < 1e-7
    assert abs(t["min_at"] - (d + r)) < 1e-9 and abs(t["max_at"] - (d - r)) < 1e-9
    # the command prints them in the file's units
    assert main(["check", str(FILE), "--set", "r=250"]) == 0
    out = capsys.readouterr().out
    assert "motion      s from 50 mm to 550 mm (limit positions: toggles), a range of 500 mm" in out
    assert f"rocker psi: swing {math.degrees(math.asin(r / d)):.6f}" in out
