"""Kinetostatics: a hand-derived slider-crank, the power balance of every scene with mass, the feed
six-bar against the independent model of spec/feed-six-bar.md §3, batches over designs, singular
systems, unconverged positions."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlink import RESULTS, load
from jaxlink.analysis.kinetostatics import reactions, solve_reactions
from jaxlink.analysis.transfer import transfer
from jaxlink.files import expr as _expr
from jaxlink.model import bodies as _bodies
from jaxlink.solvers.assemble import solve

G = 9.81


@functools.lru_cache(maxsize=None)
def scene(name, **overrides):
    """One `Mechanism` per scene and overrides, so that compiled functions are shared by the tests."""
    return load(name, overrides=overrides or None)


def slider_crank_hand(phi, omega):
    """Newton–Euler by hand for the scene slider-crank-mass (offset h1, crank h2, rod h3, guide along x):
    returns the forces at O (on crank), A (on rod), B (on slider), the guide's normal force (on the
    slider) and the drive torque. Massive crank (centroid h2/3), rod (centroid h3/2, J3) and slider,
    gravity −y, working force −200 N along x, a 2 N·m moment on the rod, spring from (200, 12) mm to B."""
    h1, h2, h3 = 0.012, 0.025, 0.080
    m2, m3, J3, m4 = 0.3, 0.5, 2.6667e-4, 0.8
    T_rod = 2.0
    e = lambda a: np.array([np.cos(a), np.sin(a)])  # noqa: E731
    en = lambda a: np.array([-np.sin(a), np.cos(a)])  # noqa: E731
    cross = lambda a, b: a[0] * b[1] - a[1] * b[0]  # noqa: E731
    gv = np.array([0.0, -G])
    # positions: sin psi = (h1 - h2 sin phi)/h3, B to the right of A
    psi = np.arcsin((h1 - h2 * np.sin(phi)) / h3)
    psid = -h2 * np.cos(phi) * omega / (h3 * np.cos(psi))
    psidd = (h2 * np.sin(phi) * omega**2 + h3 * np.sin(psi) * psid**2) / (h3 * np.cos(psi))
    xB = h2 * np.cos(phi) + h3 * np.cos(psi)
    xBdd = -h2 * np.cos(phi) * omega**2 - h3 * np.cos(psi) * psid**2 - h3 * np.sin(psi) * psidd
    aG2 = -(h2 / 3) * omega**2 * e(phi)
    aG3 = -h2 * omega**2 * e(phi) + (h3 / 2) * (psidd * en(psi) - psid**2 * e(psi))
    # slider: F_B + N ey + m4 g + F_work + F_spring = m4 a_B
    d = xB - 0.200
    tension = 10.0 + 500.0 * (abs(d) - 0.060)
    f_spring_x = -tension * np.sign(d)  # the spring pulls B towards (200, 12) mm
    FBx = m4 * xBdd + 200.0 - f_spring_x
    # rod: F_A - F_B + m3 g = m3 aG3;  moments about G3: -h3/2 e x F_A - h3/2 e x F_B + T_rod = J3 psidd
    K = m3 * (aG3 - gv)  # F_A = F_B + K
    u = e(psi)
    # -(h3/2) u x (F_B + K) - (h3/2) u x F_B + T_rod = J3 psidd  ->  -h3 u x F_B = J3 psidd + (h3/2) u x K - T_rod
    rhs = -(J3 * psidd + (h3 / 2) * cross(u, K) - T_rod) / h3  # = u x F_B = u0 FBy - u1 FBx
    FBy = (rhs + u[1] * FBx) / u[0]
    FB = np.array([FBx, FBy])
    N = m4 * G - FBy
    FA = FB + K
    # crank: F_O - F_A + m2 g = m2 aG2; moments about O: tau - rA x F_A + rG2 x m2 (g - aG2) = 0
    FO = FA + m2 * (aG2 - gv)
    tau = cross(h2 * e(phi), FA) - cross((h2 / 3) * e(phi), m2 * (gv - aG2))
    return FO, FA, FB, N, tau


def test_slider_crank_matches_hand_derivation():
    mech = scene("slider-crank-mass")
    mdl = _bodies.model(mech)
    assert mdl.joint_names == ("O", "A", "B", "guide")
    omega = 60.0
    phis = np.deg2rad(np.arange(0.0, 360.0, 15.0))
    sol, r = solve_reactions(mech, phis, omega=omega)
    assert np.all(np.asarray(r.result) == RESULTS.converged)
    force, torque = np.asarray(r.force), np.asarray(r.torque)
    scale = np.abs(force).max()
    for k, phi in enumerate(phis):
        FO, FA, FB, N, tau = slider_crank_hand(phi, omega)
        np.testing.assert_allclose(force[k, 0], FO, atol=1e-10 * scale)
        np.testing.assert_allclose(force[k, 1], FA, atol=1e-10 * scale)
        np.testing.assert_allclose(force[k, 2], FB, atol=1e-10 * scale)
        np.testing.assert_allclose(force[k, 3], [0.0, N], atol=1e-10 * scale)
        np.testing.assert_allclose(torque[k], tau, atol=1e-10 * np.abs(torque).max())
    # the slider and every force on it act at B: no moment in the guide
    assert np.abs(np.asarray(r.moment)).max() < 1e-10


# ----------------------------------------------------------------------------- power balance


def _vsum(mech, terms, env):
    x, y = 0.0, 0.0
    for t in terms:
        tx, ty = mech.term_vector(t, env)
        x, y = x + tx, y + ty
    return jnp.stack([jnp.asarray(x, jnp.float64), jnp.asarray(y, jnp.float64)])


@functools.lru_cache(maxsize=None)
def _energies(mech):
    """(q, φ, μ, ω) -> T, V, P_loads at one position (vmapped, jitted), from the bodies' declared
    centroids/angles and the loads, with velocities by forward AD along μ = dq/dφ."""
    mdl = _bodies.model(mech)
    p = jnp.asarray(mech.parameters)

    def positions(qq, ph):
        env = mech.env(qq, ph, p)
        cs = [(_vsum(mech, b.centroid, env) if b.centroid is not None else jnp.zeros(2)) for b in mdl.bodies]
        th = [(_expr.evaluate(b.angle, env, mech.kinds, mech.units, _expr.ANGLE) if b.angle is not None
               else 0.0 * ph) for b in mdl.bodies]
        fp = [_vsum(mech, f.at, env) for f in mdl.forces]
        sp = [(_vsum(mech, s.start, env), _vsum(mech, s.end, env)) for s in mdl.springs]
        return cs, th, fp, sp

    def one(q, phi, mu, omega):
        (cs, th, fp, sp), (dcs, dth, dfp, _) = jax.jvp(positions, (q, phi), (mu, jnp.ones_like(phi)))
        g = jnp.asarray(mdl.gravity)
        T, V, P = 0.0, 0.0, 0.0
        for b, c, dc, dt in zip(mdl.bodies, cs, dcs, dth):
            T = T + 0.5 * b.mass * jnp.sum((dc * omega) ** 2) + 0.5 * b.inertia * (dt * omega) ** 2
            V = V - b.mass * jnp.dot(g, c)
        for s, (a, e) in zip(mdl.springs, sp):
            ext = jnp.linalg.norm(e - a) - s.length
            V = V + s.preload * ext + 0.5 * s.stiffness * ext**2
        for f, dP in zip(mdl.forces, dfp):
            P = P + jnp.dot(jnp.asarray(f.force), dP * omega)
        for tl in mdl.torques:
            P = P + tl.torque * dth[tl.body] * omega
        return T, V, P

    return jax.jit(jax.vmap(one, in_axes=(0, 0, 0, None)))


@pytest.mark.parametrize(
    "name, overrides, start, step, omega, alpha",
    [
        ("slider-crank-mass", None, 0.0, 15.0, 60.0, 0.0),
        ("slider-crank-mass", None, 0.0, 15.0, 60.0, 900.0),
        ("sewing-feed", dict(l2=2.0, l22=1.0, gamma=-10.0), 75.0, 5.0, 575.0, 0.0),
        ("needle-arachne", None, 0.0, 5.0, 1000 * 2 * np.pi / 60, 0.0),
    ],
)
def test_power_balance(name, overrides, start, step, omega, alpha):
    """τ ω + P_loads = d(T + V)/dt, independently of the d'Alembert assembly: T and V from the
    positions and velocities only, d/dt = ω d/dφ by a 6th-order central difference over separately
    solved positions φ ± h, ±2h, ±3h (h = 1e-3 rad: truncation and rounding errors ≈ 1e-12). With
    α ≠ 0, T also changes through ω: dT/dt = ω ∂T/∂φ + (α/ω)·2T."""
    mech = scene(name, **(overrides or {}))
    phis = np.deg2rad(start + np.arange(0.0, 360.0, step))
    n = len(phis)
    h = 1e-3
    offsets = np.array([0, -3, -2, -1, 1, 2, 3])
    weights = np.array([-1.0, 9.0, -45.0, 45.0, -9.0, 1.0]) / (60.0 * h)
    grid = (phis[:, None] + h * offsets[None, :]).ravel()
    p = jnp.asarray(mech.parameters)
    sol = solve(mech, grid)
    assert np.all(np.asarray(sol.converged))
    mu = transfer(mech, jnp.asarray(grid), sol.q, p, order=1).mu
    T, V, P = (np.asarray(x).reshape(n, len(offsets)) for x in _energies(mech)(sol.q, jnp.asarray(grid), mu, omega))
    dE_dt = omega * ((T + V)[:, 1:] @ weights) + (alpha / omega) * 2 * T[:, 0]
    q = np.asarray(sol.q).reshape(n, len(offsets), -1)[:, 0]
    r = reactions(mech, phis, p, q=q, omega=omega, alpha=alpha)
    assert np.all(np.asarray(r.result) == RESULTS.converged)
    drive = np.asarray(r.torque) * omega
    err = np.abs(drive + P[:, 0] - dE_dt).max()
    assert err <= 1e-8 * np.abs(drive).max(), (err, np.abs(drive).max())


# ----------------------------------------------------------------------------- the feed six-bar

# spec/feed-six-bar.md §3: peak |reaction| (N) and its crank angle on the 5° grid, and max |Mk| (N·m)
SPEC_FEED = {
    (2.0, 1.0, -10.0): ({"A": (20.6, 190), "B": (22.3, 195), "C": (4.96, 105), "D": (16.2, 195), "E": (28.4, 375),
                         "F": (9.25, 375), "H": (2.63, 165)}, 0.019),
    (2.1, 0.9, -10.0): ({"A": (21.7, 190), "B": (23.4, 195), "C": (4.44, 105), "D": (17.0, 195), "E": (29.6, 375),
                         "F": (9.63, 375), "H": (2.66, 170)}, 0.021),
}


def test_feed_peak_reactions_match_the_independent_model():
    mech = scene("sewing-feed", l2=2.0, l22=1.0, gamma=-10.0)  # as in test_power_balance: shared compiles
    names = _bodies.model(mech).joint_names
    phis = np.deg2rad(75.0 + 5.0 * np.arange(72))
    for design, (peaks, torque) in SPEC_FEED.items():
        p = mech.with_parameters(l2=design[0], l22=design[1], gamma=design[2])
        _, r = solve_reactions(mech, phis, p, omega=575.0)
        assert np.all(np.asarray(r.result) == RESULTS.converged)
        mags = np.linalg.norm(np.asarray(r.force), axis=-1)  # (72, joints)
        for k, name in enumerate(names):
            value, angle = peaks[name]
            i = int(np.argmax(mags[:, k]))
            assert abs(mags[i, k] - value) <= 0.01 * value, (design, name, mags[i, k], value)
            assert abs(np.rad2deg(phis[i]) - angle) < 1e-9, (design, name, np.rad2deg(phis[i]), angle)
        tmax = np.abs(np.asarray(r.torque)).max()
        assert abs(tmax - torque) <= 0.01 * torque, (design, tmax, torque)


# ----------------------------------------------------------------------------- batches, failures


def test_batched_designs_match_single_designs():
    mech = scene("slider-crank-mass")
    phis = np.deg2rad(np.arange(0.0, 360.0, 15.0))  # the grid of the hand-derivation test: shared compiles
    ps = np.stack([mech.with_parameters(h2=25.0), mech.with_parameters(h2=30.0, h1=5.0)])
    sol = solve(mech, phis, jnp.asarray(ps))
    rb = reactions(mech, phis, ps, q=sol.q, omega=60.0, converged=sol.converged)
    for b in range(2):
        _, r1 = solve_reactions(mech, phis, ps[b], omega=60.0)
        np.testing.assert_allclose(np.asarray(rb.force[b]), np.asarray(r1.force), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(np.asarray(rb.torque[b]), np.asarray(r1.torque), rtol=1e-12, atol=1e-12)
    # a longer crank at the same speed needs more torque
    assert np.abs(np.asarray(rb.torque[1])).max() > np.abs(np.asarray(rb.torque[0])).max()


def test_coincident_joints_are_reported_singular(tmp_path):
    """Joint B put on top of joint A: the rod's moment balance then repeats its force balance."""
    text = scene("slider-crank-mass").file
    src = open(text).read().replace('[joints.B]\nbodies = ["rod", "slider"]\nat = ["h1 @ alpha1", "p14 @ alpha4"]',
                                    '[joints.B]\nbodies = ["rod", "slider"]\nat = ["h2 @ psi12"]')
    assert 'at = ["h2 @ psi12"]\n\n[joints.guide]' in src
    path = tmp_path / "bad.toml"
    path.write_text(src)
    mech = load(str(path))
    _, r = solve_reactions(mech, np.deg2rad([10.0, 100.0]), omega=10.0)
    assert np.all(np.asarray(r.result) == RESULTS.singular)
    assert np.all(np.asarray(r.force) == 0) and np.all(np.isfinite(np.asarray(r.torque)))


def test_unconverged_positions_are_flagged():
    mech = scene("slider-crank-mass")
    phis = np.deg2rad(np.arange(0.0, 360.0, 15.0))
    sol = solve(mech, phis)
    conv = np.ones(len(phis), bool)
    conv[1] = False
    r = reactions(mech, phis, q=sol.q, omega=10.0, converged=conv)
    assert list(np.asarray(r.result)[:3]) == [RESULTS.converged, RESULTS.not_assembled, RESULTS.converged]
    assert np.asarray(r.torque)[1] == 0.0 and np.asarray(r.torque)[0] != 0.0
