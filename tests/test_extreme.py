"""Extreme cases (issue 7, item 2): each asserts a specific, correct outcome.

- dead centre / toggle of a non-Grashof four-bar (Φ_q singular at the edge of its reach);
- a four-bar on the Grashof boundary (a change point, where the two branches meet);
- branch flips under a small perturbation of a near-boundary design;
- a design that assembles for only part of the revolution;
- scale disparity (0.3 mm crank against 60 mm links; lengths from 1e-6 m to 10 m);
- very high speed (1e5 rpm): velocities, accelerations and drive torque;
- NaN and inf inputs;
- stiff contact (the sinker at C = 1e7 N/m) against the closed-form steady lag;
- float32 on the linkage cases.

References are closed forms (`closed_forms.py`; derivatives by AD of a jnp copy of Freudenstein's
solution). Where the engine does not yet behave correctly the test states the correct outcome and
is marked `xfail(strict=True)` with the number of its entry in `notes/engine-requests.md`.
"""

from __future__ import annotations

import math
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from closed_forms import fourbar_freudenstein

import jaxlink as jl

R = jl.RESULTS
DTYPES = [np.float64, np.float32]
FOURBAR_M = open(jl.__path__[0] + "/scenes/four-bar.toml").read().replace('length_unit = "mm"',
                                                                           'length_unit = "m"')


def _xf(n):
    return pytest.mark.xfail(strict=True, reason=f"engine-requests.md #{n}")


def _wrap(x):
    return np.angle(np.exp(1j * np.asarray(x, dtype=float)))


FOURBAR = jl.loads(FOURBAR_M)  # one mechanism object for every design: one compilation per shape
FOURBAR_MM = jl.load("four-bar")


class _Design:
    """The built-in four-bar (lengths in metres, coupler point cx = b/2, cy = b/4) as a parameter
    vector of the shared mechanism `FOURBAR`."""

    def __init__(self, a, b, c, d):
        vals = {"a": a, "b": b, "c": c, "d": d, "cx": b / 2, "cy": b / 4}
        self.parameters = np.array([vals[n] for n in FOURBAR.parameter_names])


def _fourbar(a, b, c, d):
    return _Design(a, b, c, d)


#: every `_solve` of this file runs on this many inputs, its own followed by its last one repeated,
#: and returns its own positions: one compiled program per method and dtype instead of one per
#: length (the positions of a sequence never depend on inputs after them;
#: `JAXLINK_TEST_CHECK_PAD=1` compares every such solve with the unpadded one, bit for bit: all
#: equal on 2026-11-27, and this file's serial run 53 -> 33 s)
PAD = 384


def _solve(design, phis, dtype, method, q0):
    phis = np.asarray(phis).astype(dtype)
    n = len(phis)
    padded = np.concatenate([phis, np.full(PAD - n, phis[-1], dtype)])
    args = (jnp.asarray(design.parameters, dtype=dtype), np.asarray(q0).astype(dtype))
    sol = jl.solve(FOURBAR, padded, *args, options=jl.NewtonOptions(method=method))
    if os.environ.get("JAXLINK_TEST_CHECK_PAD"):
        ref = jl.solve(FOURBAR, phis, *args, options=jl.NewtonOptions(method=method))
        for a, b in zip(jax.tree_util.tree_leaves(ref), jax.tree_util.tree_leaves(sol)):
            assert np.array_equal(np.asarray(a), np.asarray(b)[:n], equal_nan=True), (method, dtype, n)
    return jax.tree_util.tree_map(lambda x: x[:n], sol)


def _branch_err(q, a, b, c, d, phis, branch):
    ref = np.stack(fourbar_freudenstein(a, b, c, d, np.asarray(phis, dtype=float), branch), 1)
    return np.abs(_wrap(np.asarray(q, dtype=float) - ref)).max(1)


def _q0(a, b, c, d, phi, branch):
    return np.array(fourbar_freudenstein(a, b, c, d, np.array([phi]), branch)).ravel()


pytestmark = pytest.mark.filterwarnings("ignore:invalid value encountered in sqrt")  # closed form off its range


# ----------------------------------------------------------------------------- dead centre / toggle

