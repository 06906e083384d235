"""The designer's bounds on a synthesized linkage: its size (`jaxlink.synthesis.size`: the target's
extent against brute force and closed forms, a design's reported size against the same measure
taken independently from the mechanism file it writes) and its least transmission angle
(`jaxlink.synthesis.transmission`, against the four-bar's closed form); `max_size` and
`min_transmission` keeping every answer within them where the unbounded search's answer is not."""

import itertools
import json

import numpy as np
import pytest
from scipy.spatial.distance import pdist

from jaxlink.cli import main as cli_main
from jaxlink.errors import MechanismError
from jaxlink.synthesis import api
from jaxlink.synthesis import bounds as B
from jaxlink.synthesis import pareto as P
from jaxlink.synthesis import search as S
from jaxlink.synthesis import size as Z
from jaxlink.synthesis import topology as T
from jaxlink.synthesis import transmission as TM
from jaxlink.synthesis.api import synthesize
from jaxlink.synthesis.target import arclength_resample, make_target
from jaxlink.synthesis.tracer import trace_exact

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

FOUR_BAR = T.topologies()[0]
#: every designer's bound off (`jaxlink.synthesis.bounds`): the search of before the defaults
OFF = dict(min_transmission=None, max_size=None, max_pivot=None)
OFF_CLI = ["--min-transmission", "0", "--max-size", "none", "--max-pivot", "none"]
# a crank-rocker (`tests/test_synthesis.py`): its size against its own coupler curve is 1.42 extents
POSE = np.array([[0, 0], [1.0, 0], [0, 0], [0.3, 0.0], [1.1, 0.8], [0.5, 0.9]])


def _planted_target():
    th = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    return trace_exact(FOUR_BAR, POSE, th)[0][:, FOUR_BAR.traced] * 40 + [100, 50]


def test_extent_against_brute_force_and_closed_forms():
    t = 2 * np.pi * np.arange(360) / 360
    assert abs(Z.extent(np.c_[3 * np.cos(t), 3 * np.sin(t)] + 7) - 6.0) < 1e-12  # a circle: its diameter
    assert abs(Z.extent([[0, 0], [4, 0], [4, 3], [0, 3], [2, 1]]) - 5.0) < 1e-15  # a rectangle: its diagonal
    rng = np.random.default_rng(2)
    for n in (2, 3, 7, 200):
        p = rng.normal(size=(n, 2))
        assert Z.extent(p) == pytest.approx(pdist(p).max(), rel=1e-15)
    line = np.c_[np.linspace(-1, 2, 50), 2 * np.linspace(-1, 2, 50)]  # collinear: no hull, every pair
    assert Z.extent(line) == pytest.approx(3 * np.sqrt(5), rel=1e-14)


def _independent_size(toml_path, target_points, n=200):
    """The size measured on the written mechanism file: every link's largest distance between two
    of its joints, every frame pivot's distance from the centroid of the target resampled at `n`
    points by arclength (closed), over the largest distance between two target points (brute force)."""
    sk = tomllib.loads(toml_path.read_text())["sketch"]
    joints = {k: np.asarray(v, float) for k, v in sk["joints"].items()}
    longest = max(np.hypot(*(joints[a] - joints[b]))
                  for names in sk["links"].values() for a, b in itertools.combinations(names, 2))
    centre = arclength_resample(np.asarray(target_points, float), n, True).mean(0)
    reach = max(np.hypot(*(joints[f] - centre)) for f in sk["frame"])
    return max(longest, reach) / pdist(target_points).max()


def test_reported_size_is_the_written_file_s(tmp_path):
    """`jaxlink synthesize` reports each design's size (table and JSON): the four-bar's equals the
    measure taken from its written file (its links are the crank, the coupler plate and the rocker:
    every pair of joints on one link is a link of the measure) to 1e-9."""
    target = _planted_target()
    f = tmp_path / "target.csv"
    f.write_text("x_mm,y_mm\n" + "\n".join(f"{float(x)!r},{float(y)!r}" for x, y in target))
    out = tmp_path / "syn"
    assert cli_main(["synthesize", str(f), "--topologies", "four-bar", "--rounds", "1", "--quick", "--no-plot",
                     "--out", str(out), *OFF_CLI]) == 0
    res = json.loads((out / "synthesis.json").read_text())
    assert res["max_size"] is None and abs(res["target"]["extent"] - pdist(target).max()) < 1e-9
    # the bounds switched off on the command line: none in force, every design meets them
    assert res["min_transmission_deg"] is None and res["max_pivot"] is None and res["bounds_met"]
    assert all(d["meets"] and d["violates"] == [] for d in res["designs"])
    best = res["designs"][0]
    assert abs(best["size"] - _independent_size(out / "synthesized.toml", target)) < 1e-9
    assert 1.0 < best["size"] < 2.0  # the planted crank-rocker's neighbourhood (1.42)
    # its least transmission angle against the closed form of the written four-bar (a full turn:
    # the extremes where the crank lies along the frame line, the diagonal C–F1 = a ∓ d)
    sk = tomllib.loads((out / "synthesized.toml").read_text())["sketch"]
    j = {k: np.asarray(v, float) for k, v in sk["joints"].items()}
    a, b, c, d = (np.hypot(*(j[x] - j[y])) for x, y in (("C", "F0"), ("J4", "C"), ("J4", "F1"), ("F1", "F0")))
    g = [np.degrees(np.arccos((b * b + c * c - (a * a + d * d - 2 * a * d * s)) / (2 * b * c))) for s in (1, -1)]
    assert abs(best["transmission_deg"] - min(min(x, 180 - x) for x in g)) < 1e-7


