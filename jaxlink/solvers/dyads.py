"""Closed-form solutions of the dyads (Assur groups of class II) of a loop-closure system.

A block of `_structure.blocks` that is one loop with two new unknowns is a dyad when each unknown
appears in exactly one vector of the loop, as follows (s = ±1 the term's sign; L, c, e known):

- **RRR** — two angles:  s_a L_a e(θ_a + c_a) + s_b L_b e(θ_b + c_b) = w  (w = −Σ other vectors).
  With u the first vector and v = w − u:  |u| = r_a, |w − u| = r_b, a circle–circle intersection
      u = x ŵ + σ h ŵ⊥,   x = (|w|² + r_a² − r_b²) / (2|w|),   h = √(r_a² − x²).
- **RRP** — an angle and a length (a slider):  s_a L_a e(θ_a + c_a) + s_b ℓ e_b = w,  with e_b a
  known unit vector:  |w − s_b ℓ e_b| = r_a  gives  s_b ℓ = w·e_b + σ √(r_a² − (w × e_b)²).
- **PP** — two lengths along known directions: a 2×2 linear system (Cramer).

σ = ±1 is the *assembly branch* (circuit) of the dyad. It is chosen once, at the first input, as
the side of the guess (`solve_nearest`: dyad by dyad, the mirror image nearer to the guessed
configuration) and kept: the closed form then stays on that branch for every input and every
design, with no Newton and no continuation. Where the square root's argument h² is ≤ 0 the dyad
is put in its collinear configuration (h = 0, the least-squares closest) and the returned residual
says by how much its loop misses: rounding at the exact toggle (assembled, within the tolerance),
more past it (cannot be assembled). The output stays finite (the double-`where` trick keeps
gradients NaN-free). `solve` also returns the sine of the angle between the columns of
each dyad's block of Φ_q (≈ 0: dead centre, toggle or change point, a singular position). Angles
are returned within ±π of the reference configuration.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from ..files import expr as _expr
from ..model.mechanism import Mechanism
from ..model.structure import blocks
from .angles import atan2, sincos


@dataclasses.dataclass(frozen=True)
class Dyad:
    kind: str  # "RRR" | "RRP" | "PP"
    loop: int
    unknowns: tuple  # (a, b) indices into q
    terms: tuple  # (term index of a, term index of b)
    offsets: tuple  # (angle offset node or None, ...) for angle unknowns: θ = q + offset
    rest: tuple  # indices of the other terms of the loop


def _angle_offset(node, name):
    """If `node` is `name + c` (c free of `name`), return c's node (or Num(0)); else None."""
    if isinstance(node, _expr.Name):
        return _expr.Num(0.0) if node.name == name else None
    if isinstance(node, _expr.Bin) and node.op in "+-":
        inl = any(n.name == name for n in _expr.names_in(node.left))
        inr = any(n.name == name for n in _expr.names_in(node.right))
        if inl and not inr:
            c = _angle_offset(node.left, name)
            if c is None:
                return None
            return _expr.Bin(node.op, c, node.right)
        if inr and not inl and node.op == "+":
            c = _angle_offset(node.right, name)
            if c is None:
                return None
            return _expr.Bin("+", node.left, c)
    return None


def _contains(node, names) -> bool:
    return any(n.name in names for n in _expr.names_in(node))


