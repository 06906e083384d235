"""Results that reproduce: the best design of a search written as a complete mechanism file
(`jaxlink/optimize/best_file.py`), re-solved the way `jaxlink kinematics` does (from its own
guesses at `[input] start`), gives the search's reported objective; for every registered
objective and for frame angles across ±180° on both circuits of a four-bar."""

import json
import math
import pathlib
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxlink
from jaxlink import load, loads
from jaxlink.optimize import Evaluator, PathData, problem_from, run
from jaxlink.optimize.best_file import best_file_text
from jaxlink.optimize.objectives import OBJECTIVES

ROOT = pathlib.Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks" / "fourbar-path" / "fourbar_path_benchmarks.json"
sys.path.insert(0, str(ROOT / "experiments" / "fourbar_plain"))
from generate import plain_text  # noqa: E402

jax.config.update("jax_enable_x64", True)


def resolved(mech, overrides, samples):
    """The objective of `mech` (its own design) re-solved from its guesses, as `jaxlink kinematics`
    solves: `jaxlink.solve` at `samples` inputs over a revolution from the search's first input,
    then the objective of the problem on that path. Asserts every position converged."""
    pr = problem_from(mech, overrides)
    obj = OBJECTIVES.build(pr)
    phis = pr.phis[0] + 2 * np.pi * np.arange(samples) / samples
    sol = jaxlink.solve(mech, phis)
    assert np.all(np.asarray(sol.result) == jaxlink.RESULTS.converged), "a position did not converge"
    order = max(obj.order, obj.report_order)
    t = jaxlink.transfer(mech, phis, sol.q, order=max(order, 0))
    lf = mech.units.length
    k = pr.point
    xy = jnp.asarray(t.points)[:, k] / lf
    dxy = None if order < 1 else jnp.asarray(t.dpoints)[:, k] / lf
    ddxy = None if order < 2 else jnp.asarray(t.ddpoints)[:, k] / lf
    return float(obj.value(PathData(xy, dxy, ddxy, jnp.asarray(sol.q), jnp.asarray(mech.parameters))))


def rotated_reference(case, theta):
    """The literature design of `case` (benchmark convention, radians) turned by `theta` about the
    origin: the same path shape, frame angle a + theta."""
    m = dict(json.loads(BENCH.read_text())[case]["reference_mechanism"])
    c, s = math.cos(theta), math.sin(theta)
    m["p1x"], m["p1y"] = c * m["p1x"] - s * m["p1y"], s * m["p1x"] + c * m["p1y"]
    m["a"] = (m["a"] + theta + math.pi) % (2 * math.pi) - math.pi
    return m


def plain_file(tmp_path, unit):
    targets = json.loads(BENCH.read_text())["yu1"]["target"]
    path = tmp_path / f"yu1-{unit}.toml"
    path.write_text(plain_text("yu1", targets, angle_unit=unit), encoding="utf-8")
    return path


@pytest.mark.parametrize("unit", ["rad", "deg"])
def test_frame_angles_across_180_deg_reproduce_on_both_circuits(tmp_path, unit):
    """A yu1-like plain file: the literature shape at frame angles from −178° to 179.9°, both
    circuits; the written file re-solved from its guesses gives the reported objective."""
    path = plain_file(tmp_path, unit)
    mech = load(path)
    over = {"circuits": "all", "report_samples": 720}
    ev = Evaluator(problem_from(mech, over), chunk=8)
    pr = ev.problem
    deg = 180 / math.pi if unit == "deg" else 1.0
    checked = 0
    for a_target in (-178.0, -120.0, -3.0, 60.0, 178.0, 179.9):
        m = rotated_reference("yu1", math.radians(a_target) - json.loads(BENCH.read_text())["yu1"][
            "reference_mechanism"]["a"])
        x = np.array([m[n] * (deg if n in ("a", "g") else 1.0) for n in pr.names])
        x[list(pr.names).index("g")] = ((m["g"] + math.pi) % (2 * math.pi) - math.pi) * deg
        u = pr.to_unit(x)
        assert np.all((u >= 0) & (u <= 1))
        for c in range(ev.n_circuits):
            rep = ev.report(u, c)
            if not rep["feasible"]:
                continue
            best = loads(best_file_text(ev, u, c, path.read_text()), file="best.toml")
            got = resolved(best, over, ev.report_samples)
            assert got == pytest.approx(rep["objective"], rel=1e-9, abs=1e-12), (a_target, c)
            checked += 1
    # the literature design is a full-turn crank on its own circuit at every frame angle
    assert checked >= 6


