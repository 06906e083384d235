"""Exact gradients by implicit differentiation against central finite differences (float64)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxlink as jl


def _feed_path_objective(mech, phis):
    iz = 0

    def f(p):
        sol = jl.solve_path(mech, phis, p)
        tr = jl.transfer(mech, phis, sol.q, p, order=0)
        xy = tr.points[:, iz]
        # a path objective: spread of the path around its centre plus a tilt term
        c = jnp.mean(xy, axis=0)
        return jnp.sum((xy - c) ** 2) * 1e6 + 1e3 * (xy[10, 0] - xy[40, 0])

    return f


def test_feed_path_gradient_matches_central_differences():
    mech = jl.load("sewing-feed")
    phis = jnp.asarray(np.deg2rad(75.0 + 5.0 * np.arange(72)))
    f = _feed_path_objective(mech, phis)
    p = jnp.asarray(mech.parameters)
    g = np.asarray(jax.jit(jax.grad(f))(p))
    names = ("l2", "l22", "gamma", "l3", "l5")
    for name in names:
        i = mech.parameter_index(name)
        h = 1e-6 * (1.0 if mech.parameter_kinds[i] == "angle" else 0.01)
        e = np.zeros_like(mech.parameters)
        e[i] = h
        # 4th-order central difference, so that truncation error is far below 1e-6
        fd = (-f(p + 2 * e) + 8 * f(p + e) - 8 * f(p - e) + f(p - 2 * e)) / (12 * h)
        assert abs(g[i] - float(fd)) <= 1e-6 * abs(float(fd)), (name, g[i], float(fd))


def test_forward_and_reverse_mode_agree():
    mech = jl.load("four-bar")
    phis = jnp.asarray(np.deg2rad(np.arange(0.0, 360.0, 10.0)))
    f = lambda p: jnp.sum(jl.solve_path(mech, phis, p).q[:, 1] ** 2)  # noqa: E731
    p = jnp.asarray(mech.parameters)
    rev = jax.jit(jax.grad(f))(p)  # compiled: eagerly, each primitive would compile on its own
    fwd = jax.jit(jax.jacfwd(f))(p)
    np.testing.assert_allclose(np.asarray(rev), np.asarray(fwd), rtol=1e-12, atol=1e-12)


def test_gradient_wrt_input_is_the_velocity():
    """d q / d phi through the implicit JVP equals the transfer function mu."""
    mech = jl.load("sewing-feed")
    phis = jnp.asarray(np.deg2rad(75.0 + 5.0 * np.arange(8)))
    p = jnp.asarray(mech.parameters)
    q, dq = jax.jit(lambda ph: jax.jvp(lambda x: jl.solve_path(mech, x, p).q, (ph,), (jnp.ones_like(ph),)))(phis)
    tr = jl.transfer(mech, phis, q, p, order=1)
    np.testing.assert_allclose(np.asarray(dq), np.asarray(tr.mu), rtol=1e-12, atol=1e-12)


def test_non_converged_positions_get_zero_gradient_not_nan():
    mech = jl.load("four-bar", overrides={"a": 40.0})  # non-Grashof: part of the turn unreachable
    phis = jnp.asarray(np.deg2rad(np.arange(0.0, 360.0, 10.0)))
    f = lambda p: jnp.sum(jl.solve_path(mech, phis, p).q)  # noqa: E731
    g = jax.jit(jax.grad(f))(jnp.asarray(mech.with_parameters(a=40.0)))
    assert np.all(np.isfinite(np.asarray(g)))


# ------------------------------------------------------------------ the implicit rule, case by case


def _central(f, p, i, h):
    """4th-order central difference of f along parameter i (truncation far below the tolerances)."""
    e = np.zeros(len(p))
    e[i] = h
    p = np.asarray(p, dtype=float)
    return (-f(p + 2 * e) + 8 * f(p + e) - 8 * f(p - e) + f(p - 2 * e)) / (12 * h)


def _check_against_differences(mech, f, p, rtol, forward: bool = False, has_aux: bool = False):
    """Reverse mode against central differences (and, with `forward`, against forward mode). The
    differences take their values from the same compiled value-and-gradient function (one
    compilation fewer than a separate `jax.jit(f)`; each test compiles a continuation solve).
    With `has_aux`, f returns (value, aux), and the aux at p is returned with the gradient (what
    a separate solve would otherwise compile for)."""
    p = np.asarray(p, dtype=float)
    main = (lambda out: out[0]) if has_aux else (lambda out: out)  # the part differentiated
    vg = jax.jit(jax.value_and_grad(f, has_aux=has_aux))
    out, g = vg(jnp.asarray(p))
    aux, g = (out[1] if has_aux else None), np.asarray(g)
    fd = np.array([_central(lambda x: float(main(vg(jnp.asarray(x))[0])), p, i,
                            1e-5 * (1.0 if k == "angle" else max(abs(p[i]), 1e-3)))
                   for i, k in enumerate(mech.parameter_kinds)])
    scale = np.abs(fd).max()
    assert np.all(np.isfinite(g))
    if forward:
        gf = np.asarray(main(jax.jit(jax.jacfwd(f, has_aux=has_aux))(jnp.asarray(p))))
        np.testing.assert_allclose(g, gf, rtol=1e-10, atol=1e-12 * scale)
    np.testing.assert_allclose(g, fd, rtol=rtol, atol=rtol * scale)
    return (g, aux) if has_aux else g


def test_closed_form_rule_all_parameters_unknowns_and_points():
    """The feed six-bar (all dyads: closed form): unknowns and the feed-dog point along 24 inputs,
    differentiated in all 11 parameters (lengths and the angle gamma) — reverse mode against
    forward mode and against central differences. (The continuation tests below check reverse
    mode against central differences only: reverse mode is the transpose of the same JVP rule.)"""
    mech = jl.load("sewing-feed")
    phis = jnp.asarray(np.deg2rad(80.0 + 15.0 * np.arange(24)))
    w = jnp.asarray(np.random.default_rng(1).normal(size=(24, 4)))

    def f(p):
        sol = jl.solve_path(mech, phis, p, points=True)
        return jnp.sum(sol.q * w) + 1e3 * jnp.sum(sol.points[:, 0] ** 2)

    _check_against_differences(mech, f, mech.parameters, 1e-7, forward=True)


@pytest.mark.parametrize("scene", ["sewing-feed", "four-bar"])
def test_continuation_rule_against_central_differences(scene):
    """The same rule after Newton with continuation (its sines and cosines computed from q)."""
    mech = jl.load(scene)
    phis = jnp.asarray(np.deg2rad(mech.input_start * 180 / np.pi + 10.0 * np.arange(36)))
    opts = jl.NewtonOptions(method="continuation")

    def f(p):
        sol = jl.solve_path(mech, phis, p, options=opts, points=True)
        return jnp.sum(jnp.sin(sol.q)) + 1e2 * jnp.sum(sol.points ** 2)

    _check_against_differences(mech, f, mech.parameters, 1e-7)


def _triad_scene():
    """A class-III Assur group (triad) driven by a crank: binary links 1, 2, 3 and a ternary link 4;
    neither loop has only two new unknowns, so Φ_q is one 4 × 4 block (no closed form). The frame
    pivots are placed so that the loops close at the guesses."""
    a, l1, l2, l3, s1, s2, alpha = 0.02, 0.07, 0.06, 0.065, 0.05, 0.045, np.deg2rad(50.0)
    phi0, t1, t2, t3, t4 = np.deg2rad([30.0, 20.0, 100.0, 70.0, -10.0])
    e = lambda t: np.array([np.cos(t), np.sin(t)])  # noqa: E731
    tip = a * e(phi0) + l1 * e(t1)
    g2 = tip + s1 * e(t4) - l2 * e(t2)
    g3 = tip + s2 * e(t4 + alpha) - l3 * e(t3)
    text = f"""
