"""The designer's numbers of a four-bar (issue 24, first step): Grashof class and type, the input's
range of motion (limit positions) and the transmission angle, against their closed forms (law of
cosines on the triangle of coupler, rocker and the diagonal from the crank pin to the rocker
pivot, whose length runs from |d − a| to d + a)."""

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

import jaxlink as jl
from jaxlink.analysis.grashof import four_bars
from jaxlink.analysis.motion import motion
from jaxlink.cli import main


@pytest.fixture(scope="module")
def four_bar():
    return jl.load("four-bar")


def _p(mech, a, b, c, d):
    p = np.array(mech.parameters, dtype=float)
    for k, v in dict(a=a, b=b, c=c, d=d).items():
        p[mech.parameter_names.index(k)] = v * 1e-3
    return p


@pytest.mark.parametrize("abcd, cls, typ", [
    ((20, 60, 45, 55), "Grashof", "crank-rocker"),       # the scene: the input shortest
    ((50, 60, 45, 20), "Grashof", "double-crank"),       # the frame shortest (drag link)
    ((50, 20, 45, 55), "Grashof", "double-rocker"),      # the coupler shortest
    ((50, 60, 20, 55), "Grashof", "rocker-crank"),       # the output shortest
    ((20, 40, 30, 55), "non-Grashof", "triple-rocker"),  # s + l = 75 > p + q = 70
    ((20, 55, 20, 55), "change point", None),            # the parallelogram: s + l = p + q
])
def test_grashof_class_and_type(four_bar, abcd, cls, typ):
    (fb,) = four_bars(four_bar, _p(four_bar, *abcd))
    assert (fb.grashof, fb.type) == (cls, typ)
    assert fb.links["input"] == pytest.approx(abcd[0] * 1e-3) and fb.links["coupler"] == pytest.approx(abcd[1] * 1e-3)


def test_crank_rocker_turns_fully_and_its_transmission_angle_is_exact(four_bar):
    a, b, c, d = 20.0, 60.0, 45.0, 55.0
    m = motion(four_bar)
    assert m.full_turn and m.lower is None
    (t,) = m.transmission
    mu_min = math.acos((b * b + c * c - (d - a) ** 2) / (2 * b * c))  # crank along the frame, toward B0
    mu_max = math.acos((b * b + c * c - (d + a) ** 2) / (2 * b * c))  # crank pointing away
    assert abs(t["min"] - mu_min) < 1e-9 and abs(t["max"] - mu_max) < 1e-9
    assert abs(math.remainder(t["min_at"], 2 * math.pi)) < 1e-6 and abs(t["max_at"] - math.pi) < 1e-6
    assert t["worst"] == pytest.approx(min(mu_min, math.pi - mu_max), abs=1e-12)
    # the rocker's swing: its extremes where crank and coupler are in line, |B − O| = b ± a,
    # the angle at the rocker pivot by the law of cosines
    (o,) = m.outputs
    gamma = [math.acos((d * d + c * c - x * x) / (2 * d * c)) for x in (b - a, b + a)]
    assert o["name"] == "phi4" and o["kind"] == "rocker" and abs(o["stroke"] - (gamma[1] - gamma[0])) < 1e-9


def test_an_obtuse_transmission_angle_is_not_folded(four_bar):
    """A crank-rocker whose transmission angle stays above 90° (b = c = 30, d = 54, a = 5 mm:
    μ from acos((b² + c² − (d − a)²)/(2bc)) = 109.5° to 159.1°). The least μ comes from the
    samples' largest cos μ, negative here: it was returned as acos(−cos μ) = 70.5° (the sample's
    candidate compared with its sign flipped). The design of the scene's structure (in-process,
    the programs of the test above)."""
    a, b, c, d = 5.0, 30.0, 30.0, 54.0
    m = motion(four_bar, _p(four_bar, a, b, c, d))
    (t,) = m.transmission
    mu_min = math.acos((b * b + c * c - (d - a) ** 2) / (2 * b * c))
    mu_max = math.acos((b * b + c * c - (d + a) ** 2) / (2 * b * c))
    assert mu_min > math.pi / 2
    assert abs(t["min"] - mu_min) < 1e-9 and abs(t["max"] - mu_max) < 1e-9
    assert t["worst"] == pytest.approx(math.pi - mu_max, abs=1e-12)