# non-Grashof: a + d = 75 > b + c = 70; the crank reaches only |φ2| ≤ φt where |A − B0| = b + c
TA, TB, TC, TD = 0.020, 0.040, 0.030, 0.055
PHI_T = math.acos((TA * TA + TD * TD - (TB + TC) ** 2) / (2 * TA * TD))  # 132.10°


def _toggle_config():
    """At the toggle the coupler and rocker are collinear: e3 along B0 − A, e4 = −e3."""
    th = math.atan2(-TA * math.sin(PHI_T), TD - TA * math.cos(PHI_T))
    return np.array([th, th + math.pi])


@pytest.mark.parametrize("method,dtype", [
    ("auto", np.float64), ("continuation", np.float64), ("auto", np.float32), ("continuation", np.float32),
])
def test_toggle_approach_and_stop(method, dtype):
    """Approaching the toggle the positions stay exact on the start branch; past it every position
    is `cannot_assemble`, with finite q; nothing converges where the loop cannot close. (Past the
    toggle by δ the loop misses by ≈ a sin φt δ = 1.5e-2 δ m: the float64 cases start at
    δ = 1e-4 (1.5 µm), the float32 ones at δ = 1e-2 (0.15 mm, 23× the float32 tolerance).)"""
    mech = _fourbar(TA, TB, TC, TD)
    before = np.deg2rad(np.arange(90.0, 126.0, 1.0))  # ≥ 6° from the toggle
    after = PHI_T + np.array([1e-4 if dtype == np.float64 else 1e-2, 3e-2, 0.1, 0.3])
    phis = np.concatenate([before, after])
    sol = _solve(mech, phis, dtype, method, _q0(TA, TB, TC, TD, phis[0], -1))
    codes = np.asarray(sol.result)
    nb = len(before)
    assert np.all(codes[:nb] == R.converged)
    tol = 1e-13 if dtype == np.float64 else 2e-6
    assert _branch_err(sol.q[:nb], TA, TB, TC, TD, before, -1).max() < tol
    assert np.all(codes[nb:] == R.cannot_assemble)
    assert np.all(np.isfinite(np.asarray(sol.q)))


@pytest.mark.parametrize("method,dtype", [
    ("auto", np.float64), ("auto", np.float32), ("continuation", np.float64), ("continuation", np.float32),
])
def test_exact_toggle_is_assembled(method, dtype):
    """At the toggle itself (φt to rounding) the linkage assembles, uniquely, in the collinear
    configuration: the position must be reported assembled (`converged`, or `singular` for the
    singular Φ_q) with that configuration, not refused as `cannot_assemble` or `max_steps`."""
    mech = _fourbar(TA, TB, TC, TD)
    phis = np.concatenate([np.deg2rad(np.arange(90.0, 132.0, 1.0)), [PHI_T]])
    sol = _solve(mech, phis, dtype, method, _q0(TA, TB, TC, TD, phis[0], -1))
    assert int(sol.result[-1]) in (R.converged, R.singular)
    tol = 1e-6 if dtype == np.float64 else 2e-3  # √eps: the error at a double root
    assert np.abs(_wrap(np.asarray(sol.q[-1], dtype=float) - _toggle_config())).max() < tol


@pytest.mark.parametrize("method", ["auto", "continuation"])
def test_float32_near_toggle_accuracy(method):
    """float32 within 3° of the toggle: what the solver calls converged must be as accurate as
    float32 allows there (the closed form reaches 7e-6 rad at 1e-3 rad from the toggle)."""
    mech = _fourbar(TA, TB, TC, TD)
    phis = np.concatenate([np.deg2rad(np.arange(90.0, 132.0, 1.0)), [PHI_T - 1e-3]])
    sol = _solve(mech, phis, np.float32, method, _q0(TA, TB, TC, TD, phis[0], -1))
    conv = np.asarray(sol.converged)
    assert conv.all()
    assert _branch_err(sol.q, TA, TB, TC, TD, phis, -1)[conv].max() < 2e-5


# ----------------------------------------------------------------------------- Grashof boundary

# s + l = p + q: 20 + 60 = 45 + 35; at φ2 = 0 all four links are collinear (a change point)
GA, GB, GC, GD = 0.020, 0.060, 0.045, 0.035


