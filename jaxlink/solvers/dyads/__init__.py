"""Closed-form solutions of the dyads (Assur groups of class II) of a loop-closure system.

A block of `jaxlink.model.structure.blocks` that is one loop with two new unknowns is a dyad when
each term of the loop holds, in those two unknowns, at most one angle θ — in its angle, as θ + c —
and at most one length ℓ — in its length or components, affinely, k ℓ + m (`classify`; c, k, m
known expressions, s = ±1 a term's sign). Gathering the terms by the angle that turns them, the
loop reads

    Σ_g R(θ_g) (a_g + ℓ b_g) + ℓ d = w,      w = −Σ (the known vectors and the known parts m),

with a_g, b_g the known vectors turned by θ_g (in θ_g's frame: Σ s m e(c), Σ s k e(c)) and d the
coefficient of ℓ in the terms that do not turn. A revolute/prismatic loop gives four pairs of
unknowns, each with a closed form (σ = ±1 the branch):

- **RRR** — two angles:  R(θ_a) a + R(θ_b) b = w. With u = R(θ_a) a and w − u = R(θ_b) b:
  |u| = |a|, |w − u| = |b|, a circle–circle intersection
      u = x ŵ + σ h ŵ⊥,   x = (|w|² + |a|² − |b|²) / (2|w|),   h = √(|a|² − x²).
  (A four-bar's coupler and rocker; a ternary link written as several terms of one angle.)
- **RRP** — an angle and a length along a direction that does not turn with it (a slider on a
  guide fixed to the frame or to a known body; the textbook RRP and PRR dyads):
  R(θ) a + ℓ d = w,  |w − ℓ d| = |a|  gives
      ℓ = (w·d + σ √(|a|² |d|² − (w × d)²)) / |d|²,   θ = ∠(w − ℓ d) − ∠a.
- **RPR** — an angle and a length along a direction that turns with it (a slider in the slot of
  a turning lever: Whitworth, crank-shaper, oscillating cylinder): R(θ)(a + ℓ b) = w,
  |a + ℓ b| = |w| gives
      ℓ = (−a·b + σ √(|b|² |w|² − (a × b)²)) / |b|²,   θ = ∠w − ∠(a + ℓ b).
  With a unit b, e = a × b is the slot's perpendicular offset from the pivot and
  ℓ = −a·b + σ √(|w|² − e²); a slot through the pivot (a = 0, or a ∥ b) is ℓ = σ|w|.
- **PP** — two lengths along known directions (the PRP dyad, and RPP/PPR whose link angle the two
  prismatic joints fix): ℓ_a d_a + ℓ_b d_b = w, a 2×2 linear system (Cramer).

(A loop where a length both turns with the angle and does not, an angle twice in one angle, or an
unknown inside a function has no closed form here: `classify` returns None, Newton's method.)

σ = ±1 is the *assembly branch* (circuit) of the dyad. It is chosen once, at the first input, as
the side of the guess (`solve_nearest`: dyad by dyad, the mirror image nearer to the guessed
configuration — RRR: the side of w that the guessed first link lies on; RRP and RPR: the guessed
length's side of the foot of the perpendicular, ℓ|d|² − w·d, ℓ|b|² + a·b; PP: +1) and kept: the
closed form then stays on that branch for every input and every design, with no Newton and no
continuation. Where the square root's argument h² is ≤ 0 the dyad is put in its collinear
configuration (h = 0, the least-squares closest) and the returned residual says by how much its
loop misses: rounding at the exact toggle (assembled, within the tolerance), more past it (cannot
be assembled). The output stays finite (the double-`where` trick keeps gradients NaN-free).

`solve` also returns the sine of the angle between the columns of each dyad's block of Φ_q (≈ 0:
dead centre, toggle or change point, a singular position): RRR h |w| / (|a| |b|) (between the two
links); RRP h / (|a| |d|) (the link against the slider's normal); RPR h / (|b| |w|) (the slot
against the line from the pivot, |u·b| / (|u| |b|)); PP |d_a × d_b| / (|d_a| |d_b|). The *reach
margin* (`reach_margins`) is its square written without a square root, signed: negative exactly
where the dyad cannot be assembled. Angles are returned within ±π of the reference configuration.
The forms themselves are `jaxlink.solvers.dyads.forms`; the classification `.classify`.
"""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp

from ...files import expr as _expr
from ...model.mechanism import Mechanism
from ..angles import sincos
from . import forms as _forms
from .classify import Dyad, Part, classify

__all__ = ["Dyad", "Part", "classify", "input_trig", "parameter_trig", "reach_margins", "solve", "solve_nearest",
           "solve_with_trig"]


