"""Design search: objectives against closed forms, the seed's published path figures, the
literature reference errors, gradients against finite differences, the searches, infeasible
designs, the CLI's JSON, and kill + resume."""

import json
import math
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlink import load, loads
from jaxlink.errors import MechanismError
from jaxlink.optimize import Evaluator, PathData, SearchResult, problem_from, run
from jaxlink.optimize.objectives import OBJECTIVES
from jaxlink.optimize.searches.lbfgs import u_of_v, v_of_u

ROOT = pathlib.Path(__file__).resolve().parents[1]
CASES = ROOT / "experiments" / "fourbar_cases"
BENCH = ROOT / "benchmarks" / "fourbar-path" / "fourbar_path_benchmarks.json"


@pytest.fixture(scope="module")
def feed():
    return Evaluator(problem_from(load("sewing-feed-opt")), chunk=64)


def _objective(kind, **options):
    mech = load("sewing-feed-opt")
    table = dict(mech.tables["optimize"], objective=kind, **options)
    return OBJECTIVES.build(problem_from(mech, table))


# ----------------------------------------------------------------------------- objectives


def test_ellipse_objective_closed_forms():
    obj = _objective("ellipse", axes=[2.5, 1.0])
    t = 2 * np.pi * np.arange(36) / 36
    # the target ellipse itself, anywhere: J = 0
    ell = PathData(jnp.stack([3.0 + 2.5 * np.cos(t), -7.0 + 1.0 * np.sin(t)], axis=1))
    assert float(obj.value(ell)) < 1e-28
    # a circle of radius r: f = r²cos²/a² + r²sin²/b² − 1, J = mean f² (by hand)
    r = 1.5
    circ = PathData(jnp.stack([r * np.cos(t), r * np.sin(t)], axis=1))
    f = r**2 * np.cos(t) ** 2 / 2.5**2 + r**2 * np.sin(t) ** 2 / 1.0**2 - 1
    assert float(obj.value(circ)) == pytest.approx(np.mean(f**2), rel=1e-12)
    assert float(obj.smooth(circ)) == pytest.approx(np.mean(f**2), rel=1e-12)


def test_points_objective_against_circle_distance():
    mech = load("sewing-feed-opt")
    rng = np.random.default_rng(1)
    targets = rng.normal(size=(7, 2)) * 2.0
    table = dict(mech.tables["optimize"], objective="points", targets=targets.tolist(), smoothing=1e-4)
    obj = OBJECTIVES.build(problem_from(mech, table))
    n, r = 20000, 1.3
    t = 2 * np.pi * np.arange(n) / n
    path = PathData(jnp.stack([r * np.cos(t), r * np.sin(t)], axis=1))
    exact = np.sum((np.hypot(*targets.T) - r) ** 2)  # distance to a circle in closed form
    v = float(obj.value(path))
    assert v == pytest.approx(exact, rel=1e-6)
    s = float(obj.smooth(path))
    assert s <= v + 1e-15 and s >= v - len(targets) * (1e-4 * 5) ** 2 * math.log(n) - 1e-12


def test_feed_reproduces_published_path_figures(feed):
    # seed 000 ch. 11: 2a = 5.1158 mm, centre (-10.6925, 55.27) from the l2 loop of the combined
    # program (2.1 / 0.3 / 14°); 2b = 2.2676 mm and Δx = 0.235 mm (2.1 / 0.9 / 2°), l4 = 46, 36 points
    pr = feed.problem
    r1 = feed.report(pr.to_unit([2.1, 0.3, 14.0]))["metrics"]
    assert r1["two_a"] == pytest.approx(5.1158, abs=6e-5)
    assert r1["sx"] == pytest.approx(-10.6925, abs=1e-3)
    assert r1["sy"] == pytest.approx(55.27, abs=5e-3)
    r2 = feed.report(pr.to_unit([2.1, 0.9, 2.0]))["metrics"]
    assert r2["two_b"] == pytest.approx(2.2676, abs=2e-4)
    assert abs(r2["dx"]) == pytest.approx(0.235, abs=5e-4)


@pytest.mark.parametrize("case", ["mcgarva"])  # its literature solution is on circuit c2
def test_literature_case_files_reproduce_reference_error(case):
    ref = json.loads(BENCH.read_text())[case]["ref_sse_nearest"]
    pr = problem_from(load(CASES / f"{case}.toml"))
    ev = Evaluator(pr, chunk=8)
    rep = ev.report(pr.to_unit(pr.file_design()), 0)
    # the polyline through 7200 samples vs the nearest of 72,000 sampled points (independent): the
    # polyline is closer to the true curve than any sample, so ours is a little smaller
    assert ref * (1 - 1e-4) <= rep["objective"] <= ref * (1 + 1e-9)