def test_least_transmission_angle_against_the_four_bar_closed_form():
    """The planted crank-rocker's least transmission angle (between coupler and rocker at B), located
    between samples, against the closed form: its extremes at θ = 0 and π, where the diagonal
    C–F1 is a ∓ d, γ = acos((b² + c² − diag²) / (2 b c)), the least of γ and 180° − γ."""
    a, d = 0.3, 1.0
    b, c = np.hypot(*(POSE[4] - POSE[3])), np.hypot(*(POSE[4] - POSE[1]))
    g = [np.degrees(np.arccos((b * b + c * c - (a * a + d * d - 2 * a * d * s)) / (2 * b * c))) for s in (1, -1)]
    want = min(min(x, 180 - x) for x in g)
    got = TM.least(FOUR_BAR, POSE, 0.0, 2 * np.pi)
    assert abs(TM.angle_deg(got.margin) - want) < 1e-9 and got.dyad == 0 and abs(got.where) < 1e-6
    assert abs(want - 37.875) < 1e-3 and TM.floor_of(30.0) == pytest.approx(0.25, abs=1e-15)


def test_bounded_searches_keep_every_design_within_the_bounds():
    """Unbounded, the search finds the planted four-bar's neighbourhood (size > 1 extent, least
    transmission angle below 45°); with `max_size` = 0.8 every answer is within 0.8 extents, with
    `min_transmission` = 50 every answer's least angle is at least 50° (located between samples),
    each another, farther design that assembles; bounds that are no positive number, or no angle
    between 0 and 90°, are refused."""
    tgt = make_target(_planted_target(), closed=True)
    free = synthesize(tgt, topologies=["four-bar"], quick=True, rounds=2, samples=4096, **OFF)
    assert free.max_size is None and free.min_transmission is None
    assert free.best.size > 1.0 and free.best.transmission_deg < 45 and free.best.distance < 0.02
    small = synthesize(tgt, topologies=["four-bar"], quick=True, rounds=2, samples=4096, max_size=0.8,
                       max_pivot=0.8, min_transmission=None)
    assert small.max_size == 0.8 and small.designs
    for d in small.designs:
        assert d.size <= 0.8 and d.meets and d.margin > 0 and np.isfinite(d.distance)
    assert small.best.distance > free.best.distance  # the bound costs accuracy here: it bites
    steep = synthesize(tgt, topologies=["four-bar"], quick=True, rounds=2, samples=4096, min_transmission=50,
                       max_size=None, max_pivot=None)
    assert steep.min_transmission == 50 and steep.designs
    for d in steep.designs:
        assert d.transmission_deg >= 50 and d.meets and d.margin > 0 and np.isfinite(d.distance)
    assert steep.best.distance > free.best.distance
    for bad in (0, -1.0, float("nan"), float("inf"), True, "2"):
        with pytest.raises(MechanismError, match="max_size"):
            synthesize(tgt, topologies=["four-bar"], quick=True, rounds=1, max_size=bad)
    for bad in (90, -5.0, float("nan"), True, "40"):
        with pytest.raises(MechanismError, match="min_transmission"):
            synthesize(tgt, topologies=["four-bar"], quick=True, rounds=1, min_transmission=bad)


# a crank-rocker whose least transmission angle is below the default 30°: crank a = 0.6, frame d = 1,
# coupler b = |(0.5, 0.8)|, rocker c = |(0.1, 0.8)| (Grashof: 0.6 + 1 <= b + c = 1.749)
STEEP = np.array([[0, 0], [1.0, 0], [0, 0], [0.6, 0.0], [1.1, 0.8], [0.5, 0.9]])
# a crank-rocker far larger than its coupler curve: frame 5, coupler and rocker about 4.8, crank 0.3
LARGE = np.array([[0, 0], [5.0, 0], [0, 0], [0.3, 0.0], [2.6, 4.2], [0.5, 0.9]])


