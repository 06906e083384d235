"""The screen's sorting network (`jaxlink.synthesis.sortnet`) against `jnp.sort`: the same values in
the same order, bit for bit, on random rows with ties, for the screen's 32 and other lengths; and the
network itself sorts every 0/1 input of up to 12 values (the 0–1 principle: then it sorts any input)."""

from __future__ import annotations

import itertools

import jax.numpy as jnp
import numpy as np

from jaxlink.synthesis.sortnet import pairs, sort_last


def test_sort_last_equals_jnp_sort():
    rng = np.random.default_rng(0)
    for n in (1, 2, 3, 7, 16, 31, 32, 33):
        x = rng.normal(size=(500, n)).astype(np.float32)
        x[:100, : n // 2] = x[:100, -1:]  # ties
        x[100:150] = -0.0  # signed zeros: min/max keep the values jnp.sort orders
        got, want = np.asarray(sort_last(jnp.asarray(x))), np.asarray(jnp.sort(jnp.asarray(x), axis=-1))
        assert np.array_equal(got, want), n


def test_network_sorts_every_zero_one_input():
    for n in range(1, 13):
        x = np.array(list(itertools.product([0, 1], repeat=n)))
        for a, b in pairs(n):
            x[:, a], x[:, b] = np.minimum(x[:, a], x[:, b]), np.maximum(x[:, a], x[:, b])
        assert np.all(np.diff(x, axis=1) >= 0), n
