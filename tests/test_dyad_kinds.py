"""Every dyad kind in closed form (issue 24 item 3) and the outputs' numbers (item 4): the
Whitworth quick-return (an RPR slot through the pivot, then an RRP ram), an offset slot, a PP and
an RRP with Cartesian and affine lengths, an RRR link of two terms — against geometry written
here — and the strokes, swings, dead centres and time ratios against their closed forms."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxlink as jl
from jaxlink.analysis.motion import motion
from jaxlink.files.reader import loads
from jaxlink.solvers import dyads as _dyads
from jaxlink.solvers.branch_points import TOGGLE, branch_points
from jaxlink.solvers.closed_form import method_for
from jaxlink.solvers.options import NewtonOptions

D, R, L, C, H = 0.300, 0.100, 0.500, 0.200, 0.520  # the scene's dimensions (m)


def whitworth_geometry(phi):
    """(theta, s, psi, x) of the scene by plane geometry: A = O1 + r e(φ) on the lever's line
    through O2 = 0, B = l e(θ), C = (x, H) with |C − B| = c on the right of B."""
    ax, ay = R * np.cos(phi), D + R * np.sin(phi)
    theta, s = np.arctan2(ay, ax), np.hypot(ax, ay)
    bx, by = L * np.cos(theta), L * np.sin(theta)
    psi = np.arcsin((H - by) / C)
    return theta, s, psi, bx + C * np.cos(psi)


@pytest.fixture(scope="module")
def whitworth():
    return jl.load("whitworth")


@pytest.fixture(scope="module")
def whitworth_motion(whitworth):
    return motion(whitworth)


@pytest.fixture(scope="module")
def slider_crank_motion():
    return motion(jl.load("slider-crank"))


def test_whitworth_takes_the_closed_form_and_matches_geometry(whitworth):
    dy = _dyads.classify(whitworth)
    assert [d.kind for d in dy] == ["RPR", "RRP"]
    assert method_for(whitworth, NewtonOptions()) == "closed_form"
    phis = np.radians(np.arange(0.0, 360.0, 7.5))
    sol = jl.solve(whitworth, phis)
    assert np.all(np.asarray(sol.result) == 0)
    ref = np.stack(whitworth_geometry(phis), axis=1)
    assert np.max(np.abs(np.asarray(sol.q) - ref)) < 1e-12


OFFSET = """
[mechanism]
name = "offset-slot"
length_unit = "mm"
angle_unit = "deg"
[parameters]
d = 100.0
r = 60.0
e = 50.0   # the slot's offset from the lever pivot O2
[input]
name = "phi"
[unknowns]
theta = 40.0
s = 100.0
[loops]
slot = ["(0, d)", "r @ phi", "-s @ theta", "-e @ theta + 90"]
"""


def test_offset_slot_geometry_toggles_and_gradients():
    """A = O1 + r e(φ) = s e(θ) + e e(θ + 90°): s = √(|A|² − e²), θ = ∠A − atan2(e, s); it
    cannot assemble where |A| < e, between the toggles sin φ = (e² − d² − r²) / (2 d r)."""
    mech = loads(OFFSET)
    (dy,) = _dyads.classify(mech)
    assert dy.kind == "RPR"
    d, r, e = 0.1, 0.06, 0.05
    phis = np.radians(np.arange(-180.0, 180.0, 1.0))
    sol = jl.solve(mech, phis)
    ax, ay = r * np.cos(phis), d + r * np.sin(phis)
    a2 = ax * ax + ay * ay
    ok = a2 > e * e
    s = np.sqrt(np.where(ok, a2 - e * e, 0.0))
    theta = np.arctan2(ay, ax) - np.arctan2(e, s)
    res = np.asarray(sol.result)
    assert np.array_equal(res == 0, ok)
    q = np.asarray(sol.q)
    assert np.max(np.abs(q[ok, 1] - s[ok])) < 1e-12
    assert np.max(np.abs(np.angle(np.exp(1j * (q[ok, 0] - theta[ok]))))) < 1e-12
    # the toggles located between samples (the reach margin's roots) against the closed form
    bp = branch_points(mech, phis, sol)
    found = np.sort(bp.input[np.asarray(bp.kind) == TOGGLE])
    t = math.asin((e * e - d * d - r * r) / (2 * d * r))
    assert np.max(np.abs(found - np.sort([t, -math.pi - t]))) < 1e-10
    # gradients by AD of the closed form against central differences; finite past the toggle
    p0 = jnp.asarray(mech.parameters)
    sigma = _dyads.solve_nearest(mech, (dy,), jnp.asarray(mech.guess), jnp.asarray(0.3), p0)[3]

    @jax.jit
    def f(p, phi):
        return _dyads.solve(mech, (dy,), sigma, jnp.asarray(mech.guess), phi, p)[0]

    jacobian = jax.jit(jax.jacfwd(f))
    jac = np.asarray(jacobian(p0, 0.3))
    hstep = 1e-7
    fd = np.stack([(np.asarray(f(p0.at[i].add(hstep), 0.3)) - np.asarray(f(p0.at[i].add(-hstep), 0.3))) / (2 * hstep)
                   for i in range(3)], axis=1)
    assert np.allclose(jac, fd, rtol=1e-6, atol=1e-6)
    assert np.all(np.isfinite(np.asarray(jacobian(p0, -math.pi / 2))))


TWO = """
[mechanism]
name = "pp-rrp"
length_unit = "mm"
angle_unit = "deg"
[parameters]
a = 30.0
b = 70.0
k = 25.0
[input]
name = "phi"
[unknowns]
x = 20.0
y = 30.0
th = 50.0
u = 80.0
[loops]
pp = ["a @ phi", "(2 * x, 0)", "-(y + 5) @ 60"]
rrp = ["(y + 5) @ 60", "b @ th", "-(u / 2 - 3) @ 10", "-(k, 0)"]
"""


def test_cartesian_and_affine_lengths_in_pp_and_rrp():
    """Lengths written as 2 x, y + 5 and u/2 − 3 (affine) and a Cartesian slide: the closed form
    closes both loops (residual written here with numpy) on the branch of the guesses."""
    mech = loads(TWO)
    assert [d.kind for d in _dyads.classify(mech)] == ["PP", "RRP"]
    phis = np.radians(np.arange(-60.0, 60.0, 5.0))
    sol = jl.solve(mech, phis)
    assert np.all(np.asarray(sol.result) == 0)
    x, y, th, u = np.asarray(sol.q).T
    a, b, k = 0.03, 0.07, 0.025
    e60, e10 = np.exp(1j * np.radians(60)), np.exp(1j * np.radians(10))
    pp = a * np.exp(1j * phis) + 2 * x - (y + 0.005) * e60
    rrp = (y + 0.005) * e60 + b * np.exp(1j * th) - (u / 2 - 0.003) * e10 - k
    assert np.max(np.abs(pp)) < 1e-15 and np.max(np.abs(rrp)) < 1e-15
    # x, y: Cramer by hand
    assert np.allclose(y + 0.005, a * np.sin(phis) / np.sin(np.radians(60)), atol=1e-15)
    # the guesses' branch: the rod's component along the guide has the sign it has at the guess
    assert np.all(np.cos(th - np.radians(10)) > 0) and math.cos(math.radians(50 - 10)) > 0


def test_a_link_written_as_two_terms_is_an_rrr_dyad():
    """The four-bar's coupler as two half vectors of one angle: the same positions."""
    fb = jl.load("four-bar")
    src = open(fb.file).read()
    two = loads(src.replace('"b @ phi3"', '"0.5 * b @ phi3", "b / 2 @ phi3"'))
    assert [d.kind for d in _dyads.classify(two)] == ["RRR"]
    phis = np.radians(np.arange(0.0, 360.0, 10.0))
    assert np.max(np.abs(np.asarray(jl.solve(two, phis).q) - np.asarray(jl.solve(fb, phis).q))) < 1e-12


