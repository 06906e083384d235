"""Branch points between samples (issue 23, item 3): change points and toggles located against their
closed forms, and the smooth continuation through change points.

Each expected value is computed here, independently of jaxlink: the Peaucellier cell's flat
configuration from its geometry (closed form, and scipy's brentq on |OC|² = L² − s²), the four-bar's
fold and toggle from the law of cosines."""

import math
import os

import numpy as np
import pytest
from scipy.optimize import brentq

import jaxlink as jl

DATA = os.path.join(os.path.dirname(__file__), "data")
R, L, S = 3.0, 5.0, 2.0  # tests/data/peaucellier.toml
LINE_X = (L * L - S * S) / (2 * R)  # OC · OD = L² − s², C on the circle |C − (r, 0)| = r


def _flat_angle():
    """|OC| = 2 r cos(θ/2) = √(L² − s²): the rhombus flat, D = C."""
    closed = 2 * math.acos(math.sqrt(L * L - S * S) / (2 * R))

    def oc2(th):  # |OC|² − (L² − s²) from the crank's geometry, C = (r + r cos θ, r sin θ)
        return (R + R * math.cos(th)) ** 2 + (R * math.sin(th)) ** 2 - (L * L - S * S)

    root = brentq(oc2, 0.1, 2.0, xtol=1e-15, rtol=1e-15)
    assert abs(root - closed) < 1e-14
    return closed


@pytest.fixture(scope="module")
def peaucellier():
    return jl.load(os.path.join(DATA, "peaucellier.toml"))


PHIS = np.deg2rad(np.arange(-115.0, 115.1, 5.0))  # through both flat configurations, ±80.41°


def test_peaucellier_change_point_located_and_kept(peaucellier):
    sol = jl.solve(peaucellier, PHIS)
    assert np.all(np.asarray(sol.result) == jl.RESULTS.converged)  # every row says converged ...
    bp = jl.branch_points(peaucellier, PHIS, sol)
    found = np.argwhere(bp.kind == 1)
    th = _flat_angle()
    # ... but the two change points between samples are named, on the rhombus's dyad (the third)
    assert [tuple(x) for x in found] == [(np.searchsorted(PHIS, -th) - 1, 2), (np.searchsorted(PHIS, th) - 1, 2)]
    got = bp.input[bp.kind == 1]
    assert np.max(np.abs(got - np.array([-th, th]))) < 1e-9
    assert not bp.smooth[bp.kind == 1].any()  # the default keeps the dyad's side: D folds onto C
    D = np.asarray(sol.points[:, 1])
    C = np.asarray(sol.points[:, 0])
    past = np.abs(PHIS) > th
    assert np.allclose(D[past], C[past], atol=1e-12)
    assert np.allclose(D[~past, 0], LINE_X, rtol=1e-12)
    assert (bp.kind == 2).sum() == 0


def test_peaucellier_smooth_stays_on_its_line(peaucellier):
    """The acceptance: with the smooth option D stays on x = (L² − s²)/(2r) at every sample."""
    for method in ("closed_form", "continuation"):
        sol = jl.solve(peaucellier, PHIS, options=jl.NewtonOptions(method=method, change_points="smooth"))
        assert np.all(np.asarray(sol.result) == jl.RESULTS.converged), method
        D = np.asarray(sol.points[:, 1])
        assert np.max(np.abs(D[:, 0] - LINE_X)) / LINE_X < 1e-9, method
        # and D is C's inverse: |OC| |OD| = L² − s², on the ray OC
        C = np.asarray(sol.points[:, 0])
        assert np.allclose(np.hypot(*C.T) * np.hypot(*D.T), L * L - S * S, rtol=1e-12)
    bp = jl.branch_points(peaucellier, PHIS, sol)
    assert bp.smooth[bp.kind == 1].all() and (bp.kind == 1).sum() == 2


def test_peaucellier_report(peaucellier):
    from jaxlink.report.kinematics import kinematics_table, print_summary

    th = np.rad2deg(_flat_angle())
    table = kinematics_table(peaucellier, PHIS, outputs=("position",))
    col = table.column("change_point_deg")
    rows = np.flatnonzero(np.isfinite(col))
    assert np.allclose(col[rows], [-th, th], atol=1e-7)
    # on the row nearest to each
    assert list(rows) == [int(np.argmin(np.abs(np.rad2deg(PHIS) - v))) for v in (-th, th)]
    import io

    out = io.StringIO()
    print_summary(table, out)
    assert f"change point at input {th:.10g}°" in out.getvalue()
    assert "--change-points smooth" in out.getvalue()


