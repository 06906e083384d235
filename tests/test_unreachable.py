"""Unreachable positions are flagged with a result code; the rest of the batch is unaffected."""

import numpy as np
from closed_forms import fourbar_freudenstein

import jaxlink as jl


def _wrap(x):
    return np.angle(np.exp(1j * np.asarray(x, dtype=float)))


def test_non_grashof_fourbar_flags_unreachable_positions():
    # |A - B0| ranges over [d - a, d + a] = [35, 75] mm but the dyad reaches only up to b + c = 70:
    # the crank cannot turn through phi2 = 180° (non-Grashof)
    mech = jl.load("four-bar", overrides={"b": 40.0, "c": 30.0})  # b + c = 70 < a + d = 75
    a, b, c, d = 0.020, 0.040, 0.030, 0.055
    phis = np.deg2rad(np.arange(0.0, 360.0, 2.0))
    dist = np.hypot(d - a * np.cos(phis), -a * np.sin(phis))
    reachable = (dist <= b + c) & (dist >= abs(b - c))
    assert 0 < reachable.sum() < len(phis)
    # start in the reachable range, on the branch of a closed form
    start = int(np.flatnonzero(reachable & (phis > np.pi / 2))[0])
    order = np.roll(np.arange(len(phis)), -start)
    ph = phis[order]
    phi3, phi4 = fourbar_freudenstein(a, b, c, d, ph[:1], -1)
    sol = jl.solve(mech, ph, mech.parameters, np.array([phi3[0], phi4[0]]))
    conv = np.asarray(sol.converged)
    codes = np.asarray(sol.result)
    r = reachable[order]
    # every unreachable position is flagged "cannot assemble", never converged
    assert not conv[~r].any()
    assert np.all(codes[~r] == jl.RESULTS.cannot_assemble)
    # outputs are finite everywhere
    assert np.all(np.isfinite(np.asarray(sol.q)))
    # reachable positions before the first failure are exact on the start branch
    first_fail = int(np.argmax(~r))
    ref = np.stack(fourbar_freudenstein(a, b, c, d, ph[:first_fail], -1), 1)
    assert np.abs(_wrap(np.asarray(sol.q)[:first_fail] - ref)).max() < 1e-12


def test_bad_designs_do_not_poison_the_batch():
    mech = jl.load("sewing-feed")
    phis = np.deg2rad(np.arange(0.0, 360.0, 5.0))
    good = mech.parameters
    nan = good.copy()
    nan[mech.parameter_index("l3")] = np.nan
    short = mech.with_parameters(l3=5.0)  # cannot be assembled anywhere
    batch = np.stack([good, nan, short, good])
    sol = jl.solve(mech, phis, batch)
    alone = jl.solve(mech, phis, good)
    conv = np.asarray(sol.converged)
    assert conv[0].all() and conv[3].all()
    assert not conv[1].any() and not conv[2].any()
    assert np.all(np.asarray(sol.result)[1] == jl.RESULTS.nonfinite)
    assert np.all(np.asarray(sol.result)[2] == jl.RESULTS.cannot_assemble)
    np.testing.assert_allclose(np.asarray(sol.q[0]), np.asarray(alone.q), rtol=1e-13, atol=1e-13)
    assert np.all(np.isfinite(np.asarray(sol.q)[[0, 2, 3]]))