# the scenes' own objectives (sewing-feed-opt's ellipse, needle-dwell's dwell) reproduce from the
# command line's best file through the compilation cache: tests/test_cache_differential.py
@pytest.mark.parametrize("scene, objective, overrides", [
    ("plain-yu1", "points", {"report_samples": 720}),
    ("sewing-feed-opt", "feed", {}),
])
def test_every_objective_reproduces_from_the_written_file(tmp_path, scene, objective, overrides):
    """A short search per registered objective, `out=` given: the JSON names `OUT.best.toml`, and
    that file re-solved from its guesses gives the reported objective to 1e-9."""
    assert set(OBJECTIVES) == {"points", "ellipse", "feed", "dwell"}  # a new one belongs here or there
    mech = load(plain_file(tmp_path, "rad")) if scene == "plain-yu1" else load(scene)
    over = dict(overrides, objective=objective)
    if objective == "points":
        over["circuits"] = "all"
    ev = Evaluator(problem_from(mech, over), chunk=32)
    res = run(ev, "montecarlo", budget=64, seed=1, out=tmp_path / "r.json")
    assert res.parameters is not None and res.value is not None
    doc = json.loads((tmp_path / "r.json").read_text())
    assert doc["best_file"] == str(tmp_path / "r.best.toml") == res.best_file
    best = load(doc["best_file"])
    assert best.file.endswith("r.best.toml")
    got = resolved(best, over, ev.report_samples)
    assert got == pytest.approx(res.value, rel=1e-9, abs=1e-12)
    # the Python API gives the same file
    assert res.best_file_text() == pathlib.Path(doc["best_file"]).read_text()
    assert np.array_equal(res.best_mechanism().parameters, best.parameters)


def test_written_file_keeps_comments_and_layout(tmp_path):
    path = plain_file(tmp_path, "deg")
    ev = Evaluator(problem_from(load(path)), chunk=8)
    u = np.full(ev.problem.n_variables, 0.5)
    text = best_file_text(ev, u, 0)
    old, new = path.read_text().splitlines(), text.splitlines()
    assert len(old) == len(new)
    changed = [i for i, (a, b) in enumerate(zip(old, new)) if a != b]
    # parameters (9 lines) and guesses (2 lines) only, each keeping its comment
    assert len(changed) <= 11
    for i in changed:
        assert old[i].split("=")[0] == new[i].split("=")[0]
        assert ("#" in old[i]) == ("#" in new[i])


def test_set_overrides_are_written_too(tmp_path):
    """A parameter changed by --set (not a variable) is part of the design: it is written."""
    path = tmp_path / "feed.toml"
    path.write_text((ROOT / "jaxlink" / "scenes" / "sewing-feed-opt.toml").read_text(), encoding="utf-8")
    mech = load(path)
    fixed = next(n for n in mech.parameter_names if n not in problem_from(mech).names and mech.kinds[n] == "length")
    value = float(mech.from_si(fixed, mech.parameters[mech.parameter_index(fixed)])) * 1.01
    mech2 = load(path, overrides={fixed: value})
    ev = Evaluator(problem_from(mech2), chunk=8)
    u = ev.problem.to_unit(ev.problem.file_design())
    best = loads(best_file_text(ev, u, 0), file="b.toml")
    k = mech.parameter_index(fixed)
    assert best.parameters[k] == mech2.parameters[k] != mech.parameters[k]
    np.testing.assert_allclose(best.parameters, mech2.parameters, rtol=1e-14)