@pytest.fixture(scope="module")
def four_bar():
    return jl.load("four-bar")


def _fourbar_p(mech, **values):
    p = np.array(mech.parameters, dtype=float)
    for k, v in values.items():
        p[mech.parameter_names.index(k)] = v * 1e-3
    return p


def test_four_bar_change_points_parallelogram(four_bar):
    """A Grashof change-point design, s + l = p + q: the parallelogram a = c, b = d folds flat at
    φ2 = 0 and 180° (|A B0| = b − c and b + c). Smooth: the rocker stays parallel to the crank."""
    p = _fourbar_p(four_bar, a=20.0, c=20.0, b=55.0, d=55.0)
    phis = np.deg2rad(np.arange(10.0, 370.0, 6.5))
    q0 = np.array([0.0, phis[0]])  # the parallelogram at φ2 = 10°: φ3 = 0, φ4 = φ2
    keep = jl.solve(four_bar, phis, p, q0)
    bp = jl.branch_points(four_bar, phis, keep, p)
    got = np.sort(bp.input[bp.kind == 1])
    assert got.shape == (2,) and np.max(np.abs(got - np.array([np.pi, 2 * np.pi]))) < 1e-9
    assert not bp.smooth[bp.kind == 1].any()
    q = np.asarray(keep.q)
    assert np.max(np.abs(q[phis > np.pi, 0])) > 0.1  # kept side past 180°: the antiparallelogram
    smooth = jl.solve(four_bar, phis, p, q0, options=jl.NewtonOptions(change_points="smooth"))
    q = np.asarray(smooth.q)
    assert np.all(np.asarray(smooth.result) == jl.RESULTS.converged)
    assert np.max(np.abs(np.sin(q[:, 0]))) < 1e-9
    assert np.max(np.abs(np.sin(q[:, 1] - phis))) < 1e-9 and np.all(np.cos(q[:, 1] - phis) > 0)


def test_four_bar_toggle(four_bar):
    """A non-Grashof four-bar (s + l > p + q) driven past its limit: the toggle where |A B0| = b + c,
    cos φ = (a² + d² − (b + c)²) / (2 a d), is located; no change point."""
    a, b, c, d = 30.0, 40.0, 35.0, 55.0
    p = _fourbar_p(four_bar, a=a, b=b, c=c, d=d)
    toggle = math.acos((a * a + d * d - (b + c) ** 2) / (2 * a * d))
    phis = np.deg2rad(np.arange(100.0, 140.0, 3.0))
    sol = jl.solve(four_bar, phis, p, np.deg2rad([40.0, 100.0]))
    res = np.asarray(sol.result)
    assert res[0] == jl.RESULTS.converged and res[-1] == jl.RESULTS.cannot_assemble
    bp = jl.branch_points(four_bar, phis, sol, p)
    assert (bp.kind == 1).sum() == 0 and (bp.kind == 2).sum() == 1
    assert abs(bp.input[bp.kind == 2][0] - toggle) < 1e-9


def test_full_turn_closing_interval_is_checked(four_bar):
    """Over a full turn the interval from the last row back to the first is checked too: the
    parallelogram sampled at 3° + 6° k folds at 360° (= 0°), between the last row and the first."""
    from jaxlink.report.kinematics import kinematics_table

    p = _fourbar_p(four_bar, a=20.0, c=20.0, b=55.0, d=55.0)
    phis = np.deg2rad(3.0 + 6.0 * np.arange(60))
    table = kinematics_table(four_bar, phis, p=p, outputs=("position",))
    found = [(b.kind, b.closing, round(b.value, 9)) for b in table.branch_points]
    assert found == [("change point", False, 180.0), ("change point", True, 360.0)]
    # each exactly half-way: the nearest row is either neighbour (177° or 183°; 357° or 3° = 363°)
    assert table.branch_points[0].nearest in (29, 30) and table.branch_points[1].nearest in (59, 0)
