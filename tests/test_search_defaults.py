"""Defaults that work on a plain file: the similarity placement found from the structure, every
circuit for the path objective, a search sized from the problem that stops by itself, `time`."""

import json
import pathlib
import sys

import jax
import numpy as np

from jaxlink import load
from jaxlink.optimize import Evaluator, problem_from, run
from jaxlink.optimize.align import detect_placement

ROOT = pathlib.Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks" / "fourbar-path" / "fourbar_path_benchmarks.json"
sys.path.insert(0, str(ROOT / "experiments" / "fourbar_plain"))
from generate import plain_text  # noqa: E402

jax.config.update("jax_enable_x64", True)


def plain(tmp_path, unit="deg"):
    path = tmp_path / "yu1.toml"
    path.write_text(plain_text("yu1", json.loads(BENCH.read_text())["yu1"]["target"], angle_unit=unit))
    return load(path)


def test_placement_and_circuits_are_found_from_the_structure(tmp_path):
    ev = Evaluator(problem_from(plain(tmp_path)), chunk=16)
    names = ev.problem.names
    ix, iy, ia, il = detect_placement(ev)
    assert (names[ix], names[iy], names[ia]) == ("p1x", "p1y", "a")
    assert sorted(names[i] for i in il) == ["l1", "l2", "l3", "l4", "l5"]
    assert ev.circuits == "all" and ev.n_circuits == 2
    # not the path objective: the file's circuit; a length left fixed: no placement
    assert Evaluator(problem_from(load("sewing-feed-opt")), chunk=16).n_circuits == 1
    mech = plain(tmp_path)
    table = dict(mech.tables["optimize"])
    table["variables"] = {k: v for k, v in table["variables"].items() if k != "l5"}
    assert detect_placement(Evaluator(problem_from(mech, table), chunk=16)) is None


def test_a_search_without_budget_stops_by_itself_and_by_time(tmp_path):
    ev = Evaluator(problem_from(plain(tmp_path), {"samples": 72, "report_samples": 720}), chunk=64)
    small = dict(starts=4, presample=128, iterations=1000, patience=10)
    res = run(ev, "gradient", seed=0, **small)
    from jaxlink.optimize.searches.gradient import AUTO_BUDGET

    assert res.complete and res.value is not None
    # it stopped on no improvement, long before 1000 iterations and its default budget of evaluations
    assert res.evaluations < 128 * 2 * 3 + 1000 * 4 * 2 * 5
    assert res.extra["stopped_by"] == "converged" and res.budget == AUTO_BUDGET > res.evaluations
    assert res.trace and all(a["objective"] > b["objective"] for a, b in zip(res.trace, res.trace[1:]))
    assert res.search_wall_s >= 0 and res.compile_s >= 0
    # no time limit unless one is given
    assert "time_limit_s" not in res.extra and "time_limit_s" not in res.to_json()
    timed = run(ev, "gradient", seed=0, time=1e-3, starts=4, presample=128)
    assert timed.complete and timed.extra["stopped_by"] == "time_limit" and timed.extra["time_limit_s"] == 1e-3
    assert timed.to_json()["stopped_by"] == "time_limit"
    assert timed.evaluations < res.evaluations
    assert np.isfinite(res.value)


class _SlowClock:
    """A machine under load, for the runner: every reading of the clock `step` seconds after the
    one before."""

    def __init__(self, step: float):
        self.t, self.step = 0.0, step

    def perf_counter(self) -> float:
        self.t += self.step
        return self.t


def test_the_default_search_gives_the_same_design_under_load(tmp_path, monkeypatch):
    """The default search (no budget, no time) counts evaluations, iterations and its presample:
    on a machine whose clock runs 30 s per reading it ends at exactly the design of a quiet run
    (with the old default, a 75 s limit whose 30 % ended the presample, it ended at another one,
    stopped by the time)."""
    from jaxlink.optimize.searches import runner

    ev = Evaluator(problem_from(plain(tmp_path), {"samples": 72, "report_samples": 720}), chunk=64)
    small = dict(starts=4, presample=128, iterations=30)
    quiet = run(ev, "gradient", seed=0, **small)
    monkeypatch.setattr(runner, "_time", _SlowClock(30.0))
    loaded = run(ev, "gradient", seed=0, **small)
    assert loaded.best_file_text() == quiet.best_file_text()
    assert (loaded.value, loaded.evaluations) == (quiet.value, quiet.evaluations)
    assert loaded.extra["stopped_by"] == quiet.extra["stopped_by"] != "time_limit"


