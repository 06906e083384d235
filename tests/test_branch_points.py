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


# ------------------------------------------------------------------ gaps between samples (issue 46, item 2)
# A dyad that cannot be assembled over a window narrower than the samples' spacing: both rows around
# it assemble, its reach margin has a negative minimum between them. Two toggles, not a change point.

A, B, D = 20.0, 40.0, 55.0  # a + d = 75 = b + c at c = 35: the change-point design; c < 35 opens a gap at 180°
GAP_PHIS = np.deg2rad(2.5 + 5.0 * np.arange(72))  # 177.5° and 182.5° straddle 180°


def _gap_c(half):
    """The rocker c (mm) whose four-bar (A, B, c, D) cannot be assembled for |φ2 − 180°| < `half`
    (rad): |A B0|² = a² + d² + 2 a d cos(half) = (b + c)² at the toggles."""
    return math.sqrt(A * A + D * D + 2 * A * D * math.cos(half)) - B


def _gap_toggles(c):
    """The toggles π ∓ δ of the four-bar (A, B, c, D), from its lengths (the half-angle form, well
    conditioned near 180°): 2 sin²(δ/2) = ((a + d)² − (b + c)²) / (2 a d)."""
    delta = 2 * math.asin(math.sqrt(((A + D) - (B + c)) * ((A + D) + (B + c)) / (4 * A * D)))
    return math.pi - delta, math.pi + delta


@pytest.mark.parametrize("half", [math.radians(0.25), 1e-3])
def test_a_gap_between_samples_is_two_toggles(four_bar, half):
    c = _gap_c(half)
    p = _fourbar_p(four_bar, a=A, b=B, c=c, d=D)
    lo, hi = _gap_toggles(float(p[four_bar.parameter_names.index("c")]) * 1e3)
    k = int(np.searchsorted(GAP_PHIS, math.pi)) - 1
    assert GAP_PHIS[k] < lo < hi < GAP_PHIS[k + 1]
    keep = jl.solve(four_bar, GAP_PHIS, p)
    assert np.all(np.asarray(keep.result) == jl.RESULTS.converged)  # every row assembles ...
    bp = jl.branch_points(four_bar, GAP_PHIS, keep, p)
    # ... and between rows k and k + 1 a gap, its two toggles in the path's order; no change point
    assert [tuple(x) for x in np.argwhere(bp.kind != 0)] == [(k, 0)] and bp.kind[k, 0] == 3
    assert abs(bp.input[k, 0] - lo) < 1e-9 and abs(bp.end[k, 0] - hi) < 1e-9
    assert not bp.smooth[k, 0]
    # the smooth continuation does not cross it: the same rows as the closed form's kept side
    smooth = jl.solve(four_bar, GAP_PHIS, p, options=jl.NewtonOptions(change_points="smooth"))
    assert np.array_equal(np.asarray(smooth.q), np.asarray(keep.q))
    assert (jl.branch_points(four_bar, GAP_PHIS, smooth, p).kind == 3).sum() == 1
    # driven in the other direction, the toggles come in the other order
    back = GAP_PHIS[::-1]
    bp = jl.branch_points(four_bar, back, jl.solve(four_bar, back, p), p)
    j = len(back) - 2 - k
    assert bp.kind[j, 0] == 3 and abs(bp.input[j, 0] - hi) < 1e-9 and abs(bp.end[j, 0] - lo) < 1e-9


def test_the_change_point_design_is_still_a_change_point(four_bar):
    """The differential case: c = 35 exactly (a + d = b + c), the margin's minimum touches zero at
    180°: a change point, crossed by the smooth continuation (its rows differ from the kept side's)."""
    p = _fourbar_p(four_bar, a=A, b=B, c=35.0, d=D)
    keep = jl.solve(four_bar, GAP_PHIS, p)
    bp = jl.branch_points(four_bar, GAP_PHIS, keep, p)
    assert (bp.kind == 1).sum() == 1 and (bp.kind == 3).sum() == 0
    assert abs(bp.input[bp.kind == 1][0] - math.pi) < 1e-9 and np.isnan(bp.end).all()
    smooth = jl.solve(four_bar, GAP_PHIS, p, options=jl.NewtonOptions(change_points="smooth"))
    assert not np.allclose(np.asarray(smooth.q), np.asarray(keep.q))


