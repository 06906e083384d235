"""Knitting sinker on a stitch cam (issue 6): cam tracks, model, integrators, jamming.

References: closed forms, the numbers published in `shared/spec/sinker-cam.md` (rebuilt from
the seed), and an independent scipy `solve_ivp` solution (`jaxlink.cam.reference_solution`).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxlink import cam as sk

SPEED = sk.butt_speed(350.0, 0.096)
GEOMS = {g.name: g for g in sk.seed_geometries()}
N_OUT = 2001


def _cam(name, arc="exact"):
    g = GEOMS[name]._replace(arc=arc)
    return sk.make_cam(g, SPEED)


def _take(tree, i):
    return jax.tree.map(lambda x: x[i], tree)


# ------------------------------------------------------------------ cam tracks
# spec table: x1 / x_arc / x2 (mm), y_total (mm), t1 / t_arc / t2 (ms)
CAM_TABLE = {
    "R10-45": (9.298, 2.071, 8.510, 15.47, 5.285, 1.177, 4.837),
    "R20-45": (8.217, 4.142, 7.521, 15.44, 4.671, 2.354, 4.275),
    "R10-50": (8.991, 2.660, 8.229, 17.23, 5.110, 1.512, 4.677),
    "R20-50": (7.602, 5.321, 6.957, 17.15, 4.321, 3.024, 3.955),
    "R10-55": (8.713, 3.192, 7.975, 19.35, 4.953, 1.814, 4.533),
    "R20-55": (7.047, 6.383, 6.450, 19.13, 4.006, 3.628, 3.666),
}


@pytest.mark.parametrize("name", sorted(CAM_TABLE))
def test_cam_table(name):
    x1, xa, x2, ytot, t1, ta, t2 = CAM_TABLE[name]
    cam = _cam(name)
    v = float(cam.speed)
    assert abs(float(cam.t_end) - 11.30e-3) < 1e-6
    assert float(cam.t_rise) * v * 1e3 == pytest.approx(x1, abs=1.5e-3)
    assert (float(cam.t_descent - cam.t_rise)) * v * 1e3 == pytest.approx(xa, abs=1.5e-3)
    assert float(cam.t_end - cam.t_descent) * v * 1e3 == pytest.approx(x2, abs=1.5e-3)
    assert float(sk.cam_eval(cam, cam.t_end)[0]) * 1e3 == pytest.approx(ytot, abs=0.006)
    assert float(cam.t_rise) * 1e3 == pytest.approx(t1, abs=1.5e-3)
    assert float(cam.t_end - cam.t_descent) * 1e3 == pytest.approx(t2, abs=1.5e-3)
    # the seed's 0.1 mm chord polygon: same ends to a few micrometres
    poly = _cam(name, "polygon")
    n_chords = int(np.sum(np.isfinite(np.asarray(poly.t0)))) - 1
    arc_len = GEOMS[name].radius * (GEOMS[name].descent_angle - GEOMS[name].rise_angle)
    assert n_chords == round(arc_len / 1e-4)
    assert float(sk.cam_eval(poly, poly.t_end)[0]) == pytest.approx(ytot * 1e-3, abs=4e-5)


@pytest.mark.parametrize("arc", ["exact", "polygon"])
def test_cam_continuity_and_slope(arc):
    cam = _cam("R20-55", arc)
    t0 = np.asarray(cam.t0)
    ks = np.arange(1, int(np.sum(np.isfinite(t0))))
    for k in ks:  # y_z continuous at every piece boundary, both formulas agree there
        left = float(sk.cam_eval(cam, t0[k], k - 1)[0])
        right = float(sk.cam_eval(cam, t0[k], k)[0])
        assert abs(left - right) < 1e-12
    # y_z' = d y_z / dt (forward AD through the track) and tan(alpha) = y_z' / v
    ts = jnp.linspace(0.0, float(cam.t_end), 97)[1:-1]

    def check(t):
        k = sk.cam_segment(cam, t)
        dyz = jax.grad(lambda tt: sk.cam_eval(cam, tt, k)[0])(t)
        _, alpha, yz_dot = sk.cam_eval(cam, t, k)
        return dyz, yz_dot, alpha

    dyz, yz_dot, alpha = jax.vmap(check)(ts)
    np.testing.assert_allclose(np.asarray(dyz), np.asarray(yz_dot), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(yz_dot), SPEED * np.tan(np.asarray(alpha)),
                               rtol=1e-12)
    # exact arc: sin(alpha) = sin(a1) + (x - x1)/R inside the transition
    if arc == "exact":
        tm = 0.5 * (float(cam.t_rise) + float(cam.t_descent))
        _, alpha, _ = sk.cam_eval(cam, tm)
        expect = math.sin(math.radians(30)) + (tm - float(cam.t_rise)) * SPEED / 0.02
        assert math.sin(float(alpha)) == pytest.approx(expect, rel=1e-12)


# ------------------------------------------------------------------ model, static thresholds
def test_damping_and_coefficients():
    p = sk.make_params()
    assert float(p.k_over_m) == pytest.approx(1065.8, abs=0.05)  # seed "1066"
    p1, p2, p3 = sk.p_coefficients(p._replace(f=jnp.asarray(0.0)))
    assert float(p2) == 0.0 and float(p3) * 1.5e-3 == pytest.approx(1.0)
    assert float(p1) == pytest.approx(9.81)
    f = 0.15
    _, p2, p3 = sk.p_coefficients(p._replace(f=jnp.asarray(f)))
    assert float(p2) * 1.5e-3 == pytest.approx(6 * f**2 / 11 - 156 * f / 36)
    assert float(p3) * 1.5e-3 == pytest.approx(1 - 120 * f**2 / 36 - 6 * f / 11)


@pytest.mark.parametrize("deg, expected", [(45, 0.1853), (50, 0.1627), (55, 0.1410),
                                           (30, 0.2608)])
def test_static_threshold(deg, expected):
    a = math.radians(deg)
    fs = float(sk.static_threshold(a))
    assert abs(fs - expected) < 1e-4
    assert abs(float(sk.drive_fraction(a, fs))) < 1e-12
    assert float(sk.drive_fraction(a, fs - 1e-3)) > 0 > float(sk.drive_fraction(a, fs + 1e-3))


# ------------------------------------------------------------------ integrators
@pytest.mark.parametrize("solver", [sk.DormandPrince5(), sk.RadauIIA5()])
def test_damped_oscillator_closed_form(solver):
    """y'' = -w^2 y - 2 z w y' (stiff for w = 1e4): matches the closed form to 1e-7."""
    w, z = 1.0e4, 0.05
    wd = w * math.sqrt(1 - z * z)

    def vf(t, u, mode, piece):
        del t, mode, piece  # unused
        return jnp.stack([u[1], -w * w * u[0] - 2 * z * w * u[1]])

    ts = jnp.linspace(0.0, 2e-3, 51)
    sol = sk.integrate_hybrid(vf, lambda t, u, k: 1.0, lambda t: 0, jnp.array([jnp.inf]),
                              jnp.array([1.0, 0.0]), 1.0, 2e-3, ts, solver=solver,
                              rtol=1e-9, atol=1e-12)
    t = np.asarray(ts)
    exact = np.exp(-z * w * t) * (np.cos(wd * t) + z * w / wd * np.sin(wd * t))
    assert int(sol.result) == sk.RESULTS.converged
    assert np.max(np.abs(np.asarray(sol.us[:, 0]) - exact)) < 1e-7