# ----------------------------------------------------------------------------- evaluator


def test_infeasible_designs_are_counted_never_nan():
    # a four-bar whose crank must turn fully: feasible iff Grashof with the crank shortest
    text = (ROOT / "jaxlink" / "scenes" / "four-bar.toml").read_text() + """
[optimize]
point = "P"
variables = { a = [5, 60], b = [20, 90] }
samples = 24
objective = "points"
targets = [[30, 40], [10, 50]]
"""
    pr = problem_from(loads(text, file="four-bar-opt.toml"))
    ev = Evaluator(pr, chunk=128)
    rng = np.random.default_rng(0)
    U = rng.random((256, 2))
    res = ev.evaluate(U)
    x = pr.to_file_units(U)
    a, b, c, d = x[:, 0], x[:, 1], 45.0, 55.0
    lengths = np.stack([a, b, np.full_like(a, c), np.full_like(a, d)], axis=1)
    s, big = lengths.min(1), lengths.max(1)
    grashof_crank = (a == s) & (s + big <= lengths.sum(1) - s - big)
    assert not np.any(np.isnan(res["value"]))
    assert np.array_equal(res["feasible"], grashof_crank)  # no design wrongly infeasible (or feasible)
    assert np.all(np.isinf(res["value"][~res["feasible"]]))
    assert 0.2 < (~res["feasible"]).mean() < 0.95


def test_gradient_matches_finite_differences(feed):
    from jaxlink.optimize.searches.gradient import smooth_value_and_grad

    designs = [[2.0, 0.7, 5.0], [2.6, 1.3, -8.0], [1.0, 3.0, 25.0], [3.5, 0.2, -29.0]]
    v = jnp.asarray(v_of_u(feed.problem.to_unit(np.array(designs))))
    c = jnp.zeros(4, int)
    value, grad, exact = smooth_value_and_grad(feed)(v, c)
    f = jax.jit(jax.vmap(lambda vv, cc: feed.smooth_single(u_of_v(vv), cc)))
    # the exact objective comes with it, from the same path solve
    np.testing.assert_allclose(np.asarray(exact), feed.evaluate(np.asarray(u_of_v(v)), np.zeros(4, int))["value"],
                               rtol=1e-12)
    h = 1e-6
    for j in range(3):
        e = jnp.zeros(3).at[j].set(h)
        fd = (f(v + e, c) - f(v - e, c)) / (2 * h)
        np.testing.assert_allclose(np.asarray(grad[:, j]), np.asarray(fd), rtol=1e-6, atol=1e-10)


# ----------------------------------------------------------------------------- searches


def test_gradient_beats_sampling_with_ten_times_fewer_evaluations(feed):
    mc = run(feed, "montecarlo", budget=2000, seed=3)
    grid = run(feed, "uniform", budget=2000, seed=3)
    gr = run(feed, "gradient", budget=200, seed=3, starts=4)
    assert gr.evaluations <= 200
    assert gr.value <= min(mc.value, grid.value)
    # the stationary point found satisfies the seed's bounds on the path
    m = gr.metrics
    assert 4.9 < m["two_a"] < 5.1 and 1.9 < m["two_b"] < 2.1


def test_a_problem_s_evaluator_is_made_once_and_changes_no_answer():
    """`run` on a Problem reuses the Evaluator of its first search (compiled once); the second
    search equals the first and a search on a fresh Evaluator, and another chunk has its own (a
    key without the chunk would hand back the first)."""
    from jaxlink.optimize.searches.runner import evaluator_for

    def numbers(res):
        doc = res.to_json()
        return {k: v for k, v in doc.items() if k not in ("wall_s", "search_wall_s", "compile_s", "trace")}

    pr = problem_from(load("sewing-feed-opt"))
    a = run(pr, "montecarlo", budget=256, seed=5, chunk=64)
    ev = evaluator_for(pr, 64)
    b = run(pr, "montecarlo", budget=256, seed=5, chunk=64)
    assert evaluator_for(pr, 64) is ev and ev.chunk == 64
    other = evaluator_for(pr, 128)
    assert other is not ev and other.chunk == 128
    fresh = run(Evaluator(problem_from(load("sewing-feed-opt")), chunk=64), "montecarlo", budget=256, seed=5)
    assert numbers(a) == numbers(b) == numbers(fresh)
    assert a.evaluations == 256 and a.value is not None


