"""The tolerance study (`jaxlink.study`): first order against closed forms, against Monte Carlo,
exact for a linear response; the linear worst case bounds every sample; infeasible samples counted
against an independent assembly check.

One study of the offset slider-crank of file-format.md §16 (a sketch: crank `crank` = a from the
pivot O1, rod `rod` = b, guide at height e = 12 mm), compiled once and moved to other designs and
tolerances (`Study.moved`, nothing recompiled). Its slider B on the guide y = e:

    B.x(θ) = O1_x + a cos θ + R,   R = √(b² − (O1_y + a sin θ − e)²)
    ∂B.x/∂a = cos θ − (O1_y + a sin θ − e) sin θ / R,   ∂B.x/∂b = b / R,
    ∂B.x/∂O1_x = 1,   ∂B.x/∂O1_y = −(O1_y + a sin θ − e) / R,
    stroke = √((a + b)² − e²) − √((b − a)² − e²)   (O1 at the origin)

and the crank pin A = O1 + a (cos θ, sin θ) is linear in (a, O1_x, O1_y): there first order is exact.
"""

import json
import math

import numpy as np
import pytest
from interrupt import Stop, stop_after

import jaxlink as jl
from jaxlink import study as st

pytestmark = pytest.mark.xdist_group("study")

FILE = """
[mechanism]
length_unit = "mm"
angle_unit = "deg"

[sketch]
frame = ["O1"]

[sketch.input]
crank = "crank"

[sketch.joints]
O1 = [0, 0]
A = [21.650635094610966, 12.5]
B = [101.64907257935190, 12.0]

[sketch.links]
crank = ["O1", "A"]
rod = ["A", "B"]

[sketch.sliders]
B = { on = "frame", along = [1, 0] }

[study]
positions = 72
samples = 4096
chunk = 4096
metrics = ["stroke", "deviation"]
distribution = "uniform"

[study.tolerances]
crank = 0.01
rod = 0.01
O1 = { radius = 0.01 }
"""
E = 12.0


@pytest.fixture(scope="module")
def setup():
    mech = jl.loads(FILE)
    inputs = st.read_study(mech)
    return mech, inputs, st.Study(mech, inputs)


def _rows(rep, name):
    return np.asarray([i for i, lab in enumerate(rep.labels) if lab[0] == name])