def _wrap_near(theta, ref):
    """θ + 2πk closest to ref (round, not fmod: several times cheaper on CPU)."""
    two_pi = 2 * jnp.pi
    return theta + two_pi * jnp.round((ref - theta) / two_pi)


def input_trig(mech: Mechanism, phis, arith: bool = True):
    """(cos, sin) of the input values (any shape), keyed by the input's name; {} for a length input.
    `arith`: by `angles.sincos` (vectorized arithmetic, for arrays of inputs), else the C library's
    (for a scalar that XLA may hoist out of a kernel's loop)."""
    if mech.input_kind != "angle":
        return {}
    return {mech.input_name: sincos(phis) if arith else (jnp.cos(phis), jnp.sin(phis))}


def parameter_trig(mech: Mechanism, P):
    """(cos, sin) of every angle parameter, keyed by name; `P` is (..., n_parameters). With these
    known, angles like `phi2 + gamma` cost no trigonometry at a position (angle addition)."""
    return {n: (jnp.cos(P[..., i]), jnp.sin(P[..., i]))
            for i, (n, k) in enumerate(zip(mech.parameter_names, mech.parameter_kinds)) if k == "angle"}


def solve(mech: Mechanism, dyads, sigma, q_ref, phi, p, trig=None):
    """All unknowns in closed form at input φ, on the branches σ.

    Returns `(q, assemblable, residual, sine)`. `assemblable` is False where a dyad's h² = r_a² − x²
    (or r_a² − (w × e_b)²) is ≤ 0: that dyad is then put in its collinear configuration (h = 0),
    the least-squares closest one, and `residual` says by how much its loop misses — rounding at
    the exact toggle (h² negative by rounding), so that `residual ≤ tol` decides whether the
    position is assembled. Each dyad's loop closes exactly in the vectors it constructs (RRR, RRP:
u with |u| = |a|; RPR: a + ℓ b with |a + ℓ b| = |w|); the solved angles turn them onto their
directions, so the loop misses by the difference of those lengths: `residual` is the largest
over the dyads of ||a| − |u|| (+ ||b| − |w − u||, RRR; ||a + ℓ b| − |w||, RPR; the components of
the linear system's miss, PP): an upper bound of max|Φ| at the solution, exact to rounding,
computed without further trigonometry (it exposes the loss of accuracy next to a dead centre).
`sine` is the smallest over the dyads of the sine of the angle between the columns of the dyad's
block of Φ_q (the package docstring gives it per kind) — 0 at a dead centre, a toggle or a change
point (h = 0, where the two branches meet), for a few multiplies.
    Angle values come from one atan2 each; (cos, sin) of solved angles are reused by later dyads.
    `trig` optionally gives (cos, sin) of the input and of angle parameters (`input_trig`,
    `parameter_trig`), computed once outside the per-position kernel. Angles are returned within
    ±π of `q_ref`.
    """
    q, ok, resid, _, sine = _solve(mech, dyads, sigma, q_ref, phi, p, trig)
    return q, ok, resid, sine


def solve_with_trig(mech: Mechanism, dyads, sigma, q_ref, phi, p, trig=None):
    """`solve`, and the (cos, sin) of every angle it used, keyed by name (the input, the angle
    parameters given in `trig`, the solved angles): `(q, assemblable, residual, sine, trig)`.
    The angles by `angles.atan2` (vectorized arithmetic, within 2 ulp of the C library's): the
    batched closed form's kernel, where it is 1.2× (float64) to 1.6× (float32) faster. `solve`
    keeps the C library's: inside the continuation's loops the arithmetic one measured slower."""
    q, ok, resid, _, sine, trig_all = _solve(mech, dyads, sigma, q_ref, phi, p, trig, with_trig=True, arith=True)
    return q, ok, resid, sine, trig_all


def solve_nearest(mech: Mechanism, dyads, q_guess, phi, p, trig=None):
    """The closed-form configuration nearest to a guess, and its branches.

    Dyad by dyad (in solve order, each with the exact solution of the earlier ones), σ is the side
    of the guess: of the two mirror-image solutions of a dyad the one nearer to the guessed
    vector (RRR: the side of the known vector w that the guessed first link lies on; RRP, RPR:
    the guessed length's side of the foot of the perpendicular; PP: +1). Returns
    `(q, assemblable, residual, sigma)`; q within ±π of the guess.
    """
    q, ok, resid, sig, _ = _solve(mech, dyads, None, q_guess, phi, p, trig)
    return q, ok, resid, sig