def test_whitworth_swing_dead_centres_and_time_ratio(whitworth_motion):
    """The lever's extremes are where the crank is perpendicular to it: φ = −90° ± acos(r/d), a
    swing of 2 asin(r/d), a time ratio (π + 2 asin(r/d)) / (π − 2 asin(r/d)); the ram's x is
    monotonic in θ over the swing, so its dead centres are the same inputs."""
    m = whitworth_motion
    outs = {o["name"]: o for o in m.outputs}
    assert set(outs) == {"theta", "s", "x"}  # psi (the connecting rod) is not a rocker
    assert [outs[n]["kind"] for n in ("theta", "s", "x")] == ["rocker", "slot", "slider"]
    beta = math.asin(R / D)
    ratio = (math.pi + 2 * beta) / (math.pi - 2 * beta)
    dead = np.sort(np.mod([-math.pi / 2 + math.acos(R / D), -math.pi / 2 - math.acos(R / D)], 2 * math.pi))
    for name in ("theta", "x"):
        o = outs[name]
        assert abs(o["time_ratio"] - ratio) < 1e-9
        at = np.sort(np.mod([a for a, _ in o["dead_centres"]], 2 * math.pi))
        assert np.max(np.abs(at - dead)) < 1e-10
        assert abs(o["rise"] + o["fall"] - 2 * math.pi) < 1e-12
    assert outs["theta"]["kind"] == "rocker" and abs(outs["theta"]["stroke"] - 2 * beta) < 1e-12
    x = whitworth_geometry(dead)[3]
    assert abs(outs["x"]["stroke"] - abs(x[1] - x[0])) < 1e-12
    # the slot's block runs from d − r to d + r, its dead centres at the crank vertical
    s = outs["s"]
    assert abs(s["stroke"] - 2 * R) < 1e-12 and s["time_ratio"] == pytest.approx(1.0, abs=1e-9)
    # the velocity ratio dθ/dφ: r (r + d sin φ) / |A|², extremes r/(r + d) at 90°, −r/(d − r) at 270°
    th = outs["theta"]
    assert abs(th["velocity_max"] - R / (R + D)) < 1e-9 and abs(th["velocity_min"] + R / (D - R)) < 1e-9


