"""Every assemblable position is found by both path methods, and nothing non-finite is `converged`.

- Windows: a linkage that cannot be assembled over part of the revolution (a non-Grashof four-bar,
  a Chebyshev-like linkage) is solved by the closed form and by Newton continuation (the coupler
  written as two vectors, which is not a dyad of known form); both must flag exactly the
  positions that the circle-intersection criterion |b − c| ≤ |B0 − A| ≤ b + c (numpy, independent
  of jaxlink) says cannot be assembled, and agree on the others (the same branch) to 1e-9.
- The lead-in from `[input] start` is reduced to half a revolution for a crank and bounded for a
  length input; a non-finite start is `nonfinite`, not a hang.
- Finiteness and the residual at the returned q are part of convergence (kinematics table,
  reactions, design evaluator); at a parallelogram's change point the loops close but the
  position is `singular`, not `converged`.
- A prismatic joint whose `axis` is not the sliding direction is refused by the reactions table.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxlink as jl
from jaxlink.errors import MechanismError
from jaxlink.results import RESULTS

jax.config.update("jax_enable_x64", True)

ROOT = Path(__file__).resolve().parents[1]
FOUR_BAR = (ROOT / "jaxlink" / "scenes" / "four-bar.toml").read_text()
# the coupler's angle written so that no dyad form applies (the same geometry): Newton
TWO_VECTORS = FOUR_BAR.replace('main = ["a @ phi2", "b @ phi3"',
                               'main = ["a @ phi2", "b @ 2 * phi3 - phi3"')

# a Chebyshev-like linkage (crank 1, frame 2, coupler 2.5 with the point P on its extension),
# with the rocker shortened to 1.2 so that it is not Grashof: windows where it cannot close
CHEBYSHEV = """
[mechanism]
name = "chebyshev-like"
length_unit = "m"
angle_unit = "deg"

[parameters]
a = 1.0
b = 2.5
c = 1.2
d = 2.0
e = 2.5

[input]
name = "phi2"

[unknowns]
phi3 = 60.0
phi4 = 100.0

[loops]
main = LOOP