def reach_margins(mech: Mechanism, dyads, sigma, q_ref, phi, p, trig=None):
    """The reach margin of every dyad at input φ on the branches σ: (n_dyads,), dimensionless,
    smooth in φ and p, negative exactly where the dyad cannot be assembled.

    The signed square of the `sine` of `solve`, written without a square root so that it goes on
    smoothly through zero (the branch point):

    - RRR: m = ((|a| + |b|)² − |w|²)(|w|² − (|a| − |b|)²) / (4 |a|² |b|²) = h² |w|² / (|a|² |b|²),
      sin² of the angle between the two links where it is ≥ 0; < 0 where |w| > |a| + |b| (the
      links cannot reach) or |w| < ||a| − |b|| (they cannot fold so short);
    - RRP: m = 1 − (w × d)² / (|a|² |d|²) = h² / (|a|² |d|²);
    - RPR: m = 1 − (a × b)² / (|b|² |w|²) = h² / (|b|² |w|²), < 0 where the pivot is nearer to
      the slot's line than its offset (|w| < |e|); ≡ 1 for a slot through the pivot (0 where w = 0:
      the slider on the pivot, where θ is undetermined);
    - PP: m = (d_a × d_b)² / (|d_a|² |d_b|²) (never negative: a PP dyad fails only with parallel
      directions).

    A later dyad's margin uses the earlier dyads' solution on σ (collinear where they cannot be
    assembled). The feasibility certificate (`jaxlink.analysis.feasibility`) minimizes it between
    samples; a branch-point locator can bisect on its zero."""
    return _solve(mech, dyads, sigma, q_ref, phi, p, trig, arith=True, margins=True)[-1]


def _known_parts(mech: Mechanism, dyad: Dyad, env, trig=None):
    """w = −Σ of the loop's other (known) vectors."""
    terms = mech.loops[dyad.loop][1]
    sx, sy = 0.0, 0.0
    for i in dyad.rest:
        x, y = mech.term_vector(terms[i], env, trig)
        sx, sy = sx + x, sy + y
    return -sx, -sy


def _vectors(mech: Mechanism, pt: Part, env, trig):
    """(s m e, s k e) of a part (None for 0): e = e(c) in the frame of the angle that turns it,
    e(α) for a known angle; (s m_x, s m_y), (s k_x, s k_y) for a Cartesian part."""
    ev = _expr.evaluate
    out: list[Any] = []
    if pt.polar:
        c, s = mech.unit_vector(pt.angle, env, trig)
        for node, role in ((pt.const[0], _expr.LENGTH), (pt.coef[0], _expr.NUMBER)):
            v = None if node is None else pt.sign * ev(node, env, mech.kinds, mech.units, role)
            out.append(None if v is None else (v * c, v * s))
        return out[0], out[1]
    for nodes, role in ((pt.const, _expr.LENGTH), (pt.coef, _expr.NUMBER)):
        if nodes[0] is None and nodes[1] is None:
            out.append(None)
            continue
        out.append(tuple(0.0 if n is None else pt.sign * ev(n, env, mech.kinds, mech.units, role) for n in nodes))
    return out[0], out[1]


def _vsum(vs):
    vs = [v for v in vs if v is not None]
    if not vs:
        return None
    x, y = vs[0]
    for a, b in vs[1:]:
        x, y = x + a, y + b
    return x, y


def _body(mech: Mechanism, parts, env, trig) -> _forms.Body:
    """The known vector turned by an angle: L e(c) as written for one term (no new square root),
    else the length and direction of the sum of its terms."""
    if len(parts) == 1 and parts[0].polar:
        pt = parts[0]
        L = _expr.evaluate(pt.const[0], env, mech.kinds, mech.units, _expr.LENGTH)
        return _forms.Body(pt.sign * L, mech.unit_vector(pt.angle, env, trig))
    v = _vsum([_vectors(mech, pt, env, trig)[0] for pt in parts])
    return _forms.body_of(*v)


def _slide(mech: Mechanism, parts, env, trig):
    """The coefficient vector of a length in `parts` (the slides among them), whether it is a unit
    vector as written (one term `±ℓ @ α`), and the sum of the parts' known vectors (or None)."""
    vecs = [_vectors(mech, pt, env, trig) for pt in parts]
    unit = len(parts) == 1 and parts[0].polar and parts[0].coef[0] == _expr.Num(1.0)
    return _vsum([v[1] for v in vecs]), unit, _vsum([v[0] for v in vecs])


