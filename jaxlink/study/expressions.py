"""The study's response expressions: a point's travel along an axis, a value at a named input
angle, an extreme over the cycle — written in `[study] metrics` next to the named metrics
(`stroke`, `speed`, …), each one scalar response (with spec limits, Cpk, first order and the worst
case like the others). docs/reference/file-format.md §17 gives the syntax:

    metrics = ["travel(Z, x)", "vx(Z) @ 30", "ay(Z) @ [30, 90]", "max(v(Z))", "min(phi4)"]

**Quantities.** Of a point P: `x(P)`, `y(P)` (position), `vx(P)`, `vy(P)`, `ax(P)`, `ay(P)`,
`jx(P)`, `jy(P)` (velocity, acceleration, jerk components), `v(P)`, `a(P)`, `j(P)` (their
magnitudes). Of an unknown U (an angle or a length of `[unknowns]`): `U` (its value), `v(U)`,
`a(U)`, `j(U)` (its first, second, third derivative). A rate is per second when `[study] rpm` is
given (a constant input speed ω: dᵏ/dtᵏ = ωᵏ dᵏ/dφᵏ), per radian of the input otherwise; its unit
says which (`mm/s`, `mm/s^2`, … or `mm/rad`, `mm/rad^2`, …).

**Expressions.**

- `travel(P, AXIS)`: max − min over the cycle of P's projection on the unit vector of AXIS:
  `x`, `y`, an angle from +x in the file's angle unit (`travel(Z, 30)`), or a vector
  `travel(Z, (1, 1))` (normalized) — a feed-dog stroke, a needle's travel;
- `Q @ ANGLE`: the quantity at the input value ANGLE (the file's angle unit; `Q @ [a, b, …]` is one
  response per angle), the position solved there from the nearest sample (not the nearest sample);
- `max(Q)`, `min(Q)`: its extreme over the cycle.

An extreme is located between the samples by Newton on the quantity's derivative
(`jaxlink.analysis.taylor.refine_extreme`: exact derivatives, not a parabola through samples), so
its value is that of the continuous cycle to rounding, whatever `positions`; its derivative with
respect to the parameters is the quantity's at the extreme (exact: the extreme's move does not
count to first order, f′ = 0 there).
"""

from __future__ import annotations

import math
import re
from typing import NamedTuple

import numpy as np

#: point quantities: name → (order, component)
POINT_QUANTITIES = {"x": (0, "x"), "y": (0, "y"), "vx": (1, "x"), "vy": (1, "y"), "ax": (2, "x"), "ay": (2, "y"),
                    "jx": (3, "x"), "jy": (3, "y"), "v": (1, "norm"), "a": (2, "norm"), "j": (3, "norm")}
#: unknown quantities: name → order (the bare name is the value, order 0)
UNKNOWN_QUANTITIES = {"v": 1, "a": 2, "j": 3}
SYNTAX = ("travel(P, x | y | ANGLE | (a, b)), Q @ ANGLE, Q @ [ANGLE, …], max(Q), min(Q); Q one of x(P), y(P), "
          "vx(P), vy(P), ax(P), ay(P), jx(P), jy(P), v(P), a(P), j(P) of a point P, or U, v(U), a(U), j(U) of "
          "an unknown U")


class Quantity(NamedTuple):
    """One quantity: `text` (as written back, `vx(Z)`), `point` (a point's, else an unknown's),
    `ref` (its index in `mech.point_names` or `mech.unknown_names`), `order` (0 value … 3 jerk),
    `component` ("x" | "y" | "norm" of a point, "" of an unknown), `angle` (an angle unknown)."""

    text: str
    point: bool
    ref: int
    order: int
    component: str
    angle: bool = False


class Expression(NamedTuple):
    """One response expression: `text` (its label), `kind` ("travel" | "at" | "max" | "min"),
    `quantity` (a `Quantity`; travel: the point's position), `axis` ((cx, cy) unit vector of a
    travel), `at` (the input value of "at", the file's angle unit)."""

    text: str
    kind: str
    quantity: Quantity
    axis: tuple | None = None
    at: float | None = None


_NAME = r"[A-Za-z_][A-Za-z0-9_]*"
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def is_expression(text: str) -> bool:
    """Whether a `metrics` entry is an expression (not one of the named metrics)."""
    return isinstance(text, str) and ("(" in text or "@" in text)