@pytest.mark.parametrize("method", ["auto", "continuation"])
@pytest.mark.parametrize("dtype", DTYPES)
def test_grashof_boundary_passes_through_change_point(method, dtype):
    """The crank turns fully; every position assembles and lies on one of the two closed-form
    branches (which meet at φ2 = 0); before the change point it is the start branch."""
    mech = _fourbar(GA, GB, GC, GD)
    phis = np.deg2rad(np.arange(-90.0, 270.0, 1.0))
    sol = _solve(mech, phis, dtype, method, _q0(GA, GB, GC, GD, phis[0], +1))
    codes = np.asarray(sol.result)
    i0 = 90  # φ2 = 0
    away = np.abs(_wrap(phis)) > np.deg2rad(4.5)
    assert np.all(codes[away] == R.converged)
    assert np.all(np.isin(codes, [R.converged, R.singular]))
    err = np.minimum(_branch_err(sol.q, GA, GB, GC, GD, phis, +1), _branch_err(sol.q, GA, GB, GC, GD, phis, -1))
    f64 = dtype == np.float64
    assert err[away].max() < (1e-12 if f64 else 2e-5)
    assert err.max() < (1e-7 if f64 else 3e-3)  # √eps at the double root
    assert _branch_err(sol.q[:i0 - 4], GA, GB, GC, GD, phis[:i0 - 4], +1).max() < (1e-12 if f64 else 2e-5)


@pytest.mark.parametrize("method", ["auto", "continuation"])
def test_grashof_change_point_is_flagged_singular(method):
    """At φ2 = 0 the configuration is collinear (φ3 = φ4 = 0 exactly) and Φ_q = [[0, 0], [b, −c]]
    is singular: the branches meet and the continuation beyond is not unique. The position must
    be reported `singular` (detected), with the collinear configuration."""
    mech = _fourbar(GA, GB, GC, GD)
    phis = np.deg2rad(np.arange(-90.0, 91.0, 1.0))
    sol = _solve(mech, phis, np.float64, method, _q0(GA, GB, GC, GD, phis[0], +1))
    i0 = 90
    assert np.abs(_wrap(np.asarray(sol.q[i0]))).max() < 1e-7
    assert int(sol.result[i0]) == R.singular


def test_float32_newton_next_to_change_point_is_not_converged_off_branch():
    """float32 Newton started within rounding of the change point (φ2 = 0, where Φ_q is singular):
    the first step, rounding noise over a pivot ratio of 1e-6, throws q up to 0.1 rad into the
    double root's valley, where Newton comes back only linearly. Whatever it reports assembled
    (`converged` or `singular`) must lie within ≈ 10 √eps (3e-3 rad, the float32 accuracy at a
    double root) of a closed-form branch: it once gave up half-way down the valley (its best
    residual was the first, noisy one), 0.015 rad off, with a residual within tol, and called that
    `converged` (an H200 continuation, and this CPU with XLA's legacy fusion emitters, reached
    q0 = (3.920868e-7, 6.283185) there), or `singular` where the pivot ratio was below 10 √eps.
    Starts up to 3e-5 rad off, inputs up to 3e-3 rad from the change point (two separate roots)."""
    from jaxlink.solvers import dyads as _dyads
    from jaxlink.solvers.newton import newton

    dt = np.float32
    p = jnp.asarray(_fourbar(GA, GB, GC, GD).parameters, dt)
    eps = float(np.finfo(dt).eps)
    rtol, thr = 1000 * eps, 10 * math.sqrt(eps)
    tol = dt(rtol) * FOURBAR.length_scale(p)
    tp = _dyads.parameter_trig(FOURBAR, p)
    d = np.concatenate([[0.0], np.geomspace(3e-8, 3e-5, 7), -np.geomspace(3e-8, 3e-5, 7)])
    q0 = np.array([0.0, 2 * np.pi]) + np.stack(np.meshgrid(d, d), -1).reshape(-1, 2)
    q0 = np.concatenate([q0, [[3.920868e-07, 6.283185]]]).astype(dt)
    phi = np.array([0.0, 1e-5, -1e-5, 3e-4, -3e-4, 3e-3, -3e-3], dt)
    q0s, phis = np.repeat(q0, len(phi), 0), np.tile(phi, len(q0))
    q, _, code, _, _ = jax.jit(jax.vmap(lambda q0, ph: newton(
        FOURBAR, q0, ph, p, tol=tol, rtol=rtol, max_steps=12, limit_step=False, singular_ratio=thr,
        trig_p=tp)))(jnp.asarray(q0s), jnp.asarray(phis))
    code = np.asarray(code)
    err = np.minimum(*[_branch_err(q, GA, GB, GC, GD, phis.astype(float), b) for b in (+1, -1)])
    assembled = (code == R.converged) | (code == R.singular)
    assert (code == R.singular).sum() >= len(code) // 2  # the test is not vacuous
    assert err[assembled].max() < 3e-3
    assert not np.any(code[-len(phi):] == R.converged)


