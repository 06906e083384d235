"""The search's last step: a candidate polished in float64 by L-BFGS on a sharper surrogate.

The refinement (`search`) runs Adam in float32 for a fixed number of steps on `distance.soft_chamfer`
at τ = 0.01 over 128 samples against the target at 100 points, its margin penalty keeping every
dyad's reach margin above 0.02: cheap enough for hundreds of candidates a round, but neither
converged nor sharp (at distances of 0.01–0.1, τ = 0.01 is no small smoothing). `polish` takes
one candidate further: scipy's L-BFGS-B (`ITERS` iterations at each τ of `TAUS`, the first
a continuation step for the second) on the same surrogate in float64 over `POLISH_T` samples
against the target at `distance.N_POINTS` (`--points`; the reported distance takes `distance.N_FINE`), with the margin
penalty `WEIGHT` · Σ max(0, `FLOOR` − S)² summed over the samples: a dyad may come closer to its
dead centre (a letter's corner is often one) yet is pushed back hard from it. The value and
gradient are one compiled program (`program`, stored like the search's, `cache.compiled`); the
optimizer runs on the host, so the result is the same in every process of a group.

The polished candidate is checked like any other (`scoring.score`: traced exactly, certified over
its whole interval, matched). If it does not assemble over its interval — L-BFGS may end a hair
across a dead centre — the points back along the segment from the start, at `BACK` of the way,
are tried in turn and the first that assembles is the result (`search` keeps whichever of the
polished and the original is nearer the target).
"""

from __future__ import annotations

import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

from ..cache import compiled
from . import distance as _dist
from . import size as _size
from . import transmission as _tm
from .target import Target, arclength_resample
from .topology import CRANK
from .tracer import trace

POLISH_T = 256
TAUS = (0.01, 0.003)
ITERS = 400
FLOOR = 0.002
WEIGHT = 1000.0
BACK = (1.0, 0.9, 0.75, 0.5, 0.25)
#: a timed target's L-BFGS-B tolerances: its loss, a squared distance, is 1e-4 … 1e-10 near a fit, and
#: the default `ftol` (2.2e-9 of max(|f|, 1)) stopped it there (the sewing feed from 1 % off its own
#: six-bar: 9.7e-4 with the defaults, 1.2e-5 with these, 0.1 s)
TIMED_TOL = {"ftol": 1e-15, "gtol": 1e-12}


def _loss(x, parents, active, traced, target, closed, u, tau, bounds=(np.inf, 0.0), sliders=False, bounded=False):
    nj = CRANK + 1 + parents.shape[0]
    pose = x[:2 * nj].reshape(nj, 2)
    start, span = x[2 * nj], jnp.where(closed > 0, 2 * np.pi, x[2 * nj + 1])
    pos, marg = trace(parents, active, pose, start + span * u, sliders)
    fit = _dist.soft_chamfer(pos[:, traced], target, closed, tau=tau)
    floor = jnp.maximum(FLOOR, _tm.AIM * _tm.thresholds(parents, bounds[1], sliders)) if bounded else FLOOR
    pen = jnp.sum(jax.nn.relu(floor - marg) ** 2)
    shorter = (1 - closed) * (jax.nn.relu(span - 2 * np.pi) ** 2 + jax.nn.relu(0.05 - span) ** 2)
    out = fit + WEIGHT * pen + 100.0 * shorter
    if bounded:  # the size penalty (`size`) as in the refinement
        frame = _size.weighted_frame(pos[:, traced], _dist.arclength_weights(pos[:, traced], closed))
        out = out + _size.WEIGHT * _size.penalty(parents, active, pose, *frame, bounds[0], sliders)
    return out


def _value_and_grad(x, parents, active, traced, target, closed, u, tau, bounds, sliders=False, bounded=False):
    return jax.value_and_grad(_loss)(x, parents, active, traced, target, closed, u, tau, bounds, sliders, bounded)