@pytest.fixture(scope="module")
def stiffness_refs():
    out = {}
    for c in (1e4, 3.5e4, 1e5, 1e6, 1e7):
        km = float(sk.damping_from_log_decrement(c, 1.5e-3))
        out[c] = sk.reference_solution(radius=0.02, descent_deg=55, f=0.1, C=c, k_over_m=km,
                                       ts=np.linspace(0.0, 19.88e-3 / SPEED, N_OUT),
                                       rtol=1e-11, max_step=5e-6)
    return out


@pytest.mark.parametrize("method", ["explicit", "implicit"])
def test_stiffness_range_against_scipy(method, stiffness_refs):
    """C = 1e4 ... 1e7 N/m (k/m from ln 2) in one vmapped call: no failure, |y - y_ref| <=
    1e-6 m at rtol = 1e-6 (in fact ~1e-9), and the contact changes the reference finds."""
    cs = np.array(sorted(stiffness_refs))
    km = np.asarray(sk.damping_from_log_decrement(cs, 1.5e-3))
    pb, cb, shape = sk.product_cases(sk.make_params(f=0.1), _cam("R20-55"), C=cs, k_over_m=km)
    sol = sk.simulate_batch(pb, cb, n_out=N_OUT, method=method)
    assert shape == (1, 1, len(cs))
    for i, c in enumerate(cs):
        _, yref, info = stiffness_refs[c]
        assert int(sol.result[i]) == sk.RESULTS.converged
        assert np.max(np.abs(np.asarray(sol.y[i]) - yref[:, 0])) < 1e-6
        assert np.max(np.abs(np.asarray(sol.v[i]) - yref[:, 1])) < 1e-4
        assert int(sol.stats.num_events[i]) == info["events"]
        assert not bool(sol.jammed[i])


