"""The command line's reports: where the linkage drawing puts every joint (against joint positions
derived by hand from each scene's geometry), tables whose rows that did not assemble are not data,
the joint-variable rates, exact input columns, input ranges in the warnings, plots and animations."""

import csv
import io
import math

import matplotlib
import numpy as np
import pytest
import tomllib
from closed_forms import fourbar_freudenstein, slider_crank_offset

import jaxlink as jl
from jaxlink.cli import main
from jaxlink.report import grid, plot
from jaxlink.report.kinematics import kinematics_table, write_csv
from jaxlink.scenes import scene_paths

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PHIS = np.deg2rad(np.arange(0.0, 360.0, 15.0))


def e(t):
    return np.stack([np.cos(t), np.sin(t)], axis=-1)


# ----------------------------------------------------------------------------- expected joints by hand
# Each returns ({name: (N, 2) position}, [names of the ground pivots]) from the parameters (SI), the
# solved unknowns q (N, n) and the inputs, following the geometry the scene's comments describe.


def fourbar_joints(v, phi):
    A = v["a"] * e(phi)
    return {"A0": 0 * A, "A": A, "B": A + v["b"] * e(v["phi3"]), "B0": np.array([v["d"], 0.0]) + 0 * A}, ["A0", "B0"]


def slider_crank_joints(v, phi):
    A = v["h2"] * e(phi)
    B = v["h1"] * e(v["alpha1"]) + v["p14"][:, None] * e(v["alpha4"])
    return {"O": 0 * A, "A": A, "B": B}, ["O"]


def sewing_joints(v, phi):
    B = v["l2"] * e(phi)
    D = B + v["l3"] * e(v["phi3"])
    F = D + v["l4"] * e(v["phi4"])
    return {"A": 0 * B, "B": B, "C": -v["l22"] * e(phi + v["gamma"]), "D": D,
            "E": np.array([v["l8"], v["l7"]]) + 0 * B, "F": F, "H": F + v["l6"] * e(v["phi6"])}, ["A", "E"]


def needle_joints(v, phi):
    A = v["l2"] * e(phi)
    C0 = np.array([v["l1"], 0.0]) + 0 * A
    B = np.stack([v["l1"] + v["l7"] + 0 * phi, v["s"]], axis=-1)
    return {"A0": 0 * A, "A": A, "C": A + v["l3"] * e(v["phi3"]), "C0": C0,
            "D": C0 + v["l4a"] * e(v["psi"] - v["beta"]), "B": B}, ["A0", "C0"]


def needle_original_joints(v, phi):
    A = v["l2"] * e(phi)
    C = A + v["l3"] * e(v["phi3"])  # the rod is hinged at C itself (D = C)
    B = np.stack([v["l1"] - v["l7"] + 0 * phi, v["s"]], axis=-1)
    return {"A0": 0 * A, "A": A, "C": C, "C0": np.array([v["l1"], v["l6"]]) + 0 * A, "B": B}, ["A0", "C0"]


EXPECTED = {
    "four-bar": fourbar_joints,
    "slider-crank": slider_crank_joints,
    "slider-crank-mass": slider_crank_joints,
    "sewing-feed": sewing_joints,
    "sewing-feed-opt": sewing_joints,
    "needle-arachne": needle_joints,
    "needle-dwell": needle_joints,
    "needle-arachne-unit": needle_joints,
    "needle-arachne-original": needle_original_joints,
}

FOURBAR_ORDERS = {
    "reordered": '["-d @ 0", "a @ phi2", "b @ phi3", "-c @ phi4"]',  # the example
    "reversed": '["d @ 0", "c @ phi4", "-b @ phi3", "-a @ phi2"]',  # the same loop walked backwards
    "rotated": '["-c @ phi4", "-d @ 0", "a @ phi2", "b @ phi3"]',
}


def linkage_scenes():
    out = []
    for name, path in scene_paths().items():
        if tomllib.loads(path.read_text()).get("mechanism", {}).get("kind") != "cam-follower":
            out.append(name)
    return out


def values(mech, q):
    v = {n: float(x) for n, x in zip(mech.parameter_names, np.asarray(mech.parameters))}
    v.update({n: np.asarray(q)[:, j] for j, n in enumerate(mech.unknown_names)})
    return v