def _cli(capsys, *args):
    from jaxlink.cli import main

    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_kinematics_names_the_gap(tmp_path, capsys):
    """The issue's case on the command line: every row converges, the gap is named in the warning,
    the summary, the CSV (`gap_from_deg`, `gap_to_deg` on the row before it) and the JSON, and the
    exit status is 1; `--change-points smooth` gives the same rows."""
    import csv
    import json

    c = _gap_c(math.radians(0.25))
    lo, hi = (math.degrees(x) for x in _gap_toggles(c))
    rows = {}
    for cp in ("keep", "smooth"):
        out, js = tmp_path / f"{cp}.csv", tmp_path / f"{cp}.json"
        code, stdout, stderr = _cli(capsys, "kinematics", "four-bar", "--set", "a=20", "--set", "b=40", "--set",
                                    f"c={c!r}", "--set", "d=55", "--start", "2.5", "--outputs", "position",
                                    "--change-points", cp, "--csv", str(out), "--json", str(js))
        assert code == 1
        text = f"gap from input {lo:.10g}° to {hi:.10g}° (loop 'main' (phi3, phi4), between rows 36 and 37)"
        assert f"warning: {text}" in stderr and text in stdout and "change point" not in stdout + stderr
        table = list(csv.reader(open(out)))
        head, body = table[0], table[1:]
        assert all(r[head.index("result")] == "converged" for r in body)
        got = [(i, float(r[head.index("gap_from_deg")]), float(r[head.index("gap_to_deg")]))
               for i, r in enumerate(body) if r[head.index("gap_from_deg")] != "nan"]
        assert len(got) == 1 and got[0][0] == 35  # the row at 177.5°
        assert abs(got[0][1] - lo) < math.degrees(1e-9) and abs(got[0][2] - hi) < math.degrees(1e-9)
        doc = json.load(open(js))["branch_points"]
        assert [(b["kind"], b["rows"]) for b in doc] == [("gap", [36, 37])]
        assert abs(doc[0]["input"] - lo) < math.degrees(1e-9) and abs(doc[0]["end"] - hi) < math.degrees(1e-9)
        rows[cp] = [r[:3] for r in body]
    assert rows["keep"] == rows["smooth"]


def test_reactions_name_the_gap(tmp_path, capsys):
    """An RRP dyad: the offset slider-crank (offset h1 = 12, crank h2 = 25) cannot be assembled where
    h1 − h2 sin ψ > h3, around ψ = 270°; with h3 = h1 + h2 cos δ the window is 270° ± δ, δ = 0.25°,
    between the rows at 267.5° and 272.5°. `reactions` names it (warning, summary, CSV) and exits 1."""
    import csv

    h1, h2 = 12.0, 25.0
    h3 = h1 + h2 * math.cos(math.radians(0.25))
    delta = math.degrees(2 * math.asin(math.sqrt((h1 + h2 - h3) / (2 * h2))))  # from h3, well conditioned
    lo, hi = 270.0 - delta, 270.0 + delta
    out = tmp_path / "r.csv"
    for extra in ((), ("--csv", str(out))):
        code, stdout, stderr = _cli(capsys, "reactions", "slider-crank-mass", "--set", f"h3={h3!r}", "--start", "2.5",
                                    *extra)
        assert code == 1
        text = f"gap from input {lo:.10g}° to {hi:.10g}° (loop 'O1ABC' (psi13, p14), between rows 54 and 55)"
        assert f"warning: {text}" in stderr and (extra or text in stdout)
    head, *body = list(csv.reader(open(out)))
    assert all(r[-1] == "converged" for r in body)
    k = [i for i, r in enumerate(body) if r[head.index("gap_from_deg")] != "nan"]
    assert k == [53]
    assert abs(float(body[53][head.index("gap_from_deg")]) - lo) < math.degrees(1e-9)
    assert abs(float(body[53][head.index("gap_to_deg")]) - hi) < math.degrees(1e-9)


@pytest.mark.parametrize("half", [math.radians(0.25), 1e-3, 0.0])
def test_the_certificate_refuses_the_gap(four_bar, half):
    """The searches' certificate (`feasibility.certify`, 72 samples) refuses both gaps and certifies
    the change-point design (half = 0): the same verdict as `branch_points`."""
    import jax
    import jax.numpy as jnp

    from jaxlink.analysis import feasibility
    from jaxlink.solvers import dyads as _dyads

    p = jnp.asarray(_fourbar_p(four_bar, a=A, b=B, c=_gap_c(half) if half else 35.0, d=D))
    dyads = _dyads.classify(four_bar)
    q = jnp.asarray(four_bar.guess)
    phis = jnp.asarray(GAP_PHIS)
    sigma = _dyads.solve_nearest(four_bar, dyads, q, phis[0], p)[3]
    cert = jax.jit(lambda pp: feasibility.certify(four_bar, dyads, sigma, q, phis, pp))(p)
    assert float(cert.sampled) > 0
    assert bool(cert.certified) == (half == 0.0)
    if half:
        assert abs(float(cert.where) - math.pi) < 1e-6