def parse(mech, text: str) -> tuple:
    """The `Expression`s of one `metrics` entry (several for `Q @ [a, b, …]`); raises ValueError
    with what is wrong (and a did-you-mean for a misspelt name)."""
    s = " ".join(str(text).split())
    m = re.fullmatch(rf"travel\s*\(\s*({_NAME})\s*,\s*(.+?)\s*\)", s)
    if m:
        q = _quantity(mech, f"x({m.group(1)})")
        axis, shown = _axis(mech, m.group(2))
        return (Expression(f"travel({m.group(1)}, {shown})", "travel", q._replace(component="axis"), axis),)
    m = re.fullmatch(r"(max|min)\s*\(\s*(.+)\s*\)", s)
    if m and "@" not in s:
        q = _quantity(mech, m.group(2))
        return (Expression(f"{m.group(1)}({q.text})", m.group(1), q),)
    if "@" in s:
        left, _, right = s.partition("@")
        q = _quantity(mech, left.strip())
        right = right.strip()
        if right.startswith("[") and right.endswith("]"):
            items = [r.strip() for r in right[1:-1].split(",")]
        else:
            items = [right]
        out = []
        for it in items:
            if not re.fullmatch(_NUMBER, it):
                raise ValueError(f"'{text}': the input angle after @ is a number in the file's angle unit (or a list "
                                 f"[a, b, …]), got '{it}'")
            out.append(Expression(f"{q.text} @ {float(it):.12g}", "at", q, at=float(it)))
        if not out:
            raise ValueError(f"'{text}': no input angle after @")
        return tuple(out)
    q = _quantity(mech, s)  # a quantity alone (its own error where it is not one)
    raise ValueError(f"'{text}': a quantity over the cycle is not one number: write {q.text} @ ANGLE, max({q.text}) "
                     f"or min({q.text}); the expressions: {SYNTAX}")


def _quantity(mech, s: str) -> Quantity:
    from ..files.keys import suggest

    s = s.strip()
    unknowns, points = tuple(mech.unknown_names), tuple(mech.point_names)
    m = re.fullmatch(rf"({_NAME})\s*\(\s*({_NAME})\s*\)", s)
    if m:
        f, name = m.groups()
        if name in points and f in POINT_QUANTITIES:
            order, comp = POINT_QUANTITIES[f]
            return Quantity(f"{f}({name})", True, points.index(name), order, comp)
        if name in unknowns and f in UNKNOWN_QUANTITIES:
            i = unknowns.index(name)
            return Quantity(f"{f}({name})", False, i, UNKNOWN_QUANTITIES[f], "", mech.unknown_kinds[i] == "angle")
        if f not in POINT_QUANTITIES:
            raise ValueError(f"'{s}': unknown quantity '{f}'{suggest(f, POINT_QUANTITIES)}; of a point: "
                             f"{', '.join(POINT_QUANTITIES)}; of an unknown: U, {', '.join(UNKNOWN_QUANTITIES)}")
        if name in unknowns:
            raise ValueError(f"'{s}': '{f}' is a point's quantity and '{name}' an unknown; of an unknown: {name}, "
                             + ", ".join(f"{g}({name})" for g in UNKNOWN_QUANTITIES))
        raise ValueError(f"'{s}': unknown point '{name}'{suggest(name, points + unknowns)}; points: "
                         f"{', '.join(points) or '(none)'}; unknowns: {', '.join(unknowns)}")
    if re.fullmatch(_NAME, s):
        if s in unknowns:
            i = unknowns.index(s)
            return Quantity(s, False, i, 0, "", mech.unknown_kinds[i] == "angle")
        raise ValueError(f"'{s}': unknown unknown{suggest(s, unknowns + points)}; unknowns: {', '.join(unknowns)} "
                         f"(a point's coordinate is x(P) or y(P))")
    raise ValueError(f"'{s}' is not a quantity; the quantities: x(P), y(P), vx(P), vy(P), ax(P), ay(P), jx(P), "
                     "jy(P), v(P), a(P), j(P) of a point, U, v(U), a(U), j(U) of an unknown")


