"""The search's refinement: Adam (optax) on a candidate's pose and interval against the smooth
surrogate (`distance.soft_chamfer`), with a penalty keeping every dyad's margin above
`MARGIN_FLOOR` (`_refine`); a timed target's against the ordered distance at its inputs
(`_refine_timed`)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import distance as _dist
from . import size as _size
from . import transmission as _tm
from .tracer import trace

REFINE_T = 128


TARGET_N = 100


MARGIN_FLOOR = 0.02


#: the input fractions of the interval where a timed candidate's margins are also kept up (the
#: refinement's penalty: its samples are the target's points, maybe few)
_TIMED_MARGIN_T = 64


def _loss(params, par, act, tr, target, closed, u, sliders, bounds=(np.inf, 0.0), bounded=False):
    pose, arc = params
    start, span = arc[0], jnp.where(closed > 0, jnp.asarray(2 * np.pi, arc.dtype), arc[1])
    pos, marg = trace(par, act, pose, start + span * u, sliders)
    fit = _dist.soft_chamfer(pos[:, tr], target, closed, tau=0.01)
    floor = jnp.maximum(MARGIN_FLOOR, _tm.AIM * _tm.thresholds(par, bounds[1], sliders)) if bounded else MARGIN_FLOOR
    pen = jnp.mean(jnp.sum(jax.nn.relu(floor - marg) ** 2, axis=-1))
    shorter = (1 - closed) * (jax.nn.relu(span - 2 * np.pi) ** 2 + jax.nn.relu(0.05 - span) ** 2)
    out = fit + 100.0 * pen + 100.0 * shorter
    if bounded:  # the size penalty (`size`), in the surrogate's normalisation of the curve
        frame = _size.weighted_frame(pos[:, tr], _dist.arclength_weights(pos[:, tr], closed))
        out = out + _size.WEIGHT * _size.penalty(par, act, pose, *frame, bounds[0], sliders)
    return out


@functools.partial(jax.jit, static_argnames=("steps", "sliders", "bounded"))
def _refine(parents, active, traced, poses, arcs, target, lr, closed, u, bounds=(np.inf, 0.0), *, steps: int,
            sliders: bool = False, bounded: bool = False):
    """Each candidate's pose and arc after `steps` Adam steps (`_adam`) on `_loss`: (poses, arcs, losses).
    `bounded`: with the size penalty for the bound `bounds` (`size`)."""
    return jax.vmap(lambda par, act, tr, pose, arc: _adam(
        _loss, (pose, arc), (par, act, tr, target, closed, u, sliders, bounds, bounded), lr, steps))(
        parents, active, traced, poses, arcs)


def _adam(loss, params, args, lr, steps: int):
    """(pose, arc, the last loss) after `steps` Adam steps on `loss(params, *args)` from `params`
    = (pose, arc): the step size falls from lr to lr / 10 along a half cosine (long strides first, a
    fine fit at the end); a non-finite gradient component counts as 0."""
    import optax  # here: importing it costs every command 0.05 s

    opt = optax.adam(lambda k: lr * (0.55 + 0.45 * jnp.cos(np.pi * jnp.minimum(k, steps) / steps)))
    g = jax.value_and_grad(loss)

    def step(carry, _):
        params, state = carry
        v, grads = g(params, *args)
        grads = jax.tree_util.tree_map(lambda x: jnp.where(jnp.isfinite(x), x, 0.0), grads)
        upd, state = opt.update(grads, state, params)
        return (optax.apply_updates(params, upd), state), v

    (params, _), vals = jax.lax.scan(step, (params, opt.init(params)), None, length=steps)
    return params[0], params[1], vals[-1]


def _loss_timed(params, par, act, tr, target, w, u, sliders, bounds=(np.inf, 0.0), bounded=False):
    pose, arc = params
    span = jax.lax.stop_gradient(arc[1])  # the target's: fixed
    um = jnp.asarray(np.linspace(0.0, 1.0, _TIMED_MARGIN_T), u.dtype)
    pos, marg = trace(par, act, pose, arc[0] + span * jnp.concatenate([u, um]), sliders)
    fit = _dist.ordered_sq(pos[:u.shape[0], tr], target, w)
    floor = jnp.maximum(MARGIN_FLOOR, _tm.AIM * _tm.thresholds(par, bounds[1], sliders)) if bounded else MARGIN_FLOOR
    pen = jnp.mean(jnp.sum(jax.nn.relu(floor - marg) ** 2, axis=-1))
    out = fit + 100.0 * pen
    if bounded:  # the size penalty (`size`), the curve at the target's inputs with its weights
        frame = _size.weighted_frame(pos[:u.shape[0], tr], w)
        out = out + _size.WEIGHT * _size.penalty(par, act, pose, *frame, bounds[0], sliders)
    return out


@functools.partial(jax.jit, static_argnames=("steps", "sliders", "bounded"))
def _refine_timed(parents, active, traced, poses, arcs, target, w, lr, u, bounds=(np.inf, 0.0), *, steps: int,
                  sliders: bool = False, bounded: bool = False):
    """`_refine` for a timed target: Adam on the pose and the interval's start (its span the
    target's) against the square of the ordered distance at the target's inputs (`timed_samples`),
    plus the margin penalty at those and at `_TIMED_MARGIN_T` inputs across the interval."""
    return jax.vmap(lambda par, act, tr, pose, arc: _adam(
        _loss_timed, (pose, arc), (par, act, tr, target, w, u, sliders, bounds, bounded), lr, steps))(
        parents, active, traced, poses, arcs)
