"""Slotted levers in path synthesis (`topology.lever`, `tracer` RPR dyads): the lever's point against
its closed form, the lever topologies' structure, the pin passing over the pivot between samples,
the sketch file (the pin sliding on the lever through its pivot, an RPR dyad of the solver) replayed
by `jaxlink kinematics`, and a planted lever design recovered by `jaxlink synthesize`."""

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
from jaxlink.synthesis.target import load_target
from jaxlink.synthesis.tracer import trace, trace_exact

#: the designer's bounds off (`jaxlink.synthesis.bounds`): the unbounded search these tests were made for
OFF_CLI = ["--min-transmission", "0", "--max-size", "none", "--max-pivot", "none"]

#: the four-bar whose rocker dyad is a slotted lever about F1 (the Whitworth quick return's lever),
#: its point P hung on the crank pin and the lever's point J4 by two links
LEVER = T.lever(T.topologies()[0], 0)
#: a pose of it that assembles over the whole turn with margins above 0.5 (drawn once)
POSE = np.array([[0.0, 0.0], [1.0, 1.0], [0.0, 0.0], [0.4, -0.2], [-0.7, 0.4], [0.1, -0.4]])


def _lever_point(pose, th):
    """J4 in closed form: the lever's angle is that of the line from its pivot F1 to the crank pin C,
    and J4 keeps its distance from F1 and its angle to that line."""
    f1, c0, j0 = pose[1], pose[3], pose[4]
    r, a0 = math.hypot(*c0), math.atan2(c0[1], c0[0])
    c = r * np.stack([np.cos(a0 + th), np.sin(a0 + th)], 1)
    gamma = math.atan2(*(j0 - f1)[::-1]) - math.atan2(*(c0 - f1)[::-1])
    psi = np.arctan2(c[:, 1] - f1[1], c[:, 0] - f1[0]) + gamma
    return f1 + math.hypot(*(j0 - f1)) * np.stack([np.cos(psi), np.sin(psi)], 1), np.hypot(*(c - f1).T)


def test_lever_against_its_closed_form():
    """The lever's point J4 to 1e-14 (NumPy) and 1e-13 (JAX, float64), the margin d²/d⁰² (d the pin's
    distance from the pivot), and the point P hung on C and J4 at its two lengths."""
    th = np.linspace(0, 2 * np.pi, 97)
    want, d = _lever_point(POSE, th)
    pos, marg = trace_exact(LEVER, POSE, th)
    assert np.max(np.abs(pos[:, 4] - want)) < 1e-14
    assert np.max(np.abs(marg[:, 0] - d ** 2 / np.sum((POSE[3] - POSE[1]) ** 2))) < 1e-14
    for a in (3, 4):
        assert np.max(np.abs(np.hypot(*(pos[:, 5] - pos[:, a]).T) - np.hypot(*(POSE[5] - POSE[a])))) < 1e-14
    arr = T.as_arrays([LEVER])
    assert arr.parents[0, 0, 1] == 3 + T.LEVER
    with jax.enable_x64(True):
        jp, jm = trace(jnp.asarray(arr.parents[0]), jnp.asarray(arr.active[0]), jnp.asarray(POSE), jnp.asarray(th),
                       sliders=True)
    assert np.max(np.abs(np.asarray(jp) - pos)) < 1e-13 and np.max(np.abs(np.asarray(jm) - marg)) < 1e-13
    # the least transmission angle counts P's revolute dyad only: the lever's margin is no angle
    from jaxlink.synthesis import transmission as TM

    dense = trace_exact(LEVER, POSE, np.linspace(0, 2 * np.pi, 20001))[1]
    mu = TM.least(LEVER, POSE, 0.0, 2 * np.pi)
    assert mu.dyad == 1 and dense[:, 0].min() < dense[:, 1].min()  # the lever's is the smaller here
    assert dense[:, 1].min() - 1e-9 < mu.margin <= dense[:, 1].min()


def test_lever_topologies():
    """Every dyad on one frame pivot other than the crank's and a moving joint of another body may be
    a lever (10 more topologies up to 8 links, 25 up to 10); the lever is a body of its pivot and
    its point, the block one more link; not a lever twice, nor a point of a body, nor about F0."""
    base8, base10 = T.topologies(8), T.topologies(10)
    lev8 = T.topologies(8, levers=True)[len(base8):]
    assert len(lev8) == 10 and len(T.topologies(10, levers=True)) - len(base10) == 25
    assert all(len(t.levers) == 1 and t.n_links <= 8 for t in lev8)
    assert LEVER.name == "four-bar+lever-J4" and LEVER.dyads == ((1, 3), (3, 4)) and LEVER.n_links == 6
    assert T.bodies(LEVER) == [(0, 3), (1, 4), (3, 5), (4, 5)] and T.rigid(LEVER) == [False, False]
    assert LEVER.n_joints == 5 and LEVER.used_frame() == [0, 1]
    assert T.leverable(LEVER) == [] and T.leverable(T.slide(T.topologies()[0], 0)) == []
    with pytest.raises(ValueError, match="slotted lever"):
        T.lever(T.topologies()[0], 1)  # the coupler point: a point of the coupler, no frame joint
    six = next(t for t in base8 if t.name == "watt-crank-frame")
    assert all(six.dyads[k][0] != 0 and six.dyads[k][1] != 0 for k in T.leverable(six))
    # its size terms (`size`): the crank, the lever's point from the pivot (the block slides: no
    # second length), P's two links; the pivots F0 and F1; the batched ones the same
    from jaxlink.synthesis import size as Z

    lengths, pivots = Z.terms(LEVER, POSE)
    want = [np.hypot(*(POSE[a] - POSE[b])) for a, b in ((3, 0), (4, 1), (5, 3), (5, 4))]
    assert np.allclose(lengths, want, rtol=0, atol=1e-15) and np.array_equal(pivots, POSE[[0, 1]])
    arr = T.as_arrays([LEVER])
    with jax.enable_x64(True):
        r = np.asarray(Z.ratios(jnp.asarray(arr.parents[0]), jnp.asarray(arr.active[0]), jnp.asarray(POSE),
                                jnp.zeros(2), 1.0, sliders=True))
    assert np.allclose(r, [want[0], want[1], 0.0, want[2], want[3], 0.0, np.hypot(*POSE[1]), 0.0], atol=1e-14)


