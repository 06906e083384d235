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


def _rot(th):
    return jnp.array([[jnp.cos(th), -jnp.sin(th)], [jnp.sin(th), jnp.cos(th)]])


def _nearest2(targets, Q):
    """(T, N) squared distances of targets (T, 2) to points Q (N, 2), as |t|² + |q|² − 2 t·q
    (no (T, N, 2) intermediate)."""
    return jnp.maximum(jnp.sum(targets**2, -1)[:, None] + jnp.sum(Q**2, -1)[None] - 2.0 * targets @ Q.T, 0.0)


def _icp(P, targets, init, iterations: int):
    """ICP from the similarity `init` = (s, θ, t): `iterations` rounds of matching each target to
    its nearest path point and the closed-form fit (module doc); → (s, θ, t, sse)."""

    def step(carry, _):
        s, th, t = carry
        M = P[jnp.argmin(_nearest2(targets, s * P @ _rot(th).T + t), axis=1)]
        mm, mt = jnp.mean(M, 0), jnp.mean(targets, 0)
        Mc, Tc = M - mm, targets - mt
        dot = jnp.sum(Mc * Tc)
        cross = jnp.sum(Mc[:, 0] * Tc[:, 1] - Mc[:, 1] * Tc[:, 0])
        th = jnp.arctan2(cross, dot)
        s = (jnp.cos(th) * dot + jnp.sin(th) * cross) / jnp.maximum(jnp.sum(Mc * Mc), 1e-300)
        s = jnp.maximum(s, 1e-6)
        t = mt - s * _rot(th) @ mm
        return (s, th, t), None

    (s, th, t), _ = jax.lax.scan(step, init, None, length=iterations)
    return s, th, t, jnp.sum(jnp.min(_nearest2(targets, s * P @ _rot(th).T + t), axis=1))


