"""`jaxlink.solvers.angles.atan2` (the closed form's vectorized atan2) against numpy's C-library
`arctan2`: within 2 ulp everywhere, the same special values, the exact derivative."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlink.solvers.angles import atan2


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
