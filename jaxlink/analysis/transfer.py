"""Velocities, accelerations and transfer functions from the solved positions — exact, by
forward-mode AD, with the same Jacobian Φ_q as the position solve.

For a 1-DOF mechanism with input φ, along the solution curve q(φ) (seed 000 §5.4, eq. 4.8–4.10):

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

from ..solvers.linalg import solve_small
from ..model.mechanism import Mechanism


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


def _second_along(f, x, v, w):
    """d²/ds² f(x + s v + s² w / 2) at s = 0 (x, v, w tuples of arrays)."""

    def curve(s):
        return f(*[xi + s * vi + 0.5 * s * s * wi for xi, vi, wi in zip(x, v, w)])

    def d1(s):
        return jax.jvp(curve, (s,), (jnp.ones_like(s),))[1]

    s0 = jnp.zeros((), dtype=jnp.result_type(x[0]))
    return jax.jvp(d1, (s0,), (jnp.ones_like(s0),))[1]


def transfer_one(mech: Mechanism, q, phi, p, order: int) -> Transfer:
    """Transfer functions of one position up to `order` (0: points only, 1: + μ, 2: + ν)."""
    pts = mech.point_positions(q, phi, p)
    if order == 0:
        return Transfer(pts, None, None, None, None)
    res = lambda qq, ph: mech.residual(qq, ph, p)  # noqa: E731
    jac = jax.jacfwd(res, argnums=0)(q, phi)
    one = jnp.ones_like(phi)
    phi_t = jax.jvp(lambda ph: res(q, ph), (phi,), (one,))[1]
    mu, _ = solve_small(jac, phi_t)
    mu = -mu
    pos = lambda qq, ph: mech.point_positions(qq, ph, p)  # noqa: E731
    dpts = jax.jvp(pos, (q, phi), (mu, one))[1]
    if order == 1:
        return Transfer(pts, mu, None, dpts, None)
    zq, zphi = jnp.zeros_like(q), jnp.zeros_like(phi)
    gamma = _second_along(res, (q, phi), (mu, one), (zq, zphi))
    nu, _ = solve_small(jac, gamma)
    nu = -nu
    ddpts = _second_along(pos, (q, phi), (mu, one), (nu, zphi))
    return Transfer(pts, mu, nu, dpts, ddpts)


def transfer(mech: Mechanism, q, phis, p, *, order: int = 2) -> Transfer:
    """`transfer_one` vmapped over positions `(N, n)`, `(N,)` — and over designs if `p` is (B, P)
    with `q` (B, N, n) and `phis` (N,) or (B, N)."""
    return _jitted_transfer(mech, order, jnp.ndim(p) == 2, jnp.ndim(phis) == 2)(q, phis, p)


@functools.lru_cache(maxsize=64)
def _jitted_transfer(mech, order, batch_p, batch_phi):
    f = jax.vmap(lambda q, phi, p: transfer_one(mech, q, phi, p, order), in_axes=(0, 0, None))
    if batch_p:
        f = jax.vmap(f, in_axes=(0, 0 if batch_phi else None, 0))
    return jax.jit(f)


def time_derivatives(t: Transfer, omega, alpha=0.0):
    """Velocities and accelerations of unknowns and points at input speed ω (rad/s or m/s) and
    input acceleration α: returns `(qdot, qddot, v_points, a_points)` (None where not computed)."""
    qd = None if t.mu is None else t.mu * omega
    qdd = None if t.nu is None else t.nu * omega**2 + t.mu * alpha
    v = None if t.dpoints is None else t.dpoints * omega
    a = None if t.ddpoints is None else t.ddpoints * omega**2 + t.dpoints * alpha
    return qd, qdd, v, a
