"""Kinetostatics: joint reactions and the driving torque from the solved kinematics (the d'Alembert
"release" method, A_S F_S = Q_S; docs/methods/kinetostatics.md).

Every moving body b is released from its joints. With its centroid c_b, mass m_b, inertia J_b about
the centroid and orientation θ_b, d'Alembert's principle gives three equations per body (forces, and
moments about a reference point r_b of the body — its centroid, or its first joint if massless):

    Σ_j F_bj  +  Σ F_ext  +  m_b g − m_b c̈_b                                         = 0
    Σ_j (P_j − r_b) × F_bj + Σ M_bj + Σ (P − r_b) × F_ext + Σ T_ext
        + (c_b − r_b) × (m_b g − m_b c̈_b) − J_b θ̈_b                                  = 0

with, per joint j between bodies (A, B), the unknown force F_j on B from A (−F_j on A): two
components (F_x, F_y) for a revolute joint at P_j; for a prismatic joint, a normal force N along
the left normal n = (−sin a, cos a) of its axis a, at P_j, and a moment M. The drive torque τ acts
on the input body (from the ground) for an angle input; for a length input s (a cylinder, a driven
slider) the drive is a force F along u = (cos a_d, sin a_d) at the point P_d (`[input] axis`, `at`):
+F u on the input body, −F u on its base (`[input] base`, the ground by default), F > 0 pushing
towards a larger s, so that its power is F ṡ when u·(v_body(P_d) − v_base(P_d)) = ṡ (checked by
`drive_errors`). Unknowns F_S = (F_1x, F_1y, …, τ or F) number 2·joints + 1, equations
3·bodies; they agree when Grübler's mobility is 1 (checked when the file is read). The accelerations
come from the transfer functions μ = dq/dφ, ν = d²q/dφ² (`analysis/transfer.py`): c̈ = c'' ω² + c' α with
c' = dc/dφ, c'' = d²c/dφ² by forward AD along the solution curve, likewise θ̈. Moment rows and
moment unknowns are scaled by the mechanism's length
scale so that A_S is O(1) in any unit.

Power balance (a check, `tests/test_kinetostatics.py`, `tests/test_length_input.py`): τ ω (F v for a
length input at speed v) + Σ P_loads = d(T + V_gravity + V_springs)/dt.

The linear solve is unrolled for n ≤ 8 (`_linalg.solve_small`) and an LU factorization with partial
pivoting otherwise (`jax.scipy.linalg.lu_factor`, what `jnp.linalg.solve` does, keeping the pivots);
a position whose A_S is singular (min |pivot| / max |entry| below `singular_ratio`: a toggle position,
or joints placed so that they over-constrain a body) gets `RESULTS.singular` and zeros, never an exception, so that
`vmap` over positions and designs never fails as a whole.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..files import expr as _expr
from ..files.expr import ANGLE
from ..model import bodies as _bodies
from ..model.mechanism import Mechanism
from ..results import RESULTS
from ..solvers.assemble import solve
from ..solvers.linalg import UNROLL_MAX, solve_small
from ..solvers.options import NewtonOptions
from .transfer import along, rates


class Reactions(NamedTuple):
    """Joint reactions and drive torque (leading axes: designs, positions as the inputs).

    **Fields:**

    - `force`: (…, J, 2) N, the force on each joint's second body from its first (x, y).
    - `moment`: (…, J) N·m, the reaction moment of each prismatic joint (0 for revolute joints).
    - `torque`: (…,) the drive: for an angle input the torque on the input body from the ground, N·m
      (counter-clockwise +); for a length input the force along `[input] axis`, N (+ pushes the
      input body towards a larger input). Also as `drive`.
    - `result`: (…,) int8 code (`RESULTS`); where not ok, the values are 0.
    - `ratio`: (…,) min |pivot| / max |entry| of the scaled system, a singularity indicator (≈ 1/condition).
    """

    force: jax.Array
    moment: jax.Array
    torque: jax.Array
    result: jax.Array
    ratio: jax.Array

    @property
    def drive(self) -> jax.Array:
        """The drive: a torque (N·m, angle input) or a force (N, length input); `torque`."""
        return self.torque


# ----------------------------------------------------------------------------- geometry


def vector_sum(mech: Mechanism, terms, env, dtype):
    """A vector sum (tuple of `Term`s) evaluated in SI: array (2,)."""
    x, y = 0.0, 0.0
    for t in terms:
        tx, ty = mech.term_vector(t, env)
        x, y = x + tx, y + ty
    return jnp.stack([jnp.asarray(x, dtype=dtype), jnp.asarray(y, dtype=dtype)])


def angle_value(mech: Mechanism, node, env, dtype):
    return jnp.asarray(_expr.evaluate(node, env, mech.kinds, mech.units, ANGLE), dtype=dtype)


def motion(mech: Mechanism, mdl: _bodies.Model, q, phi, p):
    """Centroids (nb, 2) and angles (nb,) of the bodies (0 where not declared)."""
    dtype = jnp.result_type(q)
    env = mech.env(q, phi, p)
    zero2 = jnp.zeros((2,), dtype)
    zero = jnp.zeros((), dtype)
    c = [vector_sum(mech, b.centroid, env, dtype) if b.centroid is not None else zero2 for b in mdl.bodies]
    a = [angle_value(mech, b.angle, env, dtype) if b.angle is not None else zero for b in mdl.bodies]
    return jnp.stack(c), jnp.stack(a)


def _geometry(mech: Mechanism, mdl: _bodies.Model, q, phi, p):
    """Joint points (nj, 2) and axes (nj,), force points (nf, 2), spring ends (ns, 2, 2)."""
    dtype = jnp.result_type(q)
    env = mech.env(q, phi, p)
    pts = jnp.stack([vector_sum(mech, j.at, env, dtype) for j in mdl.joints])
    axes = jnp.stack([angle_value(mech, j.axis, env, dtype) if j.axis is not None else jnp.zeros((), dtype)
                      for j in mdl.joints])
    fpts = (jnp.stack([vector_sum(mech, f.at, env, dtype) for f in mdl.forces]) if mdl.forces
            else jnp.zeros((0, 2), dtype))
    spts = (jnp.stack([jnp.stack([vector_sum(mech, s.start, env, dtype), vector_sum(mech, s.end, env, dtype)])
                       for s in mdl.springs]) if mdl.springs else jnp.zeros((0, 2, 2), dtype))
    return pts, axes, fpts, spts


def drive_line(mech: Mechanism, mdl: _bodies.Model, q, phi, p):
    """A length input's drive force: its point P_d (2,) and its direction's angle a_d (`[input] at`,
    `axis`)."""
    dtype = jnp.result_type(q)
    env = mech.env(q, phi, p)
    return vector_sum(mech, mdl.input_at, env, dtype), angle_value(mech, mdl.input_axis, env, dtype)


def body_kinematics(mech: Mechanism, mdl: _bodies.Model, q, phi, p):
    """Centroids and angles with their first and second derivatives with respect to the input:
    `((c, c', c''), (θ, θ', θ''))`, shapes (nb, 2) and (nb,)."""
    mu, nu = rates(mech, q, phi, p)
    one = jnp.ones_like(phi)
    (c, a), (c1, a1), (c2, a2) = along(lambda qq, ph: motion(mech, mdl, qq, ph, p), (q, phi), (mu, one),
                                        (nu, jnp.zeros_like(phi)))
    return (c, c1, c2), (a, a1, a2)


def _cross(r, f):
    return r[0] * f[1] - r[1] * f[0]


# ----------------------------------------------------------------------------- the system


def system(mech: Mechanism, mdl: _bodies.Model, q, phi, p, omega, alpha=0.0):
    """The scaled kinetostatic system of one position: `(A, Q, L, axes)` with A (n, n), Q (n,), the
    length scale L by which moment rows were divided and moment unknowns multiplied (the unknowns
    are (F_1x, F_1y, …, N_j, M_j/L, …, τ/L), or F in N last for a length input), and the joint axes
    (nj,) (0 for revolute joints)."""
    dtype = jnp.result_type(q)
    (c, c1, c2), (th, th1, th2) = body_kinematics(mech, mdl, q, phi, p)
    acc_c = c2 * omega**2 + c1 * alpha
    acc_th = th2 * omega**2 + th1 * alpha
    pts, axes, fpts, spts = _geometry(mech, mdl, q, phi, p)
    L = mech.length_scale(p)
    nb, nj = len(mdl.bodies), len(mdl.joints)
    n = 2 * nj + 1
    g = jnp.asarray(mdl.gravity, dtype)
    st = _static(mdl)

    # reference point of each body: its centroid if it has one, else its first joint
    ref = jnp.where(st.has_centroid[:, None], c, pts[st.first_joint])

    # unit "wrench" of each unknown column of joint k: a force f (at P_k) and a moment m (already / L)
    # revolute: (e_x, 0), (e_y, 0); prismatic: (n, 0), (0, 1) with n = (-sin a, cos a)
    normal = jnp.stack([-jnp.sin(axes), jnp.cos(axes)], axis=-1)  # (nj, 2)
    ex = jnp.broadcast_to(jnp.asarray([1.0, 0.0], dtype), (nj, 2))
    ey = jnp.broadcast_to(jnp.asarray([0.0, 1.0], dtype), (nj, 2))
    prism = st.prismatic[:, None]
    f0 = jnp.where(prism, normal, ex)
    f1 = jnp.where(prism, 0.0, ey)
    fb = jnp.stack([f0, f1], axis=1)  # (nj, 2 columns, 2)
    mb = jnp.stack([jnp.zeros((nj,), dtype), jnp.where(st.prismatic, 1.0, 0.0)], axis=1)  # (nj, 2)
    if len(st.inc_joint):
        k, i, sgn = st.inc_joint, st.inc_body, st.inc_sign
        r = pts[k] - ref[i]  # (ni, 2)
        f = fb[k]  # (ni, 2, 2)
        mom = (r[:, None, 0] * f[..., 1] - r[:, None, 1] * f[..., 0]) / L + mb[k]  # (ni, 2)
        sign = jnp.asarray(sgn, dtype)  # the dtype of q (a float64 constant would promote float32)
        vals = sign[:, None, None] * jnp.stack([f[..., 0], f[..., 1], mom], axis=-1)  # (ni, 2 cols, 3 rows)
        A = jnp.zeros((3 * nb, n), dtype).at[st.rows, st.cols].add(vals.reshape(-1))
    else:
        A = jnp.zeros((3 * nb, n), dtype)
    if mdl.drive_force:  # F along u at P_d on the input body, −F u on its base (the ground: dropped)
        pd, ad = drive_line(mech, mdl, q, phi, p)
        u = jnp.stack([jnp.cos(ad), jnp.sin(ad)])
        for body, side in ((mdl.input_body, 1.0), (mdl.input_base, -1.0)):
            if body >= 0:
                col = side * jnp.stack([u[0], u[1], _cross(pd - ref[body], u) / L])
                A = A.at[3 * body + jnp.arange(3), n - 1].add(col)
    else:
        A = A.at[3 * mdl.input_body + 2, n - 1].add(1.0)  # τ/L on the input body

    # right-hand side: Q = m c̈ − m g − F_ext;  J θ̈ − (c − r) × (m g − m c̈) − Σ (P − r) × F_ext − T_ext
    ext_f = jnp.zeros((nb + 1, 2), dtype)  # row nb collects what acts on the ground (dropped)
    ext_m = jnp.zeros((nb + 1,), dtype)
    ref_g = jnp.concatenate([ref, jnp.zeros((1, 2), dtype)])

    def apply(ext_f, ext_m, body, point, force):
        b = body if body >= 0 else nb
        return ext_f.at[b].add(force), ext_m.at[b].add(_cross(point - ref_g[b], force))

    for kf, fl in enumerate(mdl.forces):
        ext_f, ext_m = apply(ext_f, ext_m, fl.body, fpts[kf], jnp.asarray(fl.force, dtype))
    for tl in mdl.torques:
        ext_m = ext_m.at[tl.body if tl.body >= 0 else nb].add(tl.torque)
    for ks, sp in enumerate(mdl.springs):
        start, end = spts[ks, 0], spts[ks, 1]
        d = end - start
        length = _safe_norm(d)
        u = d / jnp.where(length > 0, length, 1.0)
        tension = sp.preload + sp.stiffness * (length - sp.length)
        ext_f, ext_m = apply(ext_f, ext_m, sp.a, start, tension * u)  # pulls the first end towards the second
        ext_f, ext_m = apply(ext_f, ext_m, sp.b, end, -tension * u)
    gmi = jnp.asarray(st.mass, dtype)[:, None] * (g - acc_c)  # gravity minus inertia force, (nb, 2)
    q_f = -ext_f[:nb] - gmi
    q_m = (jnp.asarray(st.inertia, dtype) * acc_th - _cross_rows(c - ref, gmi) - ext_m[:nb]) / L
    Q = jnp.stack([q_f[:, 0], q_f[:, 1], q_m], axis=1).reshape(-1)
    return A, Q, L, axes


class _Static(NamedTuple):
    has_centroid: np.ndarray  # (nb,) bool
    first_joint: np.ndarray  # (nb,) int: a joint of each body
    prismatic: np.ndarray  # (nj,) bool
    mass: np.ndarray  # (nb,)
    inertia: np.ndarray  # (nb,)
    inc_joint: np.ndarray  # (ni,) joint of each (joint, moving body) incidence
    inc_body: np.ndarray  # (ni,)
    inc_sign: np.ndarray  # (ni,) +1 on the joint's second body, −1 on its first
    rows: np.ndarray  # (ni·2·3,) rows of A for the incidence values (ni, 2 columns, 3 rows)
    cols: np.ndarray


@functools.lru_cache(maxsize=64)
def _static(mdl: _bodies.Model) -> _Static:
    inc = [(k, body, sign) for k, j in enumerate(mdl.joints) for body, sign in ((j.b, 1.0), (j.a, -1.0))
           if body >= 0]
    k = np.array([e[0] for e in inc], dtype=np.int32)
    i = np.array([e[1] for e in inc], dtype=np.int32)
    rows = (3 * i[:, None, None] + np.arange(3)[None, None, :]) + np.zeros((1, 2, 1), np.int32)
    cols = (2 * k[:, None, None] + np.arange(2)[None, :, None]) + np.zeros((1, 1, 3), np.int32)
    first = [next(kk for kk, j in enumerate(mdl.joints) if bi in (j.a, j.b)) for bi in range(len(mdl.bodies))]
    return _Static(
        np.array([b.centroid is not None for b in mdl.bodies]), np.array(first, dtype=np.int32),
        np.array([j.kind == "prismatic" for j in mdl.joints]),
        np.array([b.mass for b in mdl.bodies]), np.array([b.inertia for b in mdl.bodies]),
        k, i, np.array([e[2] for e in inc]), rows.reshape(-1), cols.reshape(-1))


def _cross_rows(r, f):
    return r[:, 0] * f[:, 1] - r[:, 1] * f[:, 0]


def _safe_norm(d):
    sq = jnp.sum(d * d)
    ok = sq > 0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, sq, 1.0)), 0.0)


def default_singular_ratio(dtype) -> float:
    return float(max(1e-10, 1e3 * np.finfo(dtype).eps))


def reactions_one(mech: Mechanism, mdl: _bodies.Model, q, phi, p, omega, alpha=0.0, *,
                  singular_ratio: float | None = None) -> Reactions:
    """Reactions and drive torque at one position (see the module docstring)."""
    dtype = jnp.result_type(q)
    A, Q, L, axes = system(mech, mdl, q, phi, p, omega, alpha)
    n = A.shape[0]
    if n <= UNROLL_MAX:
        x, ratio = solve_small(A, Q)
    else:
        lu, piv = jax.scipy.linalg.lu_factor(A)
        ratio = jnp.min(jnp.abs(jnp.diag(lu))) / jnp.maximum(jnp.max(jnp.abs(A)), jnp.finfo(dtype).tiny)
        x = jax.scipy.linalg.lu_solve((lu, piv), Q)
    thr = default_singular_ratio(dtype) if singular_ratio is None else singular_ratio
    # finiteness is part of convergence: the system (a NaN speed, non-finite accelerations) and
    # the solution, in the units returned (forces, moments and torque × the length scale)
    finite = (jnp.all(jnp.isfinite(x)) & jnp.all(jnp.isfinite(A)) & jnp.all(jnp.isfinite(Q))
              & jnp.isfinite(L) & jnp.all(jnp.isfinite(x * L)) & jnp.all(jnp.isfinite(axes)))
    code = jnp.where(~finite & ~(ratio < thr), RESULTS.nonfinite,
                     jnp.where(ratio < thr, RESULTS.singular, RESULTS.converged))
    code = jnp.where(jnp.all(jnp.isfinite(A)) & jnp.isfinite(ratio), code, RESULTS.nonfinite)
    ok = code == RESULTS.converged
    x = jnp.where(ok, x, 0.0)
    nj = len(mdl.joints)
    f = x[: 2 * nj].reshape(nj, 2)
    moments = []
    forces = []
    for k, j in enumerate(mdl.joints):
        if j.kind == "revolute":
            forces.append(f[k])
            moments.append(jnp.zeros((), dtype))
        else:
            forces.append(f[k, 0] * jnp.stack([-jnp.sin(axes[k]), jnp.cos(axes[k])]))
            moments.append(f[k, 1] * L)
    drive = x[-1] if mdl.drive_force else x[-1] * L  # F in N, or τ/L × L
    return Reactions(jnp.stack(forces), jnp.stack(moments), drive, code.astype(jnp.int8), ratio)


# ----------------------------------------------------------------------------- batched entry points


def _floating(mech, p):
    p = jnp.asarray(mech.parameters if p is None else p)
    if not jnp.issubdtype(p.dtype, jnp.floating):
        p = p.astype(jnp.result_type(float))
    return p


def _vmapped(f, p, phis, n_args: int):
    """`f(q, phi, p, *rest)` of one position vmapped over positions, and over designs if `p` is (B, P)."""
    g = jax.vmap(f, in_axes=(0, 0, None) + (None,) * n_args)
    if p.ndim == 2:
        g = jax.vmap(g, in_axes=(0, 0 if phis.ndim == 2 else None, 0) + (None,) * n_args)
    return g


@functools.partial(jax.jit, static_argnames=("singular_ratio",))
def _reactions(mech, phis, p, q, converged, omega, alpha, singular_ratio):
    mdl = _bodies.model(mech)
    p = _floating(mech, p)
    phis = jnp.asarray(phis, p.dtype)
    if q is None:
        sol = solve(mech, phis, p, points=False)
        q, converged = sol.q, sol.converged
    q = jnp.asarray(q, p.dtype)
    omega = jnp.asarray(omega, p.dtype)
    alpha = jnp.asarray(alpha, p.dtype)
    one = lambda qq, phi, pp, om, al: reactions_one(mech, mdl, qq, phi, pp, om, al,  # noqa: E731
                                                    singular_ratio=singular_ratio)
    out = _vmapped(one, p, phis, 2)(q, phis, p, omega, alpha)
    if converged is not None:
        conv = jnp.asarray(converged, dtype=bool)
        out = Reactions(
            jnp.where(conv[..., None, None], out.force, 0.0),
            jnp.where(conv[..., None], out.moment, 0.0),
            jnp.where(conv, out.torque, 0.0),
            jnp.where(conv, out.result, jnp.int8(RESULTS.not_assembled)).astype(jnp.int8),
            out.ratio,
        )
    return out


def reactions(mech: Mechanism, phis, p=None, *, omega, alpha=0.0, q=None, converged=None,
              singular_ratio: float | None = None) -> Reactions:
    """Joint reactions and the drive (torque, or force for a length input) along a sequence of
    inputs (one jitted function).

    **Arguments:**

    - `mech`: a mechanism whose file has `[bodies]` and `[joints]`.
    - `phis`: (N,) inputs, SI (rad, or m for a length input), or (B, N) for a batch of designs.
    - `p`: (P,) parameters SI (default `mech.parameters`), or (B, P).
    - `omega`, `alpha` (keyword-only): input speed (rad/s) and acceleration (rad/s²), for a length
      input m/s and m/s²; traced.
    - `q`: (N, n) or (B, N, n) solved positions (`Solution.q`); default: solved here by `solve`
      (from the file's guesses), with their `converged` flags.
    - `converged`: (…, N) bool of the position solve; positions that did not converge get
      `RESULTS.not_assembled` and zeros.
    - `singular_ratio`: pivot ratio below which the system counts as singular (static; default
      max(1e-10, 1000 eps)).

    **Returns:** `Reactions` (force, moment, torque, result, ratio) with leading axes (N,) or (B, N).
    """
    _bodies.model(mech)  # a clear error (no bodies) before tracing
    return _reactions(mech, phis, p, q, converged, omega, alpha, singular_ratio)


def solve_reactions(mech: Mechanism, phis, p=None, *, omega, alpha=0.0, singular_ratio: float | None = None,
                    options=None):
    """Solve the positions (`solve`) and then the reactions: returns `(Solution, Reactions)`.

    `p` (P,) or (B, P) as in `solve`; `phis` (N,) in rad; `omega` rad/s; `options`: the
    `NewtonOptions` of the position solve (e.g. `change_points="smooth"`; default the defaults)."""
    _bodies.model(mech)  # validate before the (longer) position solve
    sol = solve(mech, phis, p, options=options or NewtonOptions())
    return sol, reactions(mech, phis, p, omega=omega, alpha=alpha, q=sol.q, converged=sol.converged,
                          singular_ratio=singular_ratio)


class BodyMotion(NamedTuple):
    """Centroids and angles of the bodies (in the order of `[bodies]`) and their derivatives with
    respect to the input: `centroid`, `dcentroid`, `ddcentroid` (…, nb, 2) m, m/rad, m/rad²;
    `angle`, `dangle`, `ddangle` (…, nb) rad, 1, 1/rad (0 where the file declares none). Times:
    v = c′ ω, a = c″ ω² + c′ α."""

    centroid: jax.Array
    dcentroid: jax.Array
    ddcentroid: jax.Array
    angle: jax.Array
    dangle: jax.Array
    ddangle: jax.Array


@jax.jit
def _body_motion(mech, phis, q, p):
    mdl = _bodies.model(mech)
    p = _floating(mech, p)

    def one(qq, phi, pp):
        (c, c1, c2), (a, a1, a2) = body_kinematics(mech, mdl, qq, phi, pp)
        return BodyMotion(c, c1, c2, a, a1, a2)

    phis = jnp.asarray(phis, p.dtype)
    return _vmapped(one, p, phis, 0)(jnp.asarray(q, p.dtype), phis, p)


def body_motion(mech: Mechanism, phis, q, p=None) -> BodyMotion:
    """Centroids and angles of the bodies with their first and second derivatives with respect to
    the input, at solved positions `q` (N, n) (or a batch, as `transfer`)."""
    _bodies.model(mech)
    return _body_motion(mech, phis, q, p)


# ----------------------------------------------------------------------------- consistency of the file


@functools.partial(jax.jit, static_argnums=(1,))
def _jitted_points(mech, mdl, q, phis, p):
    def one(q, phi, p):
        c, a = motion(mech, mdl, q, phi, p)
        pts, _, fpts, spts = _geometry(mech, mdl, q, phi, p)
        return c, a, pts, fpts, spts

    return jax.vmap(one, in_axes=(0, 0, None))(q, phis, p)


@functools.partial(jax.jit, static_argnums=(1,))
def _jitted_velocities(mech, mdl, q, phis, p):
    """Per position: centroids, angles, joint points and axes with their input derivatives."""
    def one(q, phi, p):
        mu, _ = rates(mech, q, phi, p, order=1)
        one_ = jnp.ones_like(phi)
        (c, a), (dc, da) = jax.jvp(lambda qq, ph: motion(mech, mdl, qq, ph, p), (q, phi), (mu, one_))
        (pts, axes), (dpts, daxes) = jax.jvp(lambda qq, ph: _geometry(mech, mdl, qq, ph, p)[:2], (q, phi),
                                             (mu, one_))
        return c, dc, a, da, pts, dpts, axes, daxes

    return jax.vmap(one, in_axes=(0, 0, None))(q, phis, p)


@functools.partial(jax.jit, static_argnums=(1,))
def _jitted_drive(mech, mdl, q, phis, p):
    """Per position: a length input's drive point P_d, its input derivative and its axis."""
    def one(q, phi, p):
        mu, _ = rates(mech, q, phi, p, order=1)
        (pd, ad), (dpd, _) = jax.jvp(lambda qq, ph: drive_line(mech, mdl, qq, ph, p), (q, phi),
                                     (mu, jnp.ones_like(phi)))
        return pd, dpd, ad

    return jax.vmap(one, in_axes=(0, 0, None))(q, phis, p)


def drive_errors(mech: Mechanism, q, phis, p=None, *, rtol: float = 1e-6) -> list:
    """Check a length input's drive force against the kinematics: its direction u = (cos a_d,
    sin a_d) (`[input] axis`) must be the one in which the input s grows at its point P_d (`[input]
    at`), u·(dP_d/ds − v_base(P_d)/ṡ) = 1 at every position (the base's velocity at P_d: 0 for
    the ground; a moving base needs an `angle` and a centroid or a revolute joint, else the check
    is skipped), so that the drive's power is F ṡ and F is the force the actuator exerts. An axis
    reversed (pointing from the driven body to the base) gives −1; a point not on the actuator's
    line, something else. Returns messages (empty if all is well or for an angle input); `rtol`
    on that dimensionless rate. `q` (N, n) converged."""
    mdl = _bodies.model(mech)
    if not mdl.drive_force or len(q) == 0:
        return []
    q = jnp.asarray(q)
    pa = jnp.asarray(np.asarray(mech.parameters if p is None else p, dtype=q.dtype))
    ph = jnp.asarray(phis, dtype=q.dtype)
    pd, dpd, ad = (np.asarray(x, dtype=float) for x in _jitted_drive(mech, mdl, q, ph, pa))
    rel = dpd
    base = mdl.input_base
    if base >= 0:
        b = mdl.bodies[base]
        c, dc, a, da, pts, dpts, _, _ = (np.asarray(x, dtype=float) for x in _jitted_velocities(mech, mdl, q, ph, pa))
        rev = [k for k, j in enumerate(mdl.joints) if j.kind == "revolute" and base in (j.a, j.b)]
        if b.angle is None or (b.centroid is None and not rev):
            return []
        ref, dref = (c[:, base], dc[:, base]) if b.centroid is not None else (pts[:, rev[0]], dpts[:, rev[0]])
        r = pd - ref
        w = da[:, base]
        rel = dpd - (dref + np.stack([-w * r[:, 1], w * r[:, 0]], axis=1))
    rate = np.cos(ad) * rel[:, 0] + np.sin(ad) * rel[:, 1]
    err = np.abs(rate - 1.0)
    if not np.max(err) > rtol:
        return []
    i = int(np.argmax(err))
    at = mech.from_si(mech.input_name, float(np.asarray(phis)[i]))
    return [f"[input] axis: the drive force is not along the direction in which '{mech.input_name}' grows: at "
            f"{mech.input_name} = {at:g}, (cos axis, sin axis)·(the velocity of [input] at relative to the base, per "
            f"unit of {mech.input_name}) = {rate[i]:.6g}, not 1 (give `axis` as the actuator's direction from its base "
            "towards the driven body, and `at` a point of the driven body on its line)"]


def prismatic_errors(mech: Mechanism, q, phis, p=None, *, rtol: float = 1e-6) -> list:
    """Check the `axis` of every prismatic joint against the kinematics: the joint's two bodies must
    turn with the axis (its input derivative equals each body's angular rate; 0 for the ground), and
    their relative velocity at the joint point must lie along it (the reaction is taken normal to
    the axis: an axis naming another direction would put the guide's force in the wrong direction,
    silently). A body's velocity field comes from its angle and a reference point (its centroid,
    else one of its revolute joints); a body without them is not checked. Returns messages (empty
    if all is well); tolerance `rtol` relative to the largest relative speed (m/rad), and rad/rad
    for the rates. `q` (N, n) converged."""
    mdl = _bodies.model(mech)
    if not any(j.kind == "prismatic" for j in mdl.joints):
        return []
    q = jnp.asarray(q)
    p = jnp.asarray(np.asarray(mech.parameters if p is None else p, dtype=q.dtype))
    c, dc, a, da, pts, dpts, axes, daxes = (np.asarray(x, dtype=float) for x in _jitted_velocities(
        mech, mdl, q, jnp.asarray(phis, dtype=q.dtype), p))
    n = len(q)
    out = []

    def field(body, point):
        """Velocity (n, 2) of `body` at `point` (n, 2) and its angular rate (n,), or None."""
        if body < 0:
            return np.zeros((n, 2)), np.zeros(n)
        b = mdl.bodies[body]
        if b.angle is None:
            return None
        if b.centroid is not None:
            ref, dref = c[:, body], dc[:, body]
        else:
            rev = [k for k, j in enumerate(mdl.joints) if j.kind == "revolute" and body in (j.a, j.b)]
            if not rev:
                return None
            ref, dref = pts[:, rev[0]], dpts[:, rev[0]]
        w = da[:, body]
        r = point - ref
        return dref + np.stack([-w * r[:, 1], w * r[:, 0]], axis=1), w

    for k, j in enumerate(mdl.joints):
        if j.kind != "prismatic":
            continue
        fa, fb = field(j.a, pts[:, k]), field(j.b, pts[:, k])
        names = ["the ground" if x < 0 else f"body '{mdl.bodies[x].name}'" for x in (j.a, j.b)]
        for f, name in ((fa, names[0]), (fb, names[1])):
            if f is not None and np.max(np.abs(daxes[:, k] - f[1])) > rtol:
                out.append(f"prismatic joint '{j.name}': its axis does not turn with {name} (the axis turns at "
                           f"up to {np.max(np.abs(daxes[:, k] - f[1])):.3g} rad/rad relative to it; check `axis`)")
        if fa is None or fb is None:
            continue
        v = fb[0] - fa[0]
        speed = np.hypot(v[:, 0], v[:, 1])
        vmax = float(np.max(speed)) if n else 0.0
        if not vmax > 0:
            continue
        u = np.stack([np.cos(axes[:, k]), np.sin(axes[:, k])], axis=1)
        slip = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
        if np.max(slip) > rtol * vmax:
            i = int(np.argmax(slip / np.maximum(speed, 1e-300)))
            deg = float(np.degrees(np.arcsin(min(1.0, slip[i] / speed[i]))))
            out.append(f"prismatic joint '{j.name}': its axis is not the sliding direction: the relative motion "
                       f"of its bodies at the joint makes up to {deg:.3g}° with the axis (check `axis`: the "
                       "reaction is normal to it)")
    return out


def rigidity_errors(mech: Mechanism, q, phis, p=None, *, rtol: float | None = None) -> list:
    """Check that the points the file attaches to each body move with it: its revolute joints, its
    centroid and the points where loads act on it. For a body with an `angle`, their coordinates in
    the body's frame (rotated by −angle, relative to the first point) must stay constant over the
    positions; for a body without one, their mutual distances. Returns messages (empty if all is
    well) naming the body, the point and how much it drifts; tolerance `rtol` × the length scale
    (default max(1e-7, 1000 eps) of the dtype of `q`).
    A prismatic joint's point slides on one of its bodies and is not checked here; its axis is
    (`prismatic_errors`, whose messages are appended), and so is a length input's drive direction
    (`drive_errors`; its point `[input] at` is checked here as a point of the input body). `q` (N, n)
    converged."""
    mdl = _bodies.model(mech)
    q = jnp.asarray(q)
    if rtol is None:
        rtol = max(1e-7, 1e3 * float(jnp.finfo(q.dtype).eps))
    p = np.asarray(mech.parameters if p is None else p, dtype=q.dtype)
    c, a, pts, fpts, spts = (np.asarray(x) for x in _jitted_points(mech, mdl,
        jnp.asarray(q), jnp.asarray(phis, dtype=jnp.asarray(q).dtype), jnp.asarray(p)))
    scale = float(mech.length_scale(jnp.asarray(p)))
    unit = mech.units.length
    lu = {1.0: "m", 1e-3: "mm", 1e-2: "cm"}.get(unit, "m")
    out = []
    drive = None
    if mdl.drive_force:
        drive = np.asarray(_jitted_drive(mech, mdl, jnp.asarray(q), jnp.asarray(phis, dtype=jnp.asarray(q).dtype),
                                         jnp.asarray(p))[0])
    for i, b in enumerate(mdl.bodies):
        named = []
        for k, j in enumerate(mdl.joints):
            if j.kind == "revolute" and i in (j.a, j.b):
                named.append((f"joint {j.name}", pts[:, k]))
        if drive is not None and i == mdl.input_body:
            named.append(("the drive point [input] at", drive))
        if b.centroid is not None:
            named.append(("the centroid", c[:, i]))
        for k, f in enumerate(mdl.forces):
            if f.body == i:
                named.append((f"load {f.name}", fpts[:, k]))
        for k, s in enumerate(mdl.springs):
            for end, body in ((0, s.a), (1, s.b)):
                if body == i:
                    named.append((f"spring {s.name} ({'from' if end == 0 else 'to'})", spts[:, k, end]))
        if len(named) < 2:
            continue
        ref_name, ref = named[0]
        for name, P in named[1:]:
            d = P - ref
            if b.angle is not None:
                ca, sa = np.cos(a[:, i]), np.sin(a[:, i])
                local = np.stack([ca * d[:, 0] + sa * d[:, 1], -sa * d[:, 0] + ca * d[:, 1]], axis=1)
                drift = np.max(np.ptp(local, axis=0))
                what = f"its position relative to {ref_name}, in the frame turned by the body's angle, changes"
            else:
                dist = np.hypot(d[:, 0], d[:, 1])
                drift = np.ptp(dist)
                what = f"its distance from {ref_name} changes"
            if drift > rtol * scale:
                out.append(f"{name} is not fixed in body '{b.name}': {what} by {drift / unit:.4g} {lu} over the "
                           "positions (check its vector sum, and the body's angle)")
    return out + prismatic_errors(mech, q, phis, p) + drive_errors(mech, q, phis, p)
