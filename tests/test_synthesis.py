"""Path synthesis (jaxlink/synthesis/): the distance against closed forms and an independent scipy
computation, recovery of planted four-bar coupler curves (closed, and open by a sub-interval), the
replay of the written file through `jaxlink kinematics`, and the rejection of a candidate that
fails to assemble between two samples."""

import csv
import math

import numpy as np
import pytest
from scipy.interpolate import interp1d
from scipy.spatial.distance import cdist

from jaxlink.cli import main as cli_main
from jaxlink.synthesis import assembly as A
from jaxlink.synthesis import distance as D
from jaxlink.synthesis import topology as T
from jaxlink.synthesis.api import synthesize
from jaxlink.synthesis.assembly import certify
from jaxlink.synthesis.search import score
from jaxlink.synthesis.target import arclength_resample, load_target, make_target
from jaxlink.synthesis.tracer import trace_exact

#: the designer's bounds off (`jaxlink.synthesis.bounds`): the unbounded search these tests were made for
OFF = dict(min_transmission=None, max_size=None, max_pivot=None)
OFF_CLI = ["--min-transmission", "0", "--max-size", "none", "--max-pivot", "none"]

FOUR_BAR = T.topologies()[0]
# a crank-rocker: F0 = 0, F1 = (1, 0), crank 0.3, coupler point P off the coupler C–B
POSE = np.array([[0, 0], [1.0, 0], [0, 0], [0.3, 0.0], [1.1, 0.8], [0.5, 0.9]])


def _coupler(thetas):
    return trace_exact(FOUR_BAR, POSE, thetas)[0][:, FOUR_BAR.traced]


def _ellipse(a, b, n=4000):
    t = 2 * np.pi * np.arange(n) / n
    return np.stack([a * np.cos(t), b * np.sin(t)], 1)


def test_chamfer_of_many_angles_is_each_angle_alone_bit_for_bit():
    """The chamfer at many rotations (one k-d tree query for all, `_chamfer_rotated`) gives for each
    angle the bits of a query of that angle alone, and the brute-force distances (scipy's cdist)
    to rounding."""
    rng = np.random.default_rng(3)
    a = D.normalise(rng.normal(size=(200, 2)))[0]
    b = D.normalise(_ellipse(1.3, 0.7, 200) + 0.05 * rng.normal(size=(200, 2)))[0]
    phis = rng.uniform(-4.0, 7.0, 11)
    many = D._chamfer_rotated(a, b, phis)
    alone = np.array([D._chamfer_rotated(a, b, [phi])[0] for phi in phis])
    assert np.array_equal(many, alone)
    for phi, got in zip(phis, many):
        c, s = math.cos(phi), math.sin(phi)
        d = cdist(a @ np.array([[c, -s], [s, c]]).T, b)
        assert abs(got - (d.min(1).mean() + d.min(0).mean())) < 1e-14
    assert D._chamfer_rotated(a, b, []).shape == (0,)


def test_distance_invariance_and_zero():
    c = _coupler(np.linspace(0, 2 * np.pi, 500, endpoint=False))
    e = _ellipse(1.0, 0.5, 700) + [0.2, 0.1]
    m0 = D.match(e, c, closed=True)
    a = 0.7
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    moved = 3.7 * c @ rot.T + [12.0, -5.0]
    m1 = D.match(e, moved, closed=True)
    assert abs(m1.distance - m0.distance) < 1e-12
    assert abs(m1.scale / m0.scale - 3.7) < 1e-9
    # the placement puts the curve onto the target: placed, its best rotation is 0 and D the same
    # (0 or π: the ellipse is centrally symmetric, both rotations give the same D to rounding)
    placed = D.place(e, m1)
    m2 = D.match(placed, moved, closed=True)
    r = m2.rotation % np.pi
    assert abs(m2.distance - m1.distance) < 1e-12 and min(r, np.pi - r) < 1e-7
    assert D.match(c, c, closed=True).distance < 1e-15
    # the ordered distance: point i against point i, the rotation in closed form
    od, phi = D.ordered_distance(c @ rot.T * 2.0 + [1.0, 1.0], c)
    assert od < 1e-13 and abs(phi + a) < 1e-12
    od, _ = D.ordered_distance(np.roll(c, 5, axis=0), c)
    assert od > 0.01


