"""A closed-form batch on the CPU in chunks of designs (`lax.map`), so that its intermediate arrays
stay in the cache; the answers do not depend on the chunk, bit for bit."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .fusion import materialize

#: positions per chunk of a closed-form batch on the CPU (`_design_chunk`): its intermediate arrays
#: (≈ 70 of 8 bytes per position for the Strider) stay within the cache (measured on the Strider:
#: 8192 to 32768 alike). 0: never chunk
CHUNK_POSITIONS = 8192


def _design_chunk(B: int, N: int, n_dyads: int = 2) -> int:
    """Designs per chunk of a closed-form batch of B designs × N positions, or 0 for one piece:
    about `CHUNK_POSITIONS` positions, a divisor of B where one is near (no padding), at least 2
    designs (XLA fuses a batch of one design differently: other kernels, other roundings). Only
    for two dyads or more (one dyad's few intermediate arrays cost less than the loop: the
    four-bar's batch 8 % slower in chunks), and on a single CPU device (a GPU wants the whole
    batch, and a batch sharded over several devices is split by them)."""
    if (not CHUNK_POSITIONS or n_dyads < 2 or jax.default_backend() != "cpu"
            or jax.device_count() != 1):
        return 0
    target = max(2, CHUNK_POSITIONS // max(N, 1))
    if B < 2 * target:
        return 0
    for c in range(target, max(2, target // 2) - 1, -1):
        if B % c == 0:
            return c
    return target


def _map_designs(fn, args, axes, chunk: int):
    """`fn(*args)` over the leading (design) axis of the `args` (pytrees) whose axis is 0 (the
    others are shared), `chunk` designs at a time (`lax.map`; 0: all at once). The last chunk is
    padded by repeating the last design, and the results cut back to the batch."""
    if not chunk:
        return fn(*args)
    B = jax.tree_util.tree_leaves([a for a, x in zip(args, axes) if x == 0])[0].shape[0]
    n = -(-B // chunk)
    pad = n * chunk - B

    def split(a):
        if pad:
            a = jnp.concatenate([a, jnp.broadcast_to(a[-1:], (pad,) + a.shape[1:])])
        return a.reshape((n, chunk) + a.shape[1:])

    batched = [jax.tree_util.tree_map(split, a) for a, x in zip(args, axes) if x == 0]

    def one(xs):
        # the chunk's inputs copied first: read through the loop's slice instead, every kernel of
        # the chunk indexes them afresh, which XLA does not vectorize (and fuses differently: the
        # four-bar's points changed in the last bit, and took 2.5× as long)
        xs = materialize(xs)
        it = iter(xs)
        return fn(*(next(it) if x == 0 else a for a, x in zip(args, axes)))

    out = jax.lax.map(one, batched)
    return jax.tree_util.tree_map(lambda o: o.reshape((n * chunk,) + o.shape[2:])[:B], out)
