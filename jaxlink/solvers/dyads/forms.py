"""The closed forms of the four dyad kinds, on plain numbers (`jaxlink.solvers.dyads` states them).

Each form takes the known vector w = (wx, wy), the dyad's known vectors and its branch s = ±1, and
returns a `Closed`: the solved values (an angle with its (cos, sin), or a length), whether the
square root's argument was positive (`ok`), what the loop misses (`miss`), the sine between the
columns of the dyad's block of Φ_q (`sine`) and the reach margin (`margin`). Square roots and
divisions go through the double `where` (NaN-free gradients where the primal is fine).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax.numpy as jnp

from ..angles import atan2


class Body(NamedTuple):
    """A known vector fixed to a turning unknown θ, in θ's frame: L e(c) (L signed)."""

    L: Any
    cs: tuple  # (cos c, sin c)


class Closed(NamedTuple):
    values: tuple  # per slot: (value, (cos, sin)) for an angle, (value, None) for a length
    ok: Any
    miss: Any
    sine: Any
    margin: Any


def cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1]


def safe_sqrt(x):
    """√x and x > 0; 0 where x ≤ 0 (the collinear configuration h = 0: its miss is in the residual)."""
    ok = x > 0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, x, 1.0)), 0.0), ok


def inverse(L):
    return 1.0 / jnp.where(L != 0, L, 1.0)


def safe_norm(x2):
    """√x2 with a zero gradient (not NaN) at 0."""
    pos = x2 > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x2, 1.0)), 0.0)


def angle_from(ux, uy, L, inv_L, cs, arith: bool = False):
    """θ with L e(θ + c) = u, and (cos θ, sin θ), from u, L, 1/L and (cos c, sin c) — one atan2.

    The closed form constructs u with |u| = |L| (to rounding), so e(θ + c) = u / L needs no
    square root; atan2 is scale-free, so θ is exact whatever |u|. Also returns what the term
    L e(θ + c) misses of u, ||u| − |L|| = ||u|² − L²| / (|u| + |L|) ≈ ||u|² − L²| / (2|L|)
    (its share of the loop residual), again without a square root. `arith`: the atan2 of
    `angles.py` (vectorized arithmetic, within 2 ulp), else the C library's."""
    ex, ey = ux * inv_L, uy * inv_L  # e(θ + c)
    cc, sc = cs
    ct, st = ex * cc + ey * sc, ey * cc - ex * sc  # rotate by −c
    miss = jnp.abs((ux * ux + uy * uy) - L * L) * (0.5 * jnp.abs(inv_L))
    return (atan2 if arith else jnp.arctan2)(st, ct), (ct, st), miss


def body_of(vx, vy) -> Body:
    """A `Body` from a vector sum (its length and direction; the direction (1, 0) at 0)."""
    n = safe_norm(vx * vx + vy * vy)
    inv = inverse(n)
    return Body(n, (jnp.where(n > 0, vx * inv, 1.0), vy * inv))


def side_rrr(a: Body, w, cs_guess):
    """σ of an RRR dyad from the guessed first angle: the side of w its link lies on."""
    cg, sg = cs_guess
    cc, sc = a.cs
    ux, uy = a.L * (cg * cc - sg * sc), a.L * (sg * cc + cg * sc)
    return jnp.where(cross(w, (ux, uy)) >= 0, 1.0, -1.0)


def rrr(a: Body, b: Body, w, s, arith: bool) -> Closed:
    """RRR: a e(θa) + b e(θb) = w (the bodies in their frames), a circle–circle intersection."""
    wx, wy = w
    La, Lb = a.L, b.L
    w2 = wx * wx + wy * wy
    inv_w = 1.0 / jnp.sqrt(jnp.where(w2 > 0, w2, 1.0))
    x = 0.5 * (w2 + La * La - Lb * Lb) * inv_w
    h, ok = safe_sqrt(La * La - x * x)
    ux = (x * wx - s * h * wy) * inv_w
    uy = (x * wy + s * h * wx) * inv_w
    inv_a, inv_b = inverse(La), inverse(Lb)
    ta, csa, miss_a = angle_from(ux, uy, La, inv_a, a.cs, arith)
    tb, csb, miss_b = angle_from(wx - ux, wy - uy, Lb, inv_b, b.cs, arith)
    # |u × v| / (|La| |Lb|) with v = w − u: |u × w| = h |w|
    sine = h * (w2 * inv_w) * jnp.abs(inv_a * inv_b)
    margin = ((La + Lb) ** 2 - w2) * (w2 - (La - Lb) ** 2) * (0.5 * inv_a * inv_b) ** 2
    return Closed(((ta, csa), (tb, csb)), ok, miss_a + miss_b, sine, margin)