def _independent(curve_a, curve_b, n=200):
    """The chamfer at the best rotation, computed another way: scipy's interpolation, every
    distance (cdist), a 0.01° grid of rotations."""
    def res(c):
        c = np.concatenate([c, c[:1]])
        s = np.concatenate([[0], np.cumsum(np.hypot(*np.diff(c, axis=0).T))])
        pts = interp1d(s, c, axis=0)(s[-1] * np.arange(n) / n)
        pts = pts - pts.mean(0)
        return pts / np.sqrt((pts ** 2).sum(1).mean())

    a, b = res(curve_a), res(curve_b)
    def f(phi):
        r = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
        d = cdist(a @ r.T, b)
        return d.min(1).mean() + d.min(0).mean()

    coarse = np.radians(np.arange(0, 360, 0.5))
    phi0 = coarse[np.argmin([f(p) for p in coarse])]
    return min(f(p) for p in phi0 + np.radians(np.arange(-0.5, 0.5, 0.001)))


def test_distance_circle_ellipse_against_scipy():
    circ, ell = _ellipse(1.0, 1.0), _ellipse(2.0, 1.0)
    d = D.match_points(circ, ell, closed=True).distance  # the point chamfer (LInK's metric at n = 200)
    ref = _independent(circ, ell)
    assert d <= ref + 1e-12 and ref - d < 1e-4  # ours is the exact minimum over φ; the grid's is above it
    assert 0.05 < d < 0.5


def _floor(points, closed, n=D.N_POINTS):
    """The discretisation floor: the target against itself resampled half a spacing along (an open
    curve: its n samples from end to end against the n − 1 midway between them; rolling an open
    curve's samples would join its two ends)."""
    fine = arclength_resample(points, 20 * n, closed)
    if closed:
        return D.chamfer(D.normalise(arclength_resample(fine, n, closed))[0],
                         D.normalise(arclength_resample(np.roll(fine, -10, axis=0), n, closed))[0])
    both = arclength_resample(fine, 2 * n - 1, False)
    return D.chamfer(D.normalise(both[0::2])[0], D.normalise(both[1::2])[0])


def test_planted_four_bar_closed_and_replay(tmp_path):
    """`jaxlink synthesize` on a four-bar's coupler curve: at the discretisation floor, the files
    written, and `jaxlink kinematics` on the written file traces the reported distance."""
    import json

    target = _coupler(np.linspace(0, 2 * np.pi, 400, endpoint=False)) * 40 + [100, 50]
    f = tmp_path / "target.csv"
    f.write_text("x_mm,y_mm\n" + "\n".join(f"{float(x)!r},{float(y)!r}" for x, y in target))
    tgt = load_target(f)
    assert tgt.closed and tgt.unit == "mm"
    out_dir = tmp_path / "syn"
    assert cli_main(["synthesize", str(f), "--topologies", "four-bar", "--rounds", "1", "--quick", "--count", "400",
                     *OFF_CLI, "--out", str(out_dir)]) == 0
    res = json.loads((out_dir / "synthesis.json").read_text())
    best = res["designs"][0]
    assert (out_dir / "synthesis.png").stat().st_size > 0 and best["topology"] == "four-bar"
    assert best["distance"] <= 1.5 * _floor(tgt.points, True)
    assert best["stop_deg"] - best["start_deg"] == 360.0 and best["margin"] > 0
    # replay: `jaxlink kinematics` on the written file traces the same distance
    out = tmp_path / "replay.csv"
    rc = cli_main(["kinematics", str(out_dir / "synthesized.toml"), "--start", repr(best["start_deg"]),
                   "--step", repr(360 / best["count"]), "--count", str(best["count"]), "--outputs", "position",
                   "--units", "file", "--csv", str(out)])
    assert rc == 0
    rows = list(csv.DictReader(out.open()))
    curve = np.array([[float(x["P_x_mm"]), float(x["P_y_mm"])] for x in rows])
    assert abs(D.match(curve, tgt.points, closed=True).distance - best["distance"]) < 1e-9


