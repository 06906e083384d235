"""Timed targets in path synthesis: points to be reached at given crank angles (a CSV column
`theta_deg`), matched by the ordered distance. The reading, the distance against an independent
minimisation over the rotation, its smooth surrogate, a planted four-bar recovered with its
timing and replayed by `jaxlink kinematics`, and the check between samples."""

import csv
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from jaxlink.cli import main as cli_main
from jaxlink.errors import MechanismError
from jaxlink.synthesis import distance as D
from jaxlink.synthesis import topology as T
from jaxlink.synthesis.api import synthesize
from jaxlink.synthesis.search import score, timed_samples
from jaxlink.synthesis.target import load_target, make_target
from jaxlink.synthesis.tracer import trace_exact

#: the designer's bounds off (`jaxlink.synthesis.bounds`): the unbounded search these tests were made for
OFF = dict(min_transmission=None, max_size=None, max_pivot=None)
OFF_CLI = ["--min-transmission", "0", "--max-size", "none", "--max-pivot", "none"]

FOUR_BAR = T.topologies()[0]
POSE = np.array([[0, 0], [1.0, 0], [0, 0], [0.3, 0.0], [1.1, 0.8], [0.5, 0.9]])


def _write(path, header, rows):
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(repr(float(v)) for v in r) for r in rows))


def test_timed_csv_and_npy(tmp_path):
    """A `theta_deg` (or `theta_rad`, `crank_deg`…) column makes a target timed, in radians; points
    are kept as given (a dwell repeats one); the angles must go one way and span less than a turn."""
    f = tmp_path / "t.csv"
    _write(f, ["theta_deg", "x_mm", "y_mm"], [[10, 0, 0], [20, 1, 0], [30, 1, 0], [50, 1, 1]])
    t = load_target(f)
    assert t.timed and t.unit == "mm" and len(t.points) == 4
    assert np.allclose(t.inputs, np.radians([10, 20, 30, 50]), rtol=0, atol=1e-15)
    _write(f, ["x", "y", "crank_rad"], [[0, 0, 3], [1, 0, 2], [1, 1, 1]])
    assert np.array_equal(load_target(f).inputs, [3.0, 2.0, 1.0])  # decreasing: the crank turns back
    _write(f, ["x_mm", "y_mm"], [[0, 0], [1, 0], [1, 1]])
    assert not load_target(f).timed and load_target(f).inputs is None
    np.save(tmp_path / "t.npy", np.array([[0, 0, 0.0], [1, 0, 0.5], [1, 1, 1.0]]))
    assert np.array_equal(load_target(tmp_path / "t.npy").inputs, [0, 0.5, 1.0])
    for rows, msg in (([[0, 0, 0], [20, 1, 0], [10, 1, 1]], "one way"),
                      ([[0, 0, 0], [200, 1, 0], [360, 1, 1]], "at most one turn"),
                      ([[0, 0, 0], [0, 1, 0], [10, 1, 1]], "one way")):
        _write(f, ["theta_deg", "x", "y"], rows)
        with pytest.raises(MechanismError, match=msg):
            load_target(f)
    f.write_text("theta_deg,x,y\n0,0,0\nten,1,0\n20,1,1\n")
    with pytest.raises(MechanismError, match="theta_deg"):
        load_target(f)
    _write(f, ["theta_deg", "x", "y"], [[0, 2, 3], [10, 2, 3], [20, 2, 3]])
    with pytest.raises(MechanismError, match="all one point"):
        load_target(f)