def classify(mech: Mechanism) -> tuple | None:
    """The dyads of every block, in solve order, or None if some block has no closed form."""
    out = []
    for loops, unk in blocks(mech):
        if len(loops) != 1 or len(unk) != 2:
            return None
        li = loops[0]
        terms = mech.loops[li][1]
        names = [mech.unknown_names[i] for i in unk]
        where = {}
        for ti, t in enumerate(terms):
            inside = [n for n in names if any(_contains(nd, {n}) for nd in t.nodes())]
            if len(inside) > 1:
                return None
            if inside:
                if inside[0] in where:
                    return None
                where[inside[0]] = ti
        if len(where) != 2:
            return None
        kinds = []
        offsets = []
        for n in names:
            t = terms[where[n]]
            if not t.polar:
                return None
            if not _contains(t.length, {n}) and _contains(t.angle, {n}):
                off = _angle_offset(t.angle, n)
                if off is None:
                    return None
                kinds.append("R")
                offsets.append(off)
            elif isinstance(t.length, _expr.Name) and t.length.name == n and not _contains(t.angle, set(names)):
                kinds.append("P")
                offsets.append(None)
            else:
                return None
        kind = "".join(sorted(kinds, reverse=True))  # "RR", "RP" or "PP"
        order = (0, 1) if kinds[0] >= kinds[1] else (1, 0)  # R before P
        a, b = (unk[order[0]], unk[order[1]])
        na, nb = names[order[0]], names[order[1]]
        out.append(Dyad(
            kind={"RR": "RRR", "RP": "RRP", "PP": "PP"}[kind],
            loop=li,
            unknowns=(a, b),
            terms=(where[na], where[nb]),
            offsets=(offsets[order[0]], offsets[order[1]]),
            rest=tuple(i for i in range(len(terms)) if i not in (where[na], where[nb])),
        ))
    return tuple(out)


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def _safe_sqrt(x):
    """√x and x > 0; 0 where x ≤ 0 (the collinear configuration h = 0: its miss is in the residual)."""
    ok = x > 0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, x, 1.0)), 0.0), ok


def _inverse(L):
    return 1.0 / jnp.where(L != 0, L, 1.0)


def _known_parts(mech: Mechanism, dyad: Dyad, env, trig=None):
    """w = −Σ of the loop's other (known) vectors."""
    terms = mech.loops[dyad.loop][1]
    sx, sy = 0.0, 0.0
    for i in dyad.rest:
        x, y = mech.term_vector(terms[i], env, trig)
        sx, sy = sx + x, sy + y
    return -sx, -sy


def _radius_and_offset(mech, term, offset, env, trig):
    """For `s L @ (q + c)`: returns (signed length s·L, (cos c, sin c))."""
    L = _expr.evaluate(term.length, env, mech.kinds, mech.units, _expr.LENGTH)
    return term.sign * L, mech.unit_vector(offset, env, trig)


