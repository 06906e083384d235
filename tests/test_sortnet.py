"""The screen's sorting network (`jaxlink.synthesis.sortnet`) against `jnp.sort`: the same values in
the same order, bit for bit, on random rows with ties, for the screen's 32 and other lengths (padded
ones included); and it sorts every 0/1 input of 7 and of 12 values (the 0–1 principle: a
compare-exchange network that sorts those sorts any input)."""

from __future__ import annotations

import itertools

import jax
import jax.numpy as jnp
import numpy as np

from jaxlink.synthesis.sortnet import sort_first, sort_last


def test_sort_equals_jnp_sort():
    rng = np.random.default_rng(0)
    for n in (1, 5, 32, 33):
        x = rng.normal(size=(500, n)).astype(np.float32)
        x[:100, : n // 2] = x[:100, -1:]  # ties
        got, want = np.asarray(jax.jit(sort_last)(x)), np.asarray(jnp.sort(jnp.asarray(x), axis=-1))
        assert np.array_equal(got, want), n
        assert np.array_equal(np.asarray(jax.jit(sort_first)(x.T)), want.T), n


def test_network_sorts_every_zero_one_input():
    for n in (7, 12):  # padded to 8 and to 16
        x = np.array(list(itertools.product([0.0, 1.0], repeat=n)))
        assert np.all(np.diff(np.asarray(jax.jit(sort_last)(x)), axis=1) >= 0), n