@functools.lru_cache(maxsize=8)
def program(n_dyads: int, n_points: int = _dist.N_POINTS, sliders: bool = False, bounded: bool = False):
    """The compiled value and gradient (float64) of the polishing loss for `n_dyads` dyads
    (a padded topology, `topology.as_arrays`) and a target of `n_points` points: a callable on
    (x, parents, active, traced, target, closed, u, tau, bounds), x the pose flattened, then start and
    span. `sliders`: the parents may hold slider dyads (`tracer.trace`); `bounded`: with the size
    penalty for the bound `bounds` (`size`; unused without it)."""
    f64 = np.float64
    nj = CRANK + 1 + n_dyads
    with jax.enable_x64(True):
        avals = (jax.ShapeDtypeStruct((2 * nj + 2,), f64), jax.ShapeDtypeStruct((n_dyads, 2), np.int32),
                 jax.ShapeDtypeStruct((n_dyads,), bool), jax.ShapeDtypeStruct((), np.int32),
                 jax.ShapeDtypeStruct((n_points, 2), f64), jax.ShapeDtypeStruct((), f64),
                 jax.ShapeDtypeStruct((POLISH_T,), f64), jax.ShapeDtypeStruct((), f64),
                 jax.ShapeDtypeStruct((2,), f64))
        return compiled("synthesis-polish", _value_and_grad, avals, (sliders, bounded))


def _loss_timed(x, parents, active, traced, target, w, u, tau, bounds=(np.inf, 0.0), sliders=False, bounded=False):
    """A timed target's polishing loss: the square of the ordered distance at its points (`u`, the
    fractions of its span; `w` 1/N each) and the margin penalty there and at `POLISH_T` inputs across
    the interval; the span (x's last) is the target's, fixed (`tau` unused: the same signature)."""
    nj = CRANK + 1 + parents.shape[0]
    pose = x[:2 * nj].reshape(nj, 2)
    start, span = x[2 * nj], jax.lax.stop_gradient(x[2 * nj + 1])
    um = jnp.linspace(0.0, 1.0, POLISH_T, dtype=x.dtype)
    pos, marg = trace(parents, active, pose, start + span * jnp.concatenate([u, um]), sliders)
    fit = _dist.ordered_sq(pos[:u.shape[0], traced], target, w, eps=1e-30)
    floor = jnp.maximum(FLOOR, _tm.AIM * _tm.thresholds(parents, bounds[1], sliders)) if bounded else FLOOR
    out = fit + WEIGHT * jnp.sum(jax.nn.relu(floor - marg) ** 2)
    if bounded:  # the size penalty (`size`), the curve at the target's inputs
        frame = _size.weighted_frame(pos[:u.shape[0], traced], w)
        out = out + _size.WEIGHT * _size.penalty(parents, active, pose, *frame, bounds[0], sliders)
    return out


def _value_and_grad_timed(x, parents, active, traced, target, w, u, tau, bounds, sliders=False, bounded=False):
    return jax.value_and_grad(_loss_timed)(x, parents, active, traced, target, w, u, tau, bounds, sliders, bounded)


@functools.lru_cache(maxsize=8)
def program_timed(n_dyads: int, n_points: int, sliders: bool = False, bounded: bool = False):
    """`program` for a timed target of `n_points` points: a callable on (x, parents, active, traced,
    target (normalised), w, u, tau, bounds)."""
    f64 = np.float64
    nj = CRANK + 1 + n_dyads
    with jax.enable_x64(True):
        avals = (jax.ShapeDtypeStruct((2 * nj + 2,), f64), jax.ShapeDtypeStruct((n_dyads, 2), np.int32),
                 jax.ShapeDtypeStruct((n_dyads,), bool), jax.ShapeDtypeStruct((), np.int32),
                 jax.ShapeDtypeStruct((n_points, 2), f64), jax.ShapeDtypeStruct((n_points,), f64),
                 jax.ShapeDtypeStruct((n_points,), f64), jax.ShapeDtypeStruct((), f64),
                 jax.ShapeDtypeStruct((2,), f64))
        return compiled("synthesis-polish-timed", _value_and_grad_timed, avals, (sliders, bounded))