def _four_bar_mu(a, b, c, d):
    """The least transmission angle of a crank-rocker over a whole turn (closed form): its extremes
    where the crank lies along the frame line, the diagonal a ∓ d; the least of γ and 180° − γ."""
    g = [np.degrees(np.arccos((b * b + c * c - (a * a + d * d - 2 * a * d * s)) / (2 * b * c))) for s in (1, -1)]
    return min(min(x, 180 - x) for x in g)


def _sketch_mu(sk):
    """`_four_bar_mu` of a written four-bar (its sketch's joints)."""
    j = {k: np.asarray(v, float) for k, v in sk["joints"].items()}
    return _four_bar_mu(*(np.hypot(*(j[x] - j[y])) for x, y in (("C", "F0"), ("J4", "C"), ("J4", "F1"),
                                                                    ("F1", "F0"))))


def _sketch_sizes(sk, target_points, n=200):
    """(longest link, furthest frame pivot from the target's centre) over the target's extent, measured
    on a written mechanism (`_independent_size`'s two terms)."""
    joints = {k: np.asarray(v, float) for k, v in sk["joints"].items()}
    longest = max(np.hypot(*(joints[a] - joints[b]))
                  for names in sk["links"].values() for a, b in itertools.combinations(names, 2))
    centre = arclength_resample(np.asarray(target_points, float), n, True).mean(0)
    reach = max(np.hypot(*(joints[f] - centre)) for f in sk["frame"])
    ext = pdist(target_points).max()
    return longest / ext, reach / ext


def _design_of(pose):
    """The reported design of a pose matched against its own coupler curve (no search), checked
    against the default bounds."""
    th = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    pts = trace_exact(FOUR_BAR, pose, th)[0][:, FOUR_BAR.traced] * 40 + [100, 50]
    tgt = make_target(pts, closed=True)
    m, asm = S.score(FOUR_BAR, pose, 0.0, 2 * np.pi, tgt, n_trace=400, n_points=200)
    frame = Z.target_frame(tgt, 200)
    c = S.Candidate(FOUR_BAR, pose, 0.0, 2 * np.pi, m, asm, 0.0, size=S.size_of(FOUR_BAR, pose, m, tgt, 200, frame))
    return api._design(c, tgt, 400, "x", frame, B.DEFAULTS), pts


def test_default_bounds_refuse_a_steep_or_a_large_design():
    """A design whose least transmission angle (24.9°, closed form) is below the default 30° is not
    reported as meeting the bounds, nor one whose links are 7.8 times its curve's extent and whose
    rocker pivot is as far from its centre (measured on its written mechanism); the planted
    crank-rocker of 37.9° and 1.42 extents meets them."""
    steep, _ = _design_of(STEEP)
    want = _four_bar_mu(0.6, np.hypot(0.5, 0.8), np.hypot(0.1, 0.8), 1.0)
    assert abs(want - 24.88) < 0.01 and abs(steep.transmission_deg - want) < 1e-7
    assert not steep.meets and len(steep.violates) == 1 and steep.violates[0].startswith("transmission angle 24.9°")
    large, pts = _design_of(LARGE)
    link, pivot = _sketch_sizes(large.sketch.tables()["sketch"], pts)
    assert link > 7 and pivot > 3 and abs(large.link_size - link) < 1e-9 and abs(large.pivot_size - pivot) < 1e-9
    assert large.transmission_deg > 30 and abs(large.size - max(link, pivot)) < 1e-9
    assert [v.split()[0] for v in large.violates] == ["link", "frame"] and not large.meets
    plain, _ = _design_of(POSE)
    assert plain.meets and plain.violates == () and abs(plain.transmission_deg - 37.875) < 1e-3
    # the table and the JSON: a design that breaks a bound is never shown as meeting it; when none
    # meets them the table says so plainly, naming what the best breaks
    from jaxlink.report.synthesis import table, to_json

    tgt = make_target(pts, closed=True)
    res = api.Synthesis(tgt, [plain, large], 0.0, 3.0, 1.0, 30.0, max_pivot=3.0, simplest=0)
    rows = table(res).splitlines()
    assert "NO DESIGN" not in table(res) and rows[4].split()[8] == "yes" and rows[5].split()[8] == "link,pivot"
    doc = to_json(res)
    assert doc["bounds_met"] and doc["simplest"] == {"rank": 1, "topology": "four-bar"}
    assert [d["meets"] for d in doc["designs"]] == [True, False] and doc["designs"][1]["violates"] == list(
        large.violates)
    alone = api.Synthesis(tgt, [steep], 0.0, 3.0, 1.0, 30.0, max_pivot=3.0, simplest=0)
    assert "NO DESIGN   meets the bounds" in table(alone) and "transmission angle 24.9° < 30°" in table(alone)
    assert to_json(alone)["bounds_met"] is False
    # the bounds of the arguments: 0 or None switch the angle off, a size bound is a positive number
    assert B.checked(0, None, 2) == B.Bounds(None, None, 2.0) and B.checked(30, 3, 3) == B.DEFAULTS
    assert B.Bounds(30, 2.0, 3.0).search_size == 3.0 and B.Bounds(30, None, 3.0).search_size is None
    for bad in ((-1, 3, 3), (90, 3, 3), (30, 0, 3), (30, 3, float("inf")), (30, True, 3)):
        with pytest.raises(ValueError):
            B.checked(*bad)


