"""Exact gradients by implicit differentiation against central finite differences (float64)."""

import jax
import jax.numpy as jnp
import numpy as np

import jaxlink as jl


def _feed_path_objective(mech, phis):
    iz = 0

    def f(p):
        sol = jl.solve_path(mech, phis, p)
        tr = jl.transfer(mech, phis, sol.q, p, order=0)
        xy = tr.points[:, iz]
        # a path objective: spread of the path around its centre plus a tilt term
        c = jnp.mean(xy, axis=0)
        return jnp.sum((xy - c) ** 2) * 1e6 + 1e3 * (xy[10, 0] - xy[40, 0])

    return f


def test_feed_path_gradient_matches_central_differences():
    mech = jl.load("sewing-feed")
    phis = jnp.asarray(np.deg2rad(75.0 + 5.0 * np.arange(72)))
    f = _feed_path_objective(mech, phis)
    p = jnp.asarray(mech.parameters)
    g = np.asarray(jax.jit(jax.grad(f))(p))
    names = ("l2", "l22", "gamma", "l3", "l5")
    for name in names:
        i = mech.parameter_index(name)
        h = 1e-6 * (1.0 if mech.parameter_kinds[i] == "angle" else 0.01)
        e = np.zeros_like(mech.parameters)
        e[i] = h
        # 4th-order central difference, so that truncation error is far below 1e-6
        fd = (-f(p + 2 * e) + 8 * f(p + e) - 8 * f(p - e) + f(p - 2 * e)) / (12 * h)
        assert abs(g[i] - float(fd)) <= 1e-6 * abs(float(fd)), (name, g[i], float(fd))


def test_forward_and_reverse_mode_agree():
    mech = jl.load("four-bar")
    phis = jnp.asarray(np.deg2rad(np.arange(0.0, 360.0, 10.0)))
    f = lambda p: jnp.sum(jl.solve_path(mech, phis, p).q[:, 1] ** 2)  # noqa: E731
    p = jnp.asarray(mech.parameters)
    rev = jax.grad(f)(p)
    fwd = jax.jacfwd(f)(p)
    np.testing.assert_allclose(np.asarray(rev), np.asarray(fwd), rtol=1e-12, atol=1e-12)


def test_gradient_wrt_input_is_the_velocity():
    """d q / d phi through the implicit JVP equals the transfer function mu."""
    mech = jl.load("sewing-feed")
    phis = jnp.asarray(np.deg2rad(75.0 + 5.0 * np.arange(8)))
    p = jnp.asarray(mech.parameters)
    q, dq = jax.jvp(lambda ph: jl.solve_path(mech, ph, p).q, (phis,), (jnp.ones_like(phis),))
    tr = jl.transfer(mech, phis, q, p, order=1)
    np.testing.assert_allclose(np.asarray(dq), np.asarray(tr.mu), rtol=1e-12, atol=1e-12)


def test_non_converged_positions_get_zero_gradient_not_nan():
    mech = jl.load("four-bar", overrides={"a": 40.0})  # non-Grashof: part of the turn unreachable
    phis = jnp.asarray(np.deg2rad(np.arange(0.0, 360.0, 10.0)))
    f = lambda p: jnp.sum(jl.solve_path(mech, phis, p).q)  # noqa: E731
    g = jax.grad(f)(jnp.asarray(mech.with_parameters(a=40.0)))
    assert np.all(np.isfinite(np.asarray(g)))
