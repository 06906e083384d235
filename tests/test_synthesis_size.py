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
                     "--out", str(out)]) == 0
    res = json.loads((out / "synthesis.json").read_text())
    assert res["max_size"] is None and abs(res["target"]["extent"] - pdist(target).max()) < 1e-9
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
    free = synthesize(tgt, topologies=["four-bar"], quick=True, rounds=2, samples=4096)
    assert free.max_size is None and free.min_transmission is None
    assert free.best.size > 1.0 and free.best.transmission_deg < 45 and free.best.distance < 0.02
    small = synthesize(tgt, topologies=["four-bar"], quick=True, rounds=2, samples=4096, max_size=0.8)
    assert small.max_size == 0.8 and small.designs
    for d in small.designs:
        assert d.size <= 0.8 and d.margin > 0 and np.isfinite(d.distance)
    assert small.best.distance > free.best.distance  # the bound costs accuracy here: it bites
    steep = synthesize(tgt, topologies=["four-bar"], quick=True, rounds=2, samples=4096, min_transmission=50)
    assert steep.min_transmission == 50 and steep.designs
    for d in steep.designs:
        assert d.transmission_deg >= 50 and d.margin > 0 and np.isfinite(d.distance)
    assert steep.best.distance > free.best.distance
    for bad in (0, -1.0, float("nan"), float("inf"), True, "2"):
        with pytest.raises(MechanismError, match="max_size"):
            synthesize(tgt, topologies=["four-bar"], quick=True, rounds=1, max_size=bad)
    for bad in (0, 90, -5.0, float("nan"), True, "40"):
        with pytest.raises(MechanismError, match="min_transmission"):
            synthesize(tgt, topologies=["four-bar"], quick=True, rounds=1, min_transmission=bad)