def test_default_synthesis_keeps_the_bounds_the_unbounded_one_breaks():
    """On the coupler curve of the steep crank-rocker (24.9°), the search with the bounds off finds
    its neighbourhood, below 30°; the default search returns only designs meeting the default bounds:
    each four-bar's least angle at least 30° by the closed form of its written mechanism, its sizes
    measured there within 3 extents. Switched off, `synthesize` is the search without bounds
    (`search.search`, the same candidates bit for bit): the behaviour of before the defaults."""
    th = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    pts = trace_exact(FOUR_BAR, STEEP, th)[0][:, FOUR_BAR.traced] * 40 + [100, 50]
    tgt = make_target(pts, closed=True)
    opts = dict(quick=True, rounds=2, samples=4096)
    free = synthesize(tgt, topologies=["four-bar"], **opts, **OFF)
    assert free.best.distance < 0.02 and free.best.transmission_deg < 30 and free.bounds == B.OFF
    old = S.search(tgt, [FOUR_BAR], **opts)
    m = old[0].match
    assert (float(m.distance), float(m.scale), float(m.translation[0])) == (
        free.best.distance, free.best.scale, free.best.translation[0])
    held = synthesize(tgt, topologies=["four-bar"], **opts)
    assert held.bounds == B.DEFAULTS and held.meets and held.designs
    for d in held.designs:
        sk = d.sketch.tables()["sketch"]
        link, pivot = _sketch_sizes(sk, pts)
        assert d.meets and _sketch_mu(sk) >= 30 - 1e-9 and link <= 3 and pivot <= 3
    assert held.best.distance > free.best.distance  # the bound bites: the planted design is refused


def test_pareto_front_and_the_simplest_on_hand_made_designs():
    """The Pareto front of (distance, joints, least transmission angle, size) and the simplest design
    within 10 % of the best, on designs made by hand (no search)."""
    #           distance  joints  mu   size
    designs = [(0.0100, 10, 40.0, 1.5),  # 0: the best distance
               (0.0105, 5, 35.0, 1.2),   # 1: within 10 %, fewer joints, better size: on the front
               (0.0120, 6, 30.0, 2.0),   # 2: dominated by 1 on every objective
               (0.0200, 5, 50.0, 1.0),   # 3: the best angle and size: on the front
               (0.0100, 10, 40.0, 1.5),  # 4: the same as 0: neither dominates the other
               (0.0300, 8, float("nan"), 0.9),  # 5: the least size, its angle unknown (0°): on the front
               (0.0110, 5, 35.0, 1.2)]   # 6: as 1 with a longer distance: dominated by 1
    d, j, mu, sz = (np.array(c, float) for c in zip(*designs))
    assert P.front(d, j, mu, sz).tolist() == [True, True, False, True, True, True, False]
    assert P.front([0.1], [5], [float("nan")], [1.0]).tolist() == [True]
    # the simplest: the fewest joints within 10 % of 0.0100 (<= 0.0110): 1 and 6 have 5; 1 the nearer
    assert P.simplest(d, j) == 1
    assert P.simplest(d, j, within=0.0) == 0  # only the best distance's: 0 and 4, the first
    links = np.array([8, 6, 6, 4, 8, 6, 6])
    assert P.simplest(d, j, links) == 1 and P.simplest(d, j - (np.arange(7) == 6), links) == 6  # 4 joints
    assert P.simplest(d, j, links - 2 * (np.arange(7) == 6)) == 6  # 5 joints as 1, fewer links
    # among the designs meeting the bounds (here 2, 3, 5): the best 0.0120, within 10 %: 2 alone
    ok = np.array([False, False, True, True, False, True, False])
    assert P.simplest(d, j, links, ok) == 2
    assert P.simplest(d, j, links, np.zeros(7, bool)) == 1  # none meets them: all of them
    assert P.simplest([], []) is None and P.simplest([float("nan")], [5]) is None