def drawn(mech, phis=PHIS):
    """Solve, draw the linkage with the plot's artists at every position, and return what was drawn
    (metres): joints per position, ground symbols, points, link segments, slider blocks."""
    sol = jl.solve(mech, phis)
    ok = np.asarray(sol.converged)
    table = kinematics_table(mech, phis, outputs=("position",))
    fig, ax = plt.subplots()
    s, _ = plot.length_unit(mech)
    art = plot.LinkageArtist(ax, plot.linkage_drawing(mech, table), s)
    out = {"joints": [], "points": [], "links": [], "blocks": []}
    for k in range(len(phis)):
        art.update(k)
        x, y = art.joint_marks.get_data()
        out["joints"].append(np.stack([x, y], axis=1) / s)
        out["points"].append(np.array([m.get_data() for m in art.point_marks]).reshape(-1, 2) / s)
        links = []
        for kinds, row in zip(art.d.kinds, art.segments):
            links += [np.stack(ln.get_data(), axis=1) / s for kind, ln in zip(kinds, row) if kind == "link"]
        out["links"].append(links)
        out["blocks"].append([patch.get_xy()[:4].mean(axis=0) / s for patch in art.blocks])
    out["ground"] = art.ground_xy / s
    plt.close(fig)
    return sol, ok, out


def assert_same_set(got, want, tol, what):
    got, want = np.asarray(got).reshape(-1, 2), np.asarray(want).reshape(-1, 2)
    assert len(got) == len(want), (what, got, want)
    for w in want:
        assert np.min(np.linalg.norm(got - w, axis=1)) < tol, (what, w, got)


def check_scene(mech, joints_of):
    sol, ok, out = drawn(mech)
    assert ok.all()
    v = values(mech, sol.q)
    expected, ground = joints_of(v, PHIS)
    tol = 1e-12 * float(mech.length_scale(mech.parameters))
    for k in range(len(PHIS)):
        want = np.array([expected[n][k] for n in expected])
        assert_same_set(out["joints"][k], want, tol, f"joints at position {k}")
        np.testing.assert_allclose(out["points"][k], np.asarray(sol.points)[k], rtol=0, atol=tol)
        for seg in out["links"][k]:  # every bar runs between two of the joints
            for end in seg:
                assert np.min(np.linalg.norm(want - end, axis=1)) < tol, ("a link ends off the joints", end)
    assert_same_set(out["ground"], np.array([expected[n][0] for n in ground]), tol, "ground pivots")
    return out, expected


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_drawn_joints_are_the_mechanism_joints(name):
    out, expected = check_scene(jl.load(name), EXPECTED[name])
    for k in range(len(PHIS)):
        if name.startswith(("slider-crank", "needle")):  # one slider, its block on the slider's joint B
            assert_same_set(out["blocks"][k], expected["B"][k][None], 1e-9, "slider block")
        else:
            assert out["blocks"][k] == []


@pytest.mark.parametrize("order", sorted(FOURBAR_ORDERS))
def test_loop_order_does_not_move_the_drawing(tmp_path, order):
    text = scene_paths()["four-bar"].read_text()
    text = text.replace('main = ["a @ phi2", "b @ phi3", "-c @ phi4", "-d @ 0"]', f"main = {FOURBAR_ORDERS[order]}")
    path = tmp_path / "four-bar.toml"
    path.write_text(text)
    check_scene(jl.load(str(path)), fourbar_joints)
    # without a [points] table nothing but the frame origin is known: the crank's pivot is put there
    path.write_text(text.split("[points]")[0])
    check_scene(jl.load(str(path)), fourbar_joints)


def test_every_scene_draws_its_points_and_file_joints():
    """For any built-in linkage (also ones added later): the drawn points are the solved points, and
    every revolute joint of a [joints] table is drawn where its `at` puts it."""
    names = linkage_scenes()
    assert set(EXPECTED) <= set(names)
    for name in names:
        mech = jl.load(name)
        sol, ok, out = drawn(mech)
        for k in np.flatnonzero(ok):
            np.testing.assert_allclose(out["points"][k], np.asarray(sol.points)[k], atol=1e-12)
        if mech.bodies is None:
            continue
        v = values(mech, sol.q)
        for j in mech.bodies.joints:
            if j.kind != "revolute":
                continue
            pos = sum(_term(t, v, PHIS, mech) for t in j.at)
            for k in np.flatnonzero(ok):
                assert np.min(np.linalg.norm(out["joints"][k] - pos[k], axis=1)) < 1e-12, (name, j.name)


def _term(term, v, phi, mech):
    """A term's vector (N, 2) at the solved positions, by the file's expression evaluator."""
    p = np.asarray(mech.parameters)
    q = np.stack([v[n] for n in mech.unknown_names], axis=1)
    out = []
    for qk, pk in zip(q, phi):
        x, y = mech.term_vector(term, mech.env(qk, pk, p))
        out.append([float(x), float(y)])
    return np.array(out)


# ----------------------------------------------------------------------------- tables


def run_cli(capsys, *args):
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def read_csv(path):
    rows = list(csv.reader(open(path)))
    return rows[0], rows[1:]


