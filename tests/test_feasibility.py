"""Feasibility between samples (issue 23, item 5): a four-bar whose crank cannot pass a window
narrower than the spacing of the 72 checked positions.

The target is our own construction: frame l1 = 100, crank l2 = 30, rocker l4 = 65 (mm). With
coupler l3 < 65 the crank tip's distance to the rocker pivot, d² = l1² + l2² − 2 l1 l2 cos φ,
exceeds l3 + l4 on the window cos φ < (l1² + l2² − (l3 + l4)²) / (2 l1 l2) around φ = 180°:
for l3 = 64.99, 178.31°…181.69°, between the checked positions 177.5° and 182.5° (start 2.5°,
step 5°). The targets are 30 points of that design's coupler curve."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlink import load, loads, solve
from jaxlink.analysis import feasibility
from jaxlink.optimize import Evaluator, problem_from, run
from jaxlink.optimize.searches.base import progress_start
from jaxlink.optimize.searches.result import summarized
from jaxlink.solvers import dyads as _dyads

jax.config.update("jax_enable_x64", True)

L1, L2, L4 = 100.0, 30.0, 65.0
GAP_L3 = 64.99
DENSE = np.radians(np.arange(36000) / 100.0)  # 36 000 positions, every 0.01°


def text(l3, targets=None, bounds=(64.0, 66.0)):
    d = L1 - L2  # at phi = 0 the crank tip is at (30, 0), the rocker pivot at (100, 0)
    c = (l3**2 - L4**2 + d**2) / (2 * d)
    p4 = np.array([L2 + c, math.sqrt(l3**2 - c**2)])
    th3 = math.degrees(math.atan2(p4[1], p4[0] - L2))
    th4 = math.degrees(math.atan2(p4[1], p4[0] - L1))
    opt = ""
    if targets is not None:
        pts = ", ".join(f"[{float(x)!r}, {float(y)!r}]" for x, y in targets)
        opt = f"""
[optimize]
point = "P"
objective = "points"
start = 2.5
report_samples = 36000
variables = {{ l3 = [{bounds[0]!r}, {bounds[1]!r}] }}
targets = [{pts}]
"""
    return f"""[mechanism]
name = "gap-four-bar"
length_unit = "mm"
angle_unit = "deg"

[parameters]
l1 = {L1!r}
l2 = {L2!r}
l3 = {l3!r}
l4 = {L4!r}
l5 = 40.0
g = 30.0

[input]
name = "phi"
body = "crank"
start = 2.5

[unknowns]
th3 = {th3!r}
th4 = {th4!r}

[loops]
main = ["l2 @ phi", "l3 @ th3", "-l4 @ th4", "-l1 @ 0"]

