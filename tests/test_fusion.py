"""`solvers.fusion.materialize`: the values unchanged, and stored (a loop XLA cannot remove) even
when the first value is an integer array — the regression that let the gradient of a batched
solve recompute the closed form in every kernel of its derivative (2.6× slower at 1e4 designs)."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxlink.solvers.fusion import materialize


def _compiled(f, *args):
    return jax.jit(f).lower(*args).compile().as_text()


def test_values_unchanged_bit_for_bit():
    x = jnp.asarray(np.random.default_rng(0).normal(size=(3, 4)))
    code = jnp.arange(12, dtype=jnp.int8).reshape(3, 4)
    out = jax.jit(lambda c, v: materialize((c, jnp.sin(v), {"nan": v * jnp.nan})))(code, x)
    assert np.array_equal(out[0], code) and np.array_equal(out[1], np.sin(np.asarray(x)))
    assert np.all(np.isnan(out[2]["nan"]))


def test_the_loop_survives_compilation_with_an_integer_first_value():
    x = jnp.linspace(0.0, 1.0, 360)

    def f(x):
        code, s = materialize(((x > 0.5).astype(jnp.int8), jnp.sin(x)))
        return code.astype(x.dtype) + s * 2.0 + jnp.cos(s)

    assert " while(" in _compiled(f, x)
    # the same under vmap (a batched loop)
    assert " while(" in _compiled(jax.vmap(f), jnp.stack([x, x]))