def side_rrp(d, unit: bool, w, ell_guess):
    """σ of an RRP dyad: the guessed length's side of the foot of the perpendicular."""
    d2 = 1.0 if unit else dot(d, d)
    return jnp.where(ell_guess * d2 - dot(w, d) >= 0, 1.0, -1.0)


def rrp(a: Body, d, unit: bool, w, s, arith: bool) -> Closed:
    """RRP: a e(θ) + ℓ d = w: |w − ℓ d| = |a|,  ℓ = (w·d + σ √(a² d² − (w × d)²)) / d²."""
    wx, wy = w
    La = a.L
    along, across = dot(w, d), cross(w, d)
    if unit:
        h, ok = safe_sqrt(La * La - across * across)
        ell = along + s * h
        inv_a = inverse(La)
        sine = h * jnp.abs(inv_a)  # the link's component along the slider, over its length
        margin = 1.0 - (across * inv_a) ** 2
    else:
        d2 = dot(d, d)
        inv_d2 = inverse(d2)
        h, ok = safe_sqrt(La * La * d2 - across * across)
        ell = (along + s * h) * inv_d2
        inv_a = inverse(La)
        sine = h * jnp.abs(inv_a) * jnp.sqrt(jnp.abs(inv_d2))
        margin = 1.0 - across * across * (inv_a * inv_a) * inv_d2
    t, cs, miss = angle_from(wx - ell * d[0], wy - ell * d[1], La, inv_a, a.cs, arith)
    return Closed(((t, cs), (ell, None)), ok, miss, sine, margin)


def side_rpr(a, b, unit: bool, ell_guess):
    """σ of an RPR dyad: the guessed length's side of the foot of the perpendicular from the
    pivot onto the slot."""
    b2 = 1.0 if unit else dot(b, b)
    ab = 0.0 if a is None else dot(a, b)
    return jnp.where(ell_guess * b2 + ab >= 0, 1.0, -1.0)


def rpr(a, b, unit: bool, w, s, arith: bool) -> Closed:
    """RPR: R(θ)(a + ℓ b) = w (a, b in θ's frame; a None for 0): |a + ℓ b| = |w|,
    ℓ = (−a·b + σ √(b² w² − (a × b)²)) / b², then θ = ∠w − ∠(a + ℓ b)."""
    wx, wy = w
    w2 = wx * wx + wy * wy
    b2 = 1.0 if unit else dot(b, b)
    ab = 0.0 if a is None else dot(a, b)
    e = 0.0 if a is None else cross(a, b)  # the slot's offset from the pivot, times |b|
    h, ok = safe_sqrt(b2 * w2 - e * e)
    ell = (s * h - ab) if unit else (s * h - ab) * inverse(b2)
    ux, uy = ell * b[0], ell * b[1]
    if a is not None:
        ux, uy = ux + a[0], uy + a[1]
    inv_w2 = inverse(w2)
    cu, su = dot((ux, uy), w), cross((ux, uy), w)  # |u| |w| (cos θ, sin θ)
    t = (atan2 if arith else jnp.arctan2)(su, cu)
    u2 = ux * ux + uy * uy
    miss = jnp.abs(u2 - w2) * inverse(safe_norm(u2) + safe_norm(w2))
    inv_bw = jnp.sqrt(inv_w2) if unit else jnp.sqrt(inv_w2 * inverse(b2))
    sine = h * inv_bw  # the slot against the pivot's line: |u·b| / (|u| |b|), |u| = |w|
    margin = 1.0 - e * e * (inv_w2 if unit else inv_w2 * inverse(b2))
    margin = jnp.where(w2 > 0, margin, 0.0)
    return Closed(((t, (cu * inv_w2, su * inv_w2)), (ell, None)), ok, miss, sine, margin)


def pp(da, ua: bool, db, ub: bool, w) -> Closed:
    """PP: ℓa da + ℓb db = w, Cramer's rule."""
    wx, wy = w
    det = cross(da, db)
    if ua and ub:
        sine = jnp.abs(det)
        margin = det * det
    else:
        n2 = (1.0 if ua else dot(da, da)) * (1.0 if ub else dot(db, db))
        sine = jnp.abs(det) * jnp.sqrt(inverse(n2))
        margin = det * det * inverse(n2)
    ok = sine > 1e-12
    det = jnp.where(ok, det, 1.0)
    la, lb = cross(w, db) / det, cross(da, w) / det
    # zero to rounding, but honest where the directions are parallel (no solution)
    miss = jnp.maximum(jnp.abs(la * da[0] + lb * db[0] - wx), jnp.abs(la * da[1] + lb * db[1] - wy))
    return Closed(((la, None), (lb, None)), ok, miss, sine, margin)