def test_the_file_configuration_in_closed_form_is_the_path_solve_s():
    """The file's configuration at its start, taken from the dyads' closed form nearest to the
    guesses (a set-up of two small programs instead of the path solve's), is the path solve's to
    rounding (≤ 4 ulp of π), on the same branches; away from the start, or for a design that does
    not assemble there, the path solve decides (and refuses the latter, naming the result)."""
    from jaxlink.optimize import start
    from jaxlink.solvers.assemble import solve

    rng = np.random.default_rng(3)
    for name in ("four-bar-sketch", "sewing-feed-opt"):
        m0 = load(name)
        for k in range(3):
            scale = 1 + 0.01 * k * rng.uniform(-1, 1, len(m0.parameters))
            m = m0.replace(parameters=np.asarray(m0.parameters) * scale)
            phi0 = float(m.input_start)
            fast = start._closed_form_configuration(m, phi0)
            path = np.asarray(solve(m, np.asarray([phi0]), points=False).q)[0]
            assert fast is not None and np.max(np.abs(fast - path)) <= 4 * np.spacing(np.pi), name
            assert np.array_equal(start.circuit_signs(m, fast, phi0, all_circuits=False),
                                  start.circuit_signs(m, path, phi0, all_circuits=False))
            assert np.array_equal(start.file_configuration(m, phi0), fast)
    # a differential test: a study's responses (their branches σ, and the turn solved from the
    # configuration: every angle, point and result code) are the same bit for bit with the
    # closed-form configuration and with the path solve's; a configuration on the other branch
    # (a wrong one) changes them
    from jaxlink import study as st
    from jaxlink.solvers import dyads as _dyads
    from jaxlink.study.responses import Responses

    m = load("four-bar-sketch")
    inp = st.read_study(m, {"positions": 36, "samples": 0, "tolerances": {"crank": 0.05}})

    def numbers():
        r = Responses(m, inp)
        sol = solve(m, r.phis, np.asarray(m.parameters), r.q_file)
        return [r.sigma, *(np.asarray(x) for x in (sol.q, sol.points, sol.result))]

    fast = numbers()
    real = start._closed_form_configuration

    def mirrored(mech, phi0):
        g, p, dyads = np.asarray(mech.guess), mech.parameters, _dyads.classify(mech)
        sig = np.asarray(_dyads.solve_nearest(mech, dyads, g, phi0, p)[3])
        return np.asarray(_dyads.solve(mech, dyads, -sig, g, phi0, p)[0])

    for variant, same in ((lambda mech, phi0: None, True), (mirrored, False)):
        start._closed_form_configuration = variant
        try:
            other = numbers()
        finally:
            start._closed_form_configuration = real
        assert all(np.array_equal(a, b) for a, b in zip(fast, other)) == same
    # away from its start the path solve decides
    assert start._closed_form_configuration(m, float(m.input_start) + 0.1) is None
    # a rocker that cannot reach at the start: refused by the path solve, naming the result
    bad = m.replace(parameters=m.with_parameters(rocker=1.0))
    assert start._closed_form_configuration(bad, float(bad.input_start)) is None
    with pytest.raises(MechanismError, match="cannot be assembled at the first input"):
        start.file_configuration(bad, float(bad.input_start))


@pytest.mark.parametrize("chunk", [-4, 0, 2.5, True, "64", 2_000_000])
def test_a_chunk_outside_its_domain_is_refused_naming_the_key(chunk):
    """A chunk ≤ 0 once made `run` loop for ever (every batch empty); any chunk outside 1 … 1e6
    given to an `Evaluator` (or to `run` on one it builds: 0 there means the default) is refused."""
    pr = problem_from(load("sewing-feed-opt"))
    with pytest.raises(MechanismError, match="chunk") as e:
        Evaluator(pr, chunk=chunk)
    assert e.value.key == "optimize.chunk"
    if chunk != 0:
        with pytest.raises(MechanismError, match="chunk"):
            run(pr, "montecarlo", budget=16, chunk=chunk)


@pytest.mark.parametrize("method", ["montecarlo", "gradient"])
def test_killed_and_resumed_search_ends_with_the_same_best(feed, tmp_path, method):
    kw = dict(budget=300, seed=7, starts=4) if method == "gradient" else dict(budget=300, seed=7)
    whole = run(feed, method, out=tmp_path / "whole.json", **kw)
    part = run(feed, method, out=tmp_path / "part.json", stop_after_chunks=2, **kw)
    assert not part.complete
    assert json.loads((tmp_path / "part.json").read_text())["complete"] is False
    done = run(feed, method, out=tmp_path / "part.json", resume=True, **kw)
    assert done.complete
    assert done.evaluations == whole.evaluations
    assert done.parameters == whole.parameters
    assert done.value == whole.value
    assert json.loads((tmp_path / "part.json").read_text()) == done.to_json()
    log = [json.loads(x) for x in (tmp_path / "part.log.jsonl").read_text().splitlines()]
    assert [r["chunk"] for r in log] == list(range(1, len(log) + 1))  # nothing lost or repeated


