"""The search's rank: the screened candidates traced at `RANK_T` inputs, by a chamfer distance at
`_ROT` rotations (`_rank`), and rotated to their best angle (`_rotate`)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import distance as _dist
from . import size as _size
from . import transmission as _tm
from .screening import _DT
from .tracer import trace

RANK_T = 64


_ROT = 32


def _normalised(c, w):
    mean = jnp.sum(w[:, None] * c, axis=0)
    c = c - mean
    return c / jnp.sqrt(jnp.sum(w * jnp.sum(c * c, axis=1)) + 1e-30)


def _u(n: int, closed: bool) -> np.ndarray:
    """Fractions of the interval sampled: a closed turn without its end, an open one with both."""
    return (np.arange(n) / (n if closed else n - 1)).astype(np.float32)


@functools.partial(jax.jit, static_argnames=("sliders", "bounded"))
def _rank(parents, active, traced, poses, arcs, target, closed, u, bounds=(np.inf, 0.0), *, sliders: bool = False,
          bounded: bool = False):
    """(chamfer at the best of `_ROT` rotations, that rotation) of each candidate over its sub-arc.
    `closed` a 0/1 array (one program for open and closed targets), `u` from `_u`; inf where a dyad
    does not close at a sample (or, `bounded`, where the design is larger than `bounds`: `size`)."""

    def one(par, act, tr, pose, arc):
        pos, marg = trace(par, act, pose, arc[0] + arc[1] * u, sliders)
        c = pos[:, tr]
        w = _dist.arclength_weights(c, closed)
        fits = True
        if bounded:  # within the size, every dyad's margin above its floor
            fits = _size.within(par, act, pose, *_size.weighted_frame(c, w), bounds[0], sliders) & (
                jnp.min(marg - _tm.thresholds(par, bounds[1], sliders)) > 0)
        c = _normalised(c, w)
        phis = 2 * np.pi * jnp.arange(_ROT, dtype=_DT) / _ROT
        rot = jnp.stack([jnp.stack([jnp.cos(phis), -jnp.sin(phis)], -1),
                         jnp.stack([jnp.sin(phis), jnp.cos(phis)], -1)], -2)  # (R, 2, 2)
        rc = jnp.einsum("rij,tj->rti", rot, c)
        d = jnp.sqrt(jnp.sum((rc[:, :, None] - target[None, None]) ** 2, -1) + 1e-12)
        val = jnp.sum(w * d.min(2), axis=1) + d.min(1).mean(1)
        k = jnp.argmin(val)
        return jnp.where((jnp.min(marg) > 0) & fits, val[k], jnp.inf), phis[k]

    return jax.vmap(one)(parents, active, traced, poses, arcs)


def _rotate(poses, phi):
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    x, y = poses[..., 0], poses[..., 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=-1)