[points]
P = ["a @ phi2", "b @ phi3", "e @ phi3"]
"""
CHEB_DYADIC = CHEBYSHEV.replace("LOOP", '["a @ phi2", "b @ phi3", "-c @ phi4", "-d @ 0"]')
CHEB_TWO = CHEBYSHEV.replace("LOOP", '["a @ phi2", "0.4 * b @ phi3", "0.6 * b @ phi3", "-c @ phi4", "-d @ 0"]')

ASSEMBLED = (RESULTS.converged, RESULTS.singular)
# one grid for every solve of these files, and one worker for the whole module (`--dist
# loadgroup`): structures are equal by content, so the compiled solves are shared between tests
PHIS = np.deg2rad(np.arange(0.0, 360.0, 1.0))
pytestmark = pytest.mark.xdist_group("windows")


def assembled(sol):
    return np.isin(np.asarray(sol.result), ASSEMBLED)


def reachable(a, b, c, d, phis, margin=1e-9):
    """(assemblable, clear of the boundary) by the circle-intersection criterion, numpy."""
    w = np.hypot(a * np.cos(phis) - d, a * np.sin(phis))
    lo, hi = abs(b - c), b + c
    return (w >= lo) & (w <= hi), (np.abs(w - lo) > margin * hi) & (np.abs(w - hi) > margin * hi)


def compare(closed, cont, geometric, clear):
    a1, a2 = assembled(closed), assembled(cont)
    assert np.array_equal(a1, a2), np.nonzero(a1 != a2)
    assert np.array_equal(a1[clear], geometric[clear])
    both = a1 & a2
    assert both.sum() > 10 and (~a1).sum() > 10
    assert np.abs(np.asarray(closed.q)[both] - np.asarray(cont.q)[both]).max() < 1e-9


@pytest.mark.parametrize("sets", [{"b": 40.0, "c": 30.0}, {"a": 25.0, "b": 30.0, "c": 40.0}])
def test_four_bar_windows_same_positions(sets):
    dyadic, two = jl.loads(FOUR_BAR), jl.loads(TWO_VECTORS)
    assert jl.solve(two, np.zeros(1)).stats.steps[0] > 0  # Newton (not the closed form) on this file
    p = dyadic.with_parameters(**sets)
    phis = PHIS
    closed = jl.solve(dyadic, phis, p)
    cont = jl.solve(two, phis, p)
    x = {"a": 20.0, "b": 60.0, "c": 45.0, "d": 55.0, **sets}
    geometric, clear = reachable(x["a"], x["b"], x["c"], x["d"], phis)
    compare(closed, cont, geometric, clear)
    if "a" not in sets:  # (once: a third compilation) the same file forced through the
        # continuation: the closed form of the dyads re-assembles
        forced = jl.solve(dyadic, phis, p, options=jl.NewtonOptions(method="continuation"))
        compare(closed, forced, geometric, clear)


def test_chebyshev_like_windows_same_positions_and_points():
    dyadic, two = jl.loads(CHEB_DYADIC), jl.loads(CHEB_TWO)
    phis = PHIS
    closed, cont = jl.solve(dyadic, phis), jl.solve(two, phis)
    geometric, clear = reachable(1.0, 2.5, 1.2, 2.0, phis)
    compare(closed, cont, geometric, clear)
    both = assembled(closed)
    assert np.abs(np.asarray(closed.points)[both] - np.asarray(cont.points)[both]).max() < 1e-9
    # the path starting inside a window where it cannot close
    start = int(np.nonzero(~geometric & clear)[0][0])
    rolled = np.roll(phis, -start)
    compare(jl.solve(dyadic, rolled), jl.solve(two, rolled), np.roll(geometric, -start), np.roll(clear, -start))


def with_start(text, start):
    return text.replace('[input]\nname = "phi2"', f'[input]\nname = "phi2"\nstart = {start}')


def test_lead_in_reduced_to_one_revolution():
    two = jl.loads(TWO_VECTORS)
    phis = np.roll(PHIS, -40)  # from 40°
    ref = jl.solve(two, phis)
    # 5e5° (the file format's largest start is 1e4 rad ≈ 5.7e5°): 1e5 lead-in steps unreduced
    for start in (5e5,):
        t = time.perf_counter()
        sol = jl.solve(jl.loads(with_start(TWO_VECTORS, start)), phis)
        assert time.perf_counter() - t < 300
        assert np.all(np.asarray(sol.converged))
        # the same configurations (the guesses hold at start ≡ start mod 360°)
        d = np.asarray(sol.q) - np.asarray(ref.q)
        assert np.abs(np.angle(np.exp(1j * d))).max() < 1e-9
    # the requested angles one revolution on: the same configurations
    sol = jl.solve(two, phis + 2 * np.pi)
    assert np.abs(np.asarray(sol.points) - np.asarray(ref.points)).max() < 1e-12


def test_nonfinite_or_huge_start_is_a_result_not_a_hang():
    # (each start compiles anew, being part of the structure: NaN for one file, ∞ for the other)
    for text, start in ((FOUR_BAR, float("nan")), (TWO_VECTORS, float("inf"))):
        mech = jl.loads(text)
        bad = jl.Mechanism(parameters=mech.parameters, guess=mech.guess,
                           structure=dataclasses.replace(mech.structure, input_start=start))
        sol = jl.solve(bad, PHIS)
        assert np.all(np.asarray(sol.result) == RESULTS.nonfinite)
    # a length input (a slider driving a crank) whose guesses hold 1000 km away: the lead-in takes
    # at most MAX_LEAD_IN steps and then returns result codes
    for loop in ('["-h1 @ 90", "h2 @ psi12", "h3 @ psi13", "-s @ 0"]',
                 '["-h1 @ 90", "h2 @ psi12", "0.5 * h3 @ psi13", "0.5 * h3 @ psi13", "-s @ 0"]'):
        text = f"""
