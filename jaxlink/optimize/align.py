"""Similarity alignment of a traced path to target points (for the `points` objective).

The untimed path error of a linkage whose ground pivot, frame angle and every length are free is
invariant in *shape* under a similarity x ↦ sRx + t of the whole mechanism: the pivot moves to
s R p + t, absolute angles turn by θ, every length scales by s, relative angles stay. So each
candidate's best placement can be found without searching it: iterative closest points (ICP)
with the closed-form 2-D Procrustes (Umeyama) similarity fit,

    θ = atan2(Σ m̃ × t̃, Σ m̃ · t̃),  s = (cos θ Σ m̃·t̃ + sin θ Σ m̃×t̃) / Σ |m̃|²,  t = t̄ − s R m̄,

m̃, t̃ the centred matched path points and targets, repeated `iterations` times. The gradient
search uses it to place its presampled designs before choosing the starts (`[optimize]
placement = { x = "p1x", y = "p1y", angle = "a" }`; all length parameters must be variables).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np


@functools.partial(jax.jit, static_argnames=("iterations",))
def icp_similarity(paths, targets, *, iterations: int = 15):
    """paths (B, N, 2), targets (T, 2) → s (B,), theta (B,), t (B, 2), sse (B,) after alignment
    (nearest sampled point)."""

    def one(P):
        def step(carry, _):
            s, th, t = carry
            R = jnp.array([[jnp.cos(th), -jnp.sin(th)], [jnp.sin(th), jnp.cos(th)]])
            Q = s * P @ R.T + t
            d2 = jnp.sum((targets[:, None, :] - Q[None]) ** 2, axis=-1)
            M = P[jnp.argmin(d2, axis=1)]
            mm, mt = jnp.mean(M, 0), jnp.mean(targets, 0)
            Mc, Tc = M - mm, targets - mt
            dot = jnp.sum(Mc * Tc)
            cross = jnp.sum(Mc[:, 0] * Tc[:, 1] - Mc[:, 1] * Tc[:, 0])
            th = jnp.arctan2(cross, dot)
            s = (jnp.cos(th) * dot + jnp.sin(th) * cross) / jnp.maximum(jnp.sum(Mc * Mc), 1e-300)
            s = jnp.maximum(s, 1e-6)
            R = jnp.array([[jnp.cos(th), -jnp.sin(th)], [jnp.sin(th), jnp.cos(th)]])
            t = mt - s * R @ mm
            return (s, th, t), None

        init = (jnp.ones((), P.dtype), jnp.zeros((), P.dtype), jnp.zeros(2, P.dtype))
        (s, th, t), _ = jax.lax.scan(step, init, None, length=iterations)
        R = jnp.array([[jnp.cos(th), -jnp.sin(th)], [jnp.sin(th), jnp.cos(th)]])
        Q = s * P @ R.T + t
        sse = jnp.sum(jnp.min(jnp.sum((targets[:, None, :] - Q[None]) ** 2, axis=-1), axis=1))
        return s, th, t, sse

    return jax.vmap(one)(paths)


def placement_of(problem):
    """(x index, y index, angle index, length indices) into the variables, or None."""
    pl = problem.option("placement")
    if pl is None:
        return None
    names = list(problem.names)
    if not isinstance(pl, dict) or set(pl) != {"x", "y", "angle"}:
        raise problem.error("'placement' must be { x = NAME, y = NAME, angle = NAME } (variables)", "placement")
    for k, v in pl.items():
        if v not in names:
            raise problem.error(f"placement {k} = {v!r} is not a variable", "placement")
    mech = problem.mech
    lengths = [i for i, n in enumerate(mech.parameter_names) if mech.kinds[n] == "length"
               and n not in (pl["x"], pl["y"])]
    missing = [mech.parameter_names[i] for i in lengths if mech.parameter_names[i] not in names]
    if missing:
        raise problem.error("placement needs every length to be a variable (a similarity scales them all); "
                            f"not variables: {', '.join(missing)}", "placement")
    return (names.index(pl["x"]), names.index(pl["y"]), names.index(pl["angle"]),
            [names.index(mech.parameter_names[i]) for i in lengths])


def apply_similarity(problem, X, s, theta, t):
    """Designs X (B, V) in file units moved by x ↦ sRx + t (θ in rad); bounds enforced (angles
    wrapped into a bound range that spans a full turn, everything else clipped)."""
    ix, iy, ia, il = placement_of(problem)
    mech = problem.mech
    X = np.array(X, dtype=float)
    lf = mech.units.length
    px, py = X[:, ix] * 1.0, X[:, iy] * 1.0
    c, sn = np.cos(theta), np.sin(theta)
    X[:, ix] = s * (c * px - sn * py) + t[:, 0]
    X[:, iy] = s * (sn * px + c * py) + t[:, 1]
    del lf  # targets, paths and pivots are all in file units
    X[:, ia] = X[:, ia] + mech.from_si(problem.names[ia], theta)
    for i in il:
        X[:, i] = X[:, i] * s
    lo, hi = problem.lower, problem.upper
    full = mech.from_si(problem.names[ia], 2 * np.pi)
    if hi[ia] - lo[ia] >= full * (1 - 1e-6):
        X[:, ia] = lo[ia] + np.mod(X[:, ia] - lo[ia], full)
    return np.clip(X, lo, hi)
