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

import math

import numpy as np
import pytest

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