[mechanism]
name = "driven-slider"
length_unit = "mm"
angle_unit = "deg"
[parameters]
h1 = 12.0
h2 = 25.0
h3 = 80.0
[input]
name = "s"
start = START
[unknowns]
psi12 = 20.0
psi13 = -20.0
[loops]
main = {loop}
"""
        near = jl.loads(text.replace("START", "100.0"))
        far = jl.loads(text.replace("START", "1e9"))
        assert far.input_kind == "length"
        phis = np.array([0.09, 0.1])
        t = time.perf_counter()
        sol = jl.solve(far, phis)
        assert time.perf_counter() - t < 300
        assert np.asarray(sol.result).shape == (2,)
        assert np.all(np.asarray(jl.solve(near, phis).converged))


@pytest.mark.parametrize("text", [FOUR_BAR, TWO_VECTORS])
def test_huge_guess_is_reduced_and_checked(text):
    # a file refuses such a guess (tests/test_input_domains.py); the Python API can still give one
    mech = jl.loads(text)
    guess = np.array(mech.guess)
    guess[mech.unknown_names.index("phi3")] = 1e300
    mech = mech.replace(guess=guess)
    phis = PHIS
    sol = jl.solve(mech, phis)
    p = jnp.asarray(mech.parameters)
    r = np.asarray(jax.vmap(lambda q, f: jnp.max(jnp.abs(mech.residual(q, f, p))))(sol.q, jnp.asarray(phis)))
    tol = 1000 * np.finfo(float).eps * float(mech.length_scale(p))
    conv = np.asarray(sol.converged)
    assert conv.any() and np.all(r[conv] <= 2 * tol)  # the residual at the returned q, afresh
    table = jl_table(mech, phis)
    c = table.converged
    assert np.all(table.column("residual_m")[c] <= 2 * tol)


def jl_table(mech, phis, **kw):
    from jaxlink.report.kinematics import kinematics_table

    return kinematics_table(mech, phis, **kw)


def no_nan_converged(table):
    rows = table.data[table.converged]
    assert np.all(np.isfinite(rows))


def test_nonfinite_speed_or_tiny_lengths_are_not_converged():
    mech = jl.load("four-bar")
    phis = np.deg2rad(np.arange(0.0, 360.0, 30.0))
    for omega in (float("nan"), float("inf")):
        table = jl_table(mech, phis, omega=omega)
        assert not table.converged.any()
        assert np.all(table.result == RESULTS.nonfinite)
    tiny = np.where(np.asarray(mech.parameter_kinds) == "length", 1e-300, mech.parameters)
    table = jl_table(mech, phis, p=tiny)
    no_nan_converged(table)
    fine = jl_table(mech, phis)
    assert fine.converged.all()
    no_nan_converged(fine)


def test_reactions_nonfinite_speed():
    mech = jl.load("slider-crank-mass")
    phis = np.deg2rad(np.arange(0.0, 360.0, 30.0))
    sol, r = jl.solve_reactions(mech, phis, omega=float("nan"))
    assert np.asarray(sol.converged).all()
    assert np.all(np.asarray(r.result) == RESULTS.nonfinite)
    assert np.all(np.asarray(r.torque) == 0.0)


def test_evaluator_nonfinite_pieces_are_infeasible():
    from jaxlink.optimize import Evaluator, problem_from

    text = FOUR_BAR.replace('P = ["a @ phi2", "cx @ phi3"', 'P = ["a @ phi2", "sqrt(cos(phi2)) * cx @ phi3"') + """
[optimize]
point = "P"
variables = { a = [15, 25] }
samples = 24
objective = "points"
targets = [[30, 40], [10, 50]]
"""
    ev = Evaluator(problem_from(jl.loads(text, file="nan-point.toml")), chunk=8)
    res = ev.evaluate(np.array([[0.5], [0.2]]))
    assert not np.any(res["feasible"])
    assert np.all(np.isinf(res["value"]))


def test_parallelogram_change_point_is_singular_not_converged():
    text = FOUR_BAR.replace("b = 60.0", "b = 55.0").replace("c = 45.0", "c = 20.0").replace(
        "phi3 = 30.0", "phi3 = 5.0").replace("phi4 = 80.0", "phi4 = 60.0")
    mech = jl.loads(text)  # a = c = 20, b = d = 55: a parallelogram, change points at 0° and 180°
    phis = np.deg2rad(np.array([0.0, 30.0, 90.0, 180.0]))
    table = jl_table(mech, phis)
    res = table.result
    assert res[0] == RESULTS.singular and res[3] == RESULTS.singular
    assert not table.converged[0] and table.assembled[0]
    tol = 1000 * np.finfo(float).eps * 0.055
    assert table.column("residual_m")[0] <= tol  # the loops closed ...
    assert np.isfinite(table.column("P_x_m")[0])  # ... the positions are given ...
    assert np.isnan(table.column("P_vx_m_s")[0])  # ... the velocities are not defined
    assert table.converged[1] and table.converged[2]
    no_nan_converged(table)


def test_prismatic_axis_must_be_the_sliding_direction():
    from jaxlink.report.reactions import reactions_table

    text = (ROOT / "jaxlink" / "scenes" / "slider-crank-mass.toml").read_text()
    phis = np.deg2rad(np.arange(0.0, 360.0, 30.0))
    reactions_table(jl.loads(text), phis, omega=10.0)  # the right axis: accepted
    for wrong in ("alpha1", "psi13", "alpha4 + 10"):
        with pytest.raises(MechanismError, match="prismatic joint 'guide'"):
            reactions_table(jl.loads(text.replace('axis = "alpha4"', f'axis = "{wrong}"')), phis, omega=10.0)