def _angle_from(ux, uy, L, inv_L, cs, arith: bool = False):
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
    position is assembled. Each dyad's loop closes exactly in the vectors u, v it constructs; the
    unit vectors of the solved angles are u/L_a and v/L_b, so the loop residual with the solved
    angles is (|L_a| − |u|) û + (|L_b| − |v|) v̂. `residual` is the largest
    ||L_a| − |u|| + ||L_b| − |v|| over the dyads: an upper bound of max|Φ| at the solution, exact
    to rounding, computed without further trigonometry (it exposes the loss of accuracy next to a
    dead centre). `sine` is the smallest over the dyads of the sine of the angle between the
    columns of the dyad's block of Φ_q — RRR: between the two links, h |w| / (|L_a| |L_b|); RRP:
    the link against the slider's normal, h / |L_a|; PP: between the two directions — 0 at a dead
    centre, a toggle or a change point (h = 0, where the two branches meet), for a few multiplies.
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
    vector (RRR: the side of the known vector w that the guessed first link lies on; RRP: the
    guessed slider position's side of the foot of the perpendicular). Returns
    `(q, assemblable, residual, sigma)`; q within ±π of the guess.
    """
    q, ok, resid, sig, _ = _solve(mech, dyads, None, q_guess, phi, p, trig)
    return q, ok, resid, sig


def reach_margins(mech: Mechanism, dyads, sigma, q_ref, phi, p, trig=None):
    """The reach margin of every dyad at input φ on the branches σ: (n_dyads,), dimensionless,
    smooth in φ and p, negative exactly where the dyad cannot be assembled.

    The signed square of the `sine` of `solve`, written without a square root so that it goes on
    smoothly through zero (the branch point):

    - RRR: m = ((L_a + L_b)² − |w|²)(|w|² − (L_a − L_b)²) / (4 L_a² L_b²) = h² |w|² / (L_a² L_b²),
      sin² of the angle between the two links where it is ≥ 0; < 0 where |w| > L_a + L_b (the
      links cannot reach) or |w| < |L_a − L_b| (they cannot fold so short);
    - RRP: m = 1 − ((w × e_b) / L_a)² = h² / L_a²;
    - PP: m = (e_a × e_b)² (never negative: a PP dyad fails only with parallel directions).

    A later dyad's margin uses the earlier dyads' solution on σ (collinear where they cannot be
    assembled). The feasibility certificate (`jaxlink.analysis.feasibility`) minimizes it between
    samples; a branch-point locator can bisect on its zero."""
    return _solve(mech, dyads, sigma, q_ref, phi, p, trig, arith=True, margins=True)[-1]


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
        terms = mech.loops[d.loop][1]
        ta, tb = terms[d.terms[0]], terms[d.terms[1]]
        wx, wy = _known_parts(mech, d, env, trig)
        ia, ib = d.unknowns
        na, nb = mech.unknown_names[ia], mech.unknown_names[ib]
        if d.kind == "RRR":
            La, csa = _radius_and_offset(mech, ta, d.offsets[0], env, trig)
            Lb, csb = _radius_and_offset(mech, tb, d.offsets[1], env, trig)
            if sigma is None:  # the side of w that the guessed first vector lies on
                ca, sa = mech.unit_vector(ta.angle, {**env, na: q_ref[ia]})
                s = jnp.where(_cross((wx, wy), (La * ca, La * sa)) >= 0, 1.0, -1.0)
            else:
                s = sigma[k]
            w2 = wx * wx + wy * wy
            inv_w = 1.0 / jnp.sqrt(jnp.where(w2 > 0, w2, 1.0))
            x = 0.5 * (w2 + La * La - Lb * Lb) * inv_w
            h, ok = _safe_sqrt(La * La - x * x)
            ux = (x * wx - s * h * wy) * inv_w
            uy = (x * wy + s * h * wx) * inv_w
            inv_a, inv_b = _inverse(La), _inverse(Lb)
            env[na], trig[na], miss_a = _angle_from(ux, uy, La, inv_a, csa, arith)
            env[nb], trig[nb], miss_b = _angle_from(wx - ux, wy - uy, Lb, inv_b, csb, arith)
            miss = miss_a + miss_b
            # |u × v| / (|La| |Lb|) with v = w − u: |u × w| = h |w|
            sin_d = h * (w2 * inv_w) * jnp.abs(inv_a * inv_b)
            if margins:
                margin_list.append(((La + Lb) ** 2 - w2) * (w2 - (La - Lb) ** 2) * (0.5 * inv_a * inv_b) ** 2)
        elif d.kind == "RRP":
            La, csa = _radius_and_offset(mech, ta, d.offsets[0], env, trig)
            ca, sa = mech.unit_vector(tb.angle, env, trig)
            ex, ey = ca * tb.sign, sa * tb.sign  # the slider term is ℓ·(ex, ey)
            along = wx * ex + wy * ey
            across = wx * ey - wy * ex
            s = jnp.where(q_ref[ib] - along >= 0, 1.0, -1.0) if sigma is None else sigma[k]
            h, ok = _safe_sqrt(La * La - across * across)
            ell = along + s * h
            inv_a = _inverse(La)
            env[na], trig[na], miss = _angle_from(wx - ell * ex, wy - ell * ey, La, inv_a, csa, arith)
            env[nb] = ell
            sin_d = h * jnp.abs(inv_a)  # the link's component along the slider, over its length
            if margins:
                margin_list.append(1.0 - (across * inv_a) ** 2)
        else:  # PP: ℓa ea + ℓb eb = w
            s = jnp.ones_like(jnp.asarray(wx))
            ca, sa = mech.unit_vector(ta.angle, env, trig)
            cb, sb = mech.unit_vector(tb.angle, env, trig)
            ea = (ta.sign * ca, ta.sign * sa)
            eb = (tb.sign * cb, tb.sign * sb)
            det = _cross(ea, eb)
            ok = jnp.abs(det) > 1e-12
            sin_d = jnp.abs(det)
            if margins:
                margin_list.append(det * det)
            det = jnp.where(ok, det, 1.0)
            la, lb = _cross((wx, wy), eb) / det, _cross(ea, (wx, wy)) / det
            env[na], env[nb] = la, lb
            # zero to rounding, but honest where the directions are parallel (no solution)
            miss = jnp.maximum(jnp.abs(la * ea[0] + lb * eb[0] - wx), jnp.abs(la * ea[1] + lb * eb[1] - wy))
        sig_used.append(jnp.asarray(s, dtype=q_ref.dtype))
        ok_all = ok_all & ok
        resid = miss if resid is None else jnp.maximum(resid, miss)
        sine = sin_d if sine is None else jnp.minimum(sine, sin_d)
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
