"""Control over what XLA recomputes: `materialize`.

XLA fuses elementwise producers into each of their consumers, and on the CPU backend it
recomputes a fused producer for every element of every consumer kernel. A `sin` of the (N,)
input angles read by ten (designs × angles) kernels is then evaluated ten times per position
(`jax.lax.optimization_barrier` does not prevent this on CPU: it is removed before fusion).
`materialize` routes values through a one-trip `while_loop` whose trip count XLA cannot know at
compile time, so they are computed once, stored, and read by every consumer — measured 2.6× on the
feed six-bar's closed-form solve (benchmarks/throughput.py; docs/numbers.md, "Feed six-bar
throughput").

The loop runs exactly once (its trip count is 1 unless the probe value is NaN, when it runs zero
times) and multiplies by exactly 1, so the values are unchanged bit for bit. Use it on values
that are cheap to store and expensive to recompute (trigonometry of inputs and parameters).
Reverse-mode differentiation cannot pass through a `while_loop`: use it only where no gradient
flows (the primal of a `custom_jvp`, as in the solver).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def materialize(tree):
    """`tree` unchanged, but computed once and stored (not fused into its consumers)."""
    leaves = [x for x in jax.tree_util.tree_leaves(tree) if jnp.size(x) > 0]
    if not leaves:
        return tree
    # a floating probe: `x == x` of an integer is provably true, and XLA would remove the loop
    floats = [x for x in leaves if jnp.issubdtype(x.dtype, jnp.floating)]
    probe = jnp.ravel((floats or leaves)[0])[0]
    trips = (probe == probe).astype(jnp.int32)  # 1 (0 for NaN): unknown to the compiler

    def body(state):
        i, t = state
        one = jnp.where(i >= 0, 1, 2)  # 1 at run time; not provably 1 at compile time
        return i + 1, jax.tree_util.tree_map(lambda v: v * one.astype(v.dtype), t)

    return jax.lax.while_loop(lambda s: s[0] < trips, body, (jnp.zeros((), jnp.int32), tree))[1]



def batched_like(tree, *refs):
    """`tree` unchanged in value, but batched wherever any of `refs` is (under `jax.vmap`).

    A `while_loop` or `scan` under `vmap` finds which of its carries are batched by a fixpoint:
    it batches the body, and again whenever a carry that started unbatched (a zero counter, a
    flag) comes out batched, and once more for a batched predicate. Nested loops multiply those
    passes (the continuation solver's loops nest four deep). Starting every carry batched makes
    the first pass the last one: `jnp.where(r == r, x, x)` is x, batched like r, and XLA removes
    the select. Measured on a triad's continuation solve under vmap: lowering 4.3 s → 1.9 s."""
    leaves = [jnp.ravel(r)[0] for r in jax.tree_util.tree_leaves(refs) if jnp.size(r) > 0]
    if not leaves:
        return tree
    flag = leaves[0] == leaves[0]
    for r in leaves[1:]:
        flag = flag & (r == r)
    return jax.tree_util.tree_map(lambda x: jnp.where(flag, x, x), tree)