[points]
P = ["l2 @ phi", "l5 @ th3 + g"]
{opt}"""


def window(l3):
    """The crank angles (deg) where the four-bar cannot be assembled, by the closed form."""
    half = math.degrees(math.acos((L1**2 + L2**2 - (l3 + L4) ** 2) / (2 * L1 * L2)))
    return half, 360.0 - half


def targets():
    mech = loads(text(GAP_L3))
    phis = np.radians(3.5 + 12.0 * np.arange(30))  # 30 points of the curve, none in the window
    sol = solve(mech, phis, points=True)
    assert bool(np.all(sol.converged))
    return np.asarray(sol.points[:, 0]) * 1000.0  # mm


@pytest.fixture(scope="module")
def gap_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("gap") / "gap.toml"
    path.write_text(text(65.5, targets()))
    return path


def test_the_certificate_finds_the_window_that_72_samples_miss():
    a, b = window(GAP_L3)
    assert 177.5 < a < b < 182.5  # between two checked positions
    mech = loads(text(GAP_L3))
    dyads = _dyads.classify(mech)
    p, q = jnp.asarray(mech.parameters), jnp.asarray(mech.guess)
    phis = jnp.asarray(np.radians(2.5 + 5.0 * np.arange(72)))
    sigma = _dyads.solve_nearest(mech, dyads, q, phis[0], p)[3]
    certify = jax.jit(lambda pp: feasibility.certify(mech, dyads, sigma, q, phis, pp))
    cert = certify(p)
    # the 72 checked positions all assemble: the old check passes the design ...
    assert float(cert.sampled) > 0
    assert bool(np.all(solve(mech, np.asarray(phis)).converged))
    # ... the certificate does not: the smallest margin, at 180° (the window's centre)
    assert not bool(cert.certified) and float(cert.margin) < 0
    assert abs(math.degrees(float(cert.where)) - 180.0) < 1e-4
    # the margin's closed form at 180°: |w| = l1 + l2, ((La+Lb)² − w²)(w² − (La−Lb)²) / (4 La² Lb²)
    w2 = (L1 + L2) ** 2
    exact = ((GAP_L3 + L4) ** 2 - w2) * (w2 - (GAP_L3 - L4) ** 2) / (4 * GAP_L3**2 * L4**2)
    assert float(cert.margin) == pytest.approx(exact, rel=1e-9)
    # a dense 36 000-position solve agrees: it fails exactly inside the closed-form window
    sol = solve(mech, DENSE)
    bad = np.degrees(DENSE[~np.asarray(sol.converged)])
    assert len(bad) > 0 and a - 0.01 <= bad.min() and bad.max() <= b + 0.01
    # a design that turns fully is certified, and assembles at all 36 000 positions
    full = loads(text(65.5))  # only l3 differs: the same compiled certificate
    cert = certify(jnp.asarray(full.parameters))
    assert bool(cert.certified) and float(cert.margin) > 0
    assert bool(np.all(solve(full, DENSE).converged))


def test_the_host_certificate_is_the_jitted_one():
    """`certify_host` (what `check` runs: the margins from a program of its own, the steps in numpy)
    takes the same steps as `certify`: on the design with a window between two of 72 samples and
    on two that turn fully, the same verdict, the same minimum to rounding and its place to the
    golden section's resolution; numpy's interval estimates are the jitted ones, number for
    number. Fewer golden-section steps move the minimum's place (the comparison has teeth), and
    with one refined interval the window, the smallest estimate, is still found."""
    phis = jnp.asarray(np.radians(2.5 + 5.0 * np.arange(72)))
    mech = loads(text(GAP_L3))  # the designs differ in l3 only: one structure, one compilation
    dyads = _dyads.classify(mech)
    q = jnp.asarray(mech.guess)
    certify = jax.jit(lambda s, pp: feasibility.certify(mech, dyads, s, q, phis, pp))
    margins_at = jax.jit(lambda s, xs, pp: feasibility.margins_at(mech, dyads, s, q, xs, pp))
    for l3, windowed in ((GAP_L3, True), (65.5, False), (80.0, False)):
        p = jnp.asarray(loads(text(l3)).parameters)
        sigma = _dyads.solve_nearest(mech, dyads, q, phis[0], p)[3]
        ref = certify(sigma, p)
        calls = []

        def margins(x, sigma=sigma, p=p, calls=calls):
            calls.append(len(x))
            return np.asarray(margins_at(sigma, jnp.asarray(x), p))

        host = feasibility.certify_host(margins, np.asarray(phis))
        assert bool(host.certified) == bool(ref.certified) == (not windowed)
        assert float(host.sampled) == float(ref.sampled)
        assert float(host.margin) == pytest.approx(float(ref.margin), rel=1e-12, abs=1e-15)
        assert float(host.where) == pytest.approx(float(ref.where), abs=1e-9)
        # the samples, 8 × 8 interior points, the two first golden-section points, then each step's 8
        assert calls == [72, 64, 8, 8] + [8] * 40
        m = margins(np.asarray(phis))
        for mine, jitted in zip(feasibility.interval_minima(m, np), jax.jit(feasibility.interval_minima)(m)):
            np.testing.assert_array_equal(mine, np.asarray(jitted))
        if windowed:
            short = feasibility.certify_host(margins, np.asarray(phis), steps=5)
            assert abs(float(short.where) - float(ref.where)) > 1e-6
            one = feasibility.certify_host(margins, np.asarray(phis), refine=1)
            assert not bool(one.certified) and abs(math.degrees(float(one.where)) - 180.0) < 1e-4


def test_the_screen_s_fast_form_gives_the_same_estimates():
    """`interval_lower` (the screen: minima of the candidates, no argmin/gather) equals the third
    output of `interval_minima` exactly, on margins with negative stretches, flat (non-convex)
    runs and several dyads; `least` is `jnp.min` (NaN included)."""
    rng = np.random.default_rng(3)
    phi = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    cases = jnp.asarray(np.stack([rng.standard_normal((72, 3)),
                                  np.stack([np.cos(phi) - 0.97, 0.5 + 0 * phi, np.sin(3 * phi) ** 2], 1),
                                  np.round(rng.standard_normal((72, 3)), 1)]))
    ref = jax.jit(jax.vmap(lambda m: feasibility.interval_minima(m)[2]))(cases)
    np.testing.assert_array_equal(np.asarray(jax.jit(jax.vmap(feasibility.interval_lower))(cases)), np.asarray(ref))
    assert np.asarray(ref).min() < 0
    v = jnp.asarray([1.0, -2.0, 0.5, np.nan])
    least = jax.jit(feasibility.least)
    assert float(least(v[:3])) == -2.0 and np.isnan(float(least(v)))


def test_a_search_returns_a_design_that_assembles_at_36000_positions(gap_file):
    ev = Evaluator(problem_from(load(gap_file)), chunk=64)
    res = run(ev, "gradient", seed=0, starts=4, presample=64, iterations=30)
    # on the old code: l3 ≈ 64.993 (a window between two checked positions), feasible False
    assert res.parameters is not None and res.feasible and res.certificate["certified"]
    assert res.certificate["margin"] > 0 and res.value is not None
    l3 = res.parameters["l3"]
    assert l3 + L4 >= L1 + L2  # turns fully by the closed form
    sol = solve(res.best_mechanism(), DENSE)
    assert bool(np.all(sol.converged))
    # the JSON says what is certified
    best = res.to_json()["best"]
    assert best["certified"] is True and best["certificate"] == "reach margin" and best["fallback"] == 0

    # a best design with a window: not reported; the result falls back or, with nothing
    # certified, has no design and says why
    u = ev.problem.to_unit(np.array([GAP_L3]))
    p = progress_start(1)._replace(best_value=np.float64(0.0), best_u=u, best_circuit=np.int64(0))
    out = summarized(ev, "gradient", p, seed=0, budget=None, complete=True)
    assert out.parameters is None and "reach margin" in out.reason and "180" in out.reason
    assert out.to_json()["best"]["certified"] is False


def test_optimize_exits_1_when_no_design_turns_fully(tmp_path, capsys):
    from jaxlink.cli import main

    path = tmp_path / "gaps.toml"
    path.write_text(text(65.5, targets(), bounds=(64.98, 64.999)))  # every design has a window < 5°
    assert main(["optimize", str(path), "--method", "montecarlo", "--budget", "32", "--chunk", "64",
                 "--out", str(tmp_path / "r.json")]) == 1
    out = capsys.readouterr()
    assert "none" in out.out and "assemble" in out.err
    assert not (tmp_path / "r.best.toml").exists()


def test_a_newton_block_design_is_checked_at_ten_times_the_samples():
    """The same four-bar with its coupler's angle written as 2 th3 − th3: not of the form th3 + c,
    so the loop is a Newton block, not a dyad, and there is no reach margin. Its reported design is
    re-solved at 10 × the search's 72 samples: the window of l3 = 64.99 (178.31°…181.69°, between
    two checked positions) is found there, and a design without one passes."""
    src = text(GAP_L3, targets=[[40.0, 20.0], [30.0, 40.0], [10.0, 30.0]])
    mech = loads(src.replace('"l3 @ th3"', '"l3 @ 2 * th3 - th3"'), file="newton.toml")
    assert _dyads.classify(mech) is None
    ev = Evaluator(problem_from(mech, {"report_samples": 72}), chunk=4)
    pr = ev.problem
    for l3, turns in ((GAP_L3, False), (65.5, True)):
        u = pr.to_unit(np.array([l3]))
        rep = ev.report(u, 0)
        assert rep["feasible"]  # at the search's own 72 positions: the window falls between two
        assert rep["certificate"] == "dense re-solve" and rep["dense_positions"] == 720
        assert rep["certified"] is turns, l3