def test_first_order_against_the_closed_form(setup):
    mech, inputs, study = setup
    rep = st.tolerance(mech, study=study, samples=0)
    a, b = 25.0, math.hypot(101.64907257935190 - 21.650635094610966, 0.5)
    th = np.deg2rad(rep.input_values)
    h = a * np.sin(th) - E
    R = np.sqrt(b * b - h * h)
    J = rep.first_order.jacobian[_rows(rep, "B.x")]  # columns: crank, rod, O1_x, O1_y
    np.testing.assert_allclose(rep.nominal[_rows(rep, "B.x")], a * np.cos(th) + R, rtol=1e-12)
    np.testing.assert_allclose(J[:, 0], np.cos(th) - h * np.sin(th) / R, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(J[:, 1], b / R, rtol=1e-9)
    np.testing.assert_allclose(J[:, 2], 1.0, rtol=1e-12)
    np.testing.assert_allclose(J[:, 3], -h / R, rtol=1e-9, atol=1e-12)
    # the stroke: its extremes refined between 72 samples; its derivative that of the closed form
    s1, s2 = math.sqrt((a + b) ** 2 - E * E), math.sqrt((b - a) ** 2 - E * E)
    k = _rows(rep, "stroke(s_B)")[0]
    assert rep.nominal[k] == pytest.approx(s1 - s2, rel=1e-5)
    np.testing.assert_allclose(rep.first_order.jacobian[k], [(a + b) / s1 + (b - a) / s2, (a + b) / s1 - (b - a) / s2,
                                                             0.0, E / s1 - E / s2], rtol=2e-3, atol=1e-6)
    # σ_RSS, worst case and importance from those derivatives (uniform: σ = t/√3; the zone: σ = r/2 per axis)
    sig = np.asarray([0.01 / math.sqrt(3), 0.01 / math.sqrt(3), 0.005, 0.005])
    Jb = rep.first_order.jacobian[_rows(rep, "B.x")]
    np.testing.assert_allclose(rep.first_order.sigma_rss[_rows(rep, "B.x")], np.sqrt(((Jb * sig) ** 2).sum(1)),
                               rtol=1e-12)
    wc = 0.01 * (np.abs(Jb[:, 0]) + np.abs(Jb[:, 1]) + np.hypot(Jb[:, 2], Jb[:, 3]))
    np.testing.assert_allclose(rep.first_order.worst_case[_rows(rep, "B.x")], wc, rtol=1e-12)
    np.testing.assert_allclose(rep.first_order.importance.sum(1)[_rows(rep, "B.x")], 1.0, rtol=1e-12)
    assert rep.certificate == "reach margin" and rep.margin > 0 and not rep.warnings


def test_monte_carlo_against_first_order(setup):
    """Small tolerances: σ of Monte Carlo within its sampling error of σ_RSS (4 standard errors of the
    sample σ, per response: SE(s) = SE(s²)/(2s) from the fourth moment), no warning; the worst case
    bounds every sample (uniform inputs: the box; the remainder of second order, (0.01 mm)²/R ≈ 1e-6
    mm, is far below the margin 1e-3 relative that is allowed); first order exact on the linear A."""
    mech, inputs, study = setup
    rep = st.tolerance(mech, study=study)
    mc, f = rep.monte_carlo, rep.first_order
    assert mc.samples == 4096 and mc.feasible == 4096 and mc.infeasible == 0
    assert mc.agree.all() and not rep.warnings
    live = f.sigma_rss > 0
    assert np.all(np.abs(mc.std - f.sigma_rss)[live] <= 4 * mc.std_error[live])
    assert np.all(mc.max_abs <= f.worst_case * (1 + 1e-3) + 1e-12)
    assert np.all(mc.deviation_max <= rep.deviation_bound * (1 + 1e-3))
    # the linear response A: the samples' own mean and σ of J δx, from the same draws
    dx = st.draws(inputs, 4096)
    for name in ("A.x", "A.y"):
        rows = _rows(rep, name)
        lin = dx @ f.jacobian[rows].T
        np.testing.assert_allclose(mc.mean_shift[rows], lin.mean(0), atol=1e-12)
        np.testing.assert_allclose(mc.std[rows], lin.std(0, ddof=1), rtol=1e-9)
    # the quantiles lie within the samples' range, the lower below the upper
    assert np.all(mc.low <= mc.high) and np.all(mc.high <= mc.max_abs + 1e-15)


def test_infeasible_samples_are_counted_near_a_toggle(setup):
    """The rod b = 37.5 mm just above a + e = 37 mm: a sample assembles over the whole turn iff
    b ≥ a + |e − O1_y| (its crank at −90° must reach the guide). Monte Carlo's count equals that of
    the draws themselves; the statistics are of the feasible samples, finite."""
    mech, inputs, study = setup
    wide = st.read_study(mech, tolerances={"crank": 0.4, "rod": 0.4, "O1": {"radius": 0.3}})
    near = study.moved(x0=[25.0, 37.5, 0.0, 0.0], inputs=wide)
    rep = st.tolerance(mech, study=near)
    dx = st.draws(wide, 4096)
    a, b, y = 25.0 + dx[:, 0], 37.5 + dx[:, 1], dx[:, 3]
    expected = int(np.count_nonzero(b < a + np.abs(E - y)))
    mc = rep.monte_carlo
    assert 200 < expected < 2000
    assert mc.infeasible == expected and mc.feasible == 4096 - expected
    assert any("do not assemble" in w for w in rep.warnings)
    # the margin's linear drop reaches it
    assert any("toggle" in w for w in rep.warnings), (rep.margin, rep.margin_drop, rep.warnings)
    for v in (mc.mean_shift, mc.std, mc.low, mc.high, mc.max_abs):
        assert np.all(np.isfinite(v))



def test_monte_carlo_capability_against_limits(setup, tmp_path):
    """Percent out of spec, Cp and Cpk of the stroke against limits: normal tolerances make the
    (nearly linear) stroke normal with σ ≈ σ_RSS, so limits at nominal ± σ_RSS leave 2Φ(−1) =
    31.7 % out (within 4 binomial standard errors); the count equals that of the draws' own
    closed-form strokes, s = √((a + b)² − (e − y)²) − √((b − a)² − (e − y)²), taken as deviations
    from the nominal (except samples within 2e-5 mm of a limit: the 72 samples' refined extremes);
    Cp = (U − L) / 6s and Cpk = min(U − μ, μ − L) / 3s of the samples' mean and σ; a one-sided
    limit has no Cp; an unknown response is an error."""
    import csv
    from math import erf

    from jaxlink.errors import MechanismError
    from jaxlink.report.tolerance import write_tolerance_csv

    mech, inputs, study = setup
    tol = {"crank": 0.01, "rod": 0.01, "O1": {"radius": 0.01}}
    normal = st.read_study(mech, tolerances=tol, distribution="normal")
    first = st.tolerance(mech, study=study.moved(inputs=normal), samples=0, worst=False)
    k = _rows(first, "stroke(s_B)")[0]
    nom, sig = first.nominal[k], first.first_order.sigma_rss[k]
    limited = st.read_study(mech, tolerances=tol, distribution="normal", limits={"stroke(s_B)": [nom - sig, nom + sig]})
    rep = st.tolerance(mech, study=study.moved(inputs=limited), worst=False)
    mc = rep.monte_carlo
    assert mc.feasible == 4096 and [lim[0] for lim in mc.limits] == ["stroke(s_B)"]
    p = 1.0 - erf(1.0 / math.sqrt(2.0))  # 2 Φ(−1)
    assert abs(mc.percent_out[0] / 100 - p) <= 4 * math.sqrt(p * (1 - p) / 4096)
    dx = st.draws(limited, 4096)
    b0 = math.hypot(101.64907257935190 - 21.650635094610966, 0.5)

    def stroke(a, b, y):
        return np.sqrt((a + b) ** 2 - (E - y) ** 2) - np.sqrt((b - a) ** 2 - (E - y) ** 2)

    d = stroke(25.0 + dx[:, 0], b0 + dx[:, 1], dx[:, 3]) - stroke(25.0, b0, 0.0)
    out = (d < -sig) | (d > sig)
    near = (np.abs(np.abs(d) - sig) < 2e-5).sum()
    assert abs(int(mc.out_of_spec[0]) - int(out.sum())) <= near < 40
    s, mu = mc.std[k], nom + mc.mean_shift[k]
    assert mc.cp[0] == pytest.approx(2 * sig / (6 * s), rel=1e-12)
    assert mc.cpk[0] == pytest.approx(min(nom + sig - mu, mu - nom + sig) / (3 * s), rel=1e-12)
    assert abs(mc.cp[0] - 1 / 3) <= 4 * mc.std_error[k] / s / 3  # s within its sampling error of σ_RSS
    # tolerance.csv carries them on the stroke's row
    write_tolerance_csv(tmp_path / "t.csv", mech, rep)
    rows = {r["output"]: r for r in csv.DictReader(open(tmp_path / "t.csv", encoding="utf-8"))}
    assert float(rows["stroke(s_B)"]["mc_cpk (1)"]) == pytest.approx(mc.cpk[0], rel=1e-9)
    assert rows["deviation(B)"]["mc_cp (1)"] == ""
    # the streamed histogram of the scalar responses: every feasible sample counted once, and the
    # stroke's counts those of the closed-form strokes (merged into 16 bins: only samples within
    # 2e-5 mm of a bin's edge may move to the next one)
    scalar = [i for i, (_n, _u, j) in enumerate(rep.labels) if j is None]
    h, w = mc.histogram[scalar.index(k)], mc.histogram_width[scalar.index(k)]
    assert mc.histogram.shape == (len(scalar), 1026) and (mc.histogram.sum(axis=1) == mc.feasible).all()
    edges = np.linspace(-w, w, 17)
    want = np.histogram(np.clip(d, -w, w), edges)[0]
    near_edge = int((np.abs(d[:, None] - edges[None, :]) < 2e-5).sum())
    assert np.abs(h[1:-1].reshape(16, 64).sum(axis=1) + np.r_[h[0], [0] * 14, h[-1]] - want).sum() <= 2 * near_edge
    # the tornado's bars: J t of each parameter alone, against the closed form's derivatives of s
    # (the metric's Jacobian is that of the refined extremes of 72 samples: 6.5e-6 relative here)
    from jaxlink.report.tolerance import draw_plots, tornado_rows

    a, b, y = 25.0, b0, 0.0
    r1, r2 = np.sqrt((a + b) ** 2 - (E - y) ** 2), np.sqrt((b - a) ** 2 - (E - y) ** 2)
    ds = {"crank": (a + b) / r1 + (b - a) / r2, "rod": (a + b) / r1 - (b - a) / r2,
          "O1_x": 0.0, "O1_y": (E - y) / r1 - (E - y) / r2}
    title, unit, lo, hi = next(r for r in tornado_rows(mech, rep) if r[0] == "stroke(s_B)")
    t = rep.first_order.half_width
    for j, name in enumerate(rep.parameters):
        assert hi[j] == pytest.approx(t[j] * ds[name], rel=1e-4, abs=1e-9) and lo[j] == -hi[j]
    names = [f.name for f in draw_plots(tmp_path, mech, rep)]
    assert names == ["tolerance.png", "tornado.png", "histograms.png"]
    # a one-sided limit: no Cp, Cpk of its side; an unknown response
    one = st.read_study(mech, tolerances=tol, distribution="normal", limits={"stroke(s_B)": ["-inf", nom]})
    mc1 = st.tolerance(mech, study=study.moved(inputs=one), worst=False).monte_carlo
    assert np.isnan(mc1.cp[0]) and mc1.cpk[0] == pytest.approx((nom - mu) / (3 * s), rel=1e-12)
    assert abs(mc1.percent_out[0] / 100 - 0.5) <= 4 * math.sqrt(0.25 / 4096) + abs(mu - nom) / s
    bad = st.read_study(mech, tolerances=tol, limits={"stroke(nope)": [0, 1]})
    with pytest.raises(MechanismError, match="no scalar response"):
        st.tolerance(mech, study=study.moved(inputs=bad), worst=False)


def test_the_true_worst_case(setup, tmp_path):
    """The worst case over the box ≥ every Monte Carlo sample's deviation (uniform inputs: the
    samples lie in the box) and ≥ the linear worst case where that is reached at a corner; for the
    linear A (A = O1 + a (cos θ, sin θ)) equal to the linear worst case, the zone's disc included.
    With scalar tolerances (16 corners, wide ±0.2–0.4 mm) the search is an enumeration and equals
    the closed form's largest deviation over the 16 corners."""
    import itertools

    from jaxlink.study.worstcase import monte_carlo_objectives

    mech, inputs, study = setup
    rep = st.tolerance(mech, study=study)
    w, K, N, nc = rep.worst, len(inputs.points), inputs.positions, study.responses.n_curve
    mc = monte_carlo_objectives(rep.monte_carlo, K, N, nc)
    assert w.names == ("stroke(s_B)", "deviation(A.x)", "deviation(A.y)", "deviation(A)",
                       "deviation(B.x)", "deviation(B.y)", "deviation(B)")
    assert np.all(w.value >= mc) and not w.corners and set(w.status) == {"found"} and w.infeasible == 0
    for n in ("deviation(A.x)", "deviation(A.y)", "deviation(A)"):  # linear: 0.01 + 0.01
        assert w.value[w.names.index(n)] == pytest.approx(0.02, rel=1e-9)
        assert w.linear[w.names.index(n)] == pytest.approx(0.02, rel=1e-9)
    assert np.all(w.value >= w.linear * (1 - 1e-3))  # second order only adds here
    # every corner enumerated, against the closed form at the corners
    half = np.asarray([0.3, 0.3, 0.2, 0.4])
    tol = st.read_study(mech, tolerances={p: {"tol": h, "distribution": "uniform"}
                                          for p, h in zip(("crank", "rod", "O1_x", "O1_y"), half)})
    rep = st.tolerance(mech, study=study.moved(inputs=tol), samples=1024)
    w = rep.worst
    assert w.corners and w.candidates == 16 and set(w.status) == {"enumerated"}
    theta = np.deg2rad(rep.input_values)
    corners = study.x0 + np.asarray(list(itertools.product((-1, 1), repeat=4))) * half
    (ax, ay, bx), (ax0, ay0, bx0) = _closed_form(corners, theta), _closed_form(study.x0[None], theta)
    ref = {"deviation(A.x)": np.abs(ax - ax0).max(), "deviation(A)": np.hypot(ax - ax0, ay - ay0).max(),
           "deviation(B.x)": np.abs(bx - bx0).max(), "deviation(A.y)": 0.7}
    for n, v in ref.items():
        assert w.value[w.names.index(n)] == pytest.approx(v, rel=1e-9), n
    assert np.all(w.value >= monte_carlo_objectives(rep.monte_carlo, K, N, nc))
    # the path's linear bound Σ_j t_j ‖∂A/∂x_j‖ = 0.3 + 0.2 + 0.4 is not reached by the path itself
    assert w.linear[w.names.index("deviation(A)")] == pytest.approx(0.9) and ref["deviation(A)"] < 0.8
    import csv
    import json

    from jaxlink.report import tolerance as rt

    rt.write_all(tmp_path, mech, rep, wall_time=1.0, plot=False)
    rows = {r["output"]: r for r in csv.DictReader((tmp_path / "tolerance.csv").open())}
    assert float(rows["deviation(A)"]["worst_case (unit)"]) == pytest.approx(ref["deviation(A)"], rel=1e-9)
    assert rows["deviation(A.y)"]["worst_case_status"] == "enumerated" and rows["A.x"]["worst_case (unit)"] == ""
    out = json.loads((tmp_path / "study.json").read_text())["worst_case"]["outputs"]
    assert out[w.names.index("deviation(B.x)")]["worst"] == pytest.approx(ref["deviation(B.x)"], rel=1e-9)
    assert "worst case over the tolerance box" in rt.summary(mech, rep)

def test_the_study_table_is_checked():
    mech = jl.loads(FILE)
    bad = {
        "tolerances": ({"crank": {"tol": 0.1, "sigma": 0.1}}, "exactly one of"),
        "distribution": ({"crank": {"tol": 0.1, "distribution": "beta"}}, "'distribution' must be one of"),
        "zone": ({"A": {"radius": 0.1}}, "needs the pivot's coordinates A_x, A_y"),
        "name": ({"crank_len": 0.1}, "'crank_len' is not a parameter"),
    }
    for tol, msg in bad.values():
        with pytest.raises(jl.MechanismError, match=msg):
            st.read_study(mech, tolerances=tol)
    with pytest.raises(jl.MechanismError, match="unknown key 'sample'"):
        st.read_study(mech, sample=3)
    inputs = st.read_study(mech, tolerances={"crank": {"sigma": 0.01, "distribution": "normal", "k": 2},
                                             "rod": {"tol": 0.06, "distribution": "normal"}})
    assert inputs.tolerances[0].half_width == pytest.approx(0.02)  # t = kσ
    assert inputs.tolerances[1].sigma == pytest.approx(0.02)        # σ = t/k, k = 3


# ---------------------------------------------------------------- step 2: ranges, sampling, Sobol'
ISHIGAMI_S1 = (0.3139051827, 0.4424111333, 0.0)  # a = 7, b = 0.1 (Ishigami & Homma 1990)
ISHIGAMI_ST = (0.5575888667, 0.4424111333, 0.2436836840)


def _ishigami_design(n, seed):
    from scipy.stats import qmc

    u = qmc.Sobol(6, scramble=True, seed=seed).random(n)
    a, b = -np.pi + 2 * np.pi * u[:, :3], -np.pi + 2 * np.pi * u[:, 3:]
    ab = np.stack([np.where(np.arange(3) == j, b, a) for j in range(3)])

    def f(x):
        return np.sin(x[..., 0]) + 7 * np.sin(x[..., 1]) ** 2 + 0.1 * x[..., 2] ** 4 * np.sin(x[..., 0])
    return f(a), f(b), f(ab)


def test_sobol_estimators_against_the_ishigami_closed_form():
    """S1 (Saltelli 2010) and ST (Jansen) of the Ishigami function against its exact indices, each
    inside its bootstrap interval widened by 1.5 (the estimate is unbiased; 6 intervals at 95 %)."""
    ya, yb, yab = _ishigami_design(8192, 3)
    r = st.sobol_indices(ya, yb, yab, resamples=200, seed=5)
    for m, exact in (("S1", ISHIGAMI_S1), ("ST", ISHIGAMI_ST)):
        v, lo, hi = (getattr(r, m)[0], getattr(r, m + "_low")[0], getattr(r, m + "_high")[0])
        half = 0.5 * (hi - lo)
        assert np.all(np.abs(v - exact) <= 1.5 * half + 1e-3), (m, v, exact, half)
        assert np.all(half < 0.04)
    # a constant output: indices 0, never a NaN; weights leave samples out exactly
    c = st.sobol_indices(np.ones(64), np.ones(64), np.ones((3, 64)), resamples=10, seed=1)
    assert c.constant[0] and np.all(c.S1 == 0) and np.all(c.ST_high == 0)
    w = np.arange(8192) % 3 != 0
    rw = st.sobol_indices(ya, yb, yab, resamples=0, weight=w)
    rs = st.sobol_indices(ya[w], yb[w], yab[:, w], resamples=0)
    np.testing.assert_allclose(rw.S1, rs.S1, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(rw.ST, rs.ST, rtol=1e-9)


def test_sobol_sums_written_in_place_equal_the_concatenated_terms():
    """The accumulator's per-sample terms, written in place into a kept buffer, give the sums of
    the terms built by concatenation (the form it replaced) bit for bit, batch after batch."""
    rng = np.random.default_rng(7)
    n, M, D, R = 50, 7, 3, 20
    counts = st.sobol.bootstrap_counts(2 * n, R, 4)
    shift = rng.standard_normal(M)
    acc = st.sobol.SobolAccumulator(M, D, counts, shift=shift)
    sums = np.zeros((R + 1, M * (2 + 3 * D)))
    for start in (0, n):
        ya, yb, yab = rng.standard_normal((n, M)), rng.standard_normal((n, M)), rng.standard_normal((D, n, M))
        w = (rng.random(n) > 0.2).astype(float)
        acc.update(start, ya, yb, yab, w)
        a, b = ya - shift, yb - shift
        diff = yab - shift - a

        def flat(z):
            return z.transpose(1, 0, 2).reshape(n, -1)

        terms = np.concatenate([a + b, a * a + b * b, flat(b * diff), flat(diff), flat(diff * diff)], axis=1)
        c = np.vstack([w, counts[:, start:start + n] * w])
        sums += c @ terms
    np.testing.assert_array_equal(acc.sums, sums)


def _second_order_design(f, n, d, lo, hi, seed):
    """(ya, yb, yab, yba) of `f` on A, B (n, d uniform over [lo, hi]), AB_j and BA_j."""
    from scipy.stats import qmc

    u = lo + (hi - lo) * qmc.Sobol(2 * d, scramble=True, seed=seed).random(n)
    a, b = u[:, :d], u[:, d:]
    ab = np.stack([np.where(np.arange(d) == j, b, a) for j in range(d)])
    ba = np.stack([np.where(np.arange(d) == j, a, b) for j in range(d)])
    return f(a), f(b), f(ab), f(ba)


def test_second_order_indices_against_closed_forms_and_salib():
    """S2 (Saltelli 2002) of y = x1 + x2 + x1 x2 (+ an inert x3), x uniform on [−1, 1]: V_1 = V_2 =
    1/3, V_12 = 1/9, so S1 = 3/7, S12 = 1/7, S13 = S23 = 0; and of the Ishigami function, S13 =
    b² π⁸ (8/225) / V, S12 = S23 = 0 — each within its bootstrap interval (×1.5). Streamed over
    three batches the sums give the single batch's indices. With SALib, its S1, ST, S2 and their
    intervals on the same samples (calc_second_order=True)."""
    pairs = st.sobol.pairs(3)
    assert pairs == [(0, 1), (0, 2), (1, 2)]
    cases = [(lambda x: x[..., 0] + x[..., 1] + x[..., 0] * x[..., 1], -1.0, 1.0, [1 / 7, 0.0, 0.0]),
             (lambda x: np.sin(x[..., 0]) + 7 * np.sin(x[..., 1]) ** 2 + 0.1 * x[..., 2] ** 4 * np.sin(x[..., 0]),
              -np.pi, np.pi, [0.0, 0.01 * np.pi ** 8 * 8 / 225 / (49 / 8 + 0.1 * np.pi ** 4 / 5
                                                                   + 0.01 * np.pi ** 8 / 18 + 0.5), 0.0])]
    for f, lo, hi, exact in cases:
        ya, yb, yab, yba = _second_order_design(f, 8192, 3, lo, hi, 3)
        r = st.sobol_indices(ya, yb, yab, yba=yba, resamples=100, seed=5)
        half = 0.5 * (r.S2_high - r.S2_low)[0]
        assert np.all(np.abs(r.S2[0] - exact) <= 1.5 * half + 1e-3), (r.S2[0], exact, half)
        assert np.all(half < 0.05)
        acc = st.SobolAccumulator(1, 3, st.sobol.bootstrap_counts(8192, 100, 5), second_order=True)
        for a, b in ((0, 3000), (3000, 5000), (5000, 8192)):
            acc.update(a, ya[a:b, None], yb[a:b, None], yab[:, a:b, None], yba=yba[:, a:b, None])
        streamed = acc.result()
        for m in ("S1", "ST", "S2", "S2_low", "S2_high"):
            np.testing.assert_allclose(getattr(streamed, m), getattr(r, m), rtol=1e-9, atol=1e-12)
    salib = pytest.importorskip("SALib.analyze.sobol")
    problem = {"num_vars": 3, "names": ["x1", "x2", "x3"], "bounds": [[-np.pi, np.pi]] * 3}
    Y = np.concatenate([ya[:, None], yab.T, yba.T, yb[:, None]], 1).ravel()  # SALib's order
    s = salib.analyze(problem, Y, calc_second_order=True, seed=5, num_resamples=100)
    for m in ("S1", "ST"):
        np.testing.assert_allclose(getattr(r, m)[0], s[m], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(getattr(r, m + "_high")[0] - getattr(r, m)[0], s[m + "_conf"], rtol=1e-9,
                                   atol=1e-12)
    np.testing.assert_allclose(r.S2[0], [s["S2"][j, k] for j, k in pairs], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(r.S2_high[0] - r.S2[0], [s["S2_conf"][j, k] for j, k in pairs], rtol=1e-9,
                               atol=1e-12)


def _closed_form(x, theta):
    """A.x, A.y, B.x (n, N each) of the slider-crank at designs x (n, 4: crank, rod, O1_x, O1_y)."""
    a, b, ox, oy = (x[:, k:k + 1] for k in range(4))
    ax, ay = ox + a * np.cos(theta), oy + a * np.sin(theta)
    return ax, ay, ax + np.sqrt(b * b - (ay - E) ** 2)


RANGES = {"crank": [24.99, 25.01], "rod": [80.0, 80.02], "O1_x": [-0.01, 0.01], "O1_y": [-0.01, 0.01]}


@pytest.fixture(scope="module")
def sensitivity_run(setup):
    mech, _inputs, study = setup
    inputs = st.read_study(mech, method="sensitivity", samples=1024, seed=4, ranges=RANGES)
    rep = st.sensitivity(mech, study=study.moved(inputs=inputs))
    return mech, inputs, study, rep


def test_sensitivity_of_the_path_against_closed_forms_and_first_order(sensitivity_run):
    """The study's indices of A.x, A.y and B.x at every position are the estimators' on the closed
    form evaluated at the same designs (the samples rebuilt from `unit_blocks`); for the linear A
    (y = Σ a_j x_j, uniform inputs) S1 = ST = a_j² σ_j² / Σ exactly, which are the tolerance
    method's importance factors with the same uniform half-widths: each within its interval
    (×2: 4 × 144 comparisons). With SALib installed, SALib's numbers on the same samples."""
    mech, inputs, study, rep = sensitivity_run
    assert rep.samples == 1024 and rep.evaluations == 6144 and rep.complete == 1024 and not rep.warnings
    assert rep.feasible_fraction == 1.0 and rep.feasibility.constant[0] and np.all(rep.feasibility.ST == 0)
    theta = np.deg2rad(rep.input_values)
    u = np.concatenate(list(st.unit_blocks("sobol", 8, 1024, 4, 300)))
    a, b = st.to_values(inputs, study.x0, u[:, :4]), st.to_values(inputs, study.x0, u[:, 4:])
    ab = np.repeat(a[None], 4, axis=0)
    for j in range(4):
        ab[j][:, j] = b[:, j]
    ya, yb = _closed_form(a, theta), _closed_form(b, theta)
    yab = [_closed_form(x, theta) for x in ab]
    ind = rep.indices
    for c, name in enumerate(("A.x", "A.y", "B.x")):
        rows = _rows(rep, name)
        ref = st.sobol_indices(ya[c], yb[c], np.stack([y[c] for y in yab]), seed=[4, 1])
        for m in ("S1", "ST", "S1_low", "ST_high"):
            np.testing.assert_allclose(getattr(ind, m)[rows], getattr(ref, m), rtol=1e-6, atol=1e-8)
    # the linear A: the importance factors of the tolerance method (uniform ±(high − low)/2)
    tol = st.read_study(mech, tolerances={k: {"tol": (hi - lo) / 2, "distribution": "uniform"}
                                          for k, (lo, hi) in RANGES.items()})
    first = study.moved(x0=[25.0, 80.01, 0.0, 0.0], inputs=tol).first_order()
    for name in ("A.x", "A.y"):
        rows = _rows(rep, name)
        imp = first.importance[rows]
        for m in ("S1", "ST"):
            v, half = getattr(ind, m)[rows], 0.5 * (getattr(ind, m + "_high") - getattr(ind, m + "_low"))[rows]
            assert np.all(np.abs(v - imp) <= 2 * half + 1e-9), (name, m, np.abs(v - imp).max())
    salib = pytest.importorskip("SALib.analyze.sobol")
    problem = {"num_vars": 4, "names": list(RANGES), "bounds": list(RANGES.values())}
    rows = _rows(rep, "B.x")
    for k in (0, 17, 40):
        Y = np.concatenate([ya[2][:, k:k + 1], np.stack([y[2][:, k] for y in yab], 1), yb[2][:, k:k + 1]], 1).ravel()
        s = salib.analyze(problem, Y, calc_second_order=False, seed=[4, 1])
        np.testing.assert_allclose(ind.S1[rows[k]], s["S1"], rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(ind.ST[rows[k]], s["ST"], rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(ind.S1_high[rows[k]] - ind.S1[rows[k]], s["S1_conf"], rtol=1e-5, atol=1e-9)
        np.testing.assert_allclose(ind.ST_high[rows[k]] - ind.ST[rows[k]], s["ST_conf"], rtol=1e-5, atol=1e-9)


def _designs(inputs, study, n, second=False):
    """A, B, AB_j (and BA_j) of the study's first `n` base samples, rebuilt from `unit_blocks`."""
    u = np.concatenate(list(st.unit_blocks("sobol", 8, n, inputs.seed, 300)))
    a, b = st.to_values(inputs, study.x0, u[:, :4]), st.to_values(inputs, study.x0, u[:, 4:])
    ab = np.stack([np.where(np.arange(4) == j, b, a) for j in range(4)])
    ba = np.stack([np.where(np.arange(4) == j, a, b) for j in range(4)])
    return a, b, ab, (ba if second else None)


def test_sensitivity_overlap_batches_and_second_order(sensitivity_run, tmp_path):
    """The study's batches overlapped (batch k + 1 dispatched before batch k's sums) give the
    indices of the plain loop bit for bit; both equal the estimators fed every design's evaluation
    at once (one batch, not two: the bootstrap counts follow the base samples). With
    `second_order`: S2 of every output equals the estimators' on the same evaluations (SALib's
    scheme, BA_j), and indices.csv holds its rows (`S2`, parameter `a,b`)."""
    from jaxlink.report import sampling as rs

    mech, inputs, study, rep = sensitivity_run
    moved = study.moved(inputs=inputs)
    plain = st.sensitivity(mech, study=moved, overlap=False)
    for m in st.SobolIndices._fields[:6]:
        assert np.array_equal(getattr(plain.indices, m), getattr(rep.indices, m)), m
    a, b, ab, _ = _designs(inputs, study, 1024)
    y, ok, _labels = st.evaluate(moved, np.concatenate([a, b, ab.reshape(-1, 4)]))
    assert ok.all()
    y = y.reshape(6, 1024, -1)
    acc = st.SobolAccumulator(y.shape[2], 4, st.sobol.bootstrap_counts(1024, 100, [4, 1]), shift=rep.nominal)
    acc.update(0, y[0], y[1], y[2:])  # the study's shift: tiny ranges, the sums of y − nominal
    ref = acc.result()
    for m in st.SobolIndices._fields[:6]:
        np.testing.assert_allclose(getattr(rep.indices, m), getattr(ref, m), rtol=1e-9, atol=1e-12, err_msg=m)

    sec = st.read_study(mech, method="sensitivity", samples=400, seed=4, ranges=RANGES, bootstrap=20,
                        second_order=True)
    r2 = st.sensitivity(mech, study=study.moved(inputs=sec))
    assert r2.evaluations == 400 * 10 and r2.indices.S2.shape == (len(r2.labels), 6)
    a, b, ab, ba = _designs(sec, study, 400, second=True)
    y, ok, _labels = st.evaluate(moved, np.concatenate([a, b, ab.reshape(-1, 4), ba.reshape(-1, 4)]))
    y = y.reshape(10, 400, -1)
    acc = st.SobolAccumulator(y.shape[2], 4, st.sobol.bootstrap_counts(400, 20, [4, 1]), shift=r2.nominal,
                              second_order=True)
    acc.update(0, y[0], y[1], y[2:6], yba=y[6:])
    ref = acc.result()
    for m in ("S1", "ST", "S2", "S2_low", "S2_high"):
        np.testing.assert_allclose(getattr(r2.indices, m), getattr(ref, m), rtol=1e-9, atol=1e-12, err_msg=m)
    rs.write_indices_csv(tmp_path / "indices.csv", mech, r2)
    rows = [line.split(",") for line in (tmp_path / "indices.csv").read_text().splitlines()]
    s2 = [r for r in rows if "S2" in r]
    assert len(s2) == 6 * (len(r2.labels) + 1) and rows[0][2] == "parameter"  # the feasibility too
    assert ['"crank', 'rod"'] in [r[2:4] for r in s2]
    rs.plot_bars(tmp_path / "sobol.png", mech, r2)  # the S2 bars beside S1 and ST
    assert (tmp_path / "sobol.png").stat().st_size > 1000
    with pytest.raises(jl.MechanismError, match="second_order"):
        st.read_study(mech, method="sample", ranges=RANGES, second_order=True)
    # with `tolerance` the key asks for the second-order moments (`tolerance(second_order=...)` from the CLI)
    assert st.read_study(mech, method="tolerance", tolerances={"crank": 0.05}, second_order=True).second_order


def test_sensitivity_of_the_feasibility_and_conditional_indices(setup, tmp_path):
    """Near the toggle b = a + e: feasibility iff b ≥ a + |e − O1_y| (independent check). The
    feasible fraction of the A, B draws equals that count; O1_x does not enter it, so its indices
    of the feasibility are exactly 0; the responses' indices are conditional (a warning), finite;
    indices.csv holds no NaN and the plots are written."""
    mech, _inputs, study = setup
    ranges = {"crank": [24.0, 26.0], "rod": [36.5, 39.0], "O1_x": [-0.5, 0.5], "O1_y": [-0.5, 0.5]}
    inputs = st.read_study(mech, method="sensitivity", samples=512, seed=2, ranges=ranges, bootstrap=50)
    rep = st.sensitivity(mech, study=study.moved(x0=[25.0, 38.0, 0.0, 0.0], inputs=inputs))
    u = np.concatenate(list(st.unit_blocks("sobol", 8, 512, 2)))
    x = np.concatenate([st.to_values(inputs, study.x0, u[:, :4]), st.to_values(inputs, study.x0, u[:, 4:])])
    ok = x[:, 1] >= x[:, 0] + np.abs(E - x[:, 3])
    assert 0.2 < ok.mean() < 0.9
    assert rep.feasible_fraction == pytest.approx(ok.mean(), abs=1e-12)
    f = rep.feasibility
    assert f.S1[0, 2] == 0 and f.ST[0, 2] == 0 and f.ST[0, 1] > 0.3 and f.ST[0, 0] > 0.05
    assert 0 < rep.complete < 512 and any("conditional on feasibility" in w for w in rep.warnings)
    for v in rep.indices:  # S2 None without the second order
        assert v is None or np.all(np.isfinite(np.asarray(v, float)))
    from jaxlink.report import sampling as rs

    files = rs.write_sensitivity_all(tmp_path, mech, rep, wall_time=1.0)
    assert {p.split("/")[-1] for p in files} == {"indices.csv", "sobol.png", "sobol_curves.png", "study.json",
                                                 "study.npz"}
    text = (tmp_path / "indices.csv").read_text()
    assert "nan" not in text.lower()
    assert text.splitlines()[0] == "output,input (deg),parameter,method,value (1),low (1),high (1),conditional"
    assert len(text.splitlines()) == 1 + (1 + len(rep.labels)) * 4 * 2


def test_grid_and_samplers_keep_infeasible_designs(setup, tmp_path):
    """The grid over (crank, rod) across the toggle: every design's feasibility equals the
    independent check; the infeasible rows are kept with empty responses; the heat map is drawn.
    Each sampler draws its count inside the ranges; the Latin hypercube puts one point per slice."""
    mech, _inputs, study = setup
    ranges = {"crank": [22.0, 28.0], "rod": [33.05, 41.05], "O1_x": [-0.1, 0.1], "O1_y": [-1.0, 1.0]}
    inputs = st.read_study(mech, method="grid", ranges=ranges, levels={"crank": 13, "rod": 17, "O1_x": 1, "O1_y": 1})
    rep = st.sample(mech, grid=True, study=study.moved(inputs=inputs))
    assert rep.grid_shape == (13, 17, 1, 1) and rep.values.shape == (221, 4)
    np.testing.assert_allclose(rep.values[:17, 1], np.linspace(33.05, 41.05, 17))  # the last range varies fastest
    ok = rep.values[:, 1] >= rep.values[:, 0] + np.abs(E - rep.values[:, 3])
    assert 20 < ok.sum() < 200 and np.array_equal(rep.feasible, ok)
    from jaxlink.report import sampling as rs

    files = rs.write_sample_all(tmp_path, mech, rep, wall_time=1.0)
    assert (tmp_path / "grid.png").is_file() and len(files) == 4
    lines = (tmp_path / "study.csv").read_text().splitlines()
    assert lines[0].startswith("sample,crank (mm),rod (mm),O1_x (mm),O1_y (mm),feasible,stroke(s_B) (mm)")
    assert len(lines) == 222
    bad = [ln for ln in lines[1:] if ln.split(",")[5] == "0"]
    assert len(bad) == 221 - ok.sum() and all(set(ln.split(",")[6:]) == {""} for ln in bad)
    for sampler in ("sobol", "lhs", "halton", "random"):
        inp = st.read_study(mech, method="sample", samples=100, sampler=sampler, ranges=ranges)
        r = st.sample(mech, study=study.moved(inputs=inp))
        lo, hi = np.asarray(list(ranges.values())).T
        assert r.values.shape == (100, 4) and np.all((r.values >= lo) & (r.values <= hi))
        assert np.array_equal(r.feasible, r.values[:, 1] >= r.values[:, 0] + np.abs(E - r.values[:, 3]))
        if sampler == "lhs":
            for j in range(4):
                slices = np.floor((r.values[:, j] - lo[j]) / (hi[j] - lo[j]) * 100).astype(int)
                assert sorted(slices) == list(range(100))


def test_the_ranges_are_checked():
    mech = jl.loads(FILE)
    for ranges, msg in (({"crank": [2, 1]}, "low < high"), ({"crank": 3}, r"\[low, high\]"),
                        ({"crank_len": [1, 2]}, "'crank_len' is not a parameter")):
        with pytest.raises(jl.MechanismError, match=msg):
            st.read_study(mech, method="sample", ranges=ranges)
    with pytest.raises(jl.MechanismError, match="grid method needs"):
        st.read_study(mech, method="grid", tolerances={"crank": 0.1})
    with pytest.raises(jl.MechanismError, match="'sampler' must be one of"):
        st.read_study(mech, method="sample", sampler="faure", ranges={"crank": [1, 2]})
    with pytest.raises(jl.MechanismError, match="'levels' of 'crank'"):
        st.read_study(mech, method="grid", ranges={"crank": [1, 2]}, levels=0)
    s = st.read_study(mech, {"method": "sensitivity", "ranges": {"rod": [70, 90]}, "tolerances": {"crank": 0.1}})
    assert s.parameters == ("rod",) and s.samples == 1024  # the ranges win; the method's default count


CLI_RANGES = """
levels = { crank = 4, rod = 5, O1_x = 1, O1_y = 3 }

[study.ranges]
crank = [24.0, 26.0]
rod = [36.5, 39.0]
O1_x = [-0.5, 0.5]
O1_y = [-0.5, 0.5]
"""


def test_the_command_line_sample_grid_sensitivity(tmp_path, capsys):
    """`jaxlink study --method sample|grid|sensitivity` on one small file (16 positions, few
    designs): the files written, and each design's feasibility against the closed-form assembly
    condition b ≥ a + |e − O1_y| (the designs read back from study.csv; the sensitivity's
    samples rebuilt from the Sobol' sequence), O1_x's feasibility indices exactly 0."""
    import csv
    import json

    from jaxlink.cli import main

    src = tmp_path / "slider.toml"
    src.write_text(FILE.replace("\n[study.tolerances]", CLI_RANGES + "\n[study.tolerances]"))
    common = ["--positions", "16", "--chunk", "1024", "--no-plot", "--progress", "off", "--seed", "3"]
    files = {"study.csv", "study.json", "study.npz", "checkpoint"}
    for method, n in (("sample", 64), ("grid", 60)):
        out = tmp_path / method
        assert main(["study", str(src), "--method", method, "--samples", "64", "--out", str(out)] + common) == 0
        assert {p.name for p in out.iterdir()} == files
        rows = list(csv.DictReader((out / "study.csv").open()))
        assert len(rows) == n
        x = np.asarray([[float(r[f"{p} (mm)"]) for p in ("crank", "rod", "O1_x", "O1_y")] for r in rows])
        ok = x[:, 1] >= x[:, 0] + np.abs(E - x[:, 3])
        assert 0 < ok.sum() < n and [int(r["feasible"]) for r in rows] == ok.astype(int).tolist()
        assert json.loads((out / "study.json").read_text())["method"] == method
    # --resume of the finished sample: every chunk read back, the same study.csv; another seed refused
    out = tmp_path / "sample"
    before = (out / "study.csv").read_text()
    assert main(["study", str(src), "--method", "sample", "--samples", "64", "--out", str(out), "--resume"]
                + common) == 0
    assert (out / "study.csv").read_text() == before
    assert main(["study", str(src), "--method", "sample", "--samples", "64", "--out", str(out), "--resume"]
                + common[:-1] + ["4"]) == 2
    assert "belongs to another study (different [study] seed)" in capsys.readouterr().err
    # incremental refinement: resumed with --samples 100, the sample keeps its first 64 designs' rows;
    # --replot draws its scatter matrix
    assert main(["study", str(src), "--method", "sample", "--samples", "100", "--out", str(out), "--resume"]
                + common) == 0
    more = (out / "study.csv").read_text().splitlines()
    assert len(more) == 101 and more[:65] == before.splitlines()
    assert main(["study", str(src), "--replot", str(out)]) == 0 and (out / "scatter.png").is_file()
    out = tmp_path / "sensitivity"
    assert main(["study", str(src), "--method", "sensitivity", "--samples", "32", "--bootstrap", "20",
                 "--out", str(out)] + common) == 0
    assert {p.name for p in out.iterdir()} == {"indices.csv", "study.json", "study.npz", "checkpoint"}
    u = np.concatenate(list(st.unit_blocks("sobol", 8, 32, 3)))
    lo, hi = np.asarray([[24.0, 36.5, -0.5, -0.5], [26.0, 39.0, 0.5, 0.5]])
    ab = np.concatenate([lo + u[:, :4] * (hi - lo), lo + u[:, 4:] * (hi - lo)])
    ok = ab[:, 1] >= ab[:, 0] + np.abs(E - ab[:, 3])
    data = json.loads((out / "study.json").read_text())
    assert data["feasible_fraction"] == pytest.approx(ok.mean(), abs=1e-12)
    idx = [r for r in csv.DictReader((out / "indices.csv").open()) if r["output"] == "feasible"]
    assert {float(r["value (1)"]) for r in idx if r["parameter"] == "O1_x"} == {0.0}
    # --replot draws the plots of a study written without them, from study.json and study.npz
    assert main(["study", str(src), "--replot", str(out)]) == 0
    assert {p.name for p in out.iterdir()} == {"indices.csv", "study.json", "study.npz", "checkpoint", "sobol.png",
                                               "sobol_curves.png"}
    capsys.readouterr()


def test_a_killed_study_resumes_to_the_same_result(setup, tmp_path, monkeypatch):
    """Monte Carlo, sample and sensitivity over two batches each, interrupted after the first
    (the checkpoint written batch by batch), resumed: every array equals the uninterrupted run's
    bit for bit. A resume whose key differs (another seed, another sample count, other parameters)
    is refused with the reason, never mixed."""
    from jaxlink.study.checkpoint import Checkpoint, resume_key

    mech, inputs, study = setup
    first = study.first_order()
    n = 4096 + 100

    def ck(name, inp, what, resume=False, m=mech, **extra):
        return Checkpoint(tmp_path / name, resume_key(m, inp, chunk=study.chunk, what=what, **extra), resume=resume)

    ref = study.monte_carlo(n, first)
    with pytest.raises(Stop):
        study.monte_carlo(n, first, progress=stop_after(1), checkpoint=ck("mc", inputs, "mc", samples=n))
    assert {p.name for p in (tmp_path / "mc").iterdir()} == {"state.json", "state-000001.npz"}
    res = study.monte_carlo(n, first, checkpoint=ck("mc", inputs, "mc", resume=True, samples=n))
    for f in ref._fields:
        assert np.array_equal(np.asarray(getattr(ref, f)), np.asarray(getattr(res, f))), f
    # the key: a changed seed, sample count or parameter is refused, naming what differs
    for inp, extra, m, why in ((inputs._replace(seed=9), n, mech, "seed"), (inputs, n + 1, mech, "samples"),
                               (inputs, n, mech.replace(parameters=mech.with_parameters(rod=80.5)), "parameters")):
        with pytest.raises(jl.MechanismError, match=f"another study .*{why}"):
            study.monte_carlo(n, first, checkpoint=ck("mc", inp, "mc", resume=True, m=m, samples=extra))

    sin = st.read_study(mech, method="sample", samples=4096 + 7, seed=4, ranges=RANGES)
    s2 = study.moved(inputs=sin)
    ref = st.sample(mech, study=s2)
    with pytest.raises(Stop):
        st.sample(mech, study=s2, progress=stop_after(1), checkpoint=ck("s", sin, "sample"))
    res = st.sample(mech, study=s2, checkpoint=ck("s", sin, "sample", resume=True))
    for f in ("values", "feasible", "responses", "nominal"):
        assert np.array_equal(getattr(ref, f), getattr(res, f)), f
    with pytest.raises(jl.MechanismError, match="sampler"):
        st.sample(mech, study=s2, checkpoint=ck("s", sin._replace(sampler="halton"), "sample", resume=True))
    # incremental refinement (the command line's key of a sequence's sample leaves the count out): the
    # finished sample of 4103 designs extended to 8197 reuses its whole first chunk, evaluates the
    # rest (its partial chunk again), and equals the sample of 8197 made at once
    from jaxlink.study import sampling as _sampling

    st.sample(mech, study=s2, checkpoint=ck("e", sin._replace(samples=0), "sample"))
    big = sin._replace(samples=2 * 4096 + 5)
    s4 = study.moved(inputs=big)
    evaluated, call = [], _sampling._Evaluator.__call__
    monkeypatch.setattr(_sampling._Evaluator, "__call__", lambda self, x: evaluated.append(len(x)) or call(self, x))
    res = st.sample(mech, study=s4, checkpoint=ck("e", big._replace(samples=0), "sample", resume=True))
    assert evaluated == [4096, 5]
    ref = st.sample(mech, study=s4)
    for f in ("values", "feasible", "responses", "nominal"):
        assert np.array_equal(getattr(ref, f), getattr(res, f)), f

    sin = st.read_study(mech, method="sensitivity", samples=700, seed=4, ranges=RANGES, bootstrap=10)
    s3 = study.moved(inputs=sin)
    ref = st.sensitivity(mech, study=s3)
    with pytest.raises(Stop):
        st.sensitivity(mech, study=s3, progress=stop_after(1), checkpoint=ck("x", sin, "sensitivity"))
    res = st.sensitivity(mech, study=s3, checkpoint=ck("x", sin, "sensitivity", resume=True))
    for f in ("S1", "ST", "S1_low", "ST_high"):
        assert np.array_equal(getattr(ref.indices, f), getattr(res.indices, f)), f
    assert (res.feasible_fraction, res.complete) == (ref.feasible_fraction, ref.complete)


def test_the_monte_carlo_stopping_rule_killed_and_resumed(setup, tmp_path):
    """The precision rule on the Monte Carlo (rounds of 512, 1024, 2048 samples) killed after its
    second round and resumed: it starts again in the round saved (its batches read back, the first
    round not evaluated again) and ends with the uninterrupted result, history and statistics bit
    for bit; another `max_samples` is refused naming it."""
    from jaxlink.study.checkpoint import Checkpoint, resume_key

    mech, inputs, study = setup
    tin = inputs._replace(samples=512, precision=1e-6, max_samples=2048)
    mv = study.moved(inputs=tin)

    def ck(inp, resume=False):
        return Checkpoint(tmp_path / "mc", resume_key(mech, inp, chunk=study.chunk, what="tolerance"), resume=resume)

    rep, conv = st.converged_tolerance(mech, study=mv, worst=False)
    assert [n for n, _ in conv.history] == [512, 1024, 2048] and not conv.converged
    with pytest.raises(Stop):
        st.converged_tolerance(mech, study=mv, worst=False, progress=stop_after(2), checkpoint=ck(tin))
    saved = json.loads((tmp_path / "mc" / "state.json").read_text())
    assert saved["state"]["samples"] == 1024 and saved["state"]["history"] == [[512, conv.history[0][1]]]
    calls = []
    res, rconv = st.converged_tolerance(mech, study=mv, worst=False, progress=calls.append, checkpoint=ck(tin, True))
    assert rconv == conv and calls == [1024, 2048]  # the round saved read back, then the last one evaluated
    for f in rep.monte_carlo._fields:
        assert np.array_equal(np.asarray(getattr(rep.monte_carlo, f)), np.asarray(getattr(res.monte_carlo, f))), f
    assert np.array_equal(rep.first_order.sigma_rss, res.first_order.sigma_rss)
    with pytest.raises(jl.MechanismError, match=r"another study .*\[study\] max_samples"):
        st.converged_tolerance(mech, study=mv, worst=False, checkpoint=ck(tin._replace(max_samples=4096), True))


def test_a_study_built_without_study_is_kept_and_reused(setup, monkeypatch):
    """`tolerance(mech, inputs)` without `study=` builds its `Study` once (`study_for`): a
    second identical call gets the same one and both give a fresh Study's numbers bit for bit (the
    fixture's, built apart); a change of any one key input (a tolerance, the seed, the samples, a
    parameter's value — also changed in place —, the solver options, the chunk) gives another Study,
    whose numbers are a fresh one's. A key that ignored the tolerances would hand back the Study
    of the old ones: the same check then fails."""
    from jaxlink.solvers.options import NewtonOptions
    from jaxlink.study import reuse

    mech, inputs, study = setup

    def check(inp, samples=1024):
        """st.tolerance without study= against a fresh Study's (the fixture's moved: nothing kept)."""
        got = st.tolerance(mech, inp, samples=samples, worst=False)
        want = st.tolerance(mech, study=study.moved(inputs=inp), samples=samples, worst=False)
        for a, b in ((got.first_order, want.first_order), (got.monte_carlo, want.monte_carlo)):
            for f in () if a is None else a._fields:
                assert np.array_equal(np.asarray(getattr(a, f)), np.asarray(getattr(b, f))), f
        assert np.array_equal(got.nominal, want.nominal)

    check(inputs)
    kept = st.study_for(mech, inputs)
    check(inputs)  # the second call: the Study kept
    assert st.study_for(mech, inputs) is kept and kept.inputs == inputs
    wider = inputs._replace(tolerances=(inputs.tolerances[0]._replace(half_width=0.02, sigma=0.02 / 3 ** 0.5),)
                            + inputs.tolerances[1:])
    check(wider, samples=0)  # another tolerance: a fresh Study, its numbers (first order: one compile less)
    assert st.study_for(mech, wider) is not kept
    p = np.array(mech.parameters)
    moved = mech.replace(parameters=p)
    s = st.study_for(moved, inputs)
    assert s is kept  # another Mechanism object, the same structure and numbers: the same key
    p[mech.parameter_index("rod")] += 1e-6  # changed in place: another key; the Study kept has the old numbers
    for other in (st.study_for(mech, inputs._replace(seed=5)), st.study_for(mech, inputs._replace(samples=9)),
                  st.study_for(moved, inputs), st.study_for(mech, inputs, options=NewtonOptions(max_steps=20)),
                  st.study_for(mech, inputs, chunk=2048)):
        assert other is not kept
    assert np.array_equal(s.mech.parameters, mech.parameters)
    assert np.array_equal(st.study_for(moved, inputs).mech.parameters, p)
    # a key blind to the tolerances: the Study of the old tolerances comes back, and the check fails
    key = reuse.study_key
    monkeypatch.setattr(reuse, "study_key", lambda m, i, o, c: key(m, i._replace(tolerances=inputs.tolerances), o, c))
    narrower = inputs._replace(tolerances=(inputs.tolerances[0]._replace(half_width=0.005, sigma=0.005 / 3 ** 0.5),)
                               + inputs.tolerances[1:])
    with pytest.raises(AssertionError):
        check(narrower, samples=0)


def test_the_robust_design_map_against_the_closed_form_and_replot(setup, tmp_path, monkeypatch):
    """The robust-design map over a (crank, rod) grid across the toggle, the file's tolerances at
    every design: at every feasible design the largest σ_RSS of B.x over the cycle and the linear
    bound of B's path deviation equal the closed form's (B.y = e is constant: ‖∂B/∂x_g‖ = |∂B.x/∂x_g|,
    the zone's largest singular value √(1 + (∂B.x/∂O1_y)²)); Cpk = min(U − m, m − L) / 3σ of the
    design's stroke; one design against the single-design tolerance report (1e-12); the infeasible
    rows empty. Then `replot` draws grid.png and robust.png from study.json and study.npz alone
    (written without plots), with the evaluator made to fail."""
    import csv
    import json

    from jaxlink.report import replot as rp
    from jaxlink.report import sampling as rs

    mech, inputs, study = setup
    ranges = {"crank": [24.0, 26.0], "rod": [36.5, 39.0], "O1_x": [-0.1, 0.1], "O1_y": [-0.1, 0.1]}
    gin = st.read_study(mech, method="grid", ranges=ranges, levels={"crank": 5, "rod": 6, "O1_x": 1, "O1_y": 1},
                        robust=True, limits={"stroke(s_B)": [50.0, "inf"]},
                        tolerances=dict(mech.tables["study"]["tolerances"]), distribution="uniform")
    rep = st.sample(mech, grid=True, study=study.moved(inputs=gin))
    rob = rep.robust
    col = {name: j for j, (name, _u) in enumerate(rob.labels)}
    ok = rep.feasible
    assert 5 < ok.sum() < 30 and np.all(rob.values[~ok] == 0)
    theta = np.deg2rad(30.0 + 360.0 * np.arange(72) / 72)
    t, r_zone, sig = 0.01, 0.01, 0.01 / math.sqrt(3)
    for i in np.flatnonzero(ok):
        a, b, ox, oy = rep.values[i]
        h = oy + a * np.sin(theta) - E
        R = np.sqrt(b * b - h * h)
        da, db, dox, doy = np.cos(theta) - h * np.sin(theta) / R, b / R, np.ones_like(theta), -h / R
        s = np.sqrt((da * sig) ** 2 + (db * sig) ** 2 + (dox * r_zone / 2) ** 2 + (doy * r_zone / 2) ** 2)
        np.testing.assert_allclose(rob.values[i, col["sigma_rss(B.x)"]], s.max(), rtol=1e-9)
        bound = t * np.abs(da) + t * np.abs(db) + r_zone * np.sqrt(1 + doy ** 2)
        np.testing.assert_allclose(rob.values[i, col["worst_case_linear(B)"]], bound.max(), rtol=1e-9)
        assert rob.values[i, col["sigma_rss(B.y)"]] == pytest.approx(0, abs=1e-12)
        m = rep.responses[i, rep.labels.index(("stroke(s_B)", "mm"))]
        cpk = (m - 50.0) / (3 * rob.values[i, col["sigma_rss(stroke(s_B))"]])
        assert rob.values[i, col["cpk(stroke(s_B))"]] == pytest.approx(cpk, rel=1e-12)
    i = int(np.flatnonzero(ok)[-1])
    tin = st.read_study(mech, tolerances=dict(mech.tables["study"]["tolerances"]), distribution="uniform")
    one = st.tolerance(mech, study=study.moved(x0=rep.values[i], inputs=tin), samples=0, worst=False)
    for name, rows in (("stroke(s_B)", _rows(one, "stroke(s_B)")), ("B.x", _rows(one, "B.x"))):
        np.testing.assert_allclose(rob.values[i, col[f"sigma_rss({name})"]], one.first_order.sigma_rss[rows].max(),
                                   rtol=1e-12)
        np.testing.assert_allclose(rob.values[i, col[f"worst_case_linear({name})"]],
                                   one.first_order.worst_case[rows].max(), rtol=1e-12)
    np.testing.assert_allclose(rob.values[i, col["worst_case_linear(B)"]], one.deviation_bound[1], rtol=1e-12)

    files = rs.write_sample_all(tmp_path, mech, rep, wall_time=1.0, plot=False)
    assert {p.split("/")[-1] for p in files} == {"study.csv", "study.npz", "study.json"}
    rows = list(csv.DictReader((tmp_path / "study.csv").open()))
    assert "cpk(stroke(s_B)) (1)" in rows[0] and "worst_case_linear(B) (mm)" in rows[0]
    assert all((r["sigma_rss(B.x) (mm)"] == "") == (r["feasible"] == "0") for r in rows)
    data = json.loads((tmp_path / "study.json").read_text())
    assert data["sizes"]["designs"] == 30 and data["options"]["robust"] is True
    assert data["robust"]["limits"] == [["stroke(s_B)", 50.0, "inf"]]

    def fail(*_a, **_k):
        raise AssertionError("replot evaluated a design")
    monkeypatch.setattr(st.Study, "__init__", fail)
    monkeypatch.setattr(st.Responses, "single", fail)
    assert sorted(p.split("/")[-1] for p in rp.replot(tmp_path)) == ["grid.png", "robust.png"]
    assert (tmp_path / "grid.png").stat().st_size > 1000 and (tmp_path / "robust.png").stat().st_size > 1000
    back = rp.read(tmp_path)[1]
    assert back.labels == rep.labels and back.robust.labels == rob.labels and back.inputs == rep.inputs
    assert np.array_equal(back.robust.values, rob.values) and np.array_equal(back.values, rep.values)


# ---------------------------------------------------------------- triangular, truncated normal, boxes, second order
def test_triangular_and_truncated_normal_tolerances():
    """σ from the entry against scipy.stats' closed-form moments (triang: t/√6; truncnorm(−k, k)
    scaled by t/k); the Monte Carlo draws and the unit-cube map (`design.to_values`) have that σ
    within 4 standard errors (SE(s) from the closed-form fourth moment), lie in ±t and pass a
    Kolmogorov–Smirnov test against the scipy distribution; `sigma` given is the distribution's σ."""
    from scipy import stats

    from jaxlink.study.design import to_values

    mech = jl.loads(FILE)
    t1, t2, k = 0.03, 0.02, 2.0
    inputs = st.read_study(mech, tolerances={"crank": {"tol": t1, "distribution": "triangular"},
                                             "rod": {"tol": t2, "distribution": "truncated-normal", "k": k}})
    ref = (stats.triang(0.5, loc=-t1, scale=2 * t1), stats.truncnorm(-k, k, scale=t2 / k))
    assert inputs.tolerances[0].sigma == pytest.approx(t1 / math.sqrt(6), rel=1e-14)
    assert inputs.tolerances[0].sigma == pytest.approx(ref[0].std(), rel=1e-12)
    assert inputs.tolerances[1].sigma == pytest.approx(ref[1].std(), rel=1e-12)
    assert [t.half_width for t in inputs.tolerances] == [t1, t2]
    n = 1 << 15
    u = (np.arange(n)[:, None] + 0.5) / n * np.ones((1, 2))  # a stratified unit-cube sample
    for dx in (st.draws(inputs, n), to_values(inputs, np.zeros(2), u)):
        for j, (t, dist) in enumerate(zip((t1, t2), ref)):
            s, m4 = dist.std(), dist.moment(4)
            se = math.sqrt((m4 - s ** 4) / n) / (2 * s)
            assert abs(dx[:, j].std(ddof=1) - s) <= 4 * se
            assert np.all(np.abs(dx[:, j]) <= t) and np.abs(dx[:, j]).max() > 0.95 * t
            assert stats.kstest(dx[:, j], dist.cdf).pvalue > 1e-3
    back = st.read_study(mech, tolerances={"crank": {"sigma": ref[0].std(), "distribution": "triangular"},
                                           "rod": {"sigma": ref[1].std(), "distribution": "truncated-normal",
                                                   "k": k}})
    assert [t.half_width for t in back.tolerances] == pytest.approx([t1, t2], rel=1e-12)
    with pytest.raises(jl.MechanismError, match="circular zone is 'uniform'"):
        st.read_study(mech, tolerances={"O1": {"radius": 0.1, "distribution": "triangular"}})


def test_first_order_sigma_with_the_new_distributions(setup):
    """The pin A = O1 + a (cos θ, sin θ) is linear: its first-order σ is √Σ(g_i σ_i)² with the
    distributions' σ (triangular crank, the file's uniform rod, a rectangular zone of truncated
    normals: σ = (w/3) √(1 − 6 φ(3) / (2Φ(3) − 1))); its linear worst case uses ±t."""
    mech, inputs, study = setup
    tol = st.read_study(mech, tolerances={"crank": {"tol": 0.03, "distribution": "triangular"},
                                          "rod": 0.01,
                                          "O1": {"box": [0.01, 0.02], "distribution": "truncated-normal"}})
    rep = st.tolerance(mech, study=study.moved(inputs=tol), samples=0, worst=False)
    th = np.deg2rad(rep.input_values)
    sig = np.asarray([0.03 / math.sqrt(6), 0.01 / math.sqrt(3)] + [w / 3 * math.sqrt(
        1 - 6 * math.exp(-4.5) / math.sqrt(2 * math.pi) / math.erf(3 / math.sqrt(2))) for w in (0.01, 0.02)])
    np.testing.assert_allclose(rep.first_order.sigma, sig, rtol=1e-12)
    f = rep.first_order
    np.testing.assert_allclose(f.sigma_rss[_rows(rep, "A.x")], np.hypot(np.cos(th) * sig[0], sig[2]), rtol=1e-9)
    np.testing.assert_allclose(f.sigma_rss[_rows(rep, "A.y")], np.hypot(np.sin(th) * sig[0], sig[3]), rtol=1e-9,
                               atol=1e-15)
    np.testing.assert_allclose(f.worst_case[_rows(rep, "A.y")], 0.03 * np.abs(np.sin(th)) + 0.02, rtol=1e-9)


def test_a_rectangular_zone_worst_case_is_its_corners(setup):
    """O1 in a rectangle ±0.2 × ±0.4 mm (truncated normals: bounded, the worst case takes ±w) with
    ±0.3 mm on both links: the linear worst case of B.x is Σ t|g| with wx |g_x| + wy |g_y| for the
    zone, and the true worst case is the enumeration of the 16 corners, equal to the closed form's
    largest deviation over them."""
    import itertools

    mech, inputs, study = setup
    half = np.asarray([0.3, 0.3, 0.2, 0.4])
    tol = st.read_study(mech, tolerances={"crank": {"tol": 0.3, "distribution": "uniform"},
                                          "rod": {"tol": 0.3, "distribution": "triangular"},
                                          "O1": {"box": [0.2, 0.4], "distribution": "truncated-normal"}})
    assert tol.parameters == ("crank", "rod", "O1_x", "O1_y") and [t.box for t in tol.tolerances] == ["", "", "O1",
                                                                                                          "O1"]
    rep = st.tolerance(mech, study=study.moved(inputs=tol), samples=0)
    J = rep.first_order.jacobian[_rows(rep, "B.x")]
    np.testing.assert_allclose(rep.first_order.worst_case[_rows(rep, "B.x")], np.abs(J) @ half, rtol=1e-12)
    w = rep.worst
    assert w.corners and w.candidates == 16 and set(w.status) == {"enumerated"}
    theta = np.deg2rad(rep.input_values)
    corners = study.x0 + np.asarray(list(itertools.product((-1, 1), repeat=4))) * half
    (ax, ay, bx), (ax0, ay0, bx0) = _closed_form(corners, theta), _closed_form(study.x0[None], theta)
    for n, v in {"deviation(B.x)": np.abs(bx - bx0).max(), "deviation(A)": np.hypot(ax - ax0, ay - ay0).max(),
                 "deviation(A.y)": np.abs(ay - ay0).max()}.items():
        assert w.value[w.names.index(n)] == pytest.approx(v, rel=1e-9), n


def _bx_closed_form(x, theta):
    return _closed_form(np.atleast_2d(x), theta)[2]


def test_second_order_against_the_closed_form_and_monte_carlo(setup):
    """The Hessian of B.x(θ) = O1_x + a cos θ + √(b² − (O1_y + a sin θ − e)²) equals central
    differences of the closed form (numpy); the second-order mean shift is ½ Σ H_ii σ_i² of those,
    and std₂ the formula of docs/methods/tolerance.md with the inputs' closed-form moments (uniform:
    μ₄ = 9σ⁴/5; the uniform disc: μ₄ = r⁴/8, E[δx² δy²] = r⁴/24, checked on the draws). At ±0.3 mm
    the shift (~1e-3 mm) is far beyond the sampling error of Monte Carlo's mean once the linear part
    J δ of the same draws is taken out (a control variate: E[J δ] = 0), and they agree within 4 SE."""
    mech, inputs, study = setup
    tol = st.read_study(mech, tolerances={"crank": 0.3, "rod": 0.3, "O1": {"radius": 0.3}})
    rep = st.tolerance(mech, study=study.moved(inputs=tol), worst=False, second_order=True)
    so, f, mc = rep.second_order, rep.first_order, rep.monte_carlo
    rows = _rows(rep, "B.x")
    th = np.deg2rad(rep.input_values)
    h, x0, T = 1e-3, study.x0, 4
    e = np.eye(T) * h
    H = np.zeros((len(th), T, T))
    for i in range(T):
        for j in range(T):
            f4 = (_bx_closed_form(x0 + e[i] + e[j], th) - _bx_closed_form(x0 + e[i] - e[j], th)
                  - _bx_closed_form(x0 - e[i] + e[j], th) + _bx_closed_form(x0 - e[i] - e[j], th))
            H[:, i, j] = f4[0] / (4 * h * h)
    np.testing.assert_allclose(so.hessian[rows], H, atol=1e-6 * np.abs(H).max())
    s2 = np.asarray([0.3 ** 2 / 3, 0.3 ** 2 / 3, 0.15 ** 2, 0.15 ** 2])
    np.testing.assert_allclose(so.mean_shift[rows], 0.5 * np.einsum("kii,i->k", H, s2), rtol=1e-5, atol=1e-12)
    r4 = 0.3 ** 4
    cov = np.diag([0.8 * s2[0] ** 2, 0.8 * s2[1] ** 2, r4 / 8 - r4 / 16, r4 / 8 - r4 / 16])
    cov[2, 3] = cov[3, 2] = r4 / 24 - r4 / 16
    cross = np.outer(s2, s2)
    cross[2, 3] = cross[3, 2] = r4 / 24
    d = np.diagonal(H, axis1=1, axis2=2)
    var = (f.jacobian[rows] ** 2) @ s2 + 0.25 * np.einsum("ki,ij,kj->k", d, cov, d) + 0.5 * (
        H ** 2 * (cross * (1 - np.eye(T)))).sum((1, 2))
    np.testing.assert_allclose(so.std[rows], np.sqrt(var), rtol=1e-6)
    dx = st.draws(tol, mc.samples)
    assert np.mean(dx[:, 2] ** 2 * dx[:, 3] ** 2) == pytest.approx(r4 / 24, rel=0.05)
    assert np.mean(dx[:, 2] ** 4) == pytest.approx(r4 / 8, rel=0.05)
    # against Monte Carlo: its mean less that of J δ over the same draws
    assert mc.feasible == mc.samples
    lin = dx @ f.jacobian[rows].T
    resid = _bx_closed_form(x0 + dx, th) - _bx_closed_form(x0, th) - lin  # the closed form's nonlinear part
    se = resid.std(0, ddof=1) / math.sqrt(mc.samples)
    est = mc.mean_shift[rows] - lin.mean(0)
    np.testing.assert_allclose(est, resid.mean(0), atol=1e-9)  # Monte Carlo's responses are the closed form's
    big = np.abs(so.mean_shift[rows]) > 10 * se
    assert big.sum() > len(rows) // 2  # the shift is visible at most positions
    assert np.all(np.abs(est - so.mean_shift[rows]) <= 4 * se + 1e-3 * np.abs(so.mean_shift[rows]))
    assert np.all(np.abs(mc.std[rows] - so.std[rows]) <= 4 * mc.std_error[rows])


def test_copula_correlation_and_moments_against_closed_forms_and_draws():
    """The Pearson correlation ρ(r) of two inputs whose normal scores have correlation r (the
    Gaussian copula of Iman–Conover) by quadrature: the closed forms (uniforms (6/π) arcsin(r/2),
    normals r, normal–uniform r √(3/π)) to 1e-12; triangular and truncated normal against the
    Pearson correlation of 2¹⁸ Gaussian-copula draws (numpy) and of the study's own Iman–Conover
    draws (2¹⁶), within 4 SE; the mixed fourth moments E[δ_a² δ_b²], E[δ_a³ δ_b] the same way."""
    from scipy.stats import norm

    from jaxlink.study import copula

    mech = jl.loads(FILE)
    tols = {"uniform": {"tol": 0.04, "distribution": "uniform"}, "normal": {"tol": 0.03, "distribution": "normal"},
            "triangular": {"tol": 0.05, "distribution": "triangular"},
            "truncated-normal": {"tol": 0.02, "distribution": "truncated-normal", "k": 2.0}}

    def pair(da, db):
        return st.read_study(mech, tolerances={"crank": tols[da], "rod": tols[db]}).tolerances

    for r in (-0.9, 0.3, 0.7, 0.999):
        u, n = pair("uniform", "normal")
        assert copula.pearson(u, u, r) == pytest.approx(6 / math.pi * math.asin(r / 2), abs=1e-12)
        assert copula.pearson(n, u, r) == pytest.approx(r * math.sqrt(3 / math.pi), abs=1e-12)
        assert copula.moment(n, n, r) == pytest.approx(r * n.sigma ** 2, abs=1e-15)
        assert copula.moment(n, n, r, 2, 2) == pytest.approx((1 + 2 * r * r) * n.sigma ** 4, rel=1e-12)  # Isserlis
    rng = np.random.default_rng(7)
    N, r = 1 << 18, 0.6
    z1 = rng.standard_normal(N)
    z2 = r * z1 + math.sqrt(1 - r * r) * rng.standard_normal(N)
    for da, db in (("triangular", "truncated-normal"), ("triangular", "uniform"), ("truncated-normal", "normal")):
        ta, tb = pair(da, db)
        x = [copula.inverse_cdf(t.distribution, z, t.half_width, t.sigma, t.k) for t, z in ((ta, z1), (tb, z2))]
        np.testing.assert_allclose(x[0], st.distributions.deviations(da, norm.cdf(z1), ta.half_width, ta.sigma,
                                                                       ta.k), atol=1e-9 * ta.half_width)
        for p, q in ((1, 1), (2, 2), (3, 1)):
            v = x[0] ** p * x[1] ** q
            assert abs(copula.moment(ta, tb, r, p, q) - v.mean()) <= 4 * v.std() / math.sqrt(N), (da, db, p, q)
        rho = copula.pearson(ta, tb, r)
        assert abs(rho) < r and abs(rho - np.corrcoef(x)[0, 1]) <= 4 * (1 - rho * rho) / math.sqrt(N)
        # the Monte Carlo draws: Iman–Conover blocks of 1024 (their correlation 1 - O(1/n) of the copula's)
        study_in = st.read_study(mech, tolerances={"crank": tols[da], "rod": tols[db]},
                                 correlation={"crank": {"rod": r}})
        d = st.draws(study_in, 1 << 16)
        assert abs(np.corrcoef(d.T)[0, 1] - rho) <= 4 * (1 - rho * rho) / math.sqrt(1 << 16), (da, db)


def test_the_copula_memo_is_the_quadrature_and_keys_every_input():
    """`copula._moment` is memoized (`lru_cache`) on (each tolerance's distribution, half-width, σ,
    k; r; p; q): requested warm after each one-input change of a base request, every value equals
    the quadrature computed afresh (`__wrapped__`), and each change moves the value — so a key
    without that input would hand back the base's. A memo keyed without r (a deliberately wrong
    key) is caught by the same comparison."""
    from jaxlink.study import copula
    from jaxlink.study.inputs import Tolerance

    def tol(dist, t, k=3.0):
        sigma = {"uniform": t / math.sqrt(3), "triangular": t / math.sqrt(6), "normal": t / k}.get(dist)
        if sigma is None:  # truncated normal: σ of N(0, (t/k)²) cut at ±t
            from scipy.stats import truncnorm
            sigma = t / k * float(truncnorm.std(-k, k))
        return Tolerance("x", ("x",), "length", dist, t, sigma, k=k)

    base = (tol("truncated-normal", 0.02, 2.0), tol("triangular", 0.05), 0.6, 1, 1)
    variants = [base,
                (tol("truncated-normal", 0.02, 2.5), *base[1:]),              # k
                (tol("truncated-normal", 0.03, 2.0), *base[1:]),              # half-width (and σ)
                (tol("uniform", 0.02), *base[1:]),                            # distribution
                (base[0], tol("triangular", 0.07), *base[2:]),                # the other tolerance
                (*base[:2], 0.3, 1, 1), (*base[:3], 2, 1), (*base[:3], 1, 3)]  # r, p, q

    def fresh(ta, tb, r, p, q):
        return copula._moment.__wrapped__(copula._tolerance_key(ta), copula._tolerance_key(tb), r, p, q)

    def same_as_fresh(moment):
        moment(*base)  # the base first: each variant then meets a warm memo
        return all(moment(*v) == fresh(*v) for v in variants)

    want = [fresh(*v) for v in variants]
    assert len({round(w, 15) for w in want}) == len(want)  # each input changes the answer
    assert same_as_fresh(copula.moment)
    assert copula.moment(*base) == copula.moment(*base) == want[0]  # warm = cold

    cache: dict = {}

    def blind_moment(ta, tb, r, p, q):  # keyed without r: the first r seen stands for every r
        ka, kb = copula._tolerance_key(ta), copula._tolerance_key(tb)
        key = (ka, kb, p, q)
        if key not in cache:
            cache[key] = copula._moment.__wrapped__(ka, kb, r, p, q)
        return cache[key]

    assert not same_as_fresh(blind_moment)


def test_correlated_second_order_and_the_agreement_on_a_quadratic():
    """A quadratic response y = g·δ + ½ δᵀ H δ of correlated inputs (a uniform and a triangular
    correlated at r = 0.7, a normal, a uniform disc): the second-order mean shift ½ tr(H Σ) and std₂
    equal the mean and σ of 2¹⁶ of the study's own Monte Carlo draws within 4 SE, first order's
    σ_RSS² = gᵀ Σ g that of the linear part; the uncorrelated formulas do not. Monte Carlo's
    `agreement` flags the quadratic's mean against the nominal alone and accepts it against the
    nominal plus the second-order shift. With r = 0 the correlated path gives the independent
    formula; normal inputs: Isserlis' closed form Var₂ = gᵀ Σ g + ½ tr(H Σ H Σ); three linked
    non-normal inputs are refused with the file's key."""
    from jaxlink.study import copula
    from jaxlink.study.second_order import second_order_stats
    from jaxlink.study.tolerance import agreement, first_order_stats

    mech = jl.loads(FILE)
    tolerances = {"crank": {"tol": 0.05, "distribution": "uniform"}, "rod": {"tol": 0.06, "distribution": "triangular"},
                  "O1": {"radius": 0.04, "distribution": "uniform"}}
    tol = st.read_study(mech, tolerances=tolerances, correlation={"crank": {"rod": 0.7}})
    ind = tol._replace(correlation=())
    g = np.asarray([[1.0, -0.5, 0.5, 0.3]])
    H = np.asarray([[[2.0, 2.5, 0.2, 0.0], [2.5, 1.5, 0.0, 0.3], [0.2, 0.0, 0.5, 0.4], [0.0, 0.3, 0.4, 0.6]]])
    n = 1 << 16
    dx = st.draws(tol, n)
    y = dx @ g[0] + 0.5 * np.einsum("ni,ij,nj->n", dx, H[0], dx)
    lin = dx @ g[0]
    so, f = second_order_stats(g, H, tol), first_order_stats(g, tol)
    so_ind, f_ind = second_order_stats(g, H, ind), first_order_stats(g, ind)
    mean, s, m4 = y.mean(), y.std(ddof=1), np.mean((y - y.mean()) ** 4)
    me, se = s / math.sqrt(n), math.sqrt((m4 - s ** 4 * (n - 3) / (n - 1)) / n) / (2 * s)
    se_lin = math.sqrt((np.mean((lin - lin.mean()) ** 4) - lin.var() ** 2) / n) / (2 * lin.std())
    assert abs(so.mean_shift[0] - mean) <= 4 * me and abs(so.std[0] - s) <= 4 * se
    assert abs(f.sigma_rss[0] - lin.std(ddof=1)) <= 4 * se_lin
    assert abs(so_ind.mean_shift[0] - mean) > 10 * me and abs(f_ind.sigma_rss[0] - lin.std(ddof=1)) > 10 * se_lin
    assert f.importance.sum() == pytest.approx(1.0, rel=1e-12) and f.importance[0, 1] < 0  # g_0 g_1 ρ < 0
    sig = copula.covariance(tol)
    assert so.mean_shift[0] == pytest.approx(0.5 * np.sum(H[0] * sig), rel=1e-12)
    # the agreement: the mean against the nominal alone is flagged, against the second-order shift not
    assert abs(mean) > 10 * me
    assert not agreement([mean], [s], [me], [se], n, np.zeros(1), f)[0]
    assert agreement([mean], [s], [me], [se], n, np.zeros(1), f, so)[0]
    # r = 0 through the correlated path: the independent formula
    zero = tol._replace(correlation=(("crank", "rod", 0.0),))
    np.testing.assert_allclose(second_order_stats(g, H, zero)[:2], so_ind[:2], rtol=1e-12)
    # normal inputs linked in a chain: Isserlis
    nor = st.read_study(mech, tolerances={"crank": {"tol": 0.05, "distribution": "normal"},
                                          "rod": {"tol": 0.06, "distribution": "normal"},
                                          "O1": {"box": [0.04, 0.03], "distribution": "normal"}},
                        correlation={"crank": {"rod": 0.5}, "rod": {"O1_x": -0.4}, "O1_x": {"O1_y": 0.3}})
    sig = copula.covariance(nor)
    np.testing.assert_allclose(np.diag(sig), [t.sigma ** 2 for t in nor.tolerances], rtol=1e-14)
    assert sig[1, 2] == pytest.approx(-0.4 * nor.tolerances[1].sigma * nor.tolerances[2].sigma, rel=1e-14)
    want = g[0] @ sig @ g[0] + 0.5 * np.trace(H[0] @ sig @ H[0] @ sig)
    assert second_order_stats(g, H, nor).std[0] == pytest.approx(math.sqrt(want), rel=1e-12)
    with pytest.raises(jl.MechanismError, match="not all normal") as e:
        st.read_study(mech, tolerances={"crank": 0.05, "rod": 0.06, "O1": {"box": [0.04, 0.03]}}, second_order=True,
                      correlation={"crank": {"rod": 0.5}, "rod": {"O1_x": -0.4}})
    assert e.value.key == "study.correlation"


def test_correlated_first_order_against_monte_carlo(setup):
    """`[study.correlation]` crank–rod 0.8 (a uniform and a normal): σ_RSS = √(J Σ Jᵀ) with
    Σ_ab = σ_a σ_b ρ(0.8) equals the σ of 2¹⁴ Monte Carlo samples within 4 SE at every response,
    `agree` holds, and the uncorrelated RSS lies beyond 4 SE at most positions of B.x; the
    importance factors sum to 1; the second-order σ agrees with Monte Carlo too."""
    from jaxlink.study import copula
    from jaxlink.study.tolerance import first_order_stats

    mech, inputs, study = setup
    tol = st.read_study(mech, tolerances={"crank": {"tol": 0.05, "distribution": "uniform"},
                                          "rod": {"tol": 0.05, "distribution": "normal"}, "O1": {"radius": 0.01}},
                        correlation={"crank": {"rod": 0.8}})
    rep = st.tolerance(mech, study=study.moved(inputs=tol), samples=1 << 14, worst=False, second_order=True)
    f, mc, so = rep.first_order, rep.monte_carlo, rep.second_order
    sig = copula.covariance(tol)
    assert sig[0, 1] == pytest.approx(0.8 * math.sqrt(3 / math.pi) * f.sigma[0] * f.sigma[1], rel=1e-12)
    np.testing.assert_allclose(f.sigma_rss, np.sqrt(np.einsum("mi,ij,mj->m", f.jacobian, sig, f.jacobian)),
                               rtol=1e-12)
    live = f.sigma_rss > 0
    assert mc.feasible == mc.samples and mc.agree.all() and not rep.warnings
    assert np.all(np.abs(mc.std - f.sigma_rss)[live] <= 4 * mc.std_error[live])
    assert np.all(np.abs(mc.std - so.std)[live] <= 4 * mc.std_error[live])
    rows = _rows(rep, "B.x")
    ind = first_order_stats(f.jacobian, tol._replace(correlation=())).sigma_rss[rows]
    assert np.mean(np.abs(mc.std[rows] - ind) > 4 * mc.std_error[rows]) > 0.75
    np.testing.assert_allclose(f.importance.sum(1)[live], 1.0, rtol=1e-12)


def test_the_command_lines_tolerances_distributions_and_limits_are_the_tables():
    """`jaxlink study --tol/--dist/--limits` mean what `[study.tolerances]`, `[study] distribution`
    and `[study] limits` mean: the inputs they give equal those of the file written with the same
    keys (no compile), and a wrong name is refused on the option with the file's message and a
    did-you-mean."""
    from jaxlink.errors import MechanismError
    from jaxlink.files.overrides import blamed, study_table

    mech = jl.loads(FILE)

    def via_options(m, **kw):
        table, blame = study_table(m.tables.get("study"), **kw)
        try:
            return st.read_study(m, table)
        except MechanismError as e:
            raise blamed(e, blame) from None

    def via_file(study_text):
        return st.read_study(jl.loads(FILE.split("[study]")[0] + study_text))

    head = 'positions = 72\nsamples = 4096\nchunk = 4096\nmetrics = ["stroke", "deviation"]\n'
    got = via_options(mech, tol=["crank=0.02", "O1=0.03", "rod=sigma:0.004"], dist=["normal", "crank=triangular"],
                      limits=["stroke(s_B)=-inf,80.5", "deviation(B)=0,0.1"])
    want = via_file("[study]\n" + head + 'distribution = "normal"\nlimits = { "stroke(s_B)" = ["-inf", 80.5], '
                    '"deviation(B)" = [0, 0.1] }\n[study.tolerances]\ncrank = { tol = 0.02, distribution = '
                    '"triangular" }\nrod = { sigma = 0.004 }\nO1 = { radius = 0.03 }\n')
    assert got == want
    # a file without [study]: the options alone
    bare = jl.loads(FILE.split("[study]")[0])
    assert via_options(bare, tol=["crank=0.01", "O1=box:0.01,0.02"], dist=["uniform"]) == via_file(
        '[study]\ndistribution = "uniform"\n[study.tolerances]\ncrank = 0.01\nO1 = { box = [0.01, 0.02] }\n')
    for kw, words in ((dict(tol=["crnk=0.01"]), ("--tol crnk=0.01", "did you mean 'crank'?")),
                      (dict(tol=["rod=sigm:1"]), ("--tol rod=sigm:1", "did you mean 'sigma'?")),
                      (dict(dist=["beta"]), ("--dist beta", "unknown distribution 'beta'", "truncated-normal")),
                      (dict(dist=["unifrm"]), ("--dist unifrm", "did you mean 'uniform'?")),
                      (dict(dist=["rod=nromal"]), ("--dist rod=nromal", "did you mean 'normal'?")),
                      (dict(dist=["rdo=normal"]), ("--dist rdo=normal", "did you mean 'rod'?")),
                      (dict(dist=["O1=triangular"]), ("--dist O1=triangular", "circular zone")),
                      (dict(limits=["stroke(s_B)=2,1"]), ("--limits stroke(s_B)=2,1", "low < high")),
                      (dict(tol=["rod=-1"]), ("--tol rod=-1", "must be > 0"))):
        with pytest.raises(MechanismError) as e:
            via_options(mech, **kw)
        assert all(w in str(e.value) for w in words) and "line" not in str(e.value), (kw, str(e.value))


def test_the_command_line_studies_a_file_without_study_from_its_options(setup, capsys, monkeypatch):
    """`jaxlink study FILE --tol … --dist uniform` on a file without [study], first order: the crank
    pin A = O1 + a (cos θ, sin θ) has σ(A.x)² = σ(O1_x)² + cos²θ σ_a², largest at θ = 0 with σ_a =
    t / √3 (uniform on ±t) and σ(O1_x) = r / 2 (uniform in the disc); with --dist normal σ_a = t / 3
    and σ(O1_x) = r / 3. A limit's unknown response is refused on --limits before any work. The
    module's compiled study is moved to the command's inputs (`Study.moved`: nothing compiled)."""
    import importlib
    import pathlib
    import tempfile

    from jaxlink.cli import main

    tol_mod = importlib.import_module("jaxlink.study.tolerance")  # the module (`st.tolerance` is its function)

    monkeypatch.setattr(tol_mod, "study_for", lambda m, inputs, **kw: setup[2].moved(inputs=inputs))
    opts = ["--tol", "crank=0.01", "--tol", "rod=0.01", "--tol", "O1=radius:0.01", "--samples", "0",
            "--positions", "72"]
    with tempfile.TemporaryDirectory() as d:
        src = pathlib.Path(d) / "bare.toml"
        src.write_text(FILE.split("[study]")[0], encoding="utf-8")
        assert main(["study", str(src), *opts, "--limits", "stroke(sB)=1,2"]) == 2
        assert "--limits stroke(sB)=1,2: " in capsys.readouterr().err
        for dist, sa, so in (("uniform", 0.01 / math.sqrt(3), 0.005), ("normal", 0.01 / 3, 0.01 / 3)):
            assert main(["study", str(src), *opts, "--dist", dist]) == 0
            row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("A.x "))
            assert float(row.split()[2]) == pytest.approx(math.hypot(sa, so), rel=1e-3)  # printed to 4 digits
