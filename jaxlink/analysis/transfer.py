"""Velocities, accelerations and transfer functions from the solved positions — exact, by
forward-mode AD, with the same Jacobian Φ_q as the position solve.

For a 1-DOF mechanism with input φ, along the solution curve q(φ) :

    Φ_q μ = −Φ_φ                                μ = dq/dφ        (first transfer function)
    Φ_q ν = −d²/ds² Φ(q + s μ, φ + s)|_{s=0}    ν = d²q/dφ²      (second transfer function)

and for a point P(q, φ):  P' = P_q μ + P_φ,  P'' = d²/ds² P(q + s μ + s²ν/2, φ + s)|_{s=0}.
With the input speed ω and acceleration α:  q̇ = μ ω,  q̈ = ν ω² + μ α  (likewise for points).
These are geometric (independent of speed). Nothing here is computed unless asked for.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..model.mechanism import Mechanism
from ..solvers.linalg import solve_small


class Transfer(NamedTuple):
    """Transfer functions at each position (leading axes as the inputs; `None` if not asked).

    - `mu`, `nu`: (…, n) dq/dφ and d²q/dφ² of the unknowns.
    - `points`: (…, n_points, 2) positions; `dpoints`, `ddpoints`: their φ-derivatives.
    """

    points: jax.Array
    mu: jax.Array | None
    nu: jax.Array | None
    dpoints: jax.Array | None
    ddpoints: jax.Array | None


def along(f, x, v, w):
    """`(f(c(0)), d/ds f(c(s)), d²/ds² f(c(s)))` at s = 0 on the curve c(s) = x + s v + s² w / 2
    (x, v, w tuples of arrays), by nested forward-mode AD."""

    def curve(s):
        return f(*[xi + s * vi + 0.5 * s * s * wi for xi, vi, wi in zip(x, v, w)])

    def first(s):
        return jax.jvp(curve, (s,), (jnp.ones_like(s),))

    s0 = jnp.zeros((), dtype=jnp.result_type(x[0]))
    (val, d1), (_, d2) = jax.jvp(first, (s0,), (jnp.ones_like(s0),))
    return val, d1, d2


def rates(mech: Mechanism, q, phi, p, order: int = 2):
    """`(mu, nu)` = (dq/dφ, d²q/dφ²) at one solved position (`nu` is None for `order=1`):

        Φ_q μ = −Φ_φ,        Φ_q ν = −d²/ds² Φ(q + s μ, φ + s)|_{s=0}.
    """
    res = lambda qq, ph: mech.residual(qq, ph, p)  # noqa: E731
    jac = jax.jacfwd(res, argnums=0)(q, phi)
    one = jnp.ones_like(phi)
    phi_t = jax.jvp(lambda ph: res(q, ph), (phi,), (one,))[1]
    mu, _ = solve_small(jac, phi_t)
    mu = -mu
    if order < 2:
        return mu, None
    _, _, gamma = along(res, (q, phi), (mu, one), (jnp.zeros_like(q), jnp.zeros_like(phi)))
    nu, _ = solve_small(jac, gamma)
    return mu, -nu


def transfer_one(mech: Mechanism, q, phi, p, order: int) -> Transfer:
    """Transfer functions of one position up to `order` (0: points only, 1: + μ, 2: + ν)."""
    pts = mech.point_positions(q, phi, p)
    if order == 0:
        return Transfer(pts, None, None, None, None)
    mu, nu = rates(mech, q, phi, p, order)
    one = jnp.ones_like(phi)
    pos = lambda qq, ph: mech.point_positions(qq, ph, p)  # noqa: E731
    if order == 1:
        dpts = jax.jvp(pos, (q, phi), (mu, one))[1]
        return Transfer(pts, mu, None, dpts, None)
    _, dpts, ddpts = along(pos, (q, phi), (mu, one), (nu, jnp.zeros_like(phi)))
    return Transfer(pts, mu, nu, dpts, ddpts)


@functools.partial(jax.jit, static_argnames=("order",))
def _transfer(mech, phis, q, p, order):
    p = jnp.asarray(mech.parameters if p is None else p)
    if not jnp.issubdtype(p.dtype, jnp.floating):
        p = p.astype(jnp.result_type(float))
    q = jnp.asarray(q, p.dtype)
    phis = jnp.asarray(phis, p.dtype)
    f = jax.vmap(lambda qq, phi, pp: transfer_one(mech, qq, phi, pp, order), in_axes=(0, 0, None))
    if p.ndim == 2:
        f = jax.vmap(f, in_axes=(0, 0 if phis.ndim == 2 else None, 0))
    return f(q, phis, p)


def transfer(mech: Mechanism, phis, q, p=None, *, order: int = 2) -> Transfer:
    """Transfer functions at solved positions, jitted and `vmap`ped.

    **Arguments:** `phis` (N,) inputs; `q` (N, n) the solved unknowns (`Solution.q`); `p` (P,)
    parameters (default `mech.parameters`). A batch of designs: `p` (B, P), `q` (B, N, n), `phis`
    (N,) or (B, N). `order` (static): 0 points, 1 first, 2 second derivatives.

    **Returns:** `Transfer` with leading axes as `q`.
    """
    return _transfer(mech, phis, q, p, order)


def time_derivatives(t: Transfer, omega, alpha=0.0):
    """Velocities and accelerations of unknowns and points at input speed ω (rad/s or m/s) and
    input acceleration α: returns `(qdot, qddot, v_points, a_points)` (None where not computed)."""
    qd = None if t.mu is None else t.mu * omega
    qdd = None if t.nu is None else t.nu * omega**2 + t.mu * alpha
    v = None if t.dpoints is None else t.dpoints * omega
    a = None if t.ddpoints is None else t.ddpoints * omega**2 + t.dpoints * alpha
    return qd, qdd, v, a
