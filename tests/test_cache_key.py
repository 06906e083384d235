"""The stored traces' key, input by input (jaxlink/cache.py), in-process and cheap: a program
stored for one call and loaded back from disk (the in-process memo emptied, as in a new process)
gives the answer of the plain `jax.jit` for a call that differs in one thing — a leaf's value, a
static option, a dtype, the arguments' structure — and the check fails on a key that leaves one
of them out. The commands end to end: tests/test_cache_differential.py."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxlink
from jaxlink import cache

jax.config.update("jax_enable_x64", True)


def _poly(x, y, power):
    return (x**power + 2.0 * y,)


def _pair(t, power):
    return (t[0] ** power - t[1],)


CALLS = [  # (name, fun, args, static): one change at a time after the first
    ("poly", _poly, (np.array([1.5, 2.0]), np.array(3.0)), (2,)),
    ("poly", _poly, (np.array([0.5, 4.0]), np.array(-1.0)), (2,)),            # leaf values
    ("poly", _poly, (np.array([0.5, 4.0]), np.array(-1.0)), (3,)),            # a static option
    ("poly", _poly, (np.array([0.5, 4.0], np.float32), np.array(-1.0, np.float32)), (3,)),  # the dtype
    ("poly", _pair, ((np.array([0.5, 4.0]), np.array(-1.0)),), (3,)),          # another function, structure
]


def _mismatches() -> list:
    """Each call through a stored trace (stored, then loaded from disk) against `jax.jit`."""
    assert jax.config.jax_compilation_cache_dir, "the suite's conftest turns the cache on"
    bad = []
    for i, (name, fun, args, static) in enumerate(CALLS):
        cache._LOADED.clear()  # a new process: load from the stored file
        got = cache.traced(f"test-key-{name}", fun, args, static)[0]
        want = jax.jit(fun, static_argnums=len(args))(*args, *static)[0]
        if got.dtype != want.dtype or not np.array_equal(np.asarray(got), np.asarray(want)):
            bad.append(i)
    return bad


def test_each_input_reaches_the_key():
    assert _mismatches() == []


def test_a_key_without_the_static_options_or_the_structure_fails(monkeypatch):
    real = cache.key_text
    monkeypatch.setattr(cache, "key_text", lambda name, fun, treedef, static, leaves:
                        real(name + "-blind", _poly, jax.tree_util.tree_structure(()), (), leaves))
    assert _mismatches() != []


def test_a_function_with_a_closure_is_refused():
    k = 3.0
    with pytest.raises(TypeError, match="without a closure"):
        cache.traced("closure", lambda x: (x * k,), (np.ones(2),))


def test_a_mechanism_argument_keeps_its_guesses_as_inputs():
    """A mechanism passed as an argument: its guesses are leaves, so two guesses (the two
    branches of a four-bar) give their own answers through one stored program."""
    mech = jaxlink.load("four-bar")
    other = mech.replace(guess=-np.asarray(mech.guess))
    cache._LOADED.clear()
    a = cache.traced("test-key-guess", _guess, (mech,))[0]
    cache._LOADED.clear()
    b = cache.traced("test-key-guess", _guess, (other,))[0]
    np.testing.assert_array_equal(a, 2.0 * jnp.asarray(mech.guess))
    np.testing.assert_array_equal(b, -2.0 * jnp.asarray(mech.guess))


def _guess(m):
    return (2.0 * m.guess,)