@pytest.mark.parametrize("closed", [True, False])
def test_float64_polish_recovers_a_planted_four_bar(closed):
    """The search's last step (`polish`): from the planted four-bar's pose disturbed by 10 % of its
    size (distance 0.04-0.05), L-BFGS on the sharper surrogate comes back below the discretisation
    floor of the planted curve and below a fifth of where it started (closed: the whole turn; open:
    a sub-interval, its start and span disturbed too), certified over its whole interval."""
    from jaxlink.synthesis.search import Candidate, _polished

    th = np.linspace(0, 2 * np.pi, 400, endpoint=False) if closed else np.linspace(1.0, 3.5, 300)
    tgt = make_target(_coupler(th), closed=closed)
    rng = np.random.default_rng(1)
    pose = POSE + rng.normal(0.0, 0.1, POSE.shape)
    start, span = (0.0, 2 * np.pi) if closed else (1.0 + 0.05, 2.5 - 0.1)
    m, asm = score(FOUR_BAR, pose, start, span, tgt, n_trace=1000, n_points=D.N_POINTS)
    assert asm.ok and m.distance > 0.03
    arr = T.as_arrays([FOUR_BAR])
    out = _polished(Candidate(FOUR_BAR, pose, start, span, m, asm, 0.0), arr.parents[0], arr.active[0],
                    int(arr.traced[0]), tgt, 1000, D.N_POINTS, 0.0)
    assert out is not None and out.polished and out.assembly.ok
    assert out.match.distance < min(_floor(tgt.points, closed), m.distance / 5), (m.distance, out.match.distance)
    again = score(FOUR_BAR, out.pose, out.start, out.span, tgt, n_trace=1000, n_points=D.N_POINTS)[0]
    assert again.distance == out.match.distance
    # JAX's x64 off (a Python user's default): the polish still computes in float64, the same bits
    import jax

    jax.config.update("jax_enable_x64", False)
    try:
        off = _polished(Candidate(FOUR_BAR, pose, start, span, m, asm, 0.0), arr.parents[0], arr.active[0],
                        int(arr.traced[0]), tgt, 1000, D.N_POINTS, 0.0)
    finally:
        jax.config.update("jax_enable_x64", True)
    assert off is not None and np.array_equal(off.pose, out.pose) and (off.start, off.span) == (out.start, out.span)
    # a deadline (a time-limited search's): one that does not pass changes nothing; one already past
    # returns the start itself; one 0.2 s away stops L-BFGS early, at a point of lower loss
    import time

    from jaxlink.synthesis.polish import polish

    args = (arr.parents[0], arr.active[0], int(arr.traced[0]), pose, start, span, tgt)
    whole = polish(*args)
    late = polish(*args, deadline=time.perf_counter() + 3600.0)
    assert np.array_equal(late[0], whole[0]) and late[1:] == whole[1:]
    past = polish(*args, deadline=time.perf_counter() - 1.0)
    assert np.array_equal(past[0], pose) and past[1:] == (start, span if not closed else 2 * np.pi)
    t1 = time.perf_counter()
    cut = polish(*args, deadline=t1 + 0.2)
    assert time.perf_counter() - t1 < 0.2 + 0.5  # one evaluation past the deadline at most (~ms)
    assert not np.array_equal(cut[0], pose) and not np.array_equal(cut[0], whole[0])
    cut_d = score(FOUR_BAR, cut[0], cut[1], cut[2], tgt, n_trace=1000, n_points=D.N_POINTS)[0].distance
    assert cut_d < m.distance, (cut_d, m.distance)