@pytest.mark.parametrize("method", ["auto", "continuation"])
@pytest.mark.parametrize("dtype", DTYPES)
def test_branch_flip_under_perturbation_is_not_silent(method, dtype):
    """The boundary design with the frame 10 µm longer is a Grashof crank-rocker: its two circuits
    are separate (narrowly, near φ2 = 0), and the crank turns on one of them. A solve at 5° steps
    must not jump to the other circuit and call it converged: every converged position lies on
    the start branch (sign of sin(φ4 − φ3), i.e. of det Φ_q)."""
    d = GD + 1e-5
    mech = _fourbar(GA, GB, GC, d)
    phis = np.deg2rad(np.arange(-90.0, 270.0, 5.0))
    sol = _solve(mech, phis, dtype, method, _q0(GA, GB, GC, d, phis[0], +1))
    conv = np.asarray(sol.converged)
    assert conv.sum() >= len(phis) - 2
    q = np.asarray(sol.q, dtype=float)
    side = np.sign(np.sin(q[:, 1] - q[:, 0]))
    assert np.all(side[conv] == side[0])
    tol = 1e-10 if dtype == np.float64 else 3e-3
    assert _branch_err(q, GA, GB, GC, d, phis, +1)[conv].max() < tol


# ----------------------------------------------------------------------------- partial revolution


@pytest.mark.parametrize("method,dtype", [
    ("auto", np.float64), ("independent", np.float64), ("continuation", np.float64),
    ("auto", np.float32), ("independent", np.float32), ("continuation", np.float32),
])
def test_partial_revolution_assembles_exactly_where_reachable(method, dtype):
    """Non-Grashof: assemblable for |φ2| ≤ 132.1° only. Every reachable input (the whole revolution
    is swept, so the sweep leaves and re-enters the reachable range) is converged and on one of the
    closed-form branches; every unreachable input is `cannot_assemble`."""
    mech = _fourbar(TA, TB, TC, TD)
    phis = np.deg2rad(np.arange(1.0, 361.0, 2.0))  # 131° and 133°: ≥ 0.9° from the toggle at 132.1°
    dist = np.hypot(TD - TA * np.cos(phis), -TA * np.sin(phis))
    reach = dist <= TB + TC
    assert np.abs(dist - (TB + TC)).min() > 1e-4  # no input within float32 tolerance of the edge
    sol = _solve(mech, phis, dtype, method, _q0(TA, TB, TC, TD, phis[0], -1))
    codes = np.asarray(sol.result)
    assert np.all(codes[~reach] == R.cannot_assemble)
    assert np.all(codes[reach] == R.converged)
    err = np.minimum(_branch_err(sol.q, TA, TB, TC, TD, phis, -1), _branch_err(sol.q, TA, TB, TC, TD, phis, 1))
    assert err[reach].max() < (1e-12 if dtype == np.float64 else 2e-5)
    assert np.all(np.isfinite(np.asarray(sol.q)))


# ----------------------------------------------------------------------------- scale disparity

SCALES = {
    "0.3mm-crank-60mm-links": (0.3e-3, 0.060, 0.059, 0.060),
    "1um-crank-10m-links": (1e-6, 10.0, 10.0, 10.0),
    "micro-1e-6m": (20e-6, 60e-6, 45e-6, 55e-6),
    "large-10m": (2.0, 6.0, 4.5, 5.5),
}