def test_pin_over_the_pivot_between_samples_is_rejected():
    """The lever's pivot on the crank circle at an angle no sample hits (the crank at 0 in the pose,
    the samples 2π/64 apart, the pivot at half a step): every sample assembles, the pin passes over
    the pivot between two of them (the lever's angle undefined, J4 thrown to the other side) and
    `certify` finds the failure there, the lever's margin 0 at that input."""
    n = 64
    h = 2 * np.pi / n
    pose = np.array([[0.0, 0.0], [0.4 * math.cos(h / 2), 0.4 * math.sin(h / 2)], [0.0, 0.0], [0.4, 0.0],
                     [-0.94, -0.75], [0.34, 0.29]])
    assert trace_exact(LEVER, pose, h * np.arange(n))[1].min() > 0.02
    asm = certify(LEVER, pose, 0.0, 2 * np.pi)
    assert not asm.ok and abs(asm.where - h / 2) < 1e-6
    assert trace_exact(LEVER, pose, np.array([h / 2]))[1][0, 0] < 1e-24  # d = 0: the pin on the pivot


@pytest.mark.parametrize("name", ["four-bar+lever-J4", "watt-coupler-rocker+lever-J4"])
def test_lever_sketch_replays_the_tracer(tmp_path, name):
    """A lever topology written as a sketch (the lever a link of its pivot and its point, the block's
    pin sliding on it `through` the pivot): `jaxlink kinematics` (an RPR dyad in closed form) traces
    the tracer's path."""
    from test_synthesis import _assemblable
    from test_synthesis_sliders import _replay

    topo = next(t for t in T.topologies(8, levers=True) if t.name == name)
    pose = POSE if topo is LEVER or topo.name == LEVER.name else _assemblable(topo)
    m = D.Match(0.0, 0.4, 25.0, np.array([3.0, -2.0]))
    got, text = _replay(tmp_path, topo, pose, m)
    assert 'C = { on = "link1", through = "F1" }' in text
    want = D.place(trace_exact(topo, pose, np.radians(5.0 * np.arange(72)))[0][:, topo.traced], m)
    assert np.max(np.abs(got - want)) < 1e-9 * 25


def test_planted_lever_design_is_recovered_and_replayed(tmp_path):
    """`jaxlink synthesize --levers` (up to 6 links: the four-bar, the six-bars and the lever's
    variants) on the planted lever design's curve: the lever topology found, below the
    discretisation floor and the best four-bar, and the written file replays it to 1e-9."""
    from test_synthesis import _floor

    target = trace_exact(LEVER, POSE, np.linspace(0, 2 * np.pi, 400, endpoint=False))[0][:, 5] * 20 + [50, 30]
    f = tmp_path / "target.csv"
    f.write_text("x_mm,y_mm\n" + "\n".join(f"{float(x)!r},{float(y)!r}" for x, y in target))
    out_dir = tmp_path / "syn"
    assert cli_main(["synthesize", str(f), "--closed", "--topologies", "four-bar,four-bar+lever-J4", "--rounds", "2",
                     "--samples", "2048", "--quick", "--count", "400", "--no-plot", *OFF_CLI,
                     "--out", str(out_dir)]) == 0
    res = json.loads((out_dir / "synthesis.json").read_text())
    best = res["designs"][0]
    tgt = load_target(f)
    four = next(d for d in res["designs"] if d["topology"] == "four-bar")
    assert best["topology"] == LEVER.name and best["links"] == 6 and best["levers"] == {
        "C": {"on": "link1", "through": "F1"}}
    assert best["distance"] < _floor(tgt.points, True) and best["distance"] < four["distance"]
    assert "l4_1" in best["lengths"] and "l4_3" not in best["lengths"]
    out = tmp_path / "replay.csv"
    assert cli_main(["kinematics", str(out_dir / "synthesized.toml"), "--start", repr(best["start_deg"]),
                     "--step", repr(360 / best["count"]), "--count", str(best["count"]), "--outputs", "position",
                     "--units", "file", "--csv", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    curve = np.array([[float(x["P_x_mm"]), float(x["P_y_mm"])] for x in rows])
    assert abs(D.match(curve, tgt.points, closed=True).distance - best["distance"]) < 1e-9


def test_levers_option_adds_the_lever_topologies(tmp_path, monkeypatch):
    """`--levers` (`synthesize(levers=True)`) searches the built-ins and their lever variants; a lever
    topology is known by name without it; a non-bool is refused."""
    from test_synthesis_sliders import searched

    import jaxlink.synthesis.api as api
    from jaxlink.errors import MechanismError

    seen = searched(tmp_path, monkeypatch, ["--levers", "--max-links", "6"], ["--topologies", "four-bar+lever-J4"])
    with pytest.raises(MechanismError, match="levers"):
        api.synthesize(np.array([[0, 0], [1, 0], [1, 1.0]]), levers="yes")
    assert seen[0] == [t.name for t in T.topologies(6, levers=True)] and "four-bar+lever-J4" in seen[0]
    assert seen[1] == ["four-bar+lever-J4"]