def icp_one(P, targets, iterations: int = 15, *, inits: int = 8, refine: int = 1):
    """One path P (N, 2) → s, theta, t (2,), sse after alignment (nearest sampled point);
    traceable (the presample's fused evaluation calls it inside its own jitted batch).

    ICP only finds the placement near where it starts, so it starts `inits` times: the path's
    centroid on the targets', its RMS radius scaled to theirs, turned by θ₀ = 2πk/`inits`. Those
    runs (`iterations` rounds each) use at most 90 path points and 24 targets (evenly strided);
    the best is then refined on all of them (`refine` rounds; the search refines further). Measured on the mkh2 case
    (benchmarks/fourbar-path): the reference design moved by 40 random similarities is placed
    back to its SSE from 40 of 40 with 8 starts, 6 of 40 with one, 1 of 40 from the identity."""
    N, T = P.shape[0], targets.shape[0]
    Pc, Tc = P[::max(1, N // 90)], targets[::max(1, T // 24)]
    mp, mt = jnp.mean(P, 0), jnp.mean(targets, 0)
    rt, rp = jnp.mean(jnp.sum((targets - mt) ** 2, -1)), jnp.mean(jnp.sum((P - mp) ** 2, -1))
    s0 = jnp.sqrt(rt / jnp.maximum(rp, 1e-300))
    s0 = jnp.maximum(s0, 1e-6)

    def run(th0):
        return _icp(Pc, Tc, (s0, th0, mt - s0 * _rot(th0) @ mp), iterations)

    s, th, t, e = jax.vmap(run)(jnp.arange(inits, dtype=P.dtype) * (2 * jnp.pi / inits))
    i = jnp.argmin(jnp.where(jnp.isfinite(e), e, jnp.inf))
    return _icp(P, targets, (s[i], th[i], t[i]), refine)


@functools.partial(jax.jit, static_argnames=("iterations",))
def icp_similarity(paths, targets, *, iterations: int = 15):
    """paths (B, N, 2), targets (T, 2) → s (B,), theta (B,), t (B, 2), sse (B,) after alignment
    (nearest sampled point): `icp_one` of every path."""
    return jax.vmap(lambda P: icp_one(P, targets, iterations))(paths)


def moved(problem, placement, x, s, theta, t):
    """One design x (V,) in file units moved by x ↦ sRx + t (θ in rad), traceable: the pivot
    (x, y) rotated, scaled and shifted, the angle + θ, the other lengths × s; angles wrapped into
    a bound range that spans a full turn, everything clipped to the bounds (as `apply_similarity`)."""
    ix, iy, ia, il = placement
    px, py = x[ix], x[iy]
    c, sn = jnp.cos(theta), jnp.sin(theta)
    x = x.at[ix].set(s * (c * px - sn * py) + t[0]).at[iy].set(s * (sn * px + c * py) + t[1])
    x = x.at[ia].add(theta / float(problem.factor[ia]))
    if len(il):
        x = x.at[jnp.asarray(il)].multiply(s)
    lo, hi = float(problem.lower[ia]), float(problem.upper[ia])
    full = 2 * np.pi / float(problem.factor[ia])
    if hi - lo >= full * (1 - 1e-6):
        x = x.at[ia].set(lo + jnp.mod(x[ia] - lo, full))
    return jnp.clip(x, jnp.asarray(problem.lower), jnp.asarray(problem.upper))


def placement_of(problem, ev=None):
    """(x index, y index, angle index, length indices) into the variables, or None. Without the
    `placement` key, found from the structure when `ev` (the problem's `Evaluator`) is given
    (`detect_placement`)."""
    pl = problem.option("placement")
    if pl is not None and problem.mech.input_kind != "angle":
        raise problem.error("'placement' needs an angle input: a similarity would scale a length input's stroke "
                            "too", "placement")
    if pl is None:
        # found once per evaluator (it solves and compiles two small batches)
        return ev.compiled(("align.detect_placement",), lambda: detect_placement(ev)) if ev is not None else None
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
    scales them all), or for a mechanism solved by continuation (its start needs no placement), or
    for a length input (its stroke would have to scale too)."""
    pr = ev.problem
    mech = pr.mech
    names = list(pr.names)
    lengths = [i for i, n in enumerate(names) if mech.kinds[n] == "length"]
    angles = [i for i, n in enumerate(names) if mech.kinds[n] == "angle"]
    all_lengths = [n for n in mech.parameter_names if mech.kinds[n] == "length"]
    if (ev.start_method != "closed_form" or not angles or len(lengths) < 2 or any(n not in names for n in all_lengths)
            or mech.input_kind != "angle"):  # a similarity would scale a length input's stroke too
        return None
    cands = [(ix, iy, ia) for ix in lengths for iy in lengths if ix != iy for ia in angles]
    x0 = pr.file_design()
    phis = jnp.asarray(pr.phis[0] + 2 * np.pi * np.arange(8) / 8)
    s, th = 1.3, 0.7
    c, sn = np.cos(th), np.sin(th)

    def path_of(x):
        u = jnp.asarray((x - pr.lower) / (pr.upper - pr.lower))
        xy, ok = ev.path(u, 0, phis, 0, screen=False)
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


def aligned_batch(ev, placement):
    """Compiled (U (B, V), circuits (B,)) → (U2 (B, V), value2 (B,), feasible2 (B,)): each
    design's path on its circuit aligned to the targets (`icp_one`), the design moved by that
    similarity (`moved`) and evaluated on the same circuit; one jitted function (no host round
    trip between the steps), cached on the evaluator. Costs 2 evaluations per design."""
    pr = ev.problem
    targets = np.asarray(pr.option("targets"), dtype=float)

    def build():
        lo, width = jnp.asarray(pr.lower), jnp.asarray(pr.upper - pr.lower)
        tg = jnp.asarray(targets)
        phis_np = np.asarray(pr.phis)

        def one(u, c):
            phis = jnp.asarray(phis_np, u.dtype)
            path, ok = ev.path(u, c, phis, 0)
            s, th, t, _ = icp_one(jnp.where(ok, path.xy, 0.0), tg)
            u2 = jnp.clip((moved(pr, placement, lo + u * width, s, th, t) - lo) / width, 0.0, 1.0)
            u2 = jnp.where(ok & jnp.all(jnp.isfinite(u2)), u2, u)
            path2, ok2 = ev.path(u2, c, phis, ev.objective.order)
            v2 = ev.objective.value(path2)
            ok2 = ok & ok2 & jnp.isfinite(v2)
            return u2, jnp.where(ok2, v2, jnp.inf), ok2

        return jax.jit(jax.vmap(one))

    return ev.compiled(("align.aligned_batch", tuple(placement[:3]), tuple(placement[3])), build)
