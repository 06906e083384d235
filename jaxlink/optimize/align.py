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


def placement_of(problem, ev=None):
    """(x index, y index, angle index, length indices) into the variables, or None. Without the
    `placement` key, found from the structure when `ev` (the problem's `Evaluator`) is given
    (`detect_placement`)."""
    pl = problem.option("placement")
    if pl is None:
        return detect_placement(ev) if ev is not None else None
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


def apply_similarity(problem, X, s, theta, t, placement=None):
    """Designs X (B, V) in file units moved by x ↦ sRx + t (θ in rad); bounds enforced (angles
    wrapped into a bound range that spans a full turn, everything else clipped). `placement`:
    the indices (`placement_of`; default: from the `placement` key)."""
    ix, iy, ia, il = placement if placement is not None else placement_of(problem)
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


def detect_placement(ev):
    """The similarity placement of the problem found from the mechanism itself: variables x, y
    (lengths) and an angle such that moving the whole mechanism by x ↦ sRx + t (x, y ↦ s R (x, y)
    + t, the angle + θ, every other length × s) moves the traced path of the point by the same
    similarity. Every candidate (ordered pairs of length variables × angle variables) is checked
    on the file's design at 8 inputs with one batched path solve (s = 1.3, θ = 0.7 rad, a shift of
    (0.3, −0.2) × the path's size): the first whose path matches to 10⁻⁷ of its size is the
    placement. None if no candidate matches, or if some length is not a variable (a similarity
    scales them all), or for a mechanism solved by continuation (its start needs no placement)."""
    pr = ev.problem
    mech = pr.mech
    names = list(pr.names)
    lengths = [i for i, n in enumerate(names) if mech.kinds[n] == "length"]
    angles = [i for i, n in enumerate(names) if mech.kinds[n] == "angle"]
    all_lengths = [n for n in mech.parameter_names if mech.kinds[n] == "length"]
    if ev.start_method != "closed_form" or not angles or len(lengths) < 2 or any(n not in names for n in all_lengths):
        return None
    cands = [(ix, iy, ia) for ix in lengths for iy in lengths if ix != iy for ia in angles]
    x0 = pr.file_design()
    phis = jnp.asarray(pr.phis[0] + 2 * np.pi * np.arange(8) / 8)
    s, th = 1.3, 0.7
    c, sn = np.cos(th), np.sin(th)

    def path_of(x):
        u = jnp.asarray((x - pr.lower) / (pr.upper - pr.lower))
        xy, ok = ev.path(u, 0, phis, 0)
        return xy.xy, ok

    xy0, ok0 = jax.jit(path_of)(x0)
    xy0 = np.asarray(xy0)
    if not bool(ok0):
        return None
    size = float(np.max(np.ptp(xy0, axis=0))) or 1.0
    t = np.array([0.3, -0.2]) * size
    X = []
    for ix, iy, ia in cands:
        x = np.array(x0, dtype=float)
        x[lengths] *= s
        x[ix] = s * (c * x0[ix] - sn * x0[iy]) + t[0]
        x[iy] = s * (sn * x0[ix] + c * x0[iy]) + t[1]
        x[ia] = x0[ia] + mech.from_si(names[ia], th)
        X.append(x)
    xys, oks = jax.jit(jax.vmap(path_of))(jnp.asarray(np.array(X)))
    want = s * xy0 @ np.array([[c, -sn], [sn, c]]).T + t
    err = np.max(np.abs(np.asarray(xys) - want[None]), axis=(1, 2))
    for k in np.flatnonzero(np.asarray(oks) & (err <= 1e-7 * s * size)):
        ix, iy, ia = cands[int(k)]
        return ix, iy, ia, [i for i in lengths if i not in (ix, iy)]
    return None