def geometry(mech: Mechanism, d: Dyad, env, trig=None):
    """The known vectors of dyad `d` at `env` (every earlier unknown in it): `(w, first, second)` —
    RRR: the bodies a, b (`forms.Body`); RRP: a, (d, unit); RPR: (a vector or None), (b, unit);
    PP: (d_a, unit), (d_b, unit)."""
    wx, wy = _known_parts(mech, d, env, trig)
    fixed = d.slot(None)
    first: Any
    second: Any
    if d.kind == "RRR":
        first, second = _body(mech, d.slot(0), env, trig), _body(mech, d.slot(1), env, trig)
    elif d.kind == "RRP":
        first = _body(mech, d.slot(0), env, trig)
        dv, unit, known = _slide(mech, fixed, env, trig)
        second = (dv, unit)
        fixed = ()
        if known is not None:
            wx, wy = wx - known[0], wy - known[1]
    elif d.kind == "RPR":
        turned = d.slot(0)
        bv, unit, a = _slide(mech, [pt for pt in turned if pt.slide is not None], env, trig)
        a = _vsum([a] + [_vectors(mech, pt, env, trig)[0] for pt in turned if pt.slide is None])
        first, second = a, (bv, unit)
    else:
        da, ua, ka = _slide(mech, [pt for pt in fixed if pt.slide == 0], env, trig)
        db, ub, kb = _slide(mech, [pt for pt in fixed if pt.slide == 1], env, trig)
        first, second = (da, ua), (db, ub)
        fixed = ()
        for k in (ka, kb):
            if k is not None:
                wx, wy = wx - k[0], wy - k[1]
    for pt in fixed:  # the known parts of terms that do not turn (none beside the kinds above)
        k = _vectors(mech, pt, env, trig)[0]
        if k is not None:
            wx, wy = wx - k[0], wy - k[1]
    return (wx, wy), first, second


def _solve(mech, dyads, sigma, q_ref, phi, p, trig, with_trig: bool = False, arith: bool = False,
           margins: bool = False):
    ok_all = jnp.asarray(True)
    margin_list = []
    resid = None
    sine = None
    trig = dict(trig) if trig else {}
    if mech.input_kind == "angle" and mech.input_name not in trig:
        trig[mech.input_name] = (jnp.cos(phi), jnp.sin(phi))
    env = {n: p[i] for i, n in enumerate(mech.parameter_names)}
    env[mech.input_name] = phi
    sig_used = []
    for k, d in enumerate(dyads):
        ia, ib = d.unknowns
        w, first, second = geometry(mech, d, env, trig)
        if d.kind == "RRR":
            if sigma is None:  # the side of w that the guessed first vector lies on
                s = _forms.side_rrr(first, w, (jnp.cos(q_ref[ia]), jnp.sin(q_ref[ia])))
            else:
                s = sigma[k]
            out = _forms.rrr(first, second, w, s, arith)
        elif d.kind == "RRP":
            dv, unit = second
            s = _forms.side_rrp(dv, unit, w, q_ref[ib]) if sigma is None else sigma[k]
            out = _forms.rrp(first, dv, unit, w, s, arith)
        elif d.kind == "RPR":
            bv, unit = second
            s = _forms.side_rpr(first, bv, unit, q_ref[ib]) if sigma is None else sigma[k]
            out = _forms.rpr(first, bv, unit, w, s, arith)
        else:  # PP
            s = jnp.ones_like(jnp.asarray(w[0]))
            (da, ua), (db, ub) = first, second
            out = _forms.pp(da, ua, db, ub, w)
        for i, (value, cs) in zip(d.unknowns, out.values):
            name = mech.unknown_names[i]
            env[name] = value
            if cs is not None:
                trig[name] = cs
        if margins:
            margin_list.append(out.margin)
        sig_used.append(jnp.asarray(s, dtype=q_ref.dtype))
        ok_all = ok_all & out.ok
        resid = out.miss if resid is None else jnp.maximum(resid, out.miss)
        sine = out.sine if sine is None else jnp.minimum(sine, out.sine)
    # (an unknown of no dyad given — a prefix of the dyads, `branch_points` — is q_ref's)
    q = jnp.stack([
        _wrap_near(env[n], q_ref[i]) if k == "angle" and n in env
        else jnp.asarray(env.get(n, q_ref[i]), dtype=q_ref.dtype)
        for i, (n, k) in enumerate(zip(mech.unknown_names, mech.unknown_kinds))
    ])
    sig = jnp.stack(sig_used) if sig_used else jnp.zeros((0,), q_ref.dtype)
    if margins:
        return q, ok_all, resid, sig, sine, jnp.stack([jnp.asarray(m, q_ref.dtype) for m in margin_list])
    if with_trig:
        return q, ok_all, resid, sig, sine, trig
    return q, ok_all, resid, sig, sine