def test_ordered_distance_against_a_minimisation_over_the_rotation():
    """`match_ordered`: zero for the target moved by a similarity (and the placement undoing it);
    otherwise the RMS of |R(φ) â_i − b̂_i| at the φ that scipy's bounded minimisation finds on the
    normalised points, to 1e-9."""
    rng = np.random.default_rng(2)
    a = rng.normal(size=(17, 2))
    rot = np.array([[math.cos(0.7), -math.sin(0.7)], [math.sin(0.7), math.cos(0.7)]])
    b = 3.0 * a @ rot.T + [4.0, -1.0]
    m = D.match_ordered(a, b)
    assert m.distance < 1e-14 and abs(m.scale - 3.0) < 1e-13 and abs(m.rotation - 0.7) < 1e-13
    assert np.max(np.abs(D.place(a, m) - b)) < 1e-12
    b = b + rng.normal(scale=0.3, size=b.shape)
    an, bn = D.normalise(a)[0], D.normalise(b)[0]

    def rms(phi):
        r = an @ np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]]).T - bn
        return math.sqrt(np.mean(np.sum(r * r, axis=1)))

    grid = np.linspace(0, 2 * np.pi, 721)
    g = grid[np.argmin([rms(x) for x in grid])]
    ref = minimize_scalar(rms, bounds=(g - 0.01, g + 0.01), method="bounded", options={"xatol": 1e-12}).fun
    assert abs(D.match_ordered(a, b).distance - ref) < 1e-9


def test_ordered_surrogate_is_the_square_and_ignores_padding():
    """`distance.ordered_sq` (the refinement's loss) is the ordered distance squared, and a padded
    point (weight 0) changes nothing."""
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(9, 2)), rng.normal(size=(9, 2))
    bn = D.normalise(b)[0]
    w = np.full(9, 1 / 9)
    with jax.enable_x64(True):
        v = float(D.ordered_sq(jnp.asarray(a), jnp.asarray(bn), jnp.asarray(w), eps=0.0))
        pad = float(D.ordered_sq(jnp.asarray(np.vstack([a, [[50.0, -7.0]]])), jnp.asarray(np.vstack([bn, [[0, 0]]])),
                                 jnp.asarray(np.append(w, 0.0)), eps=0.0))
    assert abs(v - D.ordered_distance(a, b)[0] ** 2) < 1e-13 and abs(pad - v) < 1e-13


def test_timed_samples():
    """`timed_samples`: the fractions of the span, the weights and the normalised points; more points
    than asked: evenly by index, the ends kept; fewer: padded with weight 0."""
    t = np.radians([0.0, 10, 40, 100])
    tgt = make_target(np.array([[0, 0], [1, 0], [1, 1], [0, 2.0]]), inputs=t)
    p, w, u, span = timed_samples(tgt, 6)
    assert span == pytest.approx(np.radians(100)) and np.allclose(u[:4], [0, 0.1, 0.4, 1.0]) and np.all(u[4:] == 0)
    assert np.allclose(w, [0.25] * 4 + [0, 0]) and np.allclose(p[:4], D.normalise(tgt.points)[0])
    long = make_target(np.stack([np.arange(50.0), np.sin(np.arange(50.0))], 1), inputs=np.linspace(0, 3, 50))
    p, w, u, span = timed_samples(long, 8)
    assert len(u) == 8 and u[0] == 0 and u[-1] == 1 and np.all(w == 1 / 8)


