"""Sliders in path synthesis (`topology.slide`, `tracer` RRP dyads): the slider-crank's trace
against its closed form, the slider topologies' structure, the check between samples, the sketch
file replayed by `jaxlink kinematics`, and a planted slider-crank recovered by `jaxlink synthesize
--sliders`."""

import csv
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlink.cli import main as cli_main
from jaxlink.synthesis import distance as D
from jaxlink.synthesis import topology as T
from jaxlink.synthesis.assembly import certify
from jaxlink.synthesis.mechanism import placed_pose, to_sketch
from jaxlink.synthesis.search import score
from jaxlink.synthesis.target import load_target, make_target
from jaxlink.synthesis.tracer import trace, trace_exact

#: the designer's bounds off (`jaxlink.synthesis.bounds`): the unbounded search these tests were made for
OFF_CLI = ["--min-transmission", "0", "--max-size", "none", "--max-pivot", "none"]

SLIDER_CRANK = next(t for t in T.topologies(4, sliders=True) if t.name == "slider-crank")


def _pose(r, rod, e, phi=0.0, theta0=0.0, sign=1.0, guide_deg=0.0):
    """A slider-crank pose: F0 at the origin, the crank r at θ0, the guide the line at offset e from
    F0 (normal (−sin γ, cos γ)), direction γ; the slider J4 on the rod's `sign` side of the foot of
    the perpendicular from C; the coupler point P off the rod."""
    g = math.radians(guide_deg)
    u, n = np.array([math.cos(g), math.sin(g)]), np.array([-math.sin(g), math.cos(g)])
    c = r * np.array([math.cos(theta0), math.sin(theta0)])
    foot = e * n + (c @ u) * u
    off = c @ n - e
    j = foot + sign * math.sqrt(rod * rod - off * off) * u
    anchor = e * n - 1.3 * u  # any point of the guide other than J's
    p = c + 0.5 * (j - c) + 0.3 * np.array([-(j - c)[1], (j - c)[0]]) + phi
    return np.array([[0.0, 0.0], anchor, [0.0, 0.0], c, j, p])


@pytest.mark.parametrize("sign, guide_deg", [(1.0, 0.0), (-1.0, 0.0), (1.0, 37.0), (-1.0, -120.0)])
def test_slider_crank_against_its_closed_form(sign, guide_deg):
    """The slider's position along its guide s(θ) = r cos(θ − γ) + σ √(l² − (r sin(θ − γ) − e)²) and
    its margin 1 − (r sin(θ − γ) − e)²/l², on both branches and a tilted guide: the exact tracer to
    1e-14 and the batched (JAX, float64) one to 1e-13."""
    r, rod, e = 0.3, 1.0, 0.1
    pose = _pose(r, rod, e, sign=sign, guide_deg=guide_deg)
    th = np.linspace(0, 2 * np.pi, 97)
    g = math.radians(guide_deg)
    u, n = np.array([math.cos(g), math.sin(g)]), np.array([-math.sin(g), math.cos(g)])
    off = r * np.sin(th - g) - e
    s = r * np.cos(th - g) + sign * np.sqrt(rod * rod - off * off)
    want = e * n + s[:, None] * u
    pos, marg = trace_exact(SLIDER_CRANK, pose, th)
    assert np.max(np.abs(pos[:, 4] - want)) < 1e-14
    assert np.max(np.abs(marg[:, 0] - (1 - off * off / rod ** 2))) < 1e-14
    assert np.max(np.abs(np.hypot(*(pos[:, 5] - pos[:, 3]).T) - np.hypot(*(pose[5] - pose[3])))) < 1e-14
    arr = T.as_arrays([SLIDER_CRANK])
    assert arr.parents[0, 0, 1] == 1 + T.SLIDER
    with jax.enable_x64(True):
        jp, jm = trace(jnp.asarray(arr.parents[0]), jnp.asarray(arr.active[0]), jnp.asarray(pose), jnp.asarray(th),
                       True)
    assert np.max(np.abs(np.asarray(jp) - pos)) < 1e-13 and np.max(np.abs(np.asarray(jm) - marg)) < 1e-13