def test_unassembled_rows_are_not_data(tmp_path, capsys):
    """The issue's acceptance: --set b=40 --set c=30 cannot turn through 180°; every row that did
    not converge is nan in every solved column, names its result, and the warning gives the range."""
    out = tmp_path / "C.csv"
    code, stdout, stderr = run_cli(capsys, "kinematics", "four-bar", "--set", "b=40", "--set", "c=30",
                                   "--csv", str(out))
    assert code == 1
    head, rows = read_csv(out)
    assert head[-3:] == ["converged", "residual_m", "result"]
    a, b, c, d = 0.020, 0.040, 0.030, 0.055
    deg = np.arange(0.0, 360.0, 5.0)
    dist = np.hypot(d - a * np.cos(np.deg2rad(deg)), -a * np.sin(np.deg2rad(deg)))
    reach = (dist <= b + c) & (dist >= abs(b - c))
    conv = np.array([r[head.index("converged")] == "1" for r in rows])
    np.testing.assert_array_equal(conv, reach)
    solved = [i for i, h in enumerate(head) if h not in ("input_deg", "converged", "residual_m", "result")]
    for r in rows:
        if r[head.index("converged")] == "0":
            assert r[head.index("result")] == "cannot_assemble"
            assert all(r[i] in ("", "nan") for i in solved), r
            assert math.isfinite(float(r[head.index("residual_m")]))
        else:
            assert r[head.index("result")] == "converged"
            assert all(math.isfinite(float(r[i])) for i in solved)
    bad = deg[~reach]
    assert f"cannot_assemble at {bad.min():g}°–{bad.max():g}°" in stderr
    # the summary's min/max are over the reachable rows only: the rocker angle of the closed form
    phi4 = np.mod(fourbar_freudenstein(a, b, c, d, np.deg2rad(deg[reach]), -1)[1], 2 * np.pi)
    line = next(x for x in stdout.splitlines() if x.startswith("phi4_rad"))
    lo, hi = map(float, line.split()[1:])
    assert abs(lo - phi4.min()) < 1e-5 and abs(hi - phi4.max()) < 1e-5
    assert "19 positions not assembled" in stdout


def test_singular_rows_keep_positions_not_rates():
    """At the dead centre of the non-Grashof four-bar (b + c = |A − B0|) the position is assembled
    (`singular`): its points are data, its rates (unbounded there) are not."""
    mech = jl.load("four-bar", overrides={"b": 40.0, "c": 30.0})
    a, d, cx, cy = 0.020, 0.055, 0.030, 0.015
    phi_t = math.acos((a * a + d * d - 0.070**2) / (2 * a * d))
    t = kinematics_table(mech, np.array([0.0, phi_t / 2, phi_t]), outputs=("position", "velocity", "rates"))
    np.testing.assert_array_equal(t.result, [jl.RESULTS.converged, jl.RESULTS.converged, jl.RESULTS.singular])
    A = a * e(phi_t)
    u = (np.array([d, 0.0]) - A) / np.linalg.norm(np.array([d, 0.0]) - A)  # coupler along A -> B0
    P = A + cx * u + cy * np.array([-u[1], u[0]])
    assert abs(t.column("P_x_m")[-1] - P[0]) < 1e-6 and abs(t.column("P_y_m")[-1] - P[1]) < 1e-6
    assert np.isnan(t.column("phi3_rad_s")[-1]) and np.isnan(t.column("P_vx_m_s")[-1])
    assert np.isfinite(t.column("phi3_rad_s")[:2]).all()
    assert t.converged.tolist() == [True, True, False] and t.assembled.all()