def test_which_round_is_next():
    """`search._next_round` (a time-limited search): after a full round a polishing one, then full
    ones while `ROUND_MARGIN` times the last full round fits, polishing ones while only they fit,
    then none; the margin itself: a round whose last time just fits is not started."""
    from jaxlink.synthesis.search import ROUND_MARGIN, _next_round

    assert ROUND_MARGIN > 1
    assert _next_round(100.0, 30.0, 10.0, True, False) == 1  # after a full round: polishing
    assert _next_round(100.0, 30.0, 10.0, True, True) == 0  # after a polishing round: full
    assert _next_round(100.0, 30.0, 10.0, False, False) == 0  # no elites: no polishing round
    assert _next_round(30.0, 30.0, 10.0, True, True) == 1  # a full one no longer fits: polishing
    assert _next_round(30.0 * ROUND_MARGIN, 30.0, 10.0, True, True) == 0
    assert _next_round(10.0, 30.0, 10.0, True, True) == -1  # the polishing round just fits: not started
    assert _next_round(10.0 * ROUND_MARGIN, 30.0, 10.0, True, True) == 1
    assert _next_round(1e9, 30.0, 10.0, True, False) == 1 and _next_round(-1.0, 0.0, 0.0, True, True) == -1


def test_when_a_polish_starts():
    """`search._polish_starts`: with `rounds` always; one process: while at least `POLISH_MIN_S`
    of the time limit is left, however long the polish was expected to take (it stops at the
    limit); the guess only decides where several processes must polish alike (not here)."""
    from jaxlink.synthesis.search import POLISH_MIN_S, SCORE_RESERVE_S, _polish_starts

    assert SCORE_RESERVE_S < POLISH_MIN_S
    assert _polish_starts(-5.0, 100.0, True) and _polish_starts(0.0, 0.0, True)
    assert _polish_starts(POLISH_MIN_S, 30.0, False) and _polish_starts(23.0, 30.0, False)
    assert not _polish_starts(POLISH_MIN_S - 1e-3, 0.0, False) and not _polish_starts(-1.0, 0.0, False)


def test_planted_open_arc_by_subinterval():
    arc = _coupler(np.linspace(1.0, 3.5, 300))
    tgt = make_target(arc * 2.0, closed=False)
    assert not tgt.closed
    # rank and refine: the shapes of the closed run above (one program for both); a smaller screen
    r = synthesize(tgt, topologies=["four-bar"], rounds=1, quick=True, count=400, samples=1024, **OFF)
    best = r.best
    assert best.stop_deg - best.start_deg < 300
    assert best.distance <= 1.5 * _floor(tgt.points, False)


def _failing_between_samples(n: int = 64) -> np.ndarray:
    """A four-bar pose whose rocker dyad cannot close at θ = 0 yet closes at every input h/2 + k h
    (h = 2π/n): F0 = 0, F1 = (−1, 0), crank 0.3 along +x at θ = 0: |B0 − C| = 1.3 is largest at
    θ = 0; links of 1.3 − ε together cannot reach there. Sampled at θ = ±h/2 the dyad closes."""
    h = 2 * np.pi / n
    dmax, dsample = 1.3, math.sqrt(1.0 + 0.09 + 0.6 * math.cos(h / 2))
    reach = 0.5 * (dmax + dsample)          # between the sampled and the true largest distance
    l1 = 0.6
    pose = np.zeros((6, 2))
    pose[1], pose[3] = (-1.0, 0.0), (0.3 * math.cos(h / 2), 0.3 * math.sin(h / 2))
    c = pose[3]
    w = pose[1] - c
    d = np.hypot(*w)
    l2 = reach - l1
    a = (l1 ** 2 - l2 ** 2 + d ** 2) / (2 * d)
    hh = math.sqrt(l1 ** 2 - a ** 2)
    pose[4] = c + a / d * w + hh / d * np.array([-w[1], w[0]])
    pose[5] = c + 0.5 * (pose[4] - c) + [0.0, 0.2]
    return pose