def test_a_time_limit_starts_no_chunk_that_cannot_fit(tmp_path, monkeypatch):
    """With a time limit, a chunk starts only if one as long as the last fits in the time left.
    The clock at 10 s a reading (warm programs: no compilation): the check before chunk 1 reads
    10 s, chunk 1 takes 10 s; the check before chunk 2 reads 40 s, + 10 s fits in 55 s; chunk 3
    would not (70 s): two chunks, stopped by the time limit (the old rule, 'stop once 55 s of steps
    are spent', ran six)."""
    from jaxlink.optimize.searches import runner

    ev = Evaluator(problem_from(plain(tmp_path), {"samples": 72, "report_samples": 720}), chunk=64)
    small = dict(starts=4, presample=512, iterations=30)
    two = run(ev, "gradient", seed=0, stop_after_chunks=2, **small)  # also compiles every program
    run(ev, "gradient", seed=0, **small)
    monkeypatch.setattr(runner, "_time", _SlowClock(10.0))
    capped = run(ev, "gradient", seed=0, time=55.0, **small)
    assert capped.extra["stopped_by"] == "time_limit" and capped.extra["time_limit_s"] == 55.0
    assert capped.evaluations == two.evaluations and capped.wall_s == 20.0


def test_icp_places_a_moved_path_back_from_any_turn():
    """The multi-start ICP finds the similarity that puts a moved path back on targets taken from
    it, whatever the turn (a single ICP from the identity does not: the reason for the starts)."""
    import jax.numpy as jnp

    from jaxlink.optimize.align import icp_similarity

    k = np.arange(360) * 2 * np.pi / 360
    r = 1.0 + 0.5 * np.cos(k)  # a limaçon: no symmetry a wrong turn could match
    curve = np.stack([r * np.cos(k), r * np.sin(k)], axis=1)
    targets = curve[::30] * 2.0 + np.array([5.0, -3.0])
    rng = np.random.default_rng(1)
    moved = []
    for _ in range(16):
        s, th, t = np.exp(rng.uniform(-1, 1)), rng.uniform(-np.pi, np.pi), rng.uniform(-4, 4, 2)
        R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        moved.append(s * curve @ R.T + t)
    *_, sse = icp_similarity(jnp.asarray(np.array(moved)), jnp.asarray(targets))
    # every target within 2 % of the targets' size of the path (a wrong turn or scale: ~30 %);
    # the search's gradient steps converge the rest
    size = np.hypot(*np.ptp(targets, axis=0))
    assert np.all(np.asarray(sse) < len(targets) * (0.02 * size) ** 2)


def test_a_search_compiles_a_fixed_set_of_functions(tmp_path):
    """A second search on the same evaluator with another presample size (other chunk counts and
    feasible counts) compiles nothing: every batch has a fixed shape."""
    import jax.monitoring

    ev = Evaluator(problem_from(plain(tmp_path), {"samples": 72, "report_samples": 720}), chunk=64)
    run(ev, "gradient", seed=0, starts=4, presample=128, iterations=20)
    compiled = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda e, d, **kw: compiled.append(e) if e == "/jax/core/compile/backend_compile_duration" else None)
    res = run(ev, "gradient", seed=1, starts=4, presample=200, iterations=20)
    assert res.value is not None and compiled == []
    # differential: the polish without following the feasibility boundary (issue 46, item 10;
    # `searches/boundary.py`) gives the same design where it lies far from the boundary (margin
    # 0.30; the other polished starts may near it, so the evaluations may differ)
    assert res.certificate["margin"] > 0.1
    off = run(ev, "gradient", seed=1, starts=4, presample=200, iterations=20, boundary=False)
    assert off.parameters == res.parameters and off.value == res.value