def _axis(mech, s: str) -> tuple:
    """(unit vector, text) of a travel's axis."""
    s = s.strip()
    if s in ("x", "y"):
        return ((1.0, 0.0) if s == "x" else (0.0, 1.0)), s
    if re.fullmatch(_NUMBER, s):
        a = float(s) * mech.units.angle
        return (math.cos(a), math.sin(a)), f"{float(s):.12g}"
    m = re.fullmatch(rf"[(\[]\s*({_NUMBER})\s*,\s*({_NUMBER})\s*[)\]]", s)
    if m:
        v = np.asarray([float(m.group(1)), float(m.group(2))])
        n = float(np.hypot(*v))
        if n > 0 and math.isfinite(n):
            return (float(v[0] / n), float(v[1] / n)), f"({float(m.group(1)):.12g}, {float(m.group(2)):.12g})"
    raise ValueError(f"travel's axis is x, y, an angle from +x in the file's angle unit or a vector (a, b) not "
                     f"zero, got '{s}'")


def unit(e: Expression, length_unit: str, angle_unit: str, per_second: bool) -> str:
    """The unit of an expression's response: the file's unit of the quantity, over s^k (a speed
    given) or rad^k of the input (none given)."""
    q = e.quantity
    base = angle_unit if (not q.point and q.angle) else length_unit
    if q.order == 0 or e.kind == "travel":
        return base
    per = "s" if per_second else "rad"
    return f"{base}/{per}" + (f"^{q.order}" if q.order > 1 else "")


def scale(e: Expression, mech, omega: float | None) -> float:
    """SI (per radian of the input) → the response's unit."""
    q = e.quantity
    f = mech.units.angle if (not q.point and q.angle) else mech.units.length
    order = 0 if e.kind == "travel" else q.order
    return (omega ** order if omega else 1.0) / f


# ---------------------------------------------------------------------------------- traced

class _Legs(NamedTuple):
    """The extremes sought, one leg per max or min (a travel has two), as arrays so that one
    compiled Newton serves all the legs: f = sign (cp w·P⁽ᵏ⁾[ip] + cu q⁽ᵏ⁾[iu] + cn |P⁽ᵏ⁾[ip]|²)
    (a magnitude's square: the same argmax), k the leg's order."""

    sign: np.ndarray
    cp: np.ndarray
    cu: np.ndarray
    cn: np.ndarray
    ip: np.ndarray
    iu: np.ndarray
    w: np.ndarray
    turns: np.ndarray
    k: np.ndarray


def _legs(exprs, legs) -> _Legs:
    rows = []
    for j, sg in legs:
        e = exprs[j]
        q = e.quantity
        norm = q.point and q.component == "norm"
        w = e.axis if e.axis is not None else ((1.0, 0.0) if q.component == "x" else (0.0, 1.0))
        rows.append((sg, float(q.point and not norm), float(not q.point), float(norm), q.ref if q.point else 0,
                     0 if q.point else q.ref, w, float(not q.point and q.angle and q.order == 0), q.order))
    c = list(zip(*rows))
    f = [np.asarray(x, float) for x in c]
    return _Legs(f[0], f[1], f[2], f[3], np.asarray(c[4], int), np.asarray(c[5], int), f[6], f[7],
                 np.asarray(c[8], int))


def _leg_derivs(leg, qs, pts, n: int):
    """(f, f′, …)[:n] of one leg from a `series` table (`_Legs`; its order k an index)."""
    sign, cp, cu, cn, ip, iu, w, _turns, k = leg
    P = [pts[k + j, ip] for j in range(n)]
    g = [P[0] @ P[0], 2.0 * P[0] @ P[1], 2.0 * (P[1] @ P[1] + P[0] @ P[2])] if n == 3 else [P[0] @ P[0]]
    return tuple(sign * (cp * (P[j] @ w) + cu * qs[k + j, iu] + cn * g[j]) for j in range(n))


def _leg_value(leg, qs, pts):
    """The leg's quantity (not signed; a magnitude, not its square) from a `series` table."""
    import jax.numpy as jnp

    _sign, cp, cu, cn, ip, iu, w, _turns, k = leg
    P = pts[k, ip]
    return cp * (P @ w) + cu * qs[k, iu] + cn * jnp.sqrt(P @ P)