def test_fails_between_samples_is_rejected():
    n = 64
    h = 2 * np.pi / n
    pose = _failing_between_samples(n)
    offsets = h * np.arange(n)                     # inputs h/2 + k h: both sides of θ = 0, never on it
    assert trace_exact(FOUR_BAR, pose, offsets)[1].min() > 0
    asm = certify(FOUR_BAR, pose, 0.0, 2 * np.pi)
    assert not asm.ok and asm.margin < 0
    assert abs(((asm.where + h / 2 + np.pi) % (2 * np.pi)) - np.pi) < h / 2   # found at θ = 0
    tgt = make_target(_coupler(offsets), closed=True)
    assert not score(FOUR_BAR, pose, 0.0, 2 * np.pi, tgt, n_trace=n, n_points=100)[1].ok


def _certify_one(topo: T.Topology, pose: np.ndarray, start: float, span: float) -> A.Assembly:
    """`certify` with one golden-section search at a time (the shipped code before the brackets went
    side by side): the reference of the test below."""
    th = start + span * np.linspace(0.0, 1.0, A.DENSE + 1)
    m = trace_exact(topo, pose, th)[1]
    best = (float(m.min()), float(th[np.unravel_index(m.argmin(), m.shape)[0]]),
            int(np.unravel_index(m.argmin(), m.shape)[1]))
    h = th[1] - th[0]
    for k in range(m.shape[1]):
        mk = m[:, k]
        inner = np.flatnonzero((mk[1:-1] <= mk[:-2]) & (mk[1:-1] <= mk[2:])) + 1
        for i in inner[np.argsort(mk[inner])][:A.REFINE]:
            lo, hi = th[i] - h, th[i] + h

            def f(x, k=k):
                return trace_exact(topo, pose, np.array([x]))[1][0, k]

            x1, x2 = hi - A._GOLD * (hi - lo), lo + A._GOLD * (hi - lo)
            f1, f2 = f(x1), f(x2)
            while hi - lo > 1e-12:
                if f1 <= f2:
                    hi, x2, f2 = x2, x1, f1
                    x1 = hi - A._GOLD * (hi - lo)
                    f1 = f(x1)
                else:
                    lo, x1, f1 = x1, x2, f2
                    x2 = lo + A._GOLD * (hi - lo)
                    f2 = f(x2)
            for x, v in ((x1, f1), (x2, f2)):
                if v < best[0]:
                    best = (float(v), float(x), k)
    return A.Assembly(best[0], best[1], best[2], bool(best[0] > A.MIN_MARGIN))


def test_certify_side_by_side_is_one_bracket_at_a_time_bit_for_bit():
    """`certify` runs the golden-section searches of all brackets side by side; the reference
    `_certify_one` runs them one at a time (the shipped code before): the same margin, place and
    dyad to the last bit, on random assemblable poses of every topology and random intervals,
    including ones that fail between samples (the planted test above). (20 draws per topology:
    45 poses, every topology 1-5 times, one failing; 60 draws took 24 s of the suite.)"""
    rng = np.random.default_rng(3)
    n = failing = 0
    for topo in T.topologies(8):
        for _ in range(20):
            pose = rng.uniform(-1, 1, (T.CRANK + 1 + len(topo.dyads), 2))
            st, sp = rng.uniform(0, 6), rng.uniform(0.5, 6.3)
            if trace_exact(topo, pose, np.linspace(st, st + sp, 40))[1].min() <= 0:
                continue
            a, b = certify(topo, pose, st, sp), _certify_one(topo, pose, st, sp)
            assert a == b, (topo.name, a, b)
            n += 1
            failing += not a.ok
    assert n >= 40 and failing >= 1