def test_offset_slider_crank_stroke_and_time_ratio(slider_crank_motion):
    """Crank a, rod b, the guide e above the crank pivot: the slider's dead centres are where crank
    and rod are in line, x = √((b ± a)² − e²), at φ = atan2(e, x₊) and atan2(e, x₋) + π."""
    e, a, b = 0.012, 0.025, 0.080
    (o,) = slider_crank_motion.outputs
    x_out, x_in = math.sqrt((b + a) ** 2 - e * e), math.sqrt((b - a) ** 2 - e * e)
    assert o["name"] == "p14" and abs(o["stroke"] - (x_out - x_in)) < 1e-12
    phi_out, phi_in = math.atan2(e, x_out), math.atan2(e, x_in) + math.pi
    assert abs(math.remainder(o["max_at"] - phi_out, 2 * math.pi)) < 1e-10
    assert abs(math.remainder(o["min_at"] - phi_in, 2 * math.pi)) < 1e-10
    rise = (phi_out - phi_in) % (2 * math.pi)
    ratio = max(rise, 2 * math.pi - rise) / min(rise, 2 * math.pi - rise)
    assert abs(o["time_ratio"] - ratio) < 1e-9 and abs(o["rise"] - rise) < 1e-10


# ----------------------------------------------------------------------------- transmission angles
# μ = 90° − the pressure angle (Balli & Chand 2002): RRP the rod against the guide's normal, RPR the
# slot's push (normal to the slot) against the path of the lever's point at the block.


def test_offset_slider_crank_transmission_angle(slider_crank_motion):
    """Crank a, rod b, the guide e above the crank pivot: the rod's rise across the guide is
    e − a sin φ, cos μ = |e − a sin φ| / b: least μ = acos((e + a) / b) at φ = 270°, 90° where
    a sin φ = e."""
    mech = jl.load("slider-crank")
    e, a, b = 0.012, 0.025, 0.080
    (t,) = slider_crank_motion.transmission
    assert t["kind"] == "RRP" and t["unknowns"] == ("psi13", "p14")
    assert abs(np.degrees(t["min"]) - np.degrees(np.arccos((e + a) / b))) < 1e-9
    assert abs(math.remainder(t["min_at"] - 1.5 * math.pi, 2 * math.pi)) < 1e-6
    assert abs(np.degrees(t["max"]) - 90.0) < 1e-9 and abs(t["worst"] - t["min"]) < 1e-15
    phi = t["max_at"]
    assert abs(a * math.sin(phi) - e) < 1e-9
    # at the samples: the rod's angle of the solve against the closed form
    phis = np.radians(np.arange(0.0, 360.0, 15.0))
    psi = np.asarray(jl.solve(mech, phis).q)[:, 0]
    rod = np.stack([np.cos(psi), np.sin(psi)], axis=1)
    assert np.allclose(np.abs(rod[:, 1]), np.abs(e - a * np.sin(phis)) / b, atol=1e-13)


def test_whitworth_transmission_angles(whitworth_motion):
    """The slotted lever (RPR, the slot through its pivot): the block pushes normal to the lever,
    along its point's path: 90° throughout. The rod and ram (RRP, the ram on y = H): cos μ =
    |H − l sin θ| / c, least at the lever's extremes sin θ = √(1 − (r/d)²), largest at θ = 90°."""
    slot, ram = whitworth_motion.transmission
    assert (slot["kind"], ram["kind"]) == ("RPR", "RRP")
    assert abs(np.degrees(slot["min"]) - 90.0) < 1e-9 and abs(np.degrees(slot["max"]) - 90.0) < 1e-9
    mu_min = np.arccos((H - L * np.sqrt(1 - (R / D) ** 2)) / C)
    mu_max = np.arccos((H - L) / C)
    assert abs(np.degrees(ram["min"] - mu_min)) < 1e-9 and abs(np.degrees(ram["max"] - mu_max)) < 1e-9
    dead = np.mod([-math.pi / 2 + math.acos(R / D), -math.pi / 2 - math.acos(R / D)], 2 * math.pi)
    assert min(abs(math.remainder(ram["min_at"] - x, 2 * math.pi)) for x in dead) < 1e-6


def test_offset_slot_transmission_angle():
    """A slot e off the lever's pivot O2, the crank r about O1 = (0, d) turning fully (d − r > e):
    cos μ = e / |O2 A|, |O2 A| from d − r (φ = 270°, the least μ) to d + r (90°, the largest)."""
    mech = loads(OFFSET.replace("r = 60.0", "r = 30.0"))
    d, r, e = 0.1, 0.03, 0.05
    m = motion(mech)
    assert m.full_turn
    (t,) = m.transmission
    assert t["kind"] == "RPR"
    assert abs(np.degrees(t["min"] - np.arccos(e / (d - r)))) < 1e-9
    assert abs(np.degrees(t["max"] - np.arccos(e / (d + r)))) < 1e-9
    assert abs(math.remainder(t["min_at"] - 1.5 * math.pi, 2 * math.pi)) < 1e-6
    assert abs(math.remainder(t["max_at"] - 0.5 * math.pi, 2 * math.pi)) < 1e-6