def test_joint_variable_rates(tmp_path, capsys):
    """--outputs rates: q̇ = μ ω and q̈ = ν ω² of the rod angle and the slider, against central
    differences of the closed form at 600 rpm."""
    out = tmp_path / "sc.csv"
    code, _, _ = run_cli(capsys, "kinematics", "slider-crank", "--outputs", "position,rates", "--rpm", "600",
                         "--step", "10", "--csv", str(out))
    assert code == 0
    head, rows = read_csv(out)
    assert head == ["input_deg", "psi13_rad", "psi13_rad_s", "psi13_rad_s2", "p14_m", "p14_m_s", "p14_m_s2",
                    "A_x_m", "A_y_m", "B_x_m", "B_y_m", "converged", "residual_m", "result"]
    data = np.array([[float(x) for x in r[:-1]] for r in rows])
    phi = np.deg2rad(data[:, 0])
    w = 600 * 2 * np.pi / 60
    h = 1e-4

    def f(x):
        return np.stack(slider_crank_offset(0.012, np.pi / 2, 0.025, 0.080, 0.0, x))

    d1 = (f(phi + h) - f(phi - h)) / (2 * h)
    d2 = (f(phi + h) - 2 * f(phi) + f(phi - h)) / h**2
    np.testing.assert_allclose(data[:, 2], d1[0] * w, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(data[:, 5], d1[1] * w, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(data[:, 3], d2[0] * w * w, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(data[:, 6], d2[1] * w * w, rtol=1e-4, atol=1e-4)


def test_input_column_prints_as_asked(tmp_path, capsys):
    out = tmp_path / "f.csv"
    code, _, _ = run_cli(capsys, "kinematics", "four-bar", "--outputs", "position", "--start", "0.1", "--step",
                         "0.1", "--count", "4", "--csv", str(out))
    assert code == 0
    assert [r[0] for r in read_csv(out)[1]] == ["0.1", "0.2", "0.3", "0.4"]
    code, _, _ = run_cli(capsys, "kinematics", "four-bar", "--outputs", "position", "--step", "3", "--csv", str(out))
    assert [r[0] for r in read_csv(out)[1]][:6] == ["0.0", "3.0", "6.0", "9.0", "12.0", "15.0"]


def test_csv_to_standard_output(capsys):
    code, stdout, stderr = run_cli(capsys, "kinematics", "four-bar", "--outputs", "position", "--count", "3",
                                   "--csv", "-")
    assert code == 0
    rows = list(csv.reader(io.StringIO(stdout)))
    assert rows[0][0] == "input_deg" and len(rows) == 4
    assert "positions" in stderr  # the summary goes to standard error


def test_reactions_table_results_and_reduced_peaks(tmp_path, capsys):
    out = tmp_path / "r.csv"
    code, _, stderr = run_cli(capsys, "reactions", "slider-crank-mass", "--set", "h3=20", "--csv", str(out))
    assert code == 1
    head, rows = read_csv(out)
    assert head[-2:] == ["drive_torque_N_m", "result"]
    # h2 = 25, h3 = 20, offset 12: B is reachable while |12 − 25 sin φ| ≤ 20
    deg = np.array([float(r[0]) for r in rows])
    reach = np.abs(12.0 - 25.0 * np.sin(np.deg2rad(deg))) <= 20.0
    for r, ok in zip(rows, reach):
        assert (r[-1] == "converged") == ok, r
        assert all(math.isfinite(float(x)) for x in r[1:-1]) == ok
    assert "cannot_assemble at " + f"{deg[~reach].min():g}°–{deg[~reach].max():g}°" in stderr
    # a grid past 360°: peaks are reported at angles in [0, 360)
    code, stdout, _ = run_cli(capsys, "reactions", "slider-crank-mass", "--rpm", "600", "--start", "200", "--step",
                              "5")
    assert code == 0
    lines = [x for x in stdout.splitlines()[3:] if x and not x.startswith("(")]  # after the input line and the header
    angles = [float(x.split()[-1]) if "N·m" not in x else float(x.split()[-4]) for x in lines]
    assert len(angles) == 5 and all(0 <= a < 360 for a in angles)


# ----------------------------------------------------------------------------- input ranges, plots


def test_runs_wrap_around_a_full_turn():
    deg = np.arange(0.0, 360.0, 10.0)
    bad = (deg >= 340) | (deg <= 20) | ((deg >= 100) & (deg <= 120))
    assert grid.runs(bad, periodic=True) == [(34, 2), (10, 12)]
    assert grid.format_runs(deg, grid.runs(bad, True), "angle") == "340°–20°, 100°–120°"
    assert grid.runs(bad, periodic=False)[0] == (0, 2)
    assert grid.full_turn(np.deg2rad(deg), "angle") and not grid.full_turn(np.deg2rad(deg[:-1]), "angle")
    assert grid.format_value(375.0, "angle") == "15°"


def test_robust_limits_leave_out_a_spike():
    x = np.linspace(0, 2 * np.pi, 72)
    y = np.sin(x)
    assert plot.robust_limits(y) is None
    y[30] = 500.0  # a toggle's spike
    lo, hi, note = plot.robust_limits(y)
    assert -1.5 < lo < -0.9 and 0.9 < hi < 2.5 and "500" in note


def test_plot_and_animation(tmp_path, capsys):
    png, gif = tmp_path / "n.png", tmp_path / "n.gif"
    code, _, stderr = run_cli(capsys, "kinematics", "needle-arachne", "--rpm", "600", "--step", "30",
                              "--plot", str(png), "--animate", str(gif))
    assert code == 0
    assert png.stat().st_size > 10_000
    from PIL import Image

    im = Image.open(gif)
    assert im.n_frames == 12
    assert "frame" in stderr  # the progress bar


def test_written_table_round_trips():
    mech = jl.load("slider-crank")
    t = kinematics_table(mech, np.deg2rad([0.0, 30.0]), outputs=("position",), input_values=[0.0, 30.0])
    buf = io.StringIO()
    write_csv(buf, t)
    rows = list(csv.reader(io.StringIO(buf.getvalue())))
    assert [float(x) for x in rows[1][1:-3]] == list(t.data[0, 1:-3])
