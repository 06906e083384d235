"""Sorting a short axis by a fixed network of compare-exchanges (Batcher's bitonic sort), layer by
layer: the same values in the same order as `jnp.sort` (a minimum and a maximum are exact). Each
layer pairs every position i with i XOR j — a reshape and a reversal, no gather — so the network is
log₂n (log₂n + 1) / 2 elementwise steps over the whole batch (15 for 32 values).

The screen sorts millions of 32-value descriptors (`screening._screen`). Measured 2026-11-25 on 8192 ×
64 rows of 32 float32 values, 2 cores: XLA's CPU sort 1.3 s, this network along the leading axis
0.47 s (compiled in 0.2 s); an unrolled odd–even merge network over 32 separate columns ran in
0.18 s but took 2.6 s to compile, which a cold search pays."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np


def sort_first(x):
    """`jnp.sort(x, axis=0)` for a short leading axis (NaN-free input: NaN order differs from
    jnp.sort). Padded with +inf to a power of two (a float input)."""
    n = x.shape[0]
    m = 1 << max(n - 1, 0).bit_length()
    rest = x.shape[1:]
    if m != n:
        x = jnp.concatenate([x, jnp.full((m - n,) + rest, jnp.inf, x.dtype)], 0)
    i = np.arange(m).reshape((m,) + (1,) * len(rest))
    k = 2
    while k <= m:
        j = k // 2
        while j >= 1:
            partner = x.reshape((m // (2 * j), 2, j) + rest)[:, ::-1].reshape((m,) + rest)  # position i ^ j
            lower = ((i & j) == 0) == ((i & k) == 0)  # keeps the smaller of the pair (ascending blocks)
            x = jnp.where(lower, jnp.minimum(x, partner), jnp.maximum(x, partner))
            j //= 2
        k *= 2
    return x[:n]


def sort_last(x):
    """`jnp.sort(x, axis=-1)` by `sort_first` (the rows moved to the leading axis and back)."""
    return jnp.moveaxis(sort_first(jnp.moveaxis(x, -1, 0)), 0, -1)