def test_short_bounce_not_skipped():
    """f = 0.16, C = 3.5e4: the contact is lost for ~0.2 ms and only ~8 um in the rise.

    The hybrid integrator finds both switches (times within 2 us of scipy's events). With
    loose tolerances (large steps) a check of the guard at the step ends only steps over the
    bounce, while sampling the step's interpolant still finds it."""
    p = sk.make_params(f=0.16)
    cam = _cam("R10-45")
    ts = np.linspace(0.0, float(cam.t_end), N_OUT)
    dt = ts[1] - ts[0]
    _, yref, info = sk.reference_solution(radius=0.01, descent_deg=45, f=0.16, C=3.5e4,
                                          k_over_m=float(p.k_over_m), ts=ts)
    t_loss, t_regain = info["event_times"]
    assert 0.1e-3 < t_regain - t_loss < 0.4e-3
    lag_ref = np.asarray(sk.cam_profile(cam, ts)[0]) - yref[:, 0]
    assert 1e-6 < -lag_ref.min() < 2e-5
    sol = sk.simulate(p, cam, n_out=N_OUT)
    assert int(sol.stats.num_events) == 2
    lost = ts[np.asarray(sol.lag) < 0]
    assert t_loss <= lost[0] < t_loss + dt and t_regain - dt < lost[-1] <= t_regain
    assert np.all(np.asarray(sol.contact)[np.asarray(sol.lag) < -1e-9] == 0.0)
    loose = dict(n_out=N_OUT, rtol=1e-3, atol=1e-10, max_step=math.inf)  # no step cap: large steps
    assert int(sk.simulate(p, cam, event_samples=16, **loose).stats.num_events) == 2
    assert int(sk.simulate(p, cam, event_samples=1, **loose).stats.num_events) == 0
    # the default step cap (0.1 ms < the 0.22 ms bounce) alone also keeps the ends-only check honest
    capped = dict(loose, max_step=1e-4)
    assert int(sk.simulate(p, cam, event_samples=1, **capped).stats.num_events) == 2


def test_vmap_matches_single_runs():
    cams = sk.make_cam([GEOMS["R10-45"], GEOMS["R20-55"]], SPEED)
    pb, cb, shape = sk.product_cases(sk.make_params(), cams, f=[0.1, 0.15])
    batch = sk.simulate_batch(pb, cb, n_out=N_OUT)
    assert shape == (2, 2, 1)
    for i, (fi, gi) in enumerate([(0, 0), (0, 1), (1, 0), (1, 1)]):
        single = sk.simulate(sk.make_params(f=[0.1, 0.15][fi]), _take(cams, gi), n_out=N_OUT)
        np.testing.assert_allclose(np.asarray(batch.y[i]), np.asarray(single.y), atol=1e-12)
        assert int(batch.stats.num_steps[i]) == int(single.stats.num_steps)


# ------------------------------------------------------------------ published maxima
# spec section 4 (C = 3.5e4, F_P = 0, damping always on, exact arc): rebuilt reference model
RISE_F01 = dict(a=3296.0, v=1.678, lag=0.258e-3)
DESC_F01 = {"R10-45": (728.0, 1.929), "R20-45": (439.0, 1.858), "R10-50": (719.0, 2.269),
            "R20-50": (560.0, 2.231), "R10-55": (927.0, 2.756), "R20-55": (670.0, 2.688)}