def evaluate(mech, exprs: tuple, qpath, phis, p, phi0: float):
    """(E,) the expressions' values (SI, per radian of the input) of one design: `qpath` (N, n) its
    solved positions at the cycle's inputs `phis` (N,) from `phi0` (module doc).

    One program for all the expressions, whatever their number and kinds (its compile is the
    cost of an expression, paid once): the named angles' positions (Newton from the nearest
    sample) and the extremes' inputs (one `refine_extreme` for every leg, orders as indices) are
    located with the parameters held (no derivative), then all of them get the same `TRACED`
    Newton steps (the implicit derivative) and one `series` of the highest order asked."""
    import jax
    import jax.numpy as jnp

    from ..analysis import taylor

    N = qpath.shape[0]
    spacing = 2.0 * math.pi / N
    af = mech.units.angle
    ps = jax.lax.stop_gradient(p)
    held = jax.lax.stop_gradient(qpath)
    turns = jnp.unwrap(qpath, axis=0) - qpath  # (N, n) the angle unknowns' whole turns from the start
    starts: list = []  # (q, φ) located with p held, then traced
    # values at named angles: the positions there, from the nearest sample
    ats = sorted({e.at for e in exprs if e.kind == "at"})
    if ats:
        d = [(a * af - phi0) % (2.0 * math.pi) for a in ats]
        r = [int(round(x / spacing)) for x in d]
        ks = np.asarray([ri % N for ri in r])
        hs = jnp.asarray([x - ri * spacing for x, ri in zip(d, r)], qpath.dtype)
        starts.append((jax.vmap(lambda q, ph, h: taylor.position_held(mech, q, ph, ps, h))(held[ks], phis[ks], hs),
                       phis[ks] + hs))
    # extremes: the largest sample of each leg, refined between the samples
    legs = [(j, sg) for j, e in enumerate(exprs) if e.kind != "at"
            for sg in ((1.0, -1.0) if e.kind == "travel" else ((1.0,) if e.kind == "max" else (-1.0,)))]
    if legs:
        top = max(exprs[j].quantity.order for j, _ in legs)
        arrays = tuple(jnp.asarray(a) for a in _legs(exprs, legs))
        table = jax.vmap(lambda q, ph: taylor.series(mech, q, ph, ps, top))(held, phis)
        F = jax.vmap(lambda leg: jax.vmap(lambda a, b: _leg_derivs(leg, a, b, 1)[0])(*table))(arrays)  # (L, N)
        F = F + (arrays[0] * arrays[7])[:, None] * turns[:, arrays[5]].T
        at = jnp.argmax(F, axis=1)

        def refine(leg, q, ph):
            return taylor.refine_extreme(mech, q, ph, ps, lambda a, b: _leg_derivs(leg, a, b, 3), top + 2, spacing)

        phi_s, q_s = jax.vmap(refine)(arrays, held[at], phis[at])
        starts.append((q_s, phi_s))
    if not starts:
        return jnp.zeros(0, qpath.dtype)
    Q = jax.lax.stop_gradient(jnp.concatenate([s[0] for s in starts]))
    PH = jax.lax.stop_gradient(jnp.concatenate([s[1] for s in starts]))
    order = max(e.quantity.order for e in exprs)
    qt = jax.vmap(lambda q, ph: taylor.newton(mech, q, ph, p, taylor.TRACED))(Q, PH)
    qs, pts = jax.vmap(lambda q, ph: taylor.series(mech, q, ph, p, order))(qt, PH)
    out: list = [None] * len(exprs)
    for j, e in enumerate(exprs):
        if e.kind != "at":
            continue
        a, q = ats.index(e.at), e.quantity
        if not q.point:
            v = qs[a, q.order, q.ref] + (turns[ks[a], q.ref] if q.angle and q.order == 0 else 0.0)
        elif q.component == "norm":
            v = jnp.linalg.norm(pts[a, q.order, q.ref])
        else:
            v = pts[a, q.order, q.ref, 0 if q.component == "x" else 1]
        out[j] = v
    if legs:
        n = len(ats)
        v = jax.vmap(_leg_value)(arrays, qs[n:], pts[n:]) + arrays[7] * turns[at, arrays[5]]
        values = {leg: v[i] for i, leg in enumerate(legs)}
        for j, e in enumerate(exprs):
            if e.kind == "travel":
                out[j] = values[(j, 1.0)] - values[(j, -1.0)]
            elif e.kind in ("max", "min"):
                out[j] = values[(j, 1.0 if e.kind == "max" else -1.0)]
    return jnp.stack(out)