@pytest.mark.parametrize("method", ["auto", "continuation"])
@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("case", sorted(SCALES))
def test_scale_disparity(case, dtype, method):
    """Angles to a few ulps of their size whatever the length scale; the rocker's motion (its swing
    is only 2.3e-7 rad for the 1 µm crank) as exact as the angles' resolution allows; the coupler
    point to rounding relative to the link lengths."""
    a, b, c, d = SCALES[case]
    mech = _fourbar(a, b, c, d)
    phis = np.deg2rad(np.arange(0.0, 360.0, 5.0))
    sol = _solve(mech, phis, dtype, method, _q0(a, b, c, d, 0.0, -1))
    assert bool(np.all(sol.converged))
    f64 = dtype == np.float64
    phi3, phi4 = fourbar_freudenstein(a, b, c, d, phis, -1)
    q = np.asarray(sol.q, dtype=float)
    assert np.abs(_wrap(q - np.stack([phi3, phi4], 1))).max() < (4e-15 if f64 else 1e-6)
    swing = np.ptp(phi4)
    motion_err = np.abs(_wrap((q[:, 1] - q[0, 1]) - (phi4 - phi4[0]))).max()
    # absolute: the resolution of the angles themselves (a few ulps of values up to 2π, both the
    # solution's and the closed form's rounding; 2.2e-15 = 5 ulps of an angle in [2, 4) was seen)
    assert motion_err < (4e-15 if f64 else 1e-6)
    if swing > 1e-2:
        assert motion_err / swing < (1e-12 if f64 else 1e-4)
    # the coupler point P = a e2 + (b/2) e3 + (b/4) e3⊥, relative to the longest link
    tr = jl.transfer(FOURBAR, np.asarray(phis).astype(dtype), sol.q, jnp.asarray(mech.parameters, dtype=dtype),
                     order=0)
    px = a * np.cos(phis) + b / 2 * np.cos(phi3) - b / 4 * np.sin(phi3)
    py = a * np.sin(phis) + b / 2 * np.sin(phi3) + b / 4 * np.cos(phi3)
    perr = np.abs(np.asarray(tr.points[:, 0], dtype=float) - np.stack([px, py], 1)).max() / max(a, b, c, d)
    assert perr < (1e-14 if f64 else 1e-6)


# ----------------------------------------------------------------------------- very high speed


def _freudenstein_jnp(a, b, c, d, phi2, branch):
    K1, K2, K3 = d / a, d / c, (a * a - b * b + c * c + d * d) / (2 * a * c)
    A = jnp.cos(phi2) - K1 - K2 * jnp.cos(phi2) + K3
    B = -2 * jnp.sin(phi2)
    C = K1 - (K2 + 1) * jnp.cos(phi2) + K3
    phi4 = 2 * jnp.arctan2(-B + branch * jnp.sqrt(B * B - 4 * A * C), 2 * A)
    phi3 = jnp.arctan2(c * jnp.sin(phi4) - a * jnp.sin(phi2), d + c * jnp.cos(phi4) - a * jnp.cos(phi2))
    cx, cy = b / 2, b / 4
    P = jnp.stack([a * jnp.cos(phi2) + cx * jnp.cos(phi3) - cy * jnp.sin(phi3),
                   a * jnp.sin(phi2) + cx * jnp.sin(phi3) + cy * jnp.cos(phi3)])
    return jnp.concatenate([jnp.stack([phi3, phi4]), P])


