"""float32 everywhere (issue 23): every built-in linkage scene in float32 against float64 within
the documented float32 tolerance (docs/reference/cli.md, "Precision"); `kinematics --dtype float32`
on the command line against Freudenstein's closed form; the public functions under `jit`, `vmap`
and `grad` with 64-bit mode off (a subprocess) and, with it on, float32 inputs that stay float32
(no float64 constant promotes them: `jax_numpy_dtype_promotion="strict"`).

The tolerance: with rtol = 1000 × float32 eps = 1.19e-4 (the solver's float32 stopping tolerance,
`NewtonOptions.rtol`) and L the length scale (the largest |length parameter|), a row converged in
both dtypes agrees to rtol × L in every position and length unknown, rtol rad in every angle, and
rtol × the table's largest magnitude of the same quantity (its unit) in every velocity and
acceleration. Measured on the built-in scenes (every 5°): at most 4.1e-7 L, 2.0e-6 rad, 2.7e-6."""

import csv
import io
import json
import subprocess
import sys
import textwrap
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from closed_forms import fourbar_freudenstein

import jaxlink as jl
from jaxlink.errors import MechanismError
from jaxlink.report.kinematics import kinematics_table
from jaxlink.scenes import scene_paths
from jaxlink.solvers.options import default_rtol

RTOL = default_rtol(np.float32)  # 1.19e-4, the documented float32 tolerance


def _linkage_scenes():
    out = []
    for name in scene_paths():
        try:
            jl.load(name)
        except MechanismError:  # a cam-follower scene: no loops to solve
            continue
        out.append(name)
    return out


SCENES = _linkage_scenes()


def _unit_groups(columns):
    """Column index → the columns of the same quantity (their unit suffix: _m_s, _rad_s2, ...)."""
    def unit(c):
        return "_".join(c.split("_")[-2:]) if c.endswith(("_s", "_s2")) else None

    return {j: [k for k, d in enumerate(columns) if unit(d) == unit(c)] for j, c in enumerate(columns)
            if unit(c) is not None}


def _assert_within_tolerance(mech, t32, t64, rows=None):
    """Every row converged in float64 converges in float32 and agrees within the tolerance (`rows`:
    only these, which both converged)."""
    assert t64.columns == t32.columns
    if rows is None:
        assert np.array_equal(t32.converged, t64.converged), "float32 converges where float64 does"
        rows = t64.converged
    assert t32.converged[rows].all() and t64.converged[rows].all()
    L = float(mech.length_scale(mech.parameters))
    groups = _unit_groups(t64.columns)
    for j, c in enumerate(t64.columns):
        if c in ("converged", "residual_m", "result") or c.startswith(("input", "change_point", "gap_")):
            continue
        a, b = t64.data[rows, j], t32.data[rows, j]
        if j in groups:
            scale = np.abs(t64.data[rows][:, groups[j]]).max()
        else:
            scale = 1.0 if c.endswith("_rad") else L
        err = np.abs(a - b).max()
        assert err <= RTOL * scale, f"{c}: float32 differs by {err:.3g} > {RTOL:.3g} × {scale:.3g}"


# the scenes share structures (needle-dwell's is needle-arachne's, sewing-feed-opt's sewing-feed's):
# one worker compiles each once
@pytest.mark.xdist_group("float32")
@pytest.mark.parametrize("scene", SCENES)
def test_scene_float32_against_float64(scene):
    """In-process (64-bit mode on, float32 inputs): the positions every 15° of a revolution (the
    velocities and accelerations: the command-line test below; compiling them for every scene
    would cost about 20 s more)."""
    mech = jl.load(scene)
    phis = np.deg2rad(np.arange(0.0, 360.0, 15.0))
    t32 = kinematics_table(mech, phis, outputs=("position",), dtype=np.float32)
    t64 = kinematics_table(mech, phis, outputs=("position",), dtype=np.float64)
    assert t32.q.dtype == np.float32 and t64.q.dtype == np.float64
    assert t64.converged.all()
    _assert_within_tolerance(mech, t32, t64)


A, B, C, D, CX, CY = 0.020, 0.060, 0.045, 0.055, 0.030, 0.015  # four-bar.toml in metres


def _coupler_point(phis, a=A, b=B, c=C, d=D, cx=CX, cy=CY):
    """(phi3, phi4, P_x, P_y) of the four-bar scene by Freudenstein (the branch of its guess)."""
    phi3, phi4 = fourbar_freudenstein(a, b, c, d, phis, -1)
    return (phi3, phi4, a * np.cos(phis) + cx * np.cos(phi3) - cy * np.sin(phi3),
            a * np.sin(phis) + cx * np.sin(phi3) + cy * np.cos(phi3))