def test_non_grashof_input_limits_are_the_toggles():
    """The input of a triple-rocker stops where coupler and rocker come into line,
    cos φ = (a² + d² − (b + c)²) / (2 a d): ±132.1° around its start (0°). The limits are bisected
    on the dyad's margin (its sign only), so the suite's XLA level 0 finds them as the shipped
    level does (Newton's located toggle was 3.6e-9 rad off at level 0)."""
    from jaxlink.analysis.motion import motion

    a, b, c, d = 20.0, 40.0, 30.0, 55.0
    m = jl.load("four-bar")
    p = np.array(m.parameters, dtype=float)
    for k, v in zip("abcd", (a, b, c, d)):
        p[m.parameter_names.index(k)] = v * 1e-3
    r = motion(m, p)
    limit = math.acos((a * a + d * d - (b + c) ** 2) / (2 * a * d))
    assert not r.full_turn
    assert abs(r.upper - limit) < 1e-9 and abs(r.lower + limit) < 1e-9
    assert abs(r.transmission[0]["max"] - math.pi) < 1e-6  # in line at the limits


def test_a_start_that_cannot_assemble_gives_the_toggles_around_the_gap():
    """The same triple-rocker started at 180°, inside the gap it cannot reach: the limits' scan
    from the start does not apply (the start is not assembled), so the toggles come from the
    branch points — the two ends of the gap around the start, acos(…) and 2π − acos(…) — and no
    transmission angles (there is no motion through the start to report)."""
    import pathlib

    a, b, c, d = 20.0, 40.0, 30.0, 55.0
    src = (pathlib.Path(jl.__file__).parent / "scenes" / "four-bar.toml").read_text()
    text = src.replace('name = "phi2"\n', 'name = "phi2"\nstart = 180.0\n')
    text = text.replace("b = 60.0", f"b = {b}").replace("c = 45.0", f"c = {c}")
    assert text.count("start = 180.0") == 1 and f"b = {b}" in text and f"c = {c}" in text
    r = motion(jl.loads(text))
    limit = math.acos((a * a + d * d - (b + c) ** 2) / (2 * a * d))
    assert not r.full_turn and r.transmission == []
    assert abs(r.lower - limit) < 1e-6 and abs(r.upper - (2 * math.pi - limit)) < 1e-6


def test_check_prints_them(four_bar, capsys):
    assert main(["check", "four-bar"]) == 0
    out = capsys.readouterr().out
    assert "loop 'main': Grashof, crank-rocker" in out
    assert "phi2 turns fully" in out
    mu_min = math.degrees(math.acos((60.0**2 + 45.0**2 - 35.0**2) / (2 * 60 * 45)))
    assert f"{mu_min:.10g}°" in out


NARROW = r"""
import jax, json, math
jax.config.update("jax_enable_x64", True)
import numpy as np, jaxlink as jl
from jaxlink.analysis.motion import motion
src = open(jl.load("four-bar").file).read().replace('name = "phi2"', 'name = "phi2"\nstart = 1.234')
m = jl.loads(src, file="narrow.toml")
p = np.array(m.parameters, dtype=float)
for k, v in zip("abcd", (30.0, 64.999999, 65.0, 100.0)):
    p[m.parameter_names.index(k)] = v * 1e-3
ph = np.deg2rad(1.234 + 0.1 * np.arange(3600))
assert bool(np.all(np.asarray(jl.solve(m, ph, p).converged)))  # every sample of motion() assembles
r = motion(m, p)
print(json.dumps([r.full_turn, r.lower, r.upper]))
"""