@pytest.mark.parametrize("dtype", DTYPES)
def test_very_high_speed_1e5_rpm(dtype):
    """ω = 1e5 rpm: rocker rates and the coupler point's velocity (≈ 330 m/s) and acceleration
    (≈ 4e6 m/s²) against derivatives of the closed form; exact ω and ω² scaling."""
    a, b, c, d = 0.020, 0.060, 0.045, 0.055
    mech = _fourbar(a, b, c, d)
    phis = np.deg2rad(np.arange(0.0, 360.0, 10.0))
    sol = _solve(mech, phis, dtype, "auto", _q0(a, b, c, d, 0.0, -1))
    assert bool(np.all(sol.converged))
    omega = 1e5 * 2 * math.pi / 60
    tr = jl.transfer(FOURBAR, phis.astype(dtype), sol.q, jnp.asarray(mech.parameters, dtype=dtype))
    qd, qdd, v, acc = jl.time_derivatives(tr, jnp.asarray(omega, dtype=dtype))
    f = lambda x: _freudenstein_jnp(a, b, c, d, x, -1.0)  # noqa: E731
    d1 = jax.jit(jax.vmap(jax.jacfwd(f)))(jnp.asarray(phis)) * omega
    d2 = jax.jit(jax.vmap(jax.jacfwd(jax.jacfwd(f))))(jnp.asarray(phis)) * omega ** 2
    rel = 1e-11 if dtype == np.float64 else 2e-4
    got_v = np.concatenate([np.asarray(qd, dtype=float), np.asarray(v[:, 0], dtype=float)], 1)
    got_a = np.concatenate([np.asarray(qdd, dtype=float), np.asarray(acc[:, 0], dtype=float)], 1)
    assert np.abs(got_v - np.asarray(d1)).max() < rel * np.abs(d1).max()
    assert np.abs(got_a - np.asarray(d2)).max() < rel * np.abs(d2).max()
    assert np.abs(np.asarray(acc[:, 0], dtype=float)).max() > 3e6


def test_drive_torque_at_1e5_rpm_is_quadratic_in_speed():
    """Constant input speed: every reaction is F(ω) = F(0) + ω² F₂ (gravity plus inertia), so at
    1e5 rpm the torque equals T(0) + (ω/ω₁)² (T(ω₁) − T(0)) to rounding."""
    from jaxlink.analysis.kinetostatics import reactions

    mech = jl.load("slider-crank-mass")
    phis = np.deg2rad(np.arange(0.0, 360.0, 15.0))
    sol = jl.solve(mech, phis)
    assert bool(np.all(sol.converged))
    w1, w = 100.0, 1e5 * 2 * math.pi / 60
    t0, t1, tw = (np.asarray(reactions(mech, phis, q=sol.q, omega=om).torque) for om in (0.0, w1, w))
    pred = t0 + (w / w1) ** 2 * (t1 - t0)
    assert np.abs(tw).max() > 1e3 * np.abs(t0).max()  # inertia dominates at this speed
    assert np.abs(tw - pred).max() < 1e-9 * np.abs(tw).max()


# ----------------------------------------------------------------------------- NaN and inf


@pytest.mark.parametrize("method", ["auto", "continuation", "independent"])
@pytest.mark.parametrize("dtype", DTYPES)
def test_nonfinite_inputs_flag_only_their_positions(method, dtype):
    """NaN / ±inf crank angles: those positions are `nonfinite`, every other one is converged and
    equal to the clean solve; q is finite everywhere."""
    mech = FOURBAR_MM
    phis = np.deg2rad(np.arange(0.0, 360.0, 30.0))
    bad = phis.copy()
    bad[[3, 6, 9]] = [np.nan, np.inf, -np.inf]
    opts = jl.NewtonOptions(method=method)
    p = jnp.asarray(mech.parameters, dtype=dtype)
    sol = jl.solve(mech, bad.astype(dtype), p, options=opts)
    clean = jl.solve(mech, phis.astype(dtype), p, options=opts)
    codes = np.asarray(sol.result)
    ok = np.ones(len(phis), bool)
    ok[[3, 6, 9]] = False
    assert np.all(codes[~ok] == R.nonfinite)
    assert np.all(codes[ok] == R.converged)
    tol = 1e-12 if dtype == np.float64 else 1e-5
    assert np.abs(np.asarray(sol.q, dtype=float)[ok] - np.asarray(clean.q, dtype=float)[ok]).max() < tol
    assert np.all(np.isfinite(np.asarray(sol.q)))


def _length_cases():
    out = []
    for value in (np.nan, np.inf, -np.inf):
        for method in ("auto", "continuation", "independent"):
            for dtype in DTYPES:
                out.append(pytest.param(value, method, dtype, id=f"{value}-{method}-{np.dtype(dtype).name}"))
    return out