def test_planted_timed_four_bar_recovered_and_replayed(tmp_path):
    """A four-bar's coupler point at 36 inputs 5° apart, written with a `theta_deg` column (starting
    anywhere): `jaxlink synthesize` finds a four-bar at an ordered distance ≤ 0.01 (the same
    linkage at inputs 20 % further apart is at 0.073 from it), and `jaxlink kinematics` on the written
    file, at the reported `inputs_deg`, traces points at that distance (1e-9)."""
    t = np.radians(5.0 * np.arange(36))
    pts = trace_exact(FOUR_BAR, POSE, 0.4 + t)[0][:, FOUR_BAR.traced] * 40 + [100, 50]
    other = trace_exact(FOUR_BAR, POSE, 0.4 + 1.2 * t)[0][:, FOUR_BAR.traced]
    assert D.match_ordered(other, pts).distance > 0.07  # the timing is part of the target
    f = tmp_path / "timed.csv"
    _write(f, ["theta_deg", "x_mm", "y_mm"], [[123.0 + 5 * i, x, y] for i, (x, y) in enumerate(pts)])
    out_dir = tmp_path / "syn"
    assert cli_main(["synthesize", str(f), "--topologies", "four-bar", "--rounds", "2", "--samples", "2048",
                     "--quick", *OFF_CLI, "--out", str(out_dir)]) == 0
    res = json.loads((out_dir / "synthesis.json").read_text())
    best = res["designs"][0]
    assert res["target"]["timed"] and best["distance"] <= 0.01
    ins = np.array(best["inputs_deg"])
    assert np.allclose(np.diff(ins), 5.0, rtol=0, atol=1e-9) and ins[0] == pytest.approx(best["start_deg"])
    out = tmp_path / "replay.csv"
    assert cli_main(["kinematics", str(out_dir / "synthesized.toml"), "--start", repr(float(ins[0])), "--step", "5",
                     "--count", "36", "--outputs", "position", "--units", "file", "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    curve = np.array([[float(x["P_x_mm"]), float(x["P_y_mm"])] for x in rows])
    assert abs(D.match_ordered(curve, pts).distance - best["distance"]) < 1e-9


def test_timed_search_keeps_the_timing():
    """Uneven inputs (24 random angles over 270°): the search recovers the planted four-bar's
    timing (ordered distance ≤ 0.01 in two quick rounds), and the design's traced points at the
    reported inputs are the ones scored."""
    rng = np.random.default_rng(0)
    t = np.sort(rng.uniform(0, 1.5 * np.pi, 24))
    pts = trace_exact(FOUR_BAR, POSE, 0.7 + t - t[0])[0][:, FOUR_BAR.traced] * 30 + [5, 7]
    tgt = make_target(pts, inputs=t + 2.0)
    r = synthesize(tgt, topologies=["four-bar"], quick=True, rounds=2, samples=2048, **OFF)
    b = r.best
    assert b.distance <= 0.01 and len(b.inputs_deg) == 24
    assert np.allclose(np.diff(b.inputs_deg), np.degrees(np.diff(t)), rtol=0, atol=1e-9)
    assert abs(D.match_ordered(b.at_inputs, pts).distance - b.distance) < 1e-12


def test_timed_candidate_failing_between_samples_is_rejected():
    """A four-bar whose dyad cannot close at θ = 0, timed at inputs h/2 + k h on both sides of it
    (every sample closing): `score` reports the ordered distance and the failed check."""
    from test_synthesis import _failing_between_samples

    n = 64
    h = 2 * np.pi / n
    pose = _failing_between_samples(n)
    offsets = h * np.arange(n - 1)   # up to one step short of a turn: both sides of θ = 0 (at 2π − h/2)
    shifted = offsets - np.pi        # the interval −π … π − h: θ = 0 inside
    pts = trace_exact(FOUR_BAR, pose, shifted)[0][:, FOUR_BAR.traced]
    assert trace_exact(FOUR_BAR, pose, shifted)[1].min() > 0
    tgt = make_target(pts, inputs=offsets, closed=False)
    m, asm = score(FOUR_BAR, pose, -np.pi, offsets[-1], tgt, n_trace=n, n_points=100)
    assert m.distance < 1e-12 and not asm.ok and asm.margin < 0


def test_a_kinematics_table_is_a_timed_target(tmp_path):
    """`jaxlink kinematics --csv` writes `input_deg` and each point's `NAME_x_mm`, `NAME_y_mm`: read as a
    timed target, in mm, the first point's path at the table's crank angles."""
    f = tmp_path / "feed.csv"
    assert cli_main(["kinematics", "sewing-feed", "--start", "10", "--step", "5", "--count", "72", "--outputs",
                     "position", "--units", "file", "--csv", str(f)]) == 0
    rows = list(csv.DictReader(f.open()))
    t = load_target(f)
    assert t.timed and t.unit == "mm" and t.closed and len(t.points) == 72
    assert np.array_equal(t.points, [[float(r["Z_x_mm"]), float(r["Z_y_mm"])] for r in rows])
    assert np.allclose(np.degrees(t.inputs), 10 + 5 * np.arange(72), rtol=0, atol=1e-12)


def test_rigid_points_and_the_sewing_feed_as_a_planted_target():
    """A dyad on two joints of one body is a point of it (`topology.rigid`), carried with the body:
    no reach margin (a point on the line of its link, as the seed's feed dog Z on its carrier F-H, is
    as good as any). The sewing feed's own six-bar written as a `stephenson-rocker-crank` pose from
    the scene's solved angles at 0° traces the scene's Z at 72 crank angles (ordered distance 1e-13,
    the points to 1e-12 mm) and assembles over the turn; the JAX tracer agrees with NumPy's."""
    import jaxlink as jl
    from jaxlink.synthesis.tracer import trace

    for t in T.topologies(10, sliders=True):
        assert sum(T.rigid(t)) == sum(len(b) - 2 for b in T.bodies(t))
    mech = jl.load("sewing-feed")
    phis = np.radians(5.0 * np.arange(72))
    with jax.enable_x64(True):
        sol = jl.solve(mech, jnp.asarray(phis))
        z = 1e3 * np.asarray(sol.points)[:, mech.point_names.index("Z")]
        q = dict(zip(mech.unknown_names, np.asarray(sol.q)[0]))
    P = dict(zip(mech.parameter_names, 1e3 * np.asarray(mech.parameters)))  # lengths in mm (angles unused)
    g = np.radians(100.0)

    def e(a):
        return np.array([math.cos(a), math.sin(a)])

    b = P["l2"] * e(0.0)
    d = b + P["l3"] * e(q["phi3"])
    f = d + P["l4"] * e(q["phi4"])
    h = f + P["l6"] * e(q["phi6"])
    pose = np.array([[0, 0], d + P["l44"] * e(q["phi4"]), [0, 0], b, d, b + [0, 5.0], f,
                     -P["l22"] * e(g), h, f + (P["l6"] + P["l66"]) * e(q["phi6"])])
    topo = next(t for t in T.topologies() if t.name == "stephenson-rocker-crank")
    assert T.rigid(topo) == [False, True, True, True, False, True]  # Z (dyad 5) on the line F-H
    pos, marg = trace_exact(topo, pose, phis)
    assert np.max(np.abs(pos[:, topo.traced] - z)) < 1e-12 * 100
    tgt = make_target(z, inputs=phis, closed=True, unit="mm")
    m, asm = score(topo, pose, 0.0, phis[-1], tgt, n_trace=72, n_points=200)
    assert m.distance < 1e-13 and asm.ok
    arr = T.as_arrays([topo])
    with jax.enable_x64(True):
        jp, jm = trace(jnp.asarray(arr.parents[0]), jnp.asarray(arr.active[0]), jnp.asarray(pose), jnp.asarray(phis))
    assert np.max(np.abs(np.asarray(jp) - pos)) < 1e-11 and np.array_equal(np.asarray(jm) == 1.0, marg == 1.0)
    # its least transmission angle (`synthesis.transmission`, located between samples) is the worst
    # of the transmission angles `jaxlink check` reports for the scene's loops (`jl.motion`: 24.62°)
    from jaxlink.synthesis import transmission as TM

    with jax.enable_x64(True):
        worst = min(np.degrees(t["worst"]) for t in jl.motion(mech).transmission)
    assert abs(TM.angle_deg(TM.least(topo, pose, 0.0, 2 * np.pi).margin) - worst) < 1e-8 and abs(worst - 24.62) < 0.01
    # the float64 polish (`polish`, its tight tolerances) brings every joint 1 % of the size off back
    from jaxlink.synthesis.polish import polish

    off = pose + np.random.default_rng(0).normal(scale=0.12, size=pose.shape)
    assert score(topo, off, 0.0, phis[-1], tgt, n_trace=72, n_points=200)[0].distance > 0.01
    pp, st, sp = polish(arr.parents[0], arr.active[0], int(arr.traced[0]), off, 0.0, phis[-1], tgt)
    m, asm = score(topo, pp, st, sp, tgt, n_trace=72, n_points=200)
    assert m.distance < 1e-4 and asm.ok
