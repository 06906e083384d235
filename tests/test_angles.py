"""`jaxlink.solvers.angles.atan2` and `sincos` (the closed form's vectorized transcendentals)
against numpy's C-library `arctan2`, `cos`, `sin`: within 2 ulp (atan2) and 1 ulp (sincos), the
same special values, the exact derivatives, the C library's own values beyond the reduction's
range."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlink.solvers.angles import SINCOS_MAX, atan2, sincos


def _ulps(a, b):
    return np.abs(a - b) / np.spacing(np.maximum(np.abs(b), np.finfo(float).tiny))


def test_within_two_ulp_of_the_c_library_on_random_and_edge_points():
    rng = np.random.default_rng(1)
    th = np.concatenate([rng.uniform(-np.pi, np.pi, 200_000),
                         # the ratio at the switch points of the reduction (0.66, 1) and the axes
                         np.arctan(np.array([0.66, 0.66 + 1e-15, 0.66 - 1e-15, 1.0, 1 - 1e-15, 1e-8, 1e-300])),
                         np.array([0.0, np.pi / 2, np.pi, -np.pi / 2, 3 * np.pi / 4, -3 * np.pi / 4])])
    r = np.concatenate([rng.uniform(1e-3, 1e3, 200_000), np.ones(13)])
    x, y = r * np.cos(th), r * np.sin(th)
    got = np.asarray(jax.jit(atan2)(jnp.asarray(y), jnp.asarray(x)))
    want = np.arctan2(y, x)
    assert _ulps(got, want).max() <= 2.0
    # and it is not the C library itself: the two differ somewhere (the test can fail)
    assert np.any(got != want)


@pytest.mark.parametrize("y, x", [(0.0, 1.0), (-0.0, 1.0), (0.0, -1.0), (-0.0, -1.0), (1.0, 0.0),
                                  (-1.0, 0.0), (0.0, 0.0), (1e-300, 1.0), (1.0, 1e-300), (np.nan, 1.0),
                                  (1.0, np.nan), (5.0, 5.0), (-5.0, -5.0)])
def test_special_values_as_the_c_library(y, x):
    got = float(atan2(jnp.float64(y), jnp.float64(x)))
    want = float(np.arctan2(y, x))
    if np.isnan(want):
        assert np.isnan(got)
    else:
        assert got == want and np.signbit(got) == np.signbit(want)


def test_float32_within_two_ulp():
    rng = np.random.default_rng(2)
    th = rng.uniform(-np.pi, np.pi, 100_000)
    x, y = np.cos(th).astype(np.float32), np.sin(th).astype(np.float32)
    got = np.asarray(atan2(jnp.asarray(y), jnp.asarray(x)))
    assert got.dtype == np.float32
    want = np.arctan2(y.astype(float), x.astype(float))
    assert (np.abs(got - want) / np.spacing(np.abs(want).astype(np.float32))).max() <= 2.0


def test_derivative_is_exact():
    y, x = jnp.float64(0.3), jnp.float64(-1.7)
    gy, gx = jax.grad(atan2, argnums=(0, 1))(y, x)
    r2 = 0.3 ** 2 + 1.7 ** 2
    assert abs(float(gy) - (-1.7) / r2) < 1e-16 and abs(float(gx) - (-0.3) / r2) < 1e-16


def _ulps_abs(a, b):
    """|a − b| in units of the last place of b (of 1e-300 where b is smaller)."""
    return np.abs(a - b) / np.spacing(np.maximum(np.abs(b), 1e-300))


def test_sincos_within_one_ulp_of_the_c_library():
    rng = np.random.default_rng(3)
    k = np.arange(-40, 41)
    x = np.concatenate([
        rng.uniform(-2 * np.pi, 2 * np.pi, 200_000), rng.uniform(-SINCOS_MAX, SINCOS_MAX, 200_000),
        # at and next to the quadrant boundaries (where the reduced argument is smallest)
        k * (np.pi / 2), np.nextafter(k * (np.pi / 2), np.inf), np.nextafter(k * (np.pi / 2), -np.inf),
        (k + 0.5) * (np.pi / 2), np.array([1e-300, -1e-300, 1e-8, 0.7853981633974483, SINCOS_MAX])])
    c, s = (np.asarray(v) for v in jax.jit(sincos)(jnp.asarray(x)))
    assert _ulps_abs(c, np.cos(x)).max() <= 1.0 and _ulps_abs(s, np.sin(x)).max() <= 1.0
    # and it is not the C library itself: the two differ somewhere (the test can fail)
    assert np.any(c != np.cos(x)) or np.any(s != np.sin(x))


def test_sincos_special_values_and_signed_zero():
    x = jnp.asarray([0.0, -0.0])
    c, s = sincos(x)
    assert np.all(np.asarray(c) == 1.0)
    assert not np.signbit(float(s[0])) and np.signbit(float(s[1]))
    c, s = sincos(jnp.asarray([0.5, np.nan]))
    assert np.isnan(float(c[1])) and np.isnan(float(s[1]))


@pytest.mark.parametrize("beyond", [2 * SINCOS_MAX, 1e300, np.inf])
def test_sincos_beyond_the_range_is_the_c_library(beyond):
    x = np.array([0.3, -2.0, beyond])
    c, s = sincos(jnp.asarray(x))
    assert np.array_equal(np.asarray(c), np.asarray(jnp.cos(jnp.asarray(x))), equal_nan=True)
    assert np.array_equal(np.asarray(s), np.asarray(jnp.sin(jnp.asarray(x))), equal_nan=True)


def test_sincos_float32_and_under_vmap():
    x = np.linspace(-7.0, 7.0, 101)
    c, s = sincos(jnp.asarray(x, np.float32))
    assert c.dtype == np.float32 and np.abs(np.asarray(c) - np.cos(x)).max() < 1e-6
    # a batched argument: the range test is then per row (both evaluated, one selected)
    X = np.stack([x, x + 3 * SINCOS_MAX])
    c, s = jax.vmap(sincos)(jnp.asarray(X))
    assert _ulps_abs(np.asarray(c[0]), np.cos(x)).max() <= 1.0
    assert np.array_equal(np.asarray(s[1]), np.asarray(jnp.sin(jnp.asarray(X[1]))))


def test_sincos_derivative_is_exact():
    x = jnp.float64(2.2)
    dc, ds = jax.jacfwd(lambda t: jnp.stack(sincos(jnp.atleast_1d(t))))(x)[:, 0]
    assert float(dc) == -float(jnp.sin(x)) or abs(float(dc) + np.sin(2.2)) <= 1.2e-16
    assert abs(float(ds) - np.cos(2.2)) <= 1.2e-16
    g = jax.grad(lambda t: jnp.sum(sincos(t)[1] ** 2))(jnp.asarray([0.4, 1.3]))
    assert np.allclose(np.asarray(g), np.sin(2 * np.array([0.4, 1.3])), rtol=0, atol=4e-16)