[mechanism]
name = "triad"
length_unit = "m"
angle_unit = "deg"

[parameters]
a = {a}
l1 = {l1}
l2 = {l2}
l3 = {l3}
s1 = {s1}
s2 = {s2}
alpha = {np.rad2deg(alpha)}
g2x = {g2[0]}
g2y = {g2[1]}
g3x = {g3[0]}
g3y = {g3[1]}

[input]
name = "phi"
start = {np.rad2deg(phi0)}

[unknowns]
t1 = {np.rad2deg(t1)}
t2 = {np.rad2deg(t2)}
t3 = {np.rad2deg(t3)}
t4 = {np.rad2deg(t4)}

[loops]
one = ["a @ phi", "l1 @ t1", "s1 @ t4", "-l2 @ t2", "-(g2x, g2y)"]
two = ["a @ phi", "l1 @ t1", "s2 @ t4 + alpha", "-l3 @ t3", "-(g3x, g3y)"]

[points]
T = ["a @ phi", "l1 @ t1"]
"""
    return jl.loads(text)


def test_rule_on_a_single_4x4_block_against_central_differences():
    """A structure whose Φ_q is one 4 × 4 block (Gaussian elimination with pivoting in the rule)."""
    mech = _triad_scene()
    phis = jnp.asarray(np.deg2rad(26.0 + 1.0 * np.arange(12)))

    def f(p):
        s = jl.solve_path(mech, phis, p, points=True)
        return jnp.sum(jnp.cos(s.q)) + 1e3 * jnp.sum(s.points ** 2), s.result

    _, result = _check_against_differences(mech, f, mech.parameters, 1e-7, forward=True, has_aux=True)
    assert np.all(np.asarray(result) == jl.RESULTS.converged)


# s + l = p + q: 20 + 60 = 45 + 35 mm; at φ2 = 0 all four links are collinear (a change point)
_GRASHOF_BOUNDARY = {"a": 0.020, "b": 0.060, "c": 0.045, "d": 0.035, "cx": 0.03, "cy": 0.015}


@pytest.mark.parametrize("method", ["auto", "continuation"])
def test_rule_near_a_change_point(method):
    """Approaching a change point (Φ_q singular at φ2 = 0, to within 3°) the sensitivities grow
    like 1 / sin of the transmission angle; they stay exact (against central differences), and in
    the input they equal the transfer function μ."""
    mech = jl.loads(open(jl.__path__[0] + "/scenes/four-bar.toml").read().replace('length_unit = "mm"',
                                                                                 'length_unit = "m"'))
    p0 = np.array([_GRASHOF_BOUNDARY[n] for n in mech.parameter_names])
    phis = jnp.asarray(np.deg2rad(np.arange(-60.0, -2.9, 3.0)))
    opts = jl.NewtonOptions(method=method)
    # the branch that meets the other at φ2 = 0 (the start configuration by the closed form)
    q0 = jl.solve(mech, phis[:1], jnp.asarray(p0)).q[0]
    sol = jl.solve(mech, phis, jnp.asarray(p0), q0, options=opts)
    assert np.all(np.asarray(sol.result) == jl.RESULTS.converged)

    def f(p):
        return jnp.sum(jl.solve_path(mech, phis, p, q0, options=opts).q[:, 1] * jnp.arange(1.0, 1.0 + len(phis)))

    _check_against_differences(mech, f, p0, 1e-6)
    q, dq = jax.jit(lambda phs: jax.jvp(lambda ph: jl.solve_path(mech, ph, jnp.asarray(p0), q0, options=opts).q,
                                        (phs,), (jnp.ones_like(phs),)))(phis)
    mu = jl.transfer(mech, phis, q, jnp.asarray(p0), order=1).mu
    assert np.abs(np.asarray(mu)).max() > 3.0  # large: near the change point
    np.testing.assert_allclose(np.asarray(dq), np.asarray(mu), rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("method", ["auto", "continuation"])
def test_unassemblable_positions_have_zero_gradient_and_no_nan(method):
    """A non-Grashof four-bar (a = 50 mm: s + l > p + q) cannot be assembled over part of the turn: there every
    sensitivity is exactly zero (reverse and forward mode; the unknowns wherever the position is not
    converged, the points — NaN there, masked by the objective — wherever it is not assembled), and
    no NaN reaches the gradient."""
    mech = jl.load("four-bar")
    p = jnp.asarray(mech.with_parameters(a=50.0))
    phis = jnp.asarray(np.deg2rad(np.arange(0.0, 360.0, 10.0)))
    opts = jl.NewtonOptions(method=method)
    code = np.asarray(jl.solve(mech, phis, p, options=opts).result)
    not_conv = code != jl.RESULTS.converged
    not_assembled = not_conv & (code != jl.RESULTS.singular)
    assert not_assembled.any() and (~not_conv).any()

    def f(pp, mask_q, mask_pts):
        s = jl.solve_path(mech, phis, pp, options=opts, points=True)
        pts = jnp.where(jnp.isfinite(s.points), s.points, 0.0)
        return jnp.sum(s.q * mask_q[:, None]) + jnp.sum(pts * mask_pts[:, None, None])

    bad = (jnp.asarray(not_conv, float), jnp.asarray(not_assembled, float))
    grad = jax.jit(jax.grad(f))  # one compilation for both masks
    g = np.asarray(grad(p, *bad))
    gf = np.asarray(jax.jit(jax.jacfwd(f))(p, *bad))
    assert np.all(g == 0.0) and np.all(gf == 0.0)
    g = np.asarray(grad(p, 1.0 - bad[0], 1.0 - bad[1]))
    assert np.all(np.isfinite(g)) and np.any(g != 0.0)


@pytest.mark.parametrize("method", ["auto", "continuation"])
def test_second_derivatives_match_central_differences_of_the_gradient(method):
    """The Hessian (forward over reverse through the rule's own derivative, `_solve_batch_trig`)
    against central differences of the exact gradient. The stored sines and cosines once carried
    their own tangents on top of the angles' (`_known_trig`): the Hessian was 24 % off."""
    mech = jl.load("four-bar")
    phis = jnp.asarray(mech.input_start + 2 * np.pi * np.arange(12) / 12)
    opts = jl.NewtonOptions(method=method)

    def f(p):
        sol = jl.solve_path(mech, phis, p, options=opts, points=True)
        return jnp.sum(sol.points ** 2) + jnp.sum(jnp.sin(sol.q))

    p0 = jnp.asarray(mech.parameters)
    hess = np.asarray(jax.jit(jax.hessian(f))(p0))
    grad = jax.jit(jax.grad(f))
    fd = []
    for i in range(len(p0)):
        h = 1e-6 * (abs(float(p0[i])) + 1e-3)
        fd.append((np.asarray(grad(p0.at[i].add(h))) - np.asarray(grad(p0.at[i].add(-h)))) / (2 * h))
    fd = np.stack(fd)
    assert np.all(np.isfinite(hess))
    assert np.max(np.abs(hess - fd)) <= 1e-7 * np.max(np.abs(fd))
    assert np.allclose(hess, hess.T, rtol=0, atol=1e-9 * np.max(np.abs(hess)))
