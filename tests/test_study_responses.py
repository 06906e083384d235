"""The study's response expressions (jaxlink/study/expressions.py): a point's travel along an axis,
values at named input angles, extremes over the cycle — against an independent numpy model of the
sewing-feed six-bar (tests/feed_sixbar.py: circle intersections, not jaxlink's solver) and the
four-bar's hand-differentiated loop (tests/closed_forms.py), finite differences and the Monte
Carlo draws evaluated by those models."""

import csv
import math
import pathlib

import feed_sixbar
import numpy as np
import pytest
from closed_forms import fourbar_point_derivatives

import jaxlink as jl
from jaxlink.errors import MechanismError
from jaxlink.study import read_study, tolerance
from jaxlink.study.tolerance import draws

SCENES = pathlib.Path(jl.__file__).resolve().parent / "scenes"
LINKS = ("l2", "l22", "l3", "l4", "l44", "l5", "l6", "l66", "l7", "l8")
SPEC = (27.67, 27.83)  # the feed-dog stroke 27.75 ± 0.08 mm


def _feed_travel(p):
    return feed_sixbar.travel({k: np.atleast_1d(np.asarray(v, float)) for k, v in p.items()})


def _fd_gradient(f, x0, names, h=1e-3):
    """Fourth-order central differences of f (a dict of parameters → value)."""
    g = []
    for n in names:
        vals = []
        for s in (-2, -1, 1, 2):
            p = dict(x0)
            p[n] = x0[n] + s * h
            vals.append(float(f(p)[0]))
        g.append((vals[0] - 8 * vals[1] + 8 * vals[2] - vals[3]) / (12 * h))
    return np.asarray(g)


