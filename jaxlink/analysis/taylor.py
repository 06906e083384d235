"""Derivatives of any order along the cycle, a position at any input value, and an extreme located
between the samples — exact, by forward-mode AD, with the same Jacobian Φ_q as the position solve.

**Derivatives** (`series`). Along the solution curve q(φ) of a 1-DOF mechanism, with
c(s) = (q + Σ_{i≥1} q⁽ⁱ⁾ sⁱ / i!, φ + s):

    Φ_q q⁽ʲ⁾ = −dʲ/dsʲ Φ(c_j(s))|_{s=0}      j = 1, 2, …, K

where c_j carries q⁽¹⁾ … q⁽ʲ⁻¹⁾ and q⁽ʲ⁾ = 0 (the j-th derivative of Φ along c is linear in q⁽ʲ⁾ with
coefficient Φ_q): one linear solve per order, the right-hand side by j nested `jax.jvp` of
s ↦ Φ(c(s)). The points' derivatives P⁽ʲ⁾ = dʲ/dsʲ P(c_K(s)). Per radian of the input; with a
constant input speed ω, dʲ/dtʲ = ωʲ dʲ/dφʲ. Orders 1 and 2 are `transfer.rates`' μ and ν.

**A position at any input** (`position_at`): from a solved position (q, φ) a step h: the
predictor q + q⁽¹⁾ h + q⁽²⁾ h² / 2, then Newton on Φ(·, φ + h) = 0 (`NEWTON` steps, held out of the
derivative), then `TRACED` Newton steps traced in p: the derivative with respect to p is the
implicit one, −Φ_q⁻¹ Φ_p, exact (two traced steps make the second derivative exact too).

**An extreme between the samples** (`refine_extreme`): from the largest sample of a scalar f(φ)
(a coordinate, a projection, a rate, or a squared norm), Newton on f′(φ) = 0, f′ and f″ exact from
`series` (`EXTREME_STEPS` steps, each step at most one sample spacing, a non-concave f″ stepping
half a spacing uphill): the extreme's input φ*, to rounding. Its value's derivative with respect
to p is f's at φ* held fixed (the extreme's move does not count to first order: f′(φ*) = 0).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from ..model.mechanism import Mechanism
from ..solvers.linalg import solve_small

#: Newton steps of a position at a new input (held out of the derivative), then traced ones
NEWTON = 4
TRACED = 2
#: Newton steps locating an extreme between the samples
EXTREME_STEPS = 6


def _derivatives(h, n: int):
    """s ↦ (h(s), h′(s), …, h⁽ⁿ⁾(s)) by `n` nested `jax.jvp`."""
    if n == 0:
        return lambda s: (h(s),)
    low = _derivatives(h, n - 1)

    def f(s):
        v, t = jax.jvp(low, (s,), (jnp.ones_like(s),))
        return v + (t[-1],)

    return f


def _curve(q, phi, qs):
    """s ↦ (q + Σ q⁽ⁱ⁾ sⁱ / i!, φ + s)."""
    def c(s):
        return q + sum(qk * s ** (k + 1) / math.factorial(k + 1) for k, qk in enumerate(qs)), phi + s
    return c


def series(mech: Mechanism, q, phi, p, order: int):
    """(qs (order + 1, n), points (order + 1, n_points, 2)): the unknowns' and the points'
    derivatives of orders 0 … `order` with respect to the input at the solved position (q, φ)
    (module doc; `order` static)."""
    res = lambda qq, ph: mech.residual(qq, ph, p)  # noqa: E731
    jac = jax.jacfwd(res)(q, phi)
    s0 = jnp.zeros_like(phi)
    qs: list = []
    for j in range(1, order + 1):
        c = _curve(q, phi, qs + [jnp.zeros_like(q)])
        rhs = _derivatives(lambda s, c=c: res(*c(s)), j)(s0)[-1]
        x, _ = solve_small(jac, rhs)
        qs.append(-x)
    c = _curve(q, phi, qs)
    pts = _derivatives(lambda s: mech.point_positions(*c(s), p), order)(s0)
    return jnp.stack([q] + qs), jnp.stack(pts)


def newton(mech: Mechanism, q, phi, p, steps: int, loop: bool = False):
    """`steps` Newton steps on Φ(·, φ, p) = 0 from q (traced: differentiate through them);
    `loop`: in a `lax.fori_loop` (not unrolled: for steps held out of the derivative)."""
    res = lambda qq: mech.residual(qq, phi, p)  # noqa: E731

    def step(_, q):
        x, _ = solve_small(jax.jacfwd(res)(q), res(q))
        return q - x

    if loop:
        return jax.lax.fori_loop(0, steps, step, q)
    for i in range(steps):
        q = step(i, q)
    return q


def position_held(mech: Mechanism, q, phi, p, h):
    """The position at the input φ + h from the solved position (q, φ): the predictor and
    `NEWTON` steps in a loop, nothing traced (`position_at` without its traced steps)."""
    q, p = jax.lax.stop_gradient(q), jax.lax.stop_gradient(p)
    qs, _ = series(mech, q, phi, p, 2)
    return jax.lax.stop_gradient(newton(mech, qs[0] + qs[1] * h + 0.5 * qs[2] * h * h, phi + h, p, NEWTON, loop=True))


def position_at(mech: Mechanism, q, phi, p, h):
    """The position at the input φ + h from the solved position (q, φ) (module doc): the unknowns
    at φ + h, their derivative with respect to p the implicit one."""
    return newton(mech, position_held(mech, q, phi, p, h), phi + h, p, TRACED)


def refine_extreme(mech: Mechanism, q, phi, p, f, order: int, spacing: float):
    """(φ*, q*) the input and position of f's maximum near the sample (q, φ), f′(φ*) = 0 (module
    doc), held out of the derivative. `f(qs, points)` → (f, f′, f″) from a `series` of `order`
    (static: the quantity's own order + 2); `spacing` the samples' spacing (rad)."""
    ps = jax.lax.stop_gradient(p)

    def body(_, state):
        q, phi = state
        qs, pts = series(mech, q, phi, ps, max(order, 2))  # one series: the step and the predictor
        _, d1, d2 = f(qs, pts)
        concave = d2 < 0
        step = jnp.where(concave, -d1 / jnp.where(concave, d2, -1.0), 0.5 * spacing * jnp.sign(d1))
        step = jnp.clip(jnp.where(jnp.isfinite(step), step, 0.0), -spacing, spacing)
        q = newton(mech, qs[0] + qs[1] * step + 0.5 * qs[2] * step * step, phi + step, ps, NEWTON, loop=True)
        return q, phi + step

    state = (jax.lax.stop_gradient(q), jax.lax.stop_gradient(jnp.asarray(phi, q.dtype)))
    q, phi = jax.lax.fori_loop(0, EXTREME_STEPS, body, state)
    return jax.lax.stop_gradient(phi), jax.lax.stop_gradient(q)