def _wrap(x):
    return (x + np.pi) % (2 * np.pi) - np.pi


def test_kinematics_command_float32_against_closed_form():
    """`jaxlink kinematics four-bar --dtype float32` (64-bit mode off in the command), its default
    outputs: exit 0, every row converged; angles within rtol rad of Freudenstein's, the coupler
    point within rtol × L, its velocity and acceleration (ω = 1: d/dφ, d²/dφ² of the closed form by
    central differences in float64) within rtol × their largest magnitude."""
    r = subprocess.run([sys.executable, "-m", "jaxlink.cli", "kinematics", "four-bar", "--dtype", "float32",
                        "--step", "10", "--csv", "-"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "warning" not in r.stderr.lower()
    rows = list(csv.reader(io.StringIO(r.stdout)))
    head, data = rows[0], np.array([row[:-1] for row in rows[1:]], dtype=float)
    assert head[:9] == ["input_deg", "phi3_rad", "phi4_rad", "P_x_m", "P_y_m", "P_vx_m_s", "P_vy_m_s",
                        "P_ax_m_s2", "P_ay_m_s2"] and len(data) == 36
    assert np.all(data[:, head.index("converged")] == 1)
    phis = np.deg2rad(data[:, 0])
    phi3, phi4, px, py = _coupler_point(phis)
    assert np.abs(_wrap(data[:, 1] - phi3)).max() <= RTOL
    assert np.abs(_wrap(data[:, 2] - phi4)).max() <= RTOL
    assert max(np.abs(data[:, 3] - px).max(), np.abs(data[:, 4] - py).max()) <= RTOL * D
    h = 1e-4
    (_, _, xp, yp), (_, _, xm, ym) = _coupler_point(phis + h), _coupler_point(phis - h)
    v = np.stack([(xp - xm) / (2 * h), (yp - ym) / (2 * h)], 1)
    acc = np.stack([(xp - 2 * px + xm) / h**2, (yp - 2 * py + ym) / h**2], 1)
    assert np.abs(data[:, 5:7] - v).max() <= RTOL * np.abs(v).max()
    assert np.abs(data[:, 7:9] - acc).max() <= RTOL * np.abs(acc).max()


_X64_OFF = textwrap.dedent("""
    import json, warnings
    import jax, jax.numpy as jnp, numpy as np
    jax.config.update("jax_enable_x64", False)
    warnings.simplefilter("error")  # float32 inputs: no float64-meets-float32 warning either
    import jaxlink as jl
    mech = jl.load("four-bar")
    p = np.float32(mech.parameters)
    phis = np.deg2rad(np.arange(0.0, 360.0, 30.0)).astype(np.float32)
    f = lambda p: jl.solve(mech, phis, p).points[:, 0, 0].sum()
    jit_q = jax.jit(lambda p: jl.solve(mech, phis, p).q)(p)
    vmap_q = jax.vmap(lambda p: jl.solve(mech, phis, p).q)(jnp.stack([p, p * np.float32(1.01)]))
    grad = jax.grad(f)(p)
    out = {"dtypes": [str(x.dtype) for x in (jit_q, vmap_q, grad)],
           "q": np.asarray(jit_q).tolist(), "q2": np.asarray(vmap_q[1]).tolist(), "grad": np.asarray(grad).tolist()}
    print(json.dumps(out))
""")


def test_solve_with_x64_off_under_jit_vmap_grad():
    """64-bit mode off: `jl.solve` inside the caller's `jit`, `vmap` and `grad` (the float32 warning
    once raised TracerArrayConversionError on the traced `p`); all float32, within the tolerance of
    Freudenstein's closed form (the gradient of Σ P_x: central differences of it in float64)."""
    r = subprocess.run([sys.executable, "-c", _X64_OFF], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout.splitlines()[-1])
    assert got["dtypes"] == ["float32"] * 3
    phis = np.deg2rad(np.arange(0.0, 360.0, 30.0))
    p = np.array([A, B, C, D, CX, CY])
    for key, scale in (("q", 1.0), ("q2", 1.01)):
        phi3, phi4, _, _ = _coupler_point(phis, *(p * scale))
        assert np.abs(_wrap(np.asarray(got[key]) - np.stack([phi3, phi4], 1))).max() <= RTOL
    h = 1e-7
    fd = np.array([(_coupler_point(phis, *(p + h * e))[2].sum() - _coupler_point(phis, *(p - h * e))[2].sum())
                   / (2 * h) for e in np.eye(6)])
    assert np.abs(np.asarray(got["grad"]) - fd).max() <= RTOL * np.abs(fd).max()


def test_float32_inputs_stay_float32_with_x64_on():
    """64-bit mode on, float32 inputs: reactions, the dwell metrics and the design search's smoothed
    objective and its gradient compute in float32 — under strict dtype promotion, so a float64
    constant meeting a float32 value is an error, not a silent promotion."""
    sc = jl.load("slider-crank-mass")
    phis = np.deg2rad(np.arange(0.0, 360.0, 30.0)).astype(np.float32)
    with jax.numpy_dtype_promotion("strict"):
        r = jl.reactions(sc, phis, np.float32(sc.parameters), omega=10.0)
    assert r.force.dtype == r.torque.dtype == np.float32
    ref = jl.reactions(sc, phis.astype(float), sc.parameters, omega=10.0)
    assert np.abs(np.asarray(r.torque) - np.asarray(ref.torque)).max() <= RTOL * np.abs(np.asarray(ref.torque)).max()

    from jaxlink.analysis.dwell import spectral_derivatives

    s = jnp.sin(jnp.arange(16, dtype=jnp.float32) * (2 * np.pi / 16))
    with jax.numpy_dtype_promotion("strict"):
        ds, dds = spectral_derivatives(s)
    assert ds.dtype == dds.dtype == np.float32
    assert np.abs(np.asarray(ds) - np.cos(np.arange(16) * 2 * np.pi / 16)).max() < 1e-5

    from jaxlink.optimize import Evaluator, problem_from

    # the search's design → parameters map, without building an evaluator (which compiles its starts)
    pr = problem_from(jl.load("sewing-feed-opt"))
    with jax.numpy_dtype_promotion("strict"):
        p = Evaluator.params(SimpleNamespace(problem=pr, mech=pr.mech), jnp.full((pr.n_variables,), 0.5, jnp.float32))
    assert p.dtype == np.float32
    want = pr.mech.parameters.copy()
    want[list(pr.index)] = (pr.lower + 0.5 * (pr.upper - pr.lower)) * pr.factor
    assert np.allclose(np.asarray(p), want, rtol=1e-6)


def test_float32_near_a_change_point_is_flagged_or_within_tolerance():
    """Issue 46, item 8: the Peaucellier cell 0.3°–30° either side of its flat position θ* (the
    rhombus folding flat, a change point), every output. A float32 row is either `converged` and
    within the float32 tolerance of float64, or `imprecise` — the rows where the rhombus's links are
    nearer to in line than the documented bound (`jaxlink.analysis.precision`: sine 0.40 with
    accelerations): positions given, rates nan, counted in the summary. On main every row was
    `converged`, the accelerations 1.4e3× the tolerance at 1°, 0.55× at 10.8°. float64 flags none."""
    import math
    import os

    from jaxlink.analysis import precision
    from jaxlink.report.kinematics import print_summary

    mech = jl.load(os.path.join(os.path.dirname(__file__), "data", "peaucellier.toml"))
    th = 2 * math.acos(math.sqrt(5.0**2 - 2.0**2) / (2 * 3.0))  # |OC| = √(L² − s²): the flat rhombus
    off = np.array([0.3, 1.0, 3.0, 10.8, 20.0, 30.0])
    phis = np.sort(np.concatenate([th - np.deg2rad(off), th + np.deg2rad(off)]))
    outs = ("position", "velocity", "acceleration", "rates")
    # each side of θ* in a table of its own: no two consecutive rows straddle the change point, so
    # the tables locate no branch point (its program, which this test does not check, was half of
    # the test's 48 s; one table program of 6 rows per dtype, shared by both sides)
    for side in (phis[phis < th], phis[phis > th]):
        t32 = kinematics_table(mech, side, outputs=outs, dtype=np.float32)
        t64 = kinematics_table(mech, side, outputs=outs, dtype=np.float64)
        assert len(t32.branch_points) == len(t64.branch_points) == 0
        assert t64.converged.all() and not (t64.result == jl.RESULTS.imprecise).any()
        vague = t32.result == jl.RESULTS.imprecise
        near = np.abs(side - th) < np.deg2rad(5.0)
        assert near.sum() == 3 and vague[near].all()  # the rows within 3° of the flat position
        assert np.array_equal(t32.converged, ~vague) and t32.assembled.all()
        _assert_within_tolerance(mech, t32, t64, rows=~vague)
        # the flagged rows: positions given (to K₀ eps / s), every rate nan
        rates = [j for j, c in enumerate(t32.columns) if c.endswith(("_s", "_s2"))]
        assert np.isnan(t32.data[vague][:, rates]).all() and np.isfinite(t32.q[vague]).all()
        out = io.StringIO()
        print_summary(t32, out)
        assert f"{int(vague.sum())} positions imprecise (float32 too near a change point" in out.getvalue()
    assert precision.least_sine(2) == pytest.approx(0.4, abs=5e-3)  # the bound docs/reference/cli.md gives