@pytest.mark.parametrize("d, closed", [("M 0 0 L 10 0 C 10 5 5 10 0 10 Z", True), ("M 0 0 q 5 5 10 0 h 5", False)])
def test_svg_target(tmp_path, d, closed):
    f = tmp_path / "t.svg"
    f.write_text(f'<svg xmlns="http://www.w3.org/2000/svg"><path d="{d}"/></svg>')
    t = load_target(f)
    assert t.closed is closed and np.all(np.isfinite(t.points))
    if not closed:
        assert np.allclose(t.points[-1], [15, 0]) and np.allclose(t.points[16], [5, 2.5])  # q's midpoint


def _assemblable(topo: T.Topology, seed: int = 1) -> np.ndarray:
    """A random pose of `topo` whose every dyad keeps a margin above 0.05 at 73 inputs over a turn
    and that assembles over the whole turn (`certify`)."""
    rng = np.random.default_rng(seed)
    for _ in range(5000):
        pose = rng.uniform(-1, 1, (T.CRANK + 1 + len(topo.dyads), 2))
        if trace_exact(topo, pose, np.linspace(0, 2 * np.pi, 73))[1].min() > 0.05 and certify(
                topo, pose, 0.0, 2 * np.pi).ok:
            return pose
    pytest.fail(f"no assemblable {topo.name} drawn")  # pragma: no cover


@pytest.mark.parametrize("name", ["stephenson-rocker-crank", "watt-coupler-rocker+crank-pivot",
                                  "watt-coupler-rocker+crank-pivot+crank-pivot"])
