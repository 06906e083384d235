"""Morris, regression/correlation coefficients, DGSM, correlated inputs, the precision stopping
rule and Dakota's vector/list/centered studies (`jaxlink.study`).

The estimators are checked on pure-numpy models against closed forms (a linear model: μ* = |a| ×
range, SRC² = Sobol' S1 = the importance factors; the Ishigami function's exact total indices
under the DGSM bound) and against SALib and scipy on the same samples; the studies on the offset
slider-crank of tests/test_study.py (16 positions, one compiled study moved between methods) against
its closed form: the crank pin A = O1 + a (cos θ, sin θ) is linear in (a, O1_x, O1_y), the slider

    B.x(θ) = O1_x + a cos θ + R,   R = √(b² − (O1_y + a sin θ − e)²),
    ∂B.x/∂a = cos θ − h sin θ / R,  ∂B.x/∂b = b / R,  ∂B.x/∂O1_x = 1,  ∂B.x/∂O1_y = −h / R
    (h = O1_y + a sin θ − e),

and it assembles over the whole turn iff b ≥ a + |e − O1_y|.
"""

import csv
import json

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
positions = 16
chunk = 1024
bootstrap = 50
metrics = ["stroke", "deviation"]
"""
E = 12.0
NAMES = ("crank", "rod", "O1_x", "O1_y")
SMALL = {"crank": [24.99, 25.01], "rod": [80.0, 80.02], "O1_x": [-0.01, 0.01], "O1_y": [-0.01, 0.01]}
WIDE = {"crank": [20.0, 30.0], "rod": [60.0, 100.0], "O1_x": [-5.0, 5.0], "O1_y": [-8.0, 8.0]}
TOGGLE = {"crank": [24.0, 26.0], "rod": [36.5, 39.0], "O1_x": [-0.5, 0.5], "O1_y": [-0.5, 0.5]}


@pytest.fixture(scope="module")
def setup():
    mech = jl.loads(FILE)
    inputs = st.read_study(mech, method="morris", ranges=SMALL)
    return mech, st.Study(mech, inputs)


def _moved(mech, study, **keys):
    return study.moved(inputs=st.read_study(mech, **keys))


def _rows(rep, name):
    return np.asarray([i for i, lab in enumerate(rep.labels) if lab[0] == name])


def _theta(rep):
    return np.deg2rad(rep.input_values)


# ----------------------------------------------------------------------------- estimators (numpy)

def test_morris_estimator_on_a_linear_model_and_against_salib():
    """Linear y = Σ a_j x_j over ranges: μ_j = a_j w_j, μ*_j = |a_j| w_j exactly, σ_j = 0; every
    trajectory point on the grid, each factor moved once by ±Δ. A nonlinear model: SALib's
    `morris.analyze` numbers on the same trajectories."""
    groups = [np.asarray([j]) for j in range(4)]
    u, order, sign = st.trajectories(groups, 40, 4, 3)
    assert u.shape == (40, 5, 4) and np.array_equal(u * 3, np.round(u * 3))
    moved = np.abs(np.diff(u, axis=1)) > 0  # (r, D, T): exactly one column per step
    assert np.all(moved.sum(axis=2) == 1) and np.all(moved.sum(axis=1) == 1)
    lo, hi = np.asarray([1.0, 2, 3, 4]), np.asarray([2.0, 5, 4, 8])
    x = lo + u * (hi - lo)
    a = np.asarray([1.0, -2, 0.5, 0.0])
    r = st.morris_indices(x @ a, order, sign, 4, seed=1)
    np.testing.assert_allclose(r.mu[0], a * (hi - lo), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(r.mu_star[0], np.abs(a) * (hi - lo), rtol=1e-12, atol=1e-12)
    assert np.all(r.sigma[0] < 1e-12) and np.all(r.effects == 40)
    y = np.sin(x[..., 0]) * x[..., 1] ** 2 + x[..., 2] * x[..., 3]
    w = np.ones((40, 5))
    w[3, 2] = 0  # one infeasible point: the two effects that touch it weigh 0
    rw = st.morris_indices(y, order, sign, 4, weight=w, resamples=0)
    assert rw.effects[0].sum() == 40 * 4 - 2
    salib = pytest.importorskip("SALib.analyze.morris")
    problem = {"num_vars": 4, "names": list("abcd"), "bounds": np.stack([lo, hi], 1).tolist()}
    s = salib.analyze(problem, x.reshape(-1, 4), y.ravel(), num_levels=4, seed=1)
    ours = st.morris_indices(y, order, sign, 4, seed=1)
    for k in ("mu", "mu_star", "sigma"):
        np.testing.assert_allclose(getattr(ours, k)[0], s[k], rtol=1e-10)


def test_regression_on_a_linear_model_is_sobol_and_the_importance_factors():
    """y = Σ a_j x_j, x_j uniform on [low_j, high_j]: SRC_j² = a_j² w_j² / Σ_k a_k² w_k² (the
    importance factors of uniform tolerances, and Sobol' S1 = ST) within sampling error, R² = 1,
    PCC = sign(a_j); Pearson and Spearman are scipy's; a constant output gives 0, never a NaN."""
    from scipy import stats
    from scipy.stats import qmc

    lo, hi = np.asarray([1.0, 2, 3, 4]), np.asarray([2.0, 5, 4, 8])
    a = np.asarray([1.0, -2, 0.5, 0.2])
    importance = a ** 2 * (hi - lo) ** 2 / np.sum(a ** 2 * (hi - lo) ** 2)
    u = qmc.Sobol(8, scramble=True, seed=2).random(4096)
    xa, xb = lo + u[:, :4] * (hi - lo), lo + u[:, 4:] * (hi - lo)
    xab = np.stack([np.where(np.arange(4) == j, xb, xa) for j in range(4)])
    s = st.sobol_indices(xa @ a, xb @ a, xab @ a, seed=1)
    y = np.stack([xa @ a, np.exp(xa[:, 0]) * xa[:, 1], np.full(4096, 3.0)], axis=1)
    r = st.regression_indices(xa, y)
    src2 = r.values["src"][0] ** 2
    np.testing.assert_allclose(src2, importance, atol=2e-3)
    half = 0.5 * (s.S1_high[0] - s.S1_low[0])
    assert np.all(np.abs(src2 - s.S1[0]) <= 2 * half + 2e-3)
    assert r.r2[0] == pytest.approx(1.0, abs=1e-12) and np.allclose(r.values["pcc"][0], np.sign(a))
    for j in range(4):
        assert r.values["pearson"][1, j] == pytest.approx(stats.pearsonr(xa[:, j], y[:, 1])[0], abs=1e-12)
        assert r.values["spearman"][1, j] == pytest.approx(stats.spearmanr(xa[:, j], y[:, 1])[0], abs=1e-12)
        assert r.low["spearman"][1, j] < r.values["spearman"][1, j] < r.high["spearman"][1, j]
    assert r.constant.tolist() == [False, False, True]
    for d in (r.values, r.low, r.high):
        for v in d.values():
            assert np.all(np.isfinite(v)) and np.all(v[2] == 0)


def test_dgsm_bounds_the_total_indices_of_ishigami():
    """The Ishigami function on [−π, π]³ with its exact gradient: C ν_j / V ≥ ST_j (exact) for
    every factor, and ν_j against its closed form (ν₁ = E[(cos x₁ (1 + 0.1 x₃⁴))²] etc.)."""
    from scipy.stats import qmc

    x = -np.pi + 2 * np.pi * qmc.Sobol(3, scramble=True, seed=1).random(8192)
    s1, s2, s3 = (x[:, k] for k in range(3))
    y = np.sin(s1) + 7 * np.sin(s2) ** 2 + 0.1 * s3 ** 4 * np.sin(s1)
    g = np.stack([np.cos(s1) * (1 + 0.1 * s3 ** 4), 14 * np.sin(s2) * np.cos(s2), 0.4 * s3 ** 3 * np.sin(s1)], 1)
    r = st.dgsm_indices(g, y, np.full(3, (2 * np.pi) ** 2 / np.pi ** 2), resamples=50, seed=0)
    pi = np.pi
    nu1 = 0.5 * (1 + 0.2 * pi ** 4 / 5 + 0.01 * pi ** 8 / 9)
    exact_nu = [nu1, 49 / 2, 0.16 * pi ** 6 / 7 * 0.5]
    np.testing.assert_allclose(r.nu[0], exact_nu, rtol=0.02)
    st_exact = np.asarray([0.5575888667, 0.4424111333, 0.2436836840])
    assert np.all(r.bound[0] >= st_exact) and np.all(r.bound_low[0] <= r.bound[0])


def test_iman_conover_imposes_the_rank_correlation_and_keeps_the_marginals():
    """The achieved Spearman matrix is the requested one within sampling error (3/√n); every
    column keeps its values (the same sorted values)."""
    from scipy.stats import spearmanr

    rng = np.random.default_rng(0)
    x = np.stack([rng.random(4000), rng.standard_normal(4000), rng.exponential(size=4000)], axis=1)
    c = np.asarray([[1.0, 0.7, -0.3], [0.7, 1.0, 0.0], [-0.3, 0.0, 1.0]])
    y = st.iman_conover(x, c, np.random.default_rng(1))
    assert np.all(np.sort(y, axis=0) == np.sort(x, axis=0))
    assert np.abs(spearmanr(y).statistic - c).max() < 3 / np.sqrt(4000)
    assert np.abs(spearmanr(x).statistic - np.eye(3)).max() < 3 / np.sqrt(4000)


# ----------------------------------------------------------------------------- the studies


def test_morris_regression_dgsm_of_the_slider_crank(setup, tmp_path):
    """Over the small ranges: Morris μ* of A.x, A.y is |∂A/∂x| × range exactly at every position
    (σ = 0: A is linear), the rod's 0; SRC² of A.x the importance factors (within 0.03); DGSM ν of
    B.x is the closed form's mean squared derivative at the same designs. Over wide ranges (B.x
    nonlinear) the DGSM bound is above the Sobol' ST of the existing estimator at every position."""
    mech, study = setup
    m = st.morris(mech, study=_moved(mech, study, method="morris", samples=10, ranges=SMALL))
    th = _theta(m)
    w = 0.02
    ind = m.indices
    assert m.evaluations == 50 and m.feasible_fraction == 1 and not m.warnings
    for name, grads in (("A.x", (np.cos(th), 0 * th, 1 + 0 * th, 0 * th)),
                        ("A.y", (np.sin(th), 0 * th, 0 * th, 1 + 0 * th))):
        rows = _rows(m, name)
        np.testing.assert_allclose(ind.mu_star[rows], w * np.abs(np.stack(grads, 1)), rtol=1e-6, atol=1e-9)
        assert np.all(ind.sigma[rows] < 1e-6 * w)
    assert np.all(m.feasibility.mu_star == 0)
    from jaxlink.report import screening

    files = screening.write_all(tmp_path / "m", mech, m, wall_time=1.0)
    assert {p.split("/")[-1] for p in files} == {"indices.csv", "morris.png", "study.npz", "study.json"}
    head = (tmp_path / "m" / "indices.csv").read_text().splitlines()[0]
    assert head == "output,input (deg),parameter,method,unit,value (unit),low (unit),high (unit),conditional"

    g = st.regression(mech, study=_moved(mech, study, method="regression", samples=256, ranges=SMALL))
    rows = _rows(g, "A.x")
    imp = np.stack([np.cos(th) ** 2, 0 * th, 1 + 0 * th, 0 * th], 1) / (np.cos(th) ** 2 + 1)[:, None]
    np.testing.assert_allclose(g.indices.values["src"][rows] ** 2, imp, atol=0.03)
    assert np.all(g.indices.r2[rows] > 1 - 1e-9)

    d = st.dgsm(mech, study=_moved(mech, study, method="dgsm", samples=64, ranges=SMALL, seed=5))
    x = st.to_values(d.inputs, study.x0, np.concatenate(list(st.unit_blocks("sobol", 4, 64, 5))))
    a, b, ox, oy = (x[:, k:k + 1] for k in range(4))
    h = oy + a * np.sin(th) - E
    R = np.sqrt(b * b - h * h)
    exact = [np.mean(v ** 2, axis=0) for v in (np.cos(th) - h * np.sin(th) / R, b / R, 1 + 0 * R, -h / R)]
    np.testing.assert_allclose(d.indices.nu[_rows(d, "B.x")], np.stack(exact, 1), rtol=1e-7)
    # --replot: each report read back from study.npz and study.json equals the one written, and the
    # plot is redrawn from them alone
    from jaxlink.report.replot import read, replot

    for name, rep in (("m", m), ("g", g), ("d", d)):
        if name != "m":
            screening.write_all(tmp_path / name, mech, rep, wall_time=1.0, plot=False)
        back = read(tmp_path / name)[1]
        assert type(back) is type(rep) and back.labels == rep.labels
        for f in rep.indices._fields:
            a, b = getattr(rep.indices, f), getattr(back.indices, f)
            if isinstance(a, dict):
                assert all(np.array_equal(a[k], b[k]) for k in a), f
            else:
                assert np.array_equal(a, b), f
    (tmp_path / "m" / "morris.png").unlink()
    assert [p.split("/")[-1] for p in replot(tmp_path / "m")] == ["morris.png"]
    assert (tmp_path / "m" / "morris.png").is_file()

    wide_s = st.sensitivity(mech, study=_moved(mech, study, method="sensitivity", samples=256, ranges=WIDE))
    wide_d = st.dgsm(mech, study=_moved(mech, study, method="dgsm", samples=256, ranges=WIDE))
    rows = _rows(wide_s, "B.x")
    ST, hi = wide_s.indices.ST[rows], wide_s.indices.ST_high[rows]
    bound = wide_d.indices.bound[_rows(wide_d, "B.x")]
    assert np.all(bound >= ST - (hi - ST) - 0.02), np.min(bound - ST)
    assert np.any(ST[:, 1] < 0.9 * bound[:, 1])  # nonlinear in the rod: the bound is not reached


def test_feasibility_of_morris_and_regression_near_the_toggle(setup):
    """Across the toggle b = a + |e − O1_y|: Morris keeps every trajectory, weighs the effects
    with an infeasible end 0 (a warning), O1_x's feasibility μ* is exactly 0; regression's
    feasibility coefficients are over every design, the responses' over the feasible ones; no NaN."""
    mech, study = setup
    mv = study.moved(x0=[25.0, 38.0, 0.0, 0.0], inputs=st.read_study(mech, method="morris", samples=20,
                                                                     ranges=TOGGLE))
    m = st.morris(mech, study=mv)
    assert 0 < m.feasible_fraction < 1 and any("elementary effects" in w for w in m.warnings)
    assert m.feasibility.mu_star[0, 2] == 0 and m.feasibility.mu_star[0, 1] > 0
    for v in m.indices:
        assert np.all(np.isfinite(np.asarray(v, float)))
    g = st.regression(mech, study=mv.moved(inputs=st.read_study(mech, method="regression", samples=200,
                                                                ranges=TOGGLE)))
    ok = g.values[:, 1] >= g.values[:, 0] + np.abs(E - g.values[:, 3])
    assert g.feasible_fraction == pytest.approx(ok.mean()) and 0 < ok.mean() < 1
    assert g.feasibility.values["src"][0, 1] > 0.3 and g.indices.samples == ok.sum()


def test_correlated_samples_and_monte_carlo(setup):
    """`[study.correlation]` on a Latin hypercube `sample` and on the tolerance Monte Carlo draws:
    the Spearman correlation is the requested one within sampling error, the hypercube still has
    one design per slice; the table is checked."""
    from scipy.stats import spearmanr

    mech, study = setup
    inp = st.read_study(mech, method="sample", samples=400, sampler="lhs", ranges=SMALL,
                        correlation={"crank": {"rod": 0.8}, "O1_x": {"O1_y": -0.5}})
    r = st.sample(mech, study=study.moved(inputs=inp))
    rho = spearmanr(r.values).statistic
    assert abs(rho[0, 1] - 0.8) < 0.1 and abs(rho[2, 3] + 0.5) < 0.1 and abs(rho[0, 2]) < 0.15
    lo, hi = np.asarray(list(SMALL.values())).T
    for j in range(4):
        assert sorted(np.floor((r.values[:, j] - lo[j]) / (hi[j] - lo[j]) * 400).astype(int)) == list(range(400))
    tol = st.read_study(mech, tolerances={"crank": 0.1, "rod": {"tol": 0.1, "distribution": "uniform"}},
                        correlation={"rod": {"crank": 0.6}})
    d = st.draws(tol, 3000)
    assert abs(spearmanr(d[:, 0], d[:, 1]).statistic - 0.6) < 0.06
    ind = st.draws(tol._replace(correlation=()), 3000)
    assert np.array_equal(np.sort(d[:1024], axis=0), np.sort(ind[:1024], axis=0))  # the same draws, paired anew
    for bad, msg in (({"crank": {"rod": 1.0}}, "strictly between"), ({"crank": {"nope": 0.1}}, "not an input"),
                     ({"crank": {"rod": 0.9}, "rod": {"O1_x": 0.9}, "O1_x": {"crank": -0.9}}, "positive definite")):
        with pytest.raises(jl.MechanismError, match=msg):
            st.read_study(mech, method="sample", sampler="lhs", ranges=SMALL, correlation=bad)
    with pytest.raises(jl.MechanismError, match="assumes independent"):
        st.read_study(mech, method="sensitivity", ranges=SMALL, correlation={"crank": {"rod": 0.5}})
    with pytest.raises(jl.MechanismError, match="sampler"):
        st.read_study(mech, method="sample", ranges=SMALL, correlation={"crank": {"rod": 0.5}})


def test_the_precision_stopping_rule(setup):
    """Sobol': N doubles from 8 until the largest half-width is at most the precision; the report
    is `sensitivity`'s at that N; the round before was above it. A cap below: not converged, warned.
    Monte Carlo: the same rule on the mean's and σ's intervals relative to σ."""
    mech, study = setup
    mv = _moved(mech, study, method="sensitivity", samples=8, ranges=SMALL, bootstrap=30)
    rep, conv = st.converged_sensitivity(mech, study=mv, precision=0.25, max_samples=4096)
    assert conv.converged and conv.samples == rep.samples and conv.samples > 8
    assert conv.history[-1][1] <= 0.25 < conv.history[-2][1]
    assert [n for n, _ in conv.history] == [8 * 2 ** k for k in range(len(conv.history))]
    again = st.sensitivity(mech, study=mv, samples=conv.samples)
    np.testing.assert_array_equal(again.indices.ST_high, rep.indices.ST_high)
    rep2, conv2 = st.converged_sensitivity(mech, study=mv, precision=1e-4, max_samples=16)
    assert not conv2.converged and conv2.samples == 16 and any("not reached" in w for w in rep2.warnings)
    # Monte Carlo: the largest of z·se(mean)/σ and z·se(σ)/σ over the responses that vary
    from jaxlink.study.convergence import monte_carlo_half_width

    z3 = np.zeros(3)
    mc = st.MonteCarlo(100, 100, 0, z3, np.asarray([2.0, 0.0, 1.0]), np.asarray([0.1, 0.0, 0.01]),
                       np.asarray([0.2, 0.0, 0.05]), z3, z3, z3, z3, z3, np.ones(3, bool))
    assert monte_carlo_half_width(mc, 0.95) == pytest.approx(1.959963984540054 * 0.1)
    assert monte_carlo_half_width(mc._replace(feasible=0), 0.95) == np.inf


def test_vector_list_centered_studies(setup, tmp_path, capsys):
    """Dakota's studies in one batched call: the designs (vector: n + 1 points on the line to the
    final point; list: as given; centered, from the command line: the design then ±k steps per
    parameter), each row's feasibility against the closed-form condition; a Morris study's
    indices.csv from the command line."""
    from jaxlink.cli import main

    mech, study = setup
    vec = st.read_study(mech, method="vector", steps=4, final={"crank": 25.0, "rod": 34.0, "O1_x": 0.0, "O1_y": 2.0})
    lst = st.read_study(mech, method="list", list={"crank": [25, 25, 30], "rod": [80, 30, 80], "O1_x": [0, 0, 0],
                                                   "O1_y": [0, 0, 1]})
    for inp, want in ((vec, np.stack([25 + 0 * np.arange(5), np.linspace(80, 34, 5), 0 * np.arange(5),
                                      np.linspace(0, 2, 5)], 1)),
                      (lst, np.asarray([[25.0, 80, 0, 0], [25, 30, 0, 0], [30, 80, 0, 1]]))):
        r = st.parameter_study(mech, study=study.moved(inputs=inp))
        np.testing.assert_allclose(r.values, want, atol=1e-9)
        assert np.array_equal(r.feasible, want[:, 1] >= want[:, 0] + np.abs(E - want[:, 3]))
        assert 0 < r.feasible.sum() < len(want)
    src = tmp_path / "slider.toml"
    base = FILE + "seed = 2\n"
    src.write_text(base + 'method = "centered"\nsteps = 2\n[study.step]\ncrank = 0.5\nrod = 22.0\n')
    out = tmp_path / "centered"
    assert main(["study", str(src), "--out", str(out), "--progress", "off"]) == 0
    rows = list(csv.DictReader((out / "study.csv").open()))
    x = np.asarray([[float(r["crank (mm)"]), float(r["rod (mm)"])] for r in rows])
    want = np.asarray([[25, 80], [24, 80], [24.5, 80], [25.5, 80], [26, 80], [25, 36], [25, 58], [25, 102],
                       [25, 124]], float)
    np.testing.assert_allclose(x, want, atol=1e-9)
    assert [int(r["feasible"]) for r in rows] == (want[:, 1] >= want[:, 0] + E).astype(int).tolist()
    assert json.loads((out / "study.json").read_text())["method"] == "centered"
    # its plot: each parameter's line in the order of its offsets −k … k, the file's design at 0;
    # redrawn by --replot from study.json and study.npz alone
    from jaxlink.report.parameter_studies import centered_offsets
    from jaxlink.report.replot import read

    k, order = centered_offsets(read(out)[1])
    assert k == 2
    np.testing.assert_allclose(x[order[0], 0], [24, 24.5, 25, 25.5, 26], atol=1e-9)
    np.testing.assert_allclose(x[order[1], 1], [36, 58, 80, 102, 124], atol=1e-9)
    (out / "centered.png").unlink()
    assert main(["study", str(src), "--replot", str(out)]) == 0 and (out / "centered.png").is_file()
    src.write_text(base + 'method = "morris"\nsamples = 6\n[study.ranges]\ncrank = [24.0, 26.0]\nrod = [36.5, 39.0]\n')
    out = tmp_path / "morris"
    assert main(["study", str(src), "--out", str(out), "--progress", "off"]) == 0
    text = (out / "indices.csv").read_text()
    assert "nan" not in text.lower() and (out / "morris.png").is_file()
    capsys.readouterr()
    for bad, msg in (('method = "vector"\n[study.final]\nnope = 1\n', "'nope' is not a parameter"),
                     ('method = "list"\n[study.list]\ncrank = [1, 2]\nrod = [1]\n', "equal length"),
                     ('method = "centered"\n[study.step]\ncrank = -1\n', "a step is a number > 0"),
                     ('method = "sample"\nsteps = 3\n[study.ranges]\ncrank = [1, 2]\n', "belongs to the vector")):
        with pytest.raises(jl.MechanismError, match=msg):
            st.read_study(jl.loads(base + bad))


def _killed_and_resumed_on_the_command_line(src, tmp_path, monkeypatch, capsys, after_kill=None):
    """`jaxlink study SRC --out DIR`: a run into cli-ref/; a run into cli/ interrupted (Ctrl-C) just
    after its first checkpoint is saved (exit status 130; `after_kill()` must then hold); the same
    command with `--resume` prints what the uninterrupted run printed (but its first line, the
    timing)."""
    from jaxlink.cli import main
    from jaxlink.study.checkpoint import Checkpoint

    cmd = ["study", str(src), "--no-plot", "--progress", "off", "--out"]
    assert main(cmd + [str(tmp_path / "cli-ref")]) == 0
    ref_out = capsys.readouterr().out
    save = Checkpoint.save

    def killed(self, done, state):
        save(self, done, state)
        raise KeyboardInterrupt
    monkeypatch.setattr(Checkpoint, "save", killed)
    assert main(cmd + [str(tmp_path / "cli")]) == 130
    monkeypatch.undo()
    assert after_kill is None or after_kill()
    assert main(cmd + [str(tmp_path / "cli"), "--resume"]) == 0
    assert ref_out.splitlines()[1:] == capsys.readouterr().out.replace("/cli/", "/cli-ref/").splitlines()[1:]


def _written(tmp_path, name, mech, rep):
    """(indices.csv bytes, the summary, study.json without the timings, study.npz's arrays) of `rep`."""
    from jaxlink.report import screening
    from jaxlink.study import archive

    d = tmp_path / name
    screening.write_all(d, mech, rep, wall_time=1.0, plot=False)
    data = json.loads((d / "study.json").read_text())
    del data["timings_s"], data["report"]["fields"]["timings"]
    return (d / "indices.csv").read_bytes(), screening.summary(rep), data, archive.load_npz(d / "study.npz")


def test_morris_regression_dgsm_killed_and_resumed_give_the_same_bytes(setup, tmp_path, monkeypatch, capsys):
    """Morris, regression and DGSM over two batches each near the toggle (infeasible designs in
    both), interrupted after the first batch (the checkpoint written batch by batch), resumed:
    indices.csv, the summary, study.json (but the timings) and every array of study.npz equal the
    uninterrupted run's bit for bit. The resume reads the checkpoint (a perturbed saved state, a
    missing chunk change the result or are refused), and a checkpoint whose key differs (seed,
    samples, chunk, method) is refused naming the difference. From the command line: a Morris
    study interrupted (Ctrl-C) after its first checkpoint, then `--resume`d, writes the bytes of an
    uninterrupted one; a resume with another --seed is refused."""
    import shutil

    from jaxlink.study import archive
    from jaxlink.study.checkpoint import Checkpoint, resume_key

    mech, study = setup

    def ck(name, inp, resume=False, chunk=study.chunk, what=None):
        key = resume_key(mech, inp, chunk=chunk, what=what or inp.method)
        return Checkpoint(tmp_path / name, key, resume=resume)

    # one batch: 1024 // 5 = 204 Morris trajectories, 1024 regression designs, 256 DGSM designs
    for method, n, fn in (("morris", 210, st.morris), ("regression", 1100, st.regression), ("dgsm", 300, st.dgsm)):
        inp = st.read_study(mech, method=method, samples=n, ranges=TOGGLE, seed=3, bootstrap=10)
        mv = study.moved(x0=[25.0, 38.0, 0.0, 0.0], inputs=inp)
        ref = fn(mech, study=mv)
        assert 0 < ref.feasible_fraction < 1
        with pytest.raises(Stop):
            fn(mech, study=mv, progress=stop_after(1), checkpoint=ck(method, inp))
        assert json.loads((tmp_path / method / "state.json").read_text())["done"] == 1
        shutil.copytree(tmp_path / method, tmp_path / f"{method}-copy")
        res = fn(mech, study=mv, checkpoint=ck(method, inp, resume=True))
        want, got = _written(tmp_path, f"{method}-ref", mech, ref), _written(tmp_path, f"{method}-res", mech, res)
        assert want[:3] == got[:3], method
        assert want[3].keys() == got[3].keys() and all(np.array_equal(want[3][k], got[3][k]) for k in want[3])
        # the saved state is what the resumed study starts from
        copy = tmp_path / f"{method}-copy"
        if method == "regression":
            (copy / "chunk-000000.npz").unlink()
            with pytest.raises(jl.MechanismError, match="a chunk of the checkpoint is missing"):
                fn(mech, study=mv, checkpoint=ck(f"{method}-copy", inp, resume=True))
        else:
            state = archive.load_npz(copy / "state-000001.npz")
            archive.save_npz(copy / "state-000001.npz", {k: v * 1.5 if v.dtype == float else v
                                                           for k, v in state.items()})
            bad = fn(mech, study=mv, checkpoint=ck(f"{method}-copy", inp, resume=True))
            assert _written(tmp_path, f"{method}-bad", mech, bad)[0] != want[0]
        for other, why in ((inp._replace(seed=4), "seed"), (inp._replace(samples=n + 1), "samples")):
            with pytest.raises(jl.MechanismError, match=f"another study .*{why}"):
                fn(mech, study=mv, checkpoint=ck(method, other, resume=True))
    with pytest.raises(jl.MechanismError, match="another study .*chunk"):
        st.dgsm(mech, study=mv, checkpoint=ck("dgsm", inp, resume=True, chunk=512))
    with pytest.raises(jl.MechanismError, match="another study .*the study's method"):
        st.dgsm(mech, study=mv, checkpoint=ck("morris", inp, resume=True))

    from jaxlink.cli import main

    src = tmp_path / "slider.toml"
    src.write_text(FILE + 'seed = 2\nmethod = "morris"\nsamples = 400\n[study.ranges]\ncrank = [24.0, 26.0]\n'
                   'rod = [36.5, 39.0]\n')  # 1024 // 3 = 341 trajectories a batch: two batches
    _killed_and_resumed_on_the_command_line(
        src, tmp_path, monkeypatch, capsys,
        after_kill=lambda: json.loads((tmp_path / "cli" / "checkpoint" / "state.json").read_text())["done"] == 1)

    def manifest(d):
        data = json.loads((tmp_path / d / "study.json").read_text())
        del data["timings_s"], data["wall_time_s"], data["report"]["fields"]["timings"]
        return data
    assert (tmp_path / "cli-ref" / "indices.csv").read_bytes() == (tmp_path / "cli" / "indices.csv").read_bytes()
    assert manifest("cli-ref") == manifest("cli")
    assert main(["study", str(src), "--no-plot", "--progress", "off", "--out", str(tmp_path / "cli"), "--resume",
                 "--seed", "5"]) == 2
    assert "belongs to another study (different [study] seed)" in capsys.readouterr().err


def _sample_written(tmp_path, name, mech, rep):
    """(study.csv bytes, the summary, study.json without the timings, study.npz's arrays) of `rep`."""
    from jaxlink.report import sampling
    from jaxlink.study import archive

    d = tmp_path / name
    sampling.write_sample_all(d, mech, rep, wall_time=1.0, plot=False)
    data = json.loads((d / "study.json").read_text())
    del data["timings_s"], data["report"]["fields"]["timings"]
    return (d / "study.csv").read_bytes(), sampling.sample_summary(rep), data, archive.load_npz(d / "study.npz")


def _same_files(want, got):
    assert want[:3] == got[:3]
    assert want[3].keys() == got[3].keys() and all(np.array_equal(want[3][k], got[3][k]) for k in want[3])


def test_vector_study_and_the_stopping_rule_killed_and_resumed(setup, tmp_path, monkeypatch, capsys):
    """A vector study over two batches (1501 designs, chunk 1024, infeasible ones among them) killed
    after its first batch and resumed writes the uninterrupted study's study.csv, summary,
    study.json (but the timings) and study.npz bit for bit; another `steps` is refused naming the
    designs. The stopping rule (Sobol': rounds 8 … 256, the last of two batches) killed mid-round
    resumes in its round to the uninterrupted result: the same indices and history bit for bit, the
    rounds before not evaluated again (the Monte Carlo's: tests/test_study.py). From the command
    line: a vector study killed (Ctrl-C) and `--resume`d writes the bytes of an uninterrupted one."""
    from jaxlink.study.checkpoint import Checkpoint, resume_key

    mech, study = setup

    def ck(name, inp, resume=False):
        return Checkpoint(tmp_path / name, resume_key(mech, inp, chunk=study.chunk, what=inp.method), resume=resume)

    final = {"crank": 25.0, "rod": 34.0, "O1_x": 0.0, "O1_y": 2.0}
    vec = st.read_study(mech, method="vector", steps=1500, final=final)
    mv = study.moved(inputs=vec)
    ref = st.parameter_study(mech, study=mv)
    assert len(ref.feasible) == 1501 and 0 < ref.feasible.sum() < 1501
    with pytest.raises(Stop):
        st.parameter_study(mech, study=mv, progress=stop_after(1), checkpoint=ck("vector", vec))
    assert json.loads((tmp_path / "vector" / "state.json").read_text())["done"] == 1
    res = st.parameter_study(mech, study=mv, checkpoint=ck("vector", vec, resume=True))
    _same_files(_sample_written(tmp_path, "v-ref", mech, ref), _sample_written(tmp_path, "v-res", mech, res))
    with pytest.raises(jl.MechanismError, match=r"another study .*\[study\] designs"):
        st.parameter_study(mech, study=mv, checkpoint=ck("vector", st.read_study(mech, method="vector", steps=1400,
                                                                                  final=final), resume=True))

    # the stopping rule: Sobol' killed in its last round (256 base samples: 2 batches of 170)
    sin = _moved(mech, study, method="sensitivity", samples=8, ranges=SMALL, bootstrap=20, precision=1e-4,
                 max_samples=256)
    rep, conv = st.converged_sensitivity(mech, study=sin)
    assert [n for n, _ in conv.history] == [8, 16, 32, 64, 128, 256] and not conv.converged
    with pytest.raises(Stop):
        st.converged_sensitivity(mech, study=sin, progress=stop_after(6), checkpoint=ck("sobol", sin.inputs))
    saved = json.loads((tmp_path / "sobol" / "state.json").read_text())
    assert saved["done"] == 1 and saved["state"]["samples"] == 256 and len(saved["state"]["history"]) == 5
    calls = []
    res, rconv = st.converged_sensitivity(mech, study=sin, progress=calls.append,
                                          checkpoint=ck("sobol", sin.inputs, resume=True))
    assert rconv == conv and calls == [170 * 6, 86 * 6]  # the batch done counted, then the last one
    for f in ("S1", "ST", "S1_low", "S1_high", "ST_low", "ST_high"):
        for a, b in ((rep.indices, res.indices), (rep.feasibility, res.feasibility)):
            assert np.array_equal(getattr(a, f), getattr(b, f)), f
    with pytest.raises(jl.MechanismError, match=r"another study .*\[study\] precision"):
        st.converged_sensitivity(mech, study=sin, checkpoint=ck("sobol", sin.inputs._replace(precision=1e-3),
                                                                resume=True))

    src = tmp_path / "slider.toml"
    src.write_text(FILE + 'method = "vector"\nsteps = 1100\n[study.final]\ncrank = 25.0\nrod = 34.0\n')
    _killed_and_resumed_on_the_command_line(src, tmp_path, monkeypatch, capsys)
    assert (tmp_path / "cli-ref" / "study.csv").read_bytes() == (tmp_path / "cli" / "study.csv").read_bytes()