@pytest.mark.parametrize("value,method,dtype", _length_cases())
def test_nonfinite_link_length_is_nonfinite(value, method, dtype):
    """A NaN or ±inf coupler length: every position `nonfinite` (never `converged`), q finite."""
    mech = FOURBAR_MM
    P = mech.parameters.copy()
    P[mech.parameter_index("b")] = value
    sol = jl.solve(mech, np.deg2rad(np.arange(0.0, 360.0, 30.0)).astype(dtype), jnp.asarray(P, dtype=dtype),
                   options=jl.NewtonOptions(method=method))
    assert np.all(np.asarray(sol.result) == R.nonfinite)
    assert np.all(np.isfinite(np.asarray(sol.q)))


@pytest.mark.parametrize("method", ["auto", "independent", "continuation"])
@pytest.mark.parametrize("dtype", DTYPES)
def test_nan_guess_is_nonfinite_everywhere(dtype, method):
    """A NaN start guess selects no branch: every position is `nonfinite` (a continuation from a
    sanitized guess would hand out positions on an arbitrary branch)."""
    mech = FOURBAR_MM
    sol = jl.solve(mech, np.deg2rad(np.arange(0.0, 360.0, 30.0)).astype(dtype),
                   jnp.asarray(mech.parameters, dtype=dtype), np.array([np.nan, 1.0]).astype(dtype),
                   options=jl.NewtonOptions(method=method))
    assert np.all(np.asarray(sol.result) == R.nonfinite)
    assert np.all(np.isfinite(np.asarray(sol.q)))


@pytest.mark.parametrize("method", ["auto", "continuation"])
def test_nan_point_only_parameter_is_nonfinite(method):
    """NaN in a parameter used only by a point (cx): the tolerance (scaled by the largest length)
    is NaN, so nothing can be verified; the code must say `nonfinite` (check the parameters), not
    `max_steps` (which tells the user to raise max_steps)."""
    mech = FOURBAR_MM
    P = mech.parameters.copy()
    P[mech.parameter_index("cx")] = np.nan
    sol = jl.solve(mech, np.deg2rad(np.arange(0.0, 360.0, 30.0)), P, options=jl.NewtonOptions(method=method))
    assert np.all(np.asarray(sol.result) == R.nonfinite)


# ----------------------------------------------------------------------------- stiff contact


@pytest.mark.parametrize("method", ["explicit", "implicit"])
def test_stiff_contact_1e7_steady_lag_on_the_rise(method):
    """C = 1e7 N/m. On the straight rise (slope α = 30°) the sinker settles to the cam's speed with
    a constant lag l* where the contact force balances the constant load (y'' = 0, y' = y_z'):
    0 = P1 + (C l*/cos α)(P2 sin α + P3 cos α)  ⇒  l* = −P1 cos α / (C (P2 sin α + P3 cos α)),
    1.9e-7 m here. The transient decays in ~0.1 ms, so at the end of the rise the lag is l*."""
    from jaxlink import cam as sk

    m, f, C = 1.5e-3, 0.1, 1e7
    p = sk.make_params(m=m, C=C, f=f)
    geom = [g for g in sk.seed_geometries() if g.name == "R20-55"][0]
    cam = sk.make_cam(geom, sk.butt_speed(350.0, 0.096))
    sol = sk.simulate(p, cam, method=method, rtol=1e-8, atol=1e-13, n_out=2001)
    assert int(sol.result) == sk.RESULTS.converged
    R_sum = 3.2014 + 3.1216 + 6.323
    P1 = (m * 9.81 - f * R_sum) / m
    P2 = (6 * f**2 / 11 - 156 * f / 36) / m
    P3 = (1 - 120 * f**2 / 36 - 6 * f / 11) / m
    al = math.radians(30.0)
    lstar = -P1 * math.cos(al) / (C * (P2 * math.sin(al) + P3 * math.cos(al)))
    t = np.asarray(sol.t)
    window = (t > 0.8 * float(cam.t_rise)) & (t < 0.99 * float(cam.t_rise))
    lag = np.asarray(sol.lag)[window]
    assert np.all(np.asarray(sol.contact)[window] == 1)
    assert np.abs(lag / lstar - 1).max() < 1e-3
    N = np.asarray(sol.N)[window]
    assert np.abs(N / (C * lstar / math.cos(al)) - 1).max() < 1e-3