def test_maxima_f01_against_reference_model():
    names = sorted(DESC_F01)
    cams = sk.make_cam([GEOMS[n] for n in names], SPEED)
    pb, cb, _ = sk.product_cases(sk.make_params(f=0.1), cams)
    sol = sk.simulate_batch(pb, cb, n_out=N_OUT)
    for i, name in enumerate(names):
        mx = sk.maxima(_take(sol, i), _take(cams, i))
        assert mx.rise_a == pytest.approx(RISE_F01["a"], rel=0.01)
        assert mx.rise_v == pytest.approx(RISE_F01["v"], rel=0.01)
        assert mx.rise_lag == pytest.approx(RISE_F01["lag"], rel=0.01)
        assert mx.desc_a == pytest.approx(DESC_F01[name][0], rel=0.01)
        assert mx.desc_v == pytest.approx(DESC_F01[name][1], rel=0.01)
        # bounce in the rise: 0.123 mm for 1.09 ms in the reference model
        assert mx.bounce_depth == pytest.approx(0.123e-3, rel=0.02)
        assert mx.bounce_time == pytest.approx(1.09e-3, rel=0.02)


# ------------------------------------------------------------------ dynamic thresholds
SEED_BRACKET = {45: (0.18, 0.19), 50: (0.16, 0.17), 55: (0.14, 0.145)}
DYNAMIC_R10 = {45: 0.1857, 50: 0.1636, 55: 0.1427}  # issue 6


def test_dynamic_thresholds():
    geoms = sk.seed_geometries()
    th = sk.thresholds(sk.make_params(), sk.make_cam(geoms, SPEED), tol=1e-4)
    for g, s, d, lo, hi in zip(geoms, th.static_f, th.dynamic_f, th.lo, th.hi):
        deg = round(math.degrees(g.descent_angle))
        assert hi - lo <= 1e-4
        assert SEED_BRACKET[deg][0] < d <= SEED_BRACKET[deg][1]
        assert d > s  # the collapse needs D < 0 for a while
        if g.radius == 0.01:
            assert abs(d - DYNAMIC_R10[deg]) < 1e-3
    # the bracket really separates: lo does not jam, hi does
    cams = sk.make_cam(geoms, SPEED)
    assert not sk.jammed_at(sk.make_params(), cams, th.lo).any()
    assert sk.jammed_at(sk.make_params(), cams, th.hi).all()


def test_thresholds_with_another_jam_predicate():
    """`thresholds(jammed=...)` bisects any predicate: a step at f = 0.15 (0.17 for the 45 deg
    cams) is bracketed to the tolerance from the static thresholds +- half_width."""
    cams = sk.make_cam(sk.seed_geometries(), SPEED)
    step = np.where(np.round(np.degrees(np.asarray(cams.descent_angle))) == 45, 0.17, 0.15)
    calls = []

    def jammed(params, cam, f):
        calls.append(np.asarray(f))
        return np.asarray(f) >= step

    th = sk.thresholds(sk.make_params(), cams, tol=1e-5, jammed=jammed)
    assert np.all(th.lo < step) and np.all(step <= th.hi) and np.all(th.hi - th.lo <= 1e-5)
    assert np.max(np.abs(th.dynamic_f - step)) <= 0.5e-5
    assert th.num_batches == len(calls)


def test_jam_flag_and_runaway():
    cam = _cam("R10-55")
    ok = sk.simulate(sk.make_params(f=0.13), cam, n_out=N_OUT)
    jam = sk.simulate(sk.make_params(f=0.15), cam, n_out=N_OUT)
    assert not bool(ok.jammed) and bool(jam.jammed)
    assert float(cam.t_descent) < float(jam.t_jam) < float(cam.t_end)
    assert float(jam.v[-1]) < 0 and float(jam.lag[-1]) > 5e-3
    stopped = sk.simulate(sk.make_params(f=0.15), cam, n_out=N_OUT, stop_on_jam=True)
    assert int(stopped.result) == sk.RESULTS.stopped
    assert float(stopped.t_jam) == pytest.approx(float(jam.t_jam), abs=1e-6)