def test_the_feed_dog_stroke_in_one_command(tmp_path, capsys):
    """The feed-dog stroke travel(Z, x) of the built-in sewing-feed six-bar, tolerances on every
    link, spec 27.75 ± 0.08 mm, in one `jaxlink study` command: its nominal is the numpy model's to
    1e-13 at 90 positions (the extremes located between the samples, not on them), its first-order
    σ a finite-difference one's to 1e-9, its Monte Carlo samples out of spec exactly those of the
    numpy model on the same draws (and within 3 standard errors of the model's own draws), Cpk
    printed and equal to the samples' (U − μ, μ − L) / 3s."""
    from jaxlink.cli import main

    src = tmp_path / "feed.toml"
    tol = "\n".join(f"{n} = 0.02" for n in LINKS)
    src.write_text((SCENES / "sewing-feed.toml").read_text() + f"""
[study]
positions = 90
points = ["Z"]
metrics = ["travel(Z, x)"]
samples = 2048
limits = {{ "travel(Z, x)" = [{SPEC[0]}, {SPEC[1]}] }}

[study.tolerances]
{tol}
""")
    out = tmp_path / "out"
    assert main(["study", str(src), "--out", str(out), "--no-plot"]) == 0
    text = capsys.readouterr().out
    assert "travel(Z, x) in [27.67, 27.83]:" in text and "Cpk" in text
    d = np.load(out / "study.npz")
    with open(out / "tolerance.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))  # one row per response, in order
    i = [r["output"] for r in rows].index("travel(Z, x)")
    row = rows[i]
    assert row["unit"] == "mm"
    nominal = float(d["nominal"][i])
    x0 = dict(feed_sixbar.NOMINAL)
    ref = float(_feed_travel(x0)[0])
    assert abs(nominal - ref) <= 1e-13 * ref, (nominal, ref)
    assert 27.67 < ref < 27.83  # 27.7656 mm: the spec's feed-dog stroke is Z's travel along x

    # first order: σ_RSS against finite differences of the numpy model (normal, ±t = 3σ)
    g = _fd_gradient(_feed_travel, x0, LINKS)
    sigma_fd = math.sqrt(float(np.sum((g * 0.02 / 3.0) ** 2)))
    sigma = float(d["first_order.sigma_rss"][i])
    assert abs(sigma - sigma_fd) <= 1e-9 * sigma_fd, (sigma, sigma_fd)

    # Monte Carlo: the same draws through the numpy model give the same samples out of spec
    inputs = read_study(jl.load(str(src)))
    dx = draws(inputs, 2048)
    p = {k: np.full(2048, v) for k, v in x0.items()}
    for j, n in enumerate(inputs.parameters):
        p[n] = x0[n] + dx[:, j]
    t = _feed_travel(p)
    out_np = int(np.count_nonzero((t < SPEC[0]) | (t > SPEC[1])))
    assert int(d["monte_carlo.out_of_spec"][0]) == out_np
    mu, s = t.mean(), t.std(ddof=1)
    cpk = min(SPEC[1] - mu, mu - SPEC[0]) / (3 * s)
    assert abs(float(d["monte_carlo.cpk"][0]) - cpk) <= 1e-6 * abs(cpk)
    assert abs(float(row["mc_cpk (1)"]) - cpk) <= 1e-6 * abs(cpk)
    # and an independent Monte Carlo (the model's own draws): within 3 standard errors
    rng = np.random.default_rng(12345)
    n2 = 8192
    p2 = {k: np.full(n2, v) for k, v in x0.items()}
    for n in LINKS:
        p2[n] = x0[n] + rng.normal(0.0, 0.02 / 3.0, n2)
    t2 = _feed_travel(p2)
    q1 = out_np / 2048
    q2 = np.count_nonzero((t2 < SPEC[0]) | (t2 > SPEC[1])) / n2
    qq = (out_np + q2 * n2) / (2048 + n2)
    se = math.sqrt(qq * (1 - qq) * (1 / 2048 + 1 / n2))
    assert abs(q1 - q2) <= 3 * se, (q1, q2, se)


# ---------------------------------------------------------------- the four-bar: values at named angles

ANGLES = (30.0, 152.5, 271.3)  # on a sample (5° spacing), midway, off the grid
RPM = 60.0  # ω = 2π rad/s
KINDS = (("vx", 1, "real"), ("vy", 1, "imag"), ("ax", 2, "real"), ("ay", 2, "imag"), ("jx", 3, "real"),
         ("jy", 3, "imag"))
FOURBAR = dict(a=20.0, b=60.0, c=45.0, d=55.0, cx=30.0, cy=15.0)


def _fb(p, phi_deg, k):
    P, th = fourbar_point_derivatives(p["a"], p["b"], p["c"], p["d"], p["cx"], p["cy"], math.radians(phi_deg), -1)
    return P[k], th


@pytest.fixture(scope="module")
def fourbar():
    mech = jl.load("four-bar")
    metrics = [f"{n}(P) @ [{', '.join(f'{a:g}' for a in ANGLES)}]" for n, _, _ in KINDS]
    metrics += ["travel(P, 30)", "max(vx(P))", "max(phi4)"]
    inputs = read_study(mech, {"tolerances": {"a": 0.05, "b": 0.05, "c": 0.05, "d": 0.05}, "points": ["P"],
                               "positions": 72, "rpm": RPM, "samples": 512, "metrics": metrics,
                               "limits": {"vx(P) @ 30": [-110.0, -108.5]}})
    return mech, inputs, tolerance(mech, inputs)


def _row(rep, name):
    return [lab[0] for lab in rep.labels].index(name)


def test_velocity_acceleration_jerk_at_named_angles(fourbar):
    """18 numbers — vx, vy, ax, ay, jx, jy of the coupler point at 30°, 152.5°, 271.3° (on a
    sample, midway between two, off the grid of 5°) — straight from the study's responses, to 1e-9
    of the hand-differentiated loop (per second at 60 rpm)."""
    _mech, _inputs, rep = fourbar
    w = 2 * math.pi * RPM / 60
    n = 0
    for name, k, part in KINDS:
        for a in ANGLES:
            i = _row(rep, f"{name}(P) @ {a:g}")
            ref = getattr(_fb(FOURBAR, a, k)[0], part) * w ** k
            assert rep.labels[i][1] == "mm/s" + (f"^{k}" if k > 1 else "")
            assert abs(rep.nominal[i] - ref) <= 1e-9 * max(abs(ref), 1.0), (name, a, rep.nominal[i], ref)
            n += 1
    assert n == 18


def _refined_max(f, d1, d2, n=720):
    """The maximum over the turn of f(φ) (numpy), Newton on d1 = f′ with d2 = f″."""
    phis = 2 * np.pi * np.arange(n) / n
    vals = np.asarray([f(t) for t in phis])
    t = phis[np.argmax(vals)]
    for _ in range(10):
        t -= d1(t) / d2(t)
    return f(t)


def test_travel_and_extremes_between_the_samples(fourbar):
    """travel(P, 30°), max(vx(P)) and max(phi4) at 72 positions (5°) equal the continuous cycle's
    (numpy Newton on the hand-differentiated loop) to 1e-11: located between the samples, not on
    them (a sample's value misses by more than 1e-4)."""
    _mech, _inputs, rep = fourbar
    w = 2 * math.pi * RPM / 60
    u = np.exp(1j * math.radians(30.0))

    def proj(t, k):
        return (fourbar_point_derivatives(20, 60, 45, 55, 30, 15, t, -1)[0][k] * np.conj(u)).real

    hi = _refined_max(lambda t: proj(t, 0), lambda t: proj(t, 1), lambda t: proj(t, 2))
    lo = -_refined_max(lambda t: -proj(t, 0), lambda t: -proj(t, 1), lambda t: -proj(t, 2))
    i = _row(rep, "travel(P, 30)")
    assert abs(rep.nominal[i] - (hi - lo)) <= 1e-11 * (hi - lo)
    grid = np.asarray([proj(t, 0) for t in 2 * np.pi * np.arange(72) / 72])
    assert abs(np.ptp(grid) - (hi - lo)) > 1e-4  # what the samples alone give

    def vx(t, k=1):
        return fourbar_point_derivatives(20, 60, 45, 55, 30, 15, t, -1)[0][k].real

    ref = _refined_max(vx, lambda t: vx(t, 2), lambda t: vx(t, 3)) * w
    i = _row(rep, "max(vx(P))")
    assert rep.labels[i][1] == "mm/s"
    assert abs(rep.nominal[i] - ref) <= 1e-11 * abs(ref)

    def th4(t, k=0):
        return fourbar_point_derivatives(20, 60, 45, 55, 30, 15, t, -1)[1][k][1]

    ref = math.degrees(_refined_max(th4, lambda t: th4(t, 1), lambda t: th4(t, 2)))
    i = _row(rep, "max(phi4)")
    assert rep.labels[i][1] == "deg"
    assert abs(rep.nominal[i] - (ref + 360.0 * round((rep.nominal[i] - ref) / 360.0))) <= 1e-10


def test_first_order_worst_case_and_limits_at_a_named_angle(fourbar):
    """The first-order σ of vx(P) @ 30 against finite differences of the closed form; its worst
    case over the tolerance box (reported at the named angle) against the 16 corners evaluated by
    the closed form; the Monte Carlo samples out of its spec limits exactly those of the closed form
    on the same draws, Cpk from their mean and standard deviation."""
    _mech, inputs, rep = fourbar
    w = 2 * math.pi * RPM / 60
    i = _row(rep, "vx(P) @ 30")

    def vx30(p):
        return np.asarray([_fb(p, 30.0, 1)[0].real * w])

    g = _fd_gradient(vx30, FOURBAR, ("a", "b", "c", "d"), h=1e-3)
    assert np.allclose(rep.first_order.jacobian[i], g, rtol=1e-8, atol=1e-8)
    assert abs(rep.first_order.sigma_rss[i] - math.sqrt(float(np.sum((g * 0.05 / 3) ** 2)))) <= 1e-8

    wc = rep.worst
    q = list(wc.names).index("vx(P) @ 30")
    y0 = vx30(FOURBAR)[0]
    corners = []
    for s in np.ndindex(2, 2, 2, 2):
        p = dict(FOURBAR)
        for n, sj in zip("abcd", s):
            p[n] += 0.05 * (2 * sj - 1)
        corners.append(abs(vx30(p)[0] - y0))
    assert wc.value[q] >= max(corners) * (1 - 1e-9)
    if wc.status[q] == "enumerated":
        assert abs(wc.value[q] - max(corners)) <= 1e-9 * max(corners)

    mc = rep.monte_carlo
    dx = draws(inputs, 512)
    vals = []
    for row in dx:
        p = dict(FOURBAR)
        for n, v in zip(inputs.parameters, row):
            p[n] += v
        vals.append(vx30(p)[0])
    vals = np.asarray(vals)
    lo, hi = -110.0, -108.5
    assert int(mc.out_of_spec[0]) == int(np.count_nonzero((vals < lo) | (vals > hi)))
    mu, s = vals.mean(), vals.std(ddof=1)
    assert abs(mc.cpk[0] - min(hi - mu, mu - lo) / (3 * s)) <= 1e-6 * abs(mc.cpk[0])


@pytest.mark.parametrize("metric, why", [
    ("vx(PP) @ 30", "unknown point 'PP' (did you mean 'P'?)"),
    ("vz(P) @ 30", "unknown quantity 'vz' (did you mean"),
    ("vx(P)", "write vx(P) @ ANGLE, max(vx(P)) or min(vx(P))"),
    ("travel(P, z)", "travel's axis is x, y"),
    ("travel(P, (0, 0))", "travel's axis is x, y"),
    ("vx(P) @ thirty", "the input angle after @ is a number"),
    ("x(phi4)", "'x' is a point's quantity and 'phi4' an unknown"),
    ("strok", "unknown metric 'strok' (did you mean 'stroke'?)"),
])
def test_a_wrong_expression_is_refused(metric, why):
    mech = jl.load("four-bar")
    with pytest.raises(MechanismError) as e:
        read_study(mech, {"tolerances": {"a": 0.05}, "metrics": [metric]})
    assert why in str(e.value) and e.value.key == "study.metrics"