def test_slider_topologies():
    """`topologies(sliders=True)`: the built-ins, then each one's variants with one or more of its
    `slidable` dyads sliders, every name distinct; a slider's anchor is used by no other dyad and is
    no joint of the linkage; the links stay as many (a rocker becomes a slider's block), the joints
    one fewer a slider; without `sliders` the list is the revolute one; `slide` refuses a dyad it
    cannot turn into a slider."""
    for m, extra in ((4, 1), (6, 9), (8, 18)):
        plain, both = T.topologies(m), T.topologies(m, sliders=True)
        assert both[:len(plain)] == plain and len(both) == len(plain) + extra
        assert len({t.name for t in both}) == len(both)
    by = {t.name: t for t in T.topologies(10)}
    for t in T.topologies(10, sliders=True):
        if not t.sliders:
            continue
        base = by[t.name.split("+slider")[0]] if t.name != "slider-crank" else by["four-bar"]
        assert t.dyads == base.dyads or all(d in (b, b[::-1]) for d, b in zip(t.dyads, base.dyads))
        assert t.n_links == base.n_links and t.n_joints == base.n_joints - len(t.sliders)
        for k in t.sliders:
            anchor = t.dyads[k][1]
            assert 0 < anchor < T.N_FRAME and anchor not in t.used_frame()
            assert sum(anchor in d for d in t.dyads) == 1
    assert SLIDER_CRANK.dyads == ((T.CRANK, 1), (T.CRANK, 4)) and SLIDER_CRANK.sliders == (0,)
    assert (SLIDER_CRANK.n_joints, SLIDER_CRANK.n_links) == (4, 4)
    four = T.topologies(4)[0]
    with pytest.raises(ValueError, match="cannot become a slider"):
        T.slide(four, 1)  # the coupler point: a point of the coupler, no rocker
    with pytest.raises(ValueError, match="cannot become a slider"):
        T.slide(SLIDER_CRANK, 0)  # a slider already


def test_slider_failing_between_samples_is_rejected():
    """A slider-crank whose rod is a hair too short to reach the guide at θ = 90° (the crank pin
    farthest from the guide), every sample on either side of it closing: `certify` finds it there."""
    n = 64
    h = 2 * np.pi / n
    r = 0.3
    rod = 0.5 * (r + r * math.cos(h / 2))           # between the sampled and the true farthest
    pose = _pose(r, rod, 0.0, theta0=h / 2)          # inputs h/2 + k h: 90° is never sampled
    offsets = h * np.arange(n)
    assert trace_exact(SLIDER_CRANK, pose, offsets)[1].min() > 0
    asm = certify(SLIDER_CRANK, pose, 0.0, 2 * np.pi)
    assert not asm.ok and asm.margin < 0
    at = (h / 2 + asm.where) % np.pi                 # θ = 90° or 270°: the pin farthest from the guide
    assert abs(at - np.pi / 2) < h / 2
    tgt = make_target(trace_exact(SLIDER_CRANK, pose, offsets)[0][:, SLIDER_CRANK.traced], closed=True)
    assert not score(SLIDER_CRANK, pose, 0.0, 2 * np.pi, tgt, n_trace=n, n_points=100)[1].ok


