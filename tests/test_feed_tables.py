"""sewing-feed against seed 000 Tables 1-3, 11.1, 12.1 (transcribed in tests/data) and the
independent reference CSV (tests/data/reference/feed_original_2500rpm.csv)."""

import pathlib

import numpy as np
import pytest

import jaxlink as jl

DATA = pathlib.Path(__file__).parent / "data"
REF = pathlib.Path(__file__).resolve().parent / "data" / "reference" / "feed_original_2500rpm.csv"


def _feed(overrides=None, omega=1.0, start=75.0, count=73, step=5.0):
    mech = jl.load("sewing-feed", overrides=overrides)
    phis = np.deg2rad(start + step * np.arange(count))
    sol = jl.solve(mech, phis)
    assert bool(np.all(sol.converged))
    tr = jl.transfer(mech, phis, sol.q, mech.parameters)
    _, _, v, a = jl.time_derivatives(tr, omega)
    return mech, sol, np.asarray(tr.points[:, 0]), np.asarray(v[:, 0]), np.asarray(a[:, 0])


@pytest.mark.parametrize(
    "table, omega, speed_tol_mm_s, excluded",
    [
        ("seed000_table1_2500rpm.csv", 261.8, 0.75, ()),
        ("seed000_table2_3500rpm.csv", 366.5, 1.8, (170.0,)),  # 170°: the seed prints 3519.17 for 3319.49
        ("seed000_table3_4500rpm.csv", 471.2, 1.35, ()),
    ],
)
def test_original_design_tables_1_to_3(table, omega, speed_tol_mm_s, excluded):
    # The seed solved with a loose fsolve tolerance (its own rows at 75° and 435° differ by
    # 0.29 mm/s), so agreement is to its printed digits within that looseness (spec §1).
    t = np.loadtxt(DATA / table, delimiter=",", skiprows=2)
    _, _, xy, v, a = _feed(omega=omega)
    assert np.allclose(t[:, 1], 75.0 + 5.0 * np.arange(73))
    r_mm = np.hypot(xy[:, 0], xy[:, 1]) * 1e3
    speed = np.hypot(v[:, 0], v[:, 1]) * 1e3
    acc = np.hypot(a[:, 0], a[:, 1]) / 1e3  # the seed's unit: 1e6 mm/s² = 1000 m/s²
    keep = ~np.isin(t[:, 1], excluded)
    assert np.max(np.abs(r_mm - t[:, 2])) <= 0.0085
    assert np.max(np.abs(speed - t[:, 3])[keep]) <= speed_tol_mm_s
    assert np.max(np.abs(acc - t[:, 4]) / t[:, 4]) <= 6e-4
    # the typo is real: our value is the 3319.49 the seed's own ch. 9 text quotes
    if excluded:
        row = np.flatnonzero(~keep)[0]
        assert abs(speed[row] - 3319.49) < 0.5 and abs(t[row, 3] - 3519.17) < 1e-9


def test_reference_csv_to_1e9():
    ref = np.loadtxt(REF, delimiter=",", comments="#", skiprows=5)
    mech = jl.load("sewing-feed")
    phis = np.deg2rad(ref[:, 0])
    sol = jl.solve(mech, phis)
    tr = jl.transfer(mech, phis, sol.q, mech.parameters)
    qd, qdd, v, a = jl.time_derivatives(tr, 261.8)
    q = np.asarray(sol.q)
    # angles agree modulo 2π; the CSV prints 10 significant digits
    dq = np.angle(np.exp(1j * (q - ref[:, 1:5])))
    assert np.max(np.abs(dq) / np.abs(ref[:, 1:5])) < 1e-9
    ours = np.concatenate([np.asarray(qd), np.asarray(qdd), np.asarray(tr.points[:, 0]),
                           np.asarray(v[:, 0]), np.asarray(a[:, 0])], axis=1)
    theirs = ref[:, 5:19]
    scale = np.maximum(np.abs(theirs), 1e-3 * np.abs(theirs).max(axis=0))
    assert np.max(np.abs(ours - theirs) / scale) < 1e-9


def test_optimized_design_tables_11_1_and_12_1():
    sets = {"l2": 2.0, "l22": 1.0, "gamma": -10.0}
    _, _, xy, v, a = _feed(overrides=sets, omega=575.0)
    t11 = np.loadtxt(DATA / "seed000_table11_1.csv", delimiter=",", skiprows=2)
    ours11 = np.column_stack([xy[:, 0] * 1e3, xy[:, 1] * 1e3, np.hypot(*v.T), v[:, 0], v[:, 1],
                              np.hypot(*a.T), a[:, 0], a[:, 1]])
    assert np.max(np.abs(ours11 - t11[:, 1:])) <= 0.0051  # 2 decimals: rounding

    t12 = np.loadtxt(DATA / "seed000_table12_1.csv", delimiter=",", skiprows=2)
    rows = np.searchsorted(75.0 + 5.0 * np.arange(73), t12[:, 0])
    assert np.max(np.abs(xy[rows] - t12[:, 1:3])) <= 5.01e-5
    assert np.max(np.abs(v[rows] - t12[:, 3:5])) <= 1e-4
    assert np.max(np.abs(a[rows, 0] - t12[:, 5])) <= 0.07
    typo = t12[:, 0] == 295.0  # the seed prints a_y = +424.4520 for -424.4446
    assert np.max(np.abs(a[rows, 1] - t12[:, 6])[~typo]) <= 0.01
    assert abs(a[rows, 1][typo][0] + t12[typo, 6][0]) < 0.01
