"""Four-bar (Freudenstein, both branches) and offset slider-crank (closed form), float64 to 1e-12
over a full revolution, float32 to its precision; velocities/accelerations against finite
differences of the closed forms."""

import jax.numpy as jnp
import numpy as np
import pytest
from closed_forms import fourbar_freudenstein, slider_crank_offset

import jaxlink as jl


def _wrap(x):
    return np.angle(np.exp(1j * np.asarray(x, dtype=float)))


METHODS = ["closed_form", "continuation"]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("branch", [+1, -1])
def test_fourbar_both_branches_float64(branch, method):
    mech = jl.load("four-bar")
    a, b, c, d = (mech.parameters[mech.parameter_index(n)] for n in "abcd")
    phis = np.deg2rad(np.arange(0.0, 360.0, 1.0))
    phi3, phi4 = fourbar_freudenstein(a, b, c, d, phis, branch)
    q0 = np.array([phi3[0], phi4[0]])  # start on this branch; continuation must stay on it
    sol = jl.solve(mech, phis, mech.parameters, q0, options=jl.NewtonOptions(method=method))
    assert bool(np.all(sol.converged))
    err = np.abs(_wrap(np.asarray(sol.q) - np.stack([phi3, phi4], 1)))
    assert err.max() < 1e-12


def test_file_guess_selects_branch():
    mech = jl.load("four-bar")
    a, b, c, d = (mech.parameters[mech.parameter_index(n)] for n in "abcd")
    phis = np.deg2rad(np.arange(0.0, 360.0, 5.0))
    sol = jl.solve(mech, phis)
    up = np.stack(fourbar_freudenstein(a, b, c, d, phis, +1), 1)
    down = np.stack(fourbar_freudenstein(a, b, c, d, phis, -1), 1)
    e_up = np.abs(_wrap(np.asarray(sol.q) - up)).max()
    e_down = np.abs(_wrap(np.asarray(sol.q) - down)).max()
    assert min(e_up, e_down) < 1e-12 and max(e_up, e_down) > 0.1


@pytest.mark.parametrize("method", METHODS)
def test_slider_crank_float64(method):
    mech = jl.load("slider-crank")
    P = {n: mech.parameters[mech.parameter_index(n)] for n in mech.parameter_names}
    phis = np.deg2rad(np.arange(0.0, 360.0, 2.0))
    psi13, p14 = slider_crank_offset(P["h1"], P["alpha1"], P["h2"], P["h3"], P["alpha4"], phis)
    sol = jl.solve(mech, phis, options=jl.NewtonOptions(method=method))
    assert bool(np.all(sol.converged))
    q = np.asarray(sol.q)
    assert np.abs(_wrap(q[:, 0] - psi13)).max() < 1e-12
    assert np.abs(q[:, 1] - p14).max() < 1e-12 * P["h3"] / 0.08  # metres, ≈ 1e-12 relative


def test_slider_crank_velocity_acceleration_match_closed_form_derivatives():
    mech = jl.load("slider-crank")
    P = {n: mech.parameters[mech.parameter_index(n)] for n in mech.parameter_names}
    phis = np.deg2rad(np.arange(0.0, 360.0, 10.0))
    sol = jl.solve(mech, phis)
    tr = jl.transfer(mech, phis, sol.q, mech.parameters)
    omega = 100.0
    qd, qdd, _, _ = jl.time_derivatives(tr, omega)
    h = 1e-4
    f = lambda x: slider_crank_offset(P["h1"], P["alpha1"], P["h2"], P["h3"], P["alpha4"], x)[1]  # noqa: E731
    dp = (f(phis + h) - f(phis - h)) / (2 * h) * omega
    ddp = (f(phis + h) - 2 * f(phis) + f(phis - h)) / h**2 * omega**2
    assert np.abs(np.asarray(qd[:, 1]) - dp).max() < 1e-7 * np.abs(dp).max()
    assert np.abs(np.asarray(qdd[:, 1]) - ddp).max() < 1e-5 * np.abs(ddp).max()


@pytest.mark.parametrize("method", METHODS)
def test_float32_agrees_to_its_precision(method):
    mech = jl.load("four-bar")
    a, b, c, d = (mech.parameters[mech.parameter_index(n)] for n in "abcd")
    phis = np.deg2rad(np.arange(0.0, 360.0, 5.0))
    sol = jl.solve(mech, phis.astype(np.float32), jnp.asarray(mech.parameters, dtype=jnp.float32),
                   options=jl.NewtonOptions(method=method))
    assert sol.q.dtype == jnp.float32
    assert bool(np.all(sol.converged))
    ref = np.stack(fourbar_freudenstein(a, b, c, d, phis, -1), 1)  # the branch of the file's guess
    err = np.abs(_wrap(np.asarray(sol.q, dtype=float) - ref)).max()
    assert err < 2e-6  # float32 eps 1.2e-7, times the Jacobian's condition number


@pytest.mark.parametrize("scene", ["sewing-feed", "needle-arachne", "needle-arachne-original", "slider-crank"])
def test_closed_form_dyads_equal_newton_continuation(scene):
    """The closed-form dyad path and Newton with continuation give the same configuration (same
    branch) over a revolution, for the file's design and for perturbed designs in one batch."""
    mech = jl.load(scene)
    phis = np.deg2rad(np.arange(0.0, 360.0, 3.0))
    rng = np.random.default_rng(1)
    P = mech.parameters[None] * (1 + 0.002 * rng.standard_normal((4, len(mech.parameters))))
    P[0] = mech.parameters
    a = jl.solve(mech, phis, P, options=jl.NewtonOptions(method="closed_form"))
    b = jl.solve(mech, phis, P, options=jl.NewtonOptions(method="continuation"))
    both = np.asarray(a.converged) & np.asarray(b.converged)
    assert both[0].all() and both.mean() > 0.9
    np.testing.assert_array_equal(np.asarray(a.converged), np.asarray(b.converged))
    d = np.asarray(a.q) - np.asarray(b.q)
    ang = [i for i, k in enumerate(mech.unknown_kinds) if k == "angle"]
    d[..., ang] = _wrap(d[..., ang])
    assert np.abs(d[both]).max() < 1e-12