def test_a_window_between_two_samples_is_not_a_full_turn():
    """a = 30, b = 64.999999, c = 65, d = 100 (mm): the crank cannot pass 180° ± 0.017°, a window
    between two of the 3600 positions (179.934° and 180.034° from a start of 1.234°). Not a full
    turn; the limits are the toggles cos φ = (a² + d² − (b + c)²) / (2ad) (shipped XLA level)."""
    env = dict(os.environ, XLA_FLAGS=" ".join(f for f in os.environ.get("XLA_FLAGS", "").split()
                                              if "xla_backend_optimization_level" not in f))
    r = subprocess.run([sys.executable, "-c", NARROW], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    full, lower, upper = json.loads(r.stdout.strip().splitlines()[-1])
    a, b, c, d = 30.0, 64.999999, 65.0, 100.0
    toggle = math.acos((a * a + d * d - (b + c) ** 2) / (2 * a * d))
    assert not full
    assert abs(upper - toggle) < 1e-9 and abs(lower + toggle) < 1e-9


# ------------------------------------------------------------ change-point four-bars (issue 46, item 7)
# a = 30, b = 60, c = 50, d = 40 (mm): s + l = p + q = 90. At φ2 = 0 all four links lie on the frame
# line (|A B0| = d − a = b − c): the flat position, where the rocker's rate jumps from
# dφ4/dφ2 < 0 to > 0 (its least angle, φ4 = 0, a kink). Its other extreme is the dead centre where
# crank and coupler fold, |A0 B| = b − a: cos φ4 = ((b − a)² − d² − c²) / (2 d c) = −0.8, with the
# crank opposite B, φ2 = 270°. Swing acos(−0.8), rise 270°, fall 90°: time ratio 3.
CP = (30.0, 60.0, 50.0, 40.0)


def _change_point_closed_form(frame):
    a, b, c, d = CP
    swing = math.acos(((b - a) ** 2 - d * d - c * c) / (2 * d * c))  # |A0 B|² = |B0 + c e4|²
    f4 = swing + frame  # B = B0 + c e4 on the branch of the guesses (above the frame line)
    bx, by = d * math.cos(frame) + c * math.cos(f4), d * math.sin(frame) + c * math.sin(f4)
    folded = math.atan2(-by, -bx)  # the crank opposite B: A0 between A and B
    rise = math.remainder(folded - frame, 2 * math.pi) % (2 * math.pi)
    return swing, frame, folded, max(rise, 2 * math.pi - rise) / min(rise, 2 * math.pi - rise)


@pytest.mark.parametrize("frame", [0.0, 0.3])  # the flat position on the start sample; between two
def test_change_point_four_bar_swing_time_ratio_and_flat_position(four_bar, frame):
    from jaxlink.report import designer

    mech = four_bar
    if frame:  # the frame turned by 0.3 rad: the flat position at φ2 = 0.3, between the turn's samples
        src = open(four_bar.file).read().replace('"-d @ 0"', '"-d @ g"').replace("d = 55.0", "d = 55.0\ng = 17.0")
        mech = jl.loads(src.replace("g = 17.0", f"g = {math.degrees(frame)!r}"), file="rotated.toml")
    p = _p(mech, *CP)
    swing, flat, folded, ratio = _change_point_closed_form(frame)
    assert ratio == pytest.approx(3.0, abs=1e-12)
    m = motion(mech, p)
    assert m.full_turn
    assert len(m.change_points) == 1 and abs(math.remainder(m.change_points[0] - flat, 2 * math.pi)) < 1e-9
    (o,) = m.outputs
    assert abs(o["stroke"] - swing) < 1e-9 and abs(o["time_ratio"] - ratio) < 1e-9
    # one extreme is the flat position (the rocker along the frame line), not a dead centre; the
    # other the one dead centre, at `folded` or its mirror image in the frame line (the guesses'
    # branch: above the line in the scene, below it with the frame turned)
    assert o["min_flat"] != o["max_flat"]
    at_flat = o["min"] if o["min_flat"] else o["max"]
    assert abs(math.remainder(at_flat - frame, 2 * math.pi)) < 1e-9
    assert [abs(math.remainder(x - flat, 2 * math.pi)) < 1e-9 for x, _ in o["flat_positions"]] == [True]
    (dc,) = o["dead_centres"]
    assert min(abs(math.remainder(dc[0] - f, 2 * math.pi)) for f in (folded, 2 * frame - folded)) < 1e-9
    text = "\n".join(designer.lines(mech, four_bars(mech, p), m, "mm"))
    at = f"{math.degrees(flat):.6g}°"
    assert f"phi2 turns fully (on the guesses' branch), through the flat position at phi2 = {at}" in text
    assert "flat position (change point, the rate jumps) at " + ("phi2 = " if o["min_flat"] else "") + at in text
    assert "dead centres at" not in text
    doc = designer.to_json(mech, four_bars(mech, p), m)["motion"]
    assert doc["change_points_rad"] == m.change_points
    assert (doc["outputs"][0]["min_at_flat"], doc["outputs"][0]["max_at_flat"]) == (o["min_flat"], o["max_flat"])
    assert len(doc["outputs"][0]["flat_positions"]) == 1 and len(doc["outputs"][0]["dead_centres"]) == 1


def test_a_crank_rocker_has_no_flat_position(four_bar):
    """The differential case: the scene's crank-rocker (its least transmission angle 35°, a minimum
    of the margin well above zero) has no change point and both extremes are dead centres."""
    m = motion(four_bar)
    (o,) = m.outputs
    assert m.change_points == [] and o["flat_positions"] == [] and len(o["dead_centres"]) == 2
    assert not o["min_flat"] and not o["max_flat"]


def test_check_at_a_flat_start_gives_the_designers_numbers(capsys):
    """The change-point four-bar with its crank starting on the flat position (φ2 = 0: every link
    on the frame line, the loop's Jacobian singular) assembles there: `check` said `singular` and
    exited 1 with no designer's numbers; it names the singular start and gives them, the swing
    acos(−0.8) and the time ratio 3 of the closed form (printed digits)."""
    args = ["check", "four-bar"] + [f"--set={k}={v:g}" for k, v in zip("abcd", CP)]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "assembly    at the start: singular" in out and "the start is a singular position" in out
    swing, _flat, _folded, ratio = _change_point_closed_form(0.0)
    assert f"swing {math.degrees(swing):.10g}°" in out and f"time ratio {ratio:.6g}" in out
    assert "through the flat position at phi2 = 0°" in out