def _replay(tmp_path, topo, pose, m):
    """The traced point of `topo` (its search pose `pose`, placed by the match `m`) written as a sketch
    and replayed by `jaxlink kinematics` every 5°: (points in mm, the sketch's text). Also used by
    tests/test_synthesis_levers.py."""
    placed = placed_pose(topo, pose, 0.0, m)
    f = tmp_path / f"{topo.name}.toml"
    f.write_text(to_sketch(topo, placed, unit="mm").toml())
    start = math.degrees(math.atan2(*(placed[T.CRANK] - placed[0])[::-1]))
    out = tmp_path / f"{topo.name}.csv"
    assert cli_main(["kinematics", str(f), "--start", repr(start), "--step", "5", "--outputs", "position",
                     "--units", "file", "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    return np.array([[float(x["P_x_mm"]), float(x["P_y_mm"])] for x in rows]), f.read_text()


@pytest.mark.parametrize("name", ["slider-crank", "watt-crank-frame+slider-J4+slider-J7",
                                  "stephenson-coupler-frame+crank-pin+slider-J6"])
def test_slider_sketch_replays_the_tracer(tmp_path, name):
    """A slider topology written as a sketch (each slider on its frame guide, `along` its direction,
    the guide's anchor no joint): `jaxlink kinematics` traces the tracer's path."""
    from test_synthesis import _assemblable

    topo = next(t for t in T.topologies(8, sliders=True) if t.name == name)
    pose = _assemblable(topo)
    m = D.Match(0.0, 0.4, 25.0, np.array([3.0, -2.0]))
    text = to_sketch(topo, placed_pose(topo, pose, 0.0, m), unit="mm").toml()
    assert text.count("on = \"frame\"") == len(topo.sliders)
    got = _replay(tmp_path, topo, pose, m)[0]
    want = D.place(trace_exact(topo, pose, np.radians(5.0 * np.arange(72)))[0][:, topo.traced], m)
    assert np.max(np.abs(got - want)) < 1e-9 * 25


def test_planted_slider_crank_is_recovered_and_replayed(tmp_path):
    """`jaxlink synthesize --topologies slider-crank` on a slider-crank's coupler curve: recovered to a
    tenth of the discretisation floor (`_floor`, 0.032: two samplings of one curve half a spacing
    apart; 0.0022 here, the best four-bar after the same three rounds of a search of both 0.0044),
    and the written file replays the reported distance (1e-9)."""
    from test_synthesis import _floor

    pose = _pose(0.3, 1.0, 0.1)
    target = trace_exact(SLIDER_CRANK, pose, np.linspace(0, 2 * np.pi, 400, endpoint=False))[0][:, 5] * 40 + [100, 50]
    f = tmp_path / "target.csv"
    f.write_text("x_mm,y_mm\n" + "\n".join(f"{float(x)!r},{float(y)!r}" for x, y in target))
    out_dir = tmp_path / "syn"
    assert cli_main(["synthesize", str(f), "--topologies", "slider-crank", "--rounds", "3", "--samples", "2048",
                     "--quick", "--count", "400", *OFF_CLI, "--out", str(out_dir)]) == 0
    res = json.loads((out_dir / "synthesis.json").read_text())
    best = res["designs"][0]
    assert best["topology"] == "slider-crank" and best["joints"] == 4 and best["links"] == 4
    tgt = load_target(f)
    assert best["distance"] < 0.1 * _floor(tgt.points, True) and list(best["sliders"]) == ["J4"]
    assert "e4" in best["lengths"] and "l4_1" not in best["lengths"]
    out = tmp_path / "replay.csv"
    assert cli_main(["kinematics", str(out_dir / "synthesized.toml"), "--start", repr(best["start_deg"]),
                     "--step", repr(360 / best["count"]), "--count", str(best["count"]), "--outputs", "position",
                     "--units", "file", "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    curve = np.array([[float(x["P_x_mm"]), float(x["P_y_mm"])] for x in rows])
    assert abs(D.match(curve, tgt.points, closed=True).distance - best["distance"]) < 1e-9


def searched(tmp_path, monkeypatch, *argsets) -> list[list[str]]:
    """The topology names `jaxlink synthesize` hands to the search for each set of arguments (the
    search replaced by one that finds nothing: the command says so and returns 1)."""
    import jaxlink.synthesis.api as api

    seen = []

    def fake(tgt, topos, **kw):
        seen.append([t.name for t in topos])
        return []

    monkeypatch.setattr(api, "search", fake)
    f = tmp_path / "t.csv"
    f.write_text("x_mm,y_mm\n0,0\n1,0\n1,1\n0,1\n")
    for args in argsets:
        assert cli_main(["synthesize", str(f), *args]) == 1
    return seen


def test_sliders_option_adds_the_slider_topologies(tmp_path, monkeypatch):
    """`--sliders` (`synthesize(sliders=True)`) searches the built-ins and their slider variants up to
    `--max-links`; without it, the revolute ones; a slider topology is known by name either way."""
    import jaxlink.synthesis.api as api

    seen = searched(tmp_path, monkeypatch, ["--sliders", "--max-links", "6"], ["--max-links", "6"],
                    ["--topologies", "slider-crank"])
    from jaxlink.errors import MechanismError

    with pytest.raises(MechanismError, match="sliders"):
        api.synthesize(np.array([[0, 0], [1, 0], [1, 1.0]]), sliders="yes")
    assert seen[0] == [t.name for t in T.topologies(6, sliders=True)] and len(seen[0]) == 16
    assert seen[1] == [t.name for t in T.topologies(6)] and seen[2] == ["slider-crank"]


def test_certify_of_slider_topologies_is_one_bracket_at_a_time_bit_for_bit():
    """`certify`'s side-by-side brackets against the one-at-a-time reference (`test_synthesis`) on
    random assemblable poses of every slider and slotted-lever topology up to 8 links, random
    intervals, and the slider-crank failing between samples (above)."""
    from test_synthesis import _certify_one

    rng = np.random.default_rng(4)
    n = failing = 0
    for topo in T.topologies(8, sliders=True, levers=True):  # the slotted levers too
        if not (topo.sliders or topo.levers):
            continue
        for _ in range(25):
            pose = rng.uniform(-1, 1, (T.CRANK + 1 + len(topo.dyads), 2))
            st, sp = rng.uniform(0, 6), rng.uniform(0.5, 6.3)
            if trace_exact(topo, pose, np.linspace(st, st + sp, 40))[1].min() <= 0:
                continue
            a, b = certify(topo, pose, st, sp), _certify_one(topo, pose, st, sp)
            assert a == b, (topo.name, a, b)
            n += 1
            failing += not a.ok
    h = 2 * np.pi / 64
    pose = _pose(0.3, 0.15 * (1 + math.cos(h / 2)), 0.0, theta0=h / 2)
    a, b = certify(SLIDER_CRANK, pose, 0.0, 2 * np.pi), _certify_one(SLIDER_CRANK, pose, 0.0, 2 * np.pi)
    assert a == b and not a.ok
    assert n >= 50