class _PastDeadline(Exception):
    """`polish`'s deadline passed (raised out of scipy's L-BFGS-B, caught by `polish`)."""


def polish(parents: np.ndarray, active: np.ndarray, traced: int, pose: np.ndarray, start: float, span: float,
           target: Target, *, n_points: int = _dist.N_POINTS, sliders: bool = False,
           max_size: float | None = None, min_transmission: float | None = None,
           deadline: float | None = None) -> tuple[np.ndarray, float, float]:
    """(pose, start, span) of one candidate (a row of `topology.as_arrays`, its pose padded like it)
    after L-BFGS at each τ of `TAUS` (module doc), with the size penalty for `max_size` (`size`) and
    the margin floor of `min_transmission` (degrees, `transmission`) if given; the caller scores it and
    walks back (`BACK`). `deadline` (a `time.perf_counter()` time): L-BFGS stops at the first
    evaluation past it, and the point of least loss evaluated at the τ then reached is the result
    (a deadline already past: the start itself); none: the whole polish."""
    from scipy.optimize import minimize

    closed = target.closed
    timed = target.timed
    nj = pose.shape[0]
    bounded = (max_size is not None and bool(np.isfinite(max_size))) or min_transmission is not None
    _, rms, ext = _size.target_frame(target, n_points)
    bounds = np.array([_size.limit(max_size, ext, rms), _tm.floor_of(min_transmission)])
    with jax.enable_x64(True):
        par, act = jnp.asarray(parents, jnp.int32), jnp.asarray(active, bool)
        tr = jnp.asarray(traced, jnp.int32)
        if timed:  # every point, its own input; the span exact
            prog = program_timed(parents.shape[0], len(target.points), sliders, bounded)
            t_in = np.asarray(target.inputs, float)
            span = float(t_in[-1] - t_in[0])
            tgt = jnp.asarray(_dist.normalise(target.points)[0], jnp.float64)
            args = (jnp.full(len(t_in), 1.0 / len(t_in)), jnp.asarray((t_in - t_in[0]) / span, jnp.float64))
        else:
            prog = program(parents.shape[0], n_points, sliders, bounded)
            tgt = jnp.asarray(_dist.normalise(arclength_resample(target.points, n_points, closed))[0], jnp.float64)
            u = jnp.asarray(np.arange(POLISH_T) / (POLISH_T if closed else POLISH_T - 1), jnp.float64)
            args = (jnp.asarray(float(closed), jnp.float64), u)
        x = np.concatenate([np.asarray(pose, float).ravel(), [start, span]])
        for tau in TAUS[-1:] if timed else TAUS:  # the ordered distance is smooth: no continuation
            t = jnp.asarray(tau, jnp.float64)
            least = [np.inf, x]  # the least loss evaluated at this τ, and where

            def f(x, t=t, least=least):
                v, g = prog(jnp.asarray(x, jnp.float64), par, act, tr, tgt, *args, t, jnp.asarray(bounds, jnp.float64))
                v, g = float(v), np.asarray(g, float)
                if not (np.isfinite(v) and np.all(np.isfinite(g))):
                    v, g = np.inf, np.zeros_like(x)
                if v < least[0]:
                    least[:] = [v, np.array(x, float)]
                if deadline is not None and time.perf_counter() >= deadline:
                    raise _PastDeadline
                return v, g

            opts = {"maxiter": ITERS, **(TIMED_TOL if timed else {})}
            try:
                x = minimize(f, x, jac=True, method="L-BFGS-B", options=opts).x
            except _PastDeadline:
                x = np.asarray(least[1], float)
                break
    if timed:
        return x[:2 * nj].reshape(nj, 2), float(x[2 * nj]), span
    return x[:2 * nj].reshape(nj, 2), float(x[2 * nj]), (2 * np.pi if closed else float(x[2 * nj + 1]))
