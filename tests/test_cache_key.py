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
import jaxlink.scenes
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


def _mismatches(clear: bool = True) -> list:
    """Each call through a stored trace (stored, then loaded from disk; with `clear` False, one
    after the other in this process, through the in-process memo) against `jax.jit`."""
    assert jax.config.jax_compilation_cache_dir, "the suite's conftest turns the cache on"
    bad = []
    cache._LOADED.clear()
    for i, (name, fun, args, static) in enumerate(CALLS):
        if clear:
            cache._LOADED.clear()  # a new process: load from the stored file
        try:
            got = cache.traced(f"test-key-{name}", fun, args, static)[0]
        except Exception:  # noqa: BLE001 (a program of another call refusing these arguments)
            bad.append(i)
            continue
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


def test_the_in_process_memo_keys_each_input():
    """The calls one after the other in one process (the memo kept): each gets its own answer;
    and a memo key without the static options or the structure fails the same check."""
    assert _mismatches(clear=False) == []


def test_an_in_process_memo_key_without_static_options_or_structure_fails(monkeypatch):
    monkeypatch.setattr(cache, "_fast_key", lambda name, fun, treedef, static, leaves:
                        ("blind", tuple(np.shape(a) for a in leaves)))
    assert _mismatches(clear=False) != []


def test_the_in_process_memo_tells_two_structures_with_the_same_shapes_apart():
    """Two mechanisms whose numbers have the same shapes but whose loops differ (the frame vector
    of the other sign): one after the other in this process, each its own residual."""
    text = (jaxlink.scenes.SCENE_DIR / "four-bar.toml").read_text()
    a = jaxlink.loads(text)
    b = jaxlink.loads(text.replace('"-d @ 0"', '"d @ 180"'))
    c = jaxlink.loads(text.replace('"-d @ 0"', '"-d @ 10"'))
    assert a.structure != c.structure and a.parameters.shape == c.parameters.shape
    cache._LOADED.clear()
    got = [np.asarray(cache.traced("test-key-residual", _residual, (m,))[0]) for m in (a, b, c)]
    want = [np.asarray(m.residual(m.guess, m.input_start, m.parameters)) for m in (a, b, c)]
    for g, w in zip(got, want):
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-15)
    assert np.abs(got[0] - got[2]).max() > 1e-3


def _residual(m):
    return (m.residual(m.guess, m.input_start, m.parameters),)


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