# ----------------------------------------------------------------------------- files and CLI


def test_bad_optimize_sections_name_the_key():
    mech = load("sewing-feed-opt")
    bad = [
        ({"variables": {"l9": [0, 1]}}, "variables.l9"),
        ({"variables": {"l2": [3, 1]}}, "variables.l2"),
        ({"objective": "nope"}, "objective"),
        ({"point": "Q"}, "point"),
        ({"samples": 2}, "samples"),
        ({"colour": 1}, "colour"),
    ]
    for override, key in bad:
        with pytest.raises(MechanismError) as exc:
            problem_from(mech, override)
        assert exc.value.key == "optimize." + key


def test_cli_writes_the_spec_json(tmp_path, capsys):
    from jaxlink.cli import main

    out = tmp_path / "r.json"
    assert main(["optimize", "sewing-feed-opt", "--method", "montecarlo", "--budget", "64",
                 "--chunk", "64", "--out", str(out), "--progress", "off"]) == 0
    data = json.loads(out.read_text())
    for key in ("method", "best", "evaluations", "wall_s", "infeasible_fraction"):
        assert key in data
    assert set(data["best"]["parameters"]) == {"l2", "l22", "gamma"}
    assert data["evaluations"] == 64 and data["method"] == "montecarlo"
    assert main(["optimize", "four-bar", "--method", "uniform"]) == 2  # no [optimize] section
    # the public entry point on the problem gives the same document (but the time)
    res = run(problem_from(load("sewing-feed-opt")), "montecarlo", budget=64, seed=0, chunk=64)
    assert isinstance(res, SearchResult) and res.parameters == data["best"]["parameters"]
    doc = res.to_json()
    untimed = lambda d: {**d, "wall_s": 0, "search_wall_s": 0, "compile_s": 0, "best_file": 0, "trace": [{**t, "seconds": 0} for t in d["trace"]]}  # noqa: E501, E731
    assert list(doc) == list(data) and untimed(doc) == untimed(data)


def test_resuming_another_search_is_refused(feed, tmp_path):
    out = tmp_path / "r.json"
    run(feed, "montecarlo", budget=64, seed=1, out=out)
    with pytest.raises(MechanismError, match="another search"):
        run(feed, "montecarlo", budget=64, seed=2, out=out, resume=True)
    with pytest.raises(MechanismError, match="another search"):
        run(feed, "uniform", budget=64, seed=1, out=out, resume=True)


_KILLED = r"""
import sys
from jaxlink.cli import main
sys.exit(main(["optimize", "sewing-feed-opt", "--method", "montecarlo", "--budget", sys.argv[1], "--seed", "5",
               "--chunk", "64", "--out", sys.argv[2], "--progress", "off"]))
"""


def test_kill_9_then_resume_gives_the_uninterrupted_result(feed, tmp_path):
    """A Monte Carlo search of the CLI killed (SIGKILL) after a few checkpoints and resumed ends
    with exactly the best design, value and counts of an uninterrupted search."""
    import os
    import signal
    import subprocess
    import sys
    import time

    budget = 64 * 300
    out = tmp_path / "r.json"
    log = tmp_path / "r.log.jsonl"
    proc = subprocess.Popen([sys.executable, "-c", _KILLED, str(budget), str(out)], cwd=ROOT)
    t0 = time.monotonic()
    while (not log.exists() or len(log.read_text().splitlines()) < 3) and time.monotonic() - t0 < 240:
        assert proc.poll() is None, "the search ended before it was killed"
        time.sleep(0.01)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    killed = json.loads(out.read_text())
    assert killed["complete"] is False and 0 < killed["evaluations"] < budget
    # resumed here (the same file, [optimize], chunk, method, seed and budget as the CLI's search)
    done = run(feed, "montecarlo", budget=budget, seed=5, out=out, resume=True)
    whole = run(feed, "montecarlo", budget=budget, seed=5)
    assert done.complete and done.evaluations == whole.evaluations == budget
    assert done.designs == whole.designs and done.infeasible_fraction == whole.infeasible_fraction
    assert done.parameters == whole.parameters and done.search_value == whole.search_value
    assert json.loads(out.read_text()) == done.to_json()


