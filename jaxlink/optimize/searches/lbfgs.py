"""What both gradient searches share: the map from the box to unbounded variables, and optax's
L-BFGS run per start.

- **Bounds.** A normalized design u ∈ [0, 1]^V is reached from unbounded variables v by
  u = (1 − cos πv)/2 (smooth, every v lands inside the box); back, v = arccos(1 − 2u)/π.
- **L-BFGS.** The search direction of every start is d = −H g from optax's `scale_by_lbfgs`
  (the two-loop recursion over the `memory` latest curvature pairs s = Δv, y = Δg, with the
  initial inverse Hessian (s·y / y·y) I of the latest pair), vmapped over the starts. Its state
  remembers the point it last saw (`params`, `updates`): one `update(g, state, v)` stores the
  pair (v − params, g − updates) and returns H g. A pair with s = 0 gets the weight 0 and
  changes no direction; `anchored` uses that to move the remembered point without a pair.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optax


def u_of_v(v):
    """Unbounded variables → normalized design in [0, 1]^V: u = (1 − cos πv)/2 (traceable)."""
    return 0.5 - 0.5 * jnp.cos(jnp.pi * v)


def v_of_u(u):
    """Normalized design → unbounded variables: v = arccos(1 − 2u)/π ∈ [0, 1] (numpy)."""
    return np.arccos(np.clip(1.0 - 2.0 * np.asarray(u), -1.0, 1.0)) / np.pi


def transform(memory: int) -> optax.GradientTransformation:
    return optax.scale_by_lbfgs(memory_size=int(memory))


def to_numpy(tree):
    return jax.tree_util.tree_map(np.asarray, tree)


def initial(memory: int, starts: int, n_variables: int):
    """The L-BFGS state of `starts` starts (numpy leaves, leading axis = starts)."""
    return to_numpy(jax.vmap(transform(memory).init)(jnp.zeros((starts, n_variables))))


def directions(ev, memory: int):
    """Compiled (g (S, V), state, v (S, V)) → (−H g, state after storing each start's pair);
    cached on the evaluator."""

    def build():
        tx = transform(memory)

        def one(g, state, v):
            d, state = tx.update(g, state, v)
            return -d, state

        return jax.jit(jax.vmap(one))

    return ev.compiled(("lbfgs.directions", int(memory)), build)


def select(mask, new, old):
    """Per start: the leaves of `new` where `mask` (S,), else those of `old`."""
    mask = np.asarray(mask)
    return jax.tree_util.tree_map(
        lambda a, b: np.where(mask.reshape((-1,) + (1,) * (np.ndim(a) - 1)), np.asarray(a), np.asarray(b)), new, old)


def anchored(state, v, g):
    """The state remembering the point (v, g): its next `update` at (v, g) stores no pair."""
    return state._replace(params=np.asarray(v), updates=np.asarray(g))


def forgotten(state, v, g):
    """The state with no curvature pairs, remembering (v, g): the next accepted point stores the
    first pair again (optax's `init` would skip it: its first update only takes the point)."""
    return state._replace(
        count=np.ones_like(state.count), params=np.asarray(v), updates=np.asarray(g),
        diff_params_memory=np.zeros_like(state.diff_params_memory),
        diff_updates_memory=np.zeros_like(state.diff_updates_memory),
        weights_memory=np.zeros_like(state.weights_memory))


def empty(state) -> np.ndarray:
    """(S,) starts without a curvature pair (every weight zero)."""
    return ~np.any(np.asarray(state.weights_memory) != 0, axis=1)