def test_six_bar_sketch_replays_the_tracer(tmp_path, name):
    """A Stephenson six-bar (6 dyads, plates on the crank, coupler, rocker and dyad), an eight-bar
    whose last link shares the crank's frame pivot (three links at one pin) and a ten-bar grown from
    it to the same pivot again (four links there), written as a sketch: `jaxlink kinematics` traces
    the tracer's path (no search: the written-file check alone)."""
    from jaxlink.synthesis.mechanism import placed_pose, to_sketch

    topo = next(t for t in T.topologies(10) if t.name == name)
    pose = _assemblable(topo)
    m = D.Match(0.0, 0.4, 25.0, np.array([3.0, -2.0]))
    placed = placed_pose(topo, pose, 0.0, m)
    f = tmp_path / "six.toml"
    f.write_text(to_sketch(topo, placed, unit="mm").toml())
    start = math.degrees(math.atan2(*(placed[T.CRANK] - placed[0])[::-1]))
    out = tmp_path / "six.csv"
    assert cli_main(["kinematics", str(f), "--start", repr(start), "--step", "5", "--outputs", "position",
                     "--units", "file", "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    got = np.array([[float(x["P_x_mm"]), float(x["P_y_mm"])] for x in rows])
    want = D.place(trace_exact(topo, pose, np.radians(5.0 * np.arange(72)))[0][:, topo.traced], m)
    assert np.max(np.abs(got - want)) < 1e-9 * 25


def test_polishing_slots_go_to_the_best_three_topologies():
    """A polishing round's slots: as many as asked, only on the three topologies with the lowest
    refined value, evenly, each one's best two as they are before any jittered copy."""
    from jaxlink.synthesis.search import _polish_slots

    rng = np.random.default_rng(0)
    pose = {ti: [(rng.normal(size=(6, 2)).astype(np.float32), np.array([0.5, 2.0], np.float32)) for _ in range(2)]
            for ti in range(5)}
    vals = {ti: [(v,), (v + 1,)] for ti, v in zip(range(5), [0.3, 0.1, 0.5, 0.2, 0.05])}
    stix, p, a = _polish_slots(pose, vals, 24, 0.02, False, rng)
    assert p.shape == (24, 6, 2) and a.shape == (24, 2)
    assert sorted(set(stix.tolist())) == [1, 3, 4] and all(np.sum(stix == t) == 8 for t in (1, 3, 4))
    for t in (1, 3, 4):
        slots = np.flatnonzero(stix == t)
        assert np.array_equal(p[slots[0]], pose[t][0][0]) and np.array_equal(p[slots[1]], pose[t][1][0])
        assert not np.allclose(p[slots[2]], pose[t][0][0]) and np.allclose(p[slots[2]], pose[t][0][0], atol=0.2)


def test_topology_objects_are_searched():
    """`synthesize(topologies=[...])` takes a `Topology` (one grown by `grow`) beside the built-ins'
    names: the answer carries its name and recovers its planted curve (the four-bar with its rocker
    dyad's parents written the other way round: the same program as the closed run above)."""
    from jaxlink.errors import MechanismError

    mine = T.Topology("my-four-bar", ((1, T.CRANK), (T.CRANK, 4)), FOUR_BAR.traced)
    pose = POSE.copy()
    pose[4] = [1.1, -0.8]     # the rocker dyad's branch sign flips with its parents' order: the other assembly
    target = trace_exact(mine, pose, np.linspace(0, 2 * np.pi, 400, endpoint=False))[0][:, mine.traced]
    r = synthesize(target, topologies=[mine], rounds=1, quick=True, count=400, **OFF)
    assert [d.topology for d in r.designs] == ["my-four-bar"] and r.best.joints == 5
    assert r.best.distance <= 1.5 * _floor(target, True)
    for bad in (3, 0, -1, 4.5, True):
        with pytest.raises(MechanismError, match="max_links"):
            synthesize(target, max_links=bad, time_limit=1)
    for bad in (-1, 1.5, True, "4"):
        with pytest.raises(MechanismError, match="finish"):
            synthesize(target, finish=bad, time_limit=1)
    for bad in (0, -2, 1.5, True, "2"):
        with pytest.raises(MechanismError, match="per_topology"):
            synthesize(target, per_topology=bad, time_limit=1)
    with pytest.raises(MechanismError, match="unknown topology"):
        synthesize(target, topologies=["no-such-bar"], time_limit=1)
    big = T.Topology("seventeen", tuple([(T.CRANK, 1)] * 17), 20)
    with pytest.raises(MechanismError, match="more than 16 dyads"):
        synthesize(target, topologies=[big], time_limit=1)
    with pytest.raises(MechanismError, match="two topologies named"):
        synthesize(target, topologies=[mine, T.grow(mine, 4, 5)], time_limit=1)
    for bad in (0, -5.0, float("nan"), float("inf"), "60", True):  # inf: a search that never ends
        with pytest.raises(MechanismError, match="time_limit"):
            synthesize(target, time_limit=bad)


def test_builtin_topologies_by_links():
    """The built-ins by `max_links`: the four-bar; the six six-bars; the nine eight-bars (16 at 8,
    unchanged by the ten-bars); the 27 ten-bars at 10, each an eight-bar grown by one more dyad from
    its traced point to F0, F1 or C: 10 links, 12 joints, every name distinct, each body's joints
    counted once (a dyad on two joints of one body a point of it, else two binary links)."""
    counts = {m: len(T.topologies(m)) for m in (4, 6, 8, 10)}
    assert counts == {4: 1, 6: 7, 8: 16, 10: 43}
    ten = T.topologies(10)[16:]
    eight = {t.name: t for t in T.topologies(8)}
    assert len({t.name for t in T.topologies(10)}) == 43
    for t in ten:
        base = eight[t.name.rsplit("+", 1)[0]]
        n = len(base.dyads)
        assert (t.n_links, t.n_joints, len(t.dyads)) == (10, 12, n + 2)
        assert t.dyads[:n] == base.dyads and t.dyads[n][0] == base.traced
        assert t.dyads[n + 1] == (base.traced, T.CRANK + 1 + n) and t.traced == T.CRANK + 1 + n + 1