def test_background_compilation_errors_reach_the_caller():
    from jaxlink.optimize.searches.base import compile_ahead

    def broken(x):
        raise ValueError("no such objective term")

    future = compile_ahead(jax.jit(broken), np.zeros(3))
    with pytest.raises(ValueError, match="no such objective term"):
        future.result()


# ----------------------------------------------------------------------------- starts, sharding

_SHARDED = r"""
import json
import jax
jax.config.update("jax_enable_x64", True)
assert len(jax.devices()) == 4, jax.devices()
from jaxlink import load
from jaxlink.optimize import Evaluator, problem_from
from jaxlink.optimize.searches import searcher
ev = Evaluator(problem_from(load("sewing-feed-opt")), chunk=64)
assert ev.n_devices == 4
s = searcher(ev, "montecarlo", budget=256, seed=11)
st = s.init()
while not s.done(st):
    st = s.step(st)
p = st.progress
print(json.dumps([p.best_u.tolist(), float(p.best_value), int(p.evaluations)]))
"""


def test_sharded_run_equals_single_device_run(feed):
    import os
    import subprocess
    import sys

    from jaxlink.optimize.searches import searcher

    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", _SHARDED], env=env, capture_output=True, text=True,
                          timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    best_u, best_value, evaluations = json.loads(proc.stdout.strip().splitlines()[-1])
    assert feed.n_devices == 1
    s = searcher(feed, "montecarlo", budget=256, seed=11)
    st = s.init()
    while not s.done(st):
        st = s.step(st)
    p = st.progress
    assert evaluations == int(p.evaluations) == 256
    np.testing.assert_array_equal(np.asarray(best_u), p.best_u)
    assert best_value == pytest.approx(float(p.best_value), rel=1e-13)


def _feed_assemblable(l2, l22, gamma, p, sigma1, phis):
    """Independent numpy check: both dyads of the feed six-bar close at every input, with the
    lever dyad on branch sigma1 (circle-circle intersections, spec/feed-six-bar.md)."""
    ok = np.ones(len(l2), bool)
    E = np.array([p["l8"], p["l7"]])
    for phi in phis:
        B = l2[:, None] * np.array([np.cos(phi), np.sin(phi)])
        w = E - B
        r = np.hypot(*w.T)
        x = (r**2 + p["l3"] ** 2 - p["l44"] ** 2) / (2 * r)
        h2 = p["l3"] ** 2 - x**2
        ok &= h2 >= 0
        h = np.sqrt(np.maximum(h2, 0))
        D = B + (x[:, None] * w + sigma1 * h[:, None] * np.stack([-w[:, 1], w[:, 0]], 1)) / r[:, None]
        F = D + p["l4"] / p["l44"] * (E - D)
        C = -l22[:, None] * np.stack([np.cos(phi + gamma), np.sin(phi + gamma)], 1)
        dist = np.hypot(*(C - F).T)
        ok &= (dist <= p["l5"] + p["l6"]) & (dist >= abs(p["l5"] - p["l6"]))
    return ok


def test_continuation_start_rarely_declares_assemblable_designs_infeasible(feed):
    # ground truth: the independent numpy circle intersections on the file's lever branch; the
    # continuation in the parameters must agree (and the closed-form start exactly)
    mech = load("sewing-feed-opt")
    table = dict(mech.tables["optimize"], start_method="continuation",
                 variables={"l2": [0.0, 25.0], "l22": [0.0, 25.0], "gamma": [-180.0, 180.0]})
    pr = problem_from(mech, table)
    cont = Evaluator(pr, chunk=512)
    U = np.random.default_rng(5).random((512, 3))
    x = pr.to_file_units(U)
    p = {n: mech.from_si(n, v) for n, v in zip(mech.parameter_names, mech.parameters)}
    q = cont.q_file  # the file's configuration at the first input: its lever-dyad branch
    B = p["l2"] * np.array([np.cos(pr.phis[0]), np.sin(pr.phis[0])])
    D = B + p["l3"] * np.array([np.cos(q[0]), np.sin(q[0])])
    E = np.array([p["l8"], p["l7"]])
    u, v = E - B, D - B
    sigma1 = np.sign(u[0] * v[1] - u[1] * v[0])
    truth = _feed_assemblable(x[:, 0], x[:, 1], np.deg2rad(x[:, 2]), p, sigma1, pr.phis)
    assert 0.05 < (~truth).mean() < 0.95  # the box does reach unassemblable designs
    b = cont.evaluate(U)
    wrongly = truth & ~b["feasible"]
    assert not np.any(b["feasible"] & ~truth)
    assert wrongly.mean() <= 0.01, wrongly.mean()
