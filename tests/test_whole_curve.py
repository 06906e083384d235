"""The whole closed curve of a linkage whose input cannot turn fully (`jl.whole_curve`): its
segments end at the closed-form limit positions, it closes, it stays on the loops, and each
segment is the circle–circle intersection on its side (numpy, written here)."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import jaxlink as jl

jax.config.update("jax_enable_x64", True)
pytestmark = pytest.mark.xdist_group("sketch")

TRIPLE_ROCKER = """
[mechanism]
length_unit = "mm"
angle_unit = "deg"
[parameters]
a = 30.0
b = 40.0
c = 35.0
d = 50.0
[input]
name = "phi2"
start = 90.0
[unknowns]
phi3 = 0.0
phi4 = 60.0
[loops]
main = ["a @ phi2", "b @ phi3", "-c @ phi4", "-d @ 0"]
[points]
B = ["a @ phi2", "b @ phi3"]
"""


def _coupler_joint(a, b, c, d, phi, side):
    """B of the four-bar A0 = 0, B0 = (d, 0): |B − A| = b, |B − B0| = c, left (+1) or right of A → B0."""
    A = np.stack([a * np.cos(phi), a * np.sin(phi)], -1)
    w = np.array([d, 0.0]) - A
    dist = np.hypot(w[:, 0], w[:, 1])
    e = w / dist[:, None]
    x = (b * b - c * c + dist**2) / (2 * dist)
    hh = np.sqrt(np.maximum(b * b - x * x, 0.0))
    return A + x[:, None] * e + side * hh[:, None] * np.stack([-e[:, 1], e[:, 0]], -1)


def test_triple_rocker_whole_curve_switches_branch_at_its_limits():
    mech = jl.loads(TRIPLE_ROCKER)
    wc = jl.whole_curve(mech, samples=720)
    a, b, c, d = 30.0, 40.0, 35.0, 50.0
    limit = np.arccos((a * a + d * d - (b + c) ** 2) / (2 * a * d))  # coupler and rocker in line
    assert not wc.full_turn and len(wc.segments) == 2
    (f0, t0, s0), (f1, t1, s1) = wc.segments
    assert abs(f0 + limit) < 1e-9 and abs(t0 - limit) < 1e-9 and abs(f1 - limit) < 1e-9 and abs(t1 + limit) < 1e-9
    assert s0 == (-s1[0],)
    # closed, on the loop everywhere, and each half the intersection on its own side
    assert np.abs(wc.points[0] - wc.points[-1]).max() < 1e-15
    r = jax.vmap(mech.residual, in_axes=(0, 0, None))(wc.q, wc.input, mech.parameters)
    assert float(np.abs(r).max()) < 1e-15
    sides = []
    for k in (0, 1):
        sel = wc.segment == k
        errs = [np.abs(_coupler_joint(a, b, c, d, wc.input[sel], sgn) * 1e-3 - wc.points[sel, 0]).max()
                for sgn in (1.0, -1.0)]
        # to rounding, amplified by the square root next to the toggles (|h| ~ sqrt(ulp) there)
        assert min(errs) < 1e-9 and max(errs) > 1e-3, errs
        sides.append(int(np.argmin(errs)))
    assert sides[0] != sides[1]  # the two halves are the two assemblies


def _watt_limits(r, c, o2):
    """The closed-form limits of Watt's linkage (rockers r from the origin and from o2, coupler c)
    driven by one rocker: where coupler and the other rocker are in line, |r e(φ) − o2| = c ± r."""
    alpha, D = np.arctan2(o2[1], o2[0]), np.hypot(*o2)
    limits = []
    for L in (c + r, abs(c - r)):
        cos_ = (r * r + D * D - L * L) / (2 * r * D)
        if abs(cos_) <= 1:
            limits += [alpha + np.arccos(cos_), alpha - np.arccos(cos_)]
    return limits


def test_watt_linkage_driven_by_a_rocker_traces_its_figure_eight():
    """Watt's straight-line linkage: two equal rockers O1A, O2B and a coupler AB with its midpoint
    M; driven by the rocker O1A, which reaches an interval only. The whole curve is the
    figure-eight of M, both halves; the limits are where coupler and the other rocker are in line:
    |O1 + r e(φ) − O2| = c + r or |c − r|."""
    r, c = 50.0, 30.0
    o2 = np.array([70.0, 30.0])
    text = f"""
[mechanism]
length_unit = "mm"
angle_unit = "deg"
[parameters]
r1 = {r}
r2 = {r}
cc = {c}
ox = {o2[0]}
oy = {o2[1]}
[input]
name = "phi1"
start = 10.0
[unknowns]
phi3 = 90.0
phi4 = 190.0
[loops]
main = ["r1 @ phi1", "cc @ phi3", "-r2 @ phi4", "-(ox, oy)"]
[points]
M = ["r1 @ phi1", "cc/2 @ phi3"]
"""
    mech = jl.loads(text)
    motion_check = jl.solve(mech, np.radians([10.0]))
    assert bool(motion_check.converged[0])
    wc = jl.whole_curve(mech, samples=720)
    assert not wc.full_turn and len(wc.segments) == 2
    # the closed-form limits: |r e(φ) − o2|² = L² ⇒ cos(φ − α) = (r² + |o2|² − L²) / (2 r |o2|)
    limits = _watt_limits(r, c, o2)
    ends = [e for a, b, _ in wc.segments for e in (a, b)]
    for e in ends:
        assert min(abs(np.remainder(e - lim + np.pi, 2 * np.pi) - np.pi) for lim in limits) < 1e-9, (e, limits)
    # the figure-eight crosses itself: M passes the same place on the two halves
    h0, h1 = wc.points[wc.segment == 0, 0], wc.points[wc.segment == 1, 0]
    gap = np.min(np.hypot(h0[:, None, 0] - h1[None, :, 0], h0[:, None, 1] - h1[None, :, 1]))
    assert gap < 2e-4  # within a sample's spacing (m)
    r_ = jax.vmap(mech.residual, in_axes=(0, 0, None))(wc.q, wc.input, mech.parameters)
    assert float(np.abs(r_).max()) < 1e-15


def test_a_crank_turns_fully_in_one_segment():
    wc = jl.whole_curve(jl.load("four-bar"), samples=360)
    assert wc.full_turn and len(wc.segments) == 1
    a, b, _ = wc.segments[0]
    assert b - a == pytest.approx(2 * np.pi)


def test_motion_reports_watt_linkage_input_limits_to_the_closed_form():
    """`jl.motion` (what `jaxlink check` prints as the range of motion) on Watt's linkage driven
    by one rocker: the limits around the start are the closed-form ones to 1e-9 rad."""
    r, c, o2 = 50.0, 30.0, np.array([70.0, 30.0])
    text = f"""
[mechanism]
length_unit = "mm"
angle_unit = "deg"
[parameters]
r1 = {r}
r2 = {r}
cc = {c}
[input]
name = "phi1"
start = 10.0
[unknowns]
phi3 = 90.0
phi4 = 190.0
[loops]
main = ["r1 @ phi1", "cc @ phi3", "-r2 @ phi4", "-({o2[0]}, {o2[1]})"]
"""
    m = jl.motion(jl.loads(text), samples=720)
    assert not m.full_turn
    limits = _watt_limits(r, c, o2)
    limits = np.asarray(limits)
    start = np.radians(10.0)
    # the nearest closed-form limits below and above the start, as the input turns back and forward
    below = max(x - 2 * np.pi * np.ceil((x - start) / (2 * np.pi)) for x in limits)
    above = min(x + 2 * np.pi * np.ceil((start - x) / (2 * np.pi)) for x in limits)
    assert abs(m.lower - below) < 1e-9 and abs(m.upper - above) < 1e-9, (m.lower, m.upper, below, above)


def test_kinematics_json_holds_the_designer_numbers(tmp_path, capsys):
    """`kinematics --json`: the columns' extremes are the CSV's, and the designer's numbers are
    there in SI: the Whitworth ram's time ratio against its closed form (π + 2β)/(π − 2β),
    sin β = r/d (crank r = 100, pivots d = 300 apart)."""
    import csv
    import json

    from jaxlink.cli import main

    out, table = tmp_path / "w.json", tmp_path / "w.csv"
    assert main(["kinematics", "whitworth", "--rpm", "60", "--numbers", "--json", str(out), "--csv", str(table)]) == 0
    text = capsys.readouterr().out
    assert "time ratio" in text and "stroke" in text  # the summary prints them too
    doc = json.loads(out.read_text())
    with open(table) as fh:
        rows = list(csv.reader(fh))
    j = rows[0].index("C_x_m")
    col = np.asarray([float(r[j]) for r in rows[1:]])
    assert doc["columns"]["C_x_m"] == {"min": col.min(), "max": col.max()}
    assert doc["positions"] == {"count": 72, "converged": 72, "results": {"converged": 72}}
    beta = np.arcsin(100.0 / 300.0)
    ram = [o for o in doc["designer"]["motion"]["outputs"] if o["name"] == "x"][0]
    assert abs(ram["time_ratio"] - (np.pi + 2 * beta) / (np.pi - 2 * beta)) < 1e-9
    assert doc["designer"]["motion"]["full_turn"] is True


def test_kinematics_whole_curve_command(tmp_path, capsys):
    """`kinematics --whole-curve`: the CSV's rows are the curve (segments 0 and 1, the input
    turning back at the closed-form limit), in the file's units with --units file."""
    import csv

    from jaxlink.cli import main

    path, out = tmp_path / "tr.toml", tmp_path / "tr.csv"
    path.write_text(TRIPLE_ROCKER)
    assert main(["kinematics", str(path), "--whole-curve", "--count", "360", "--csv", str(out), "--units", "file"]) == 0
    text = capsys.readouterr().out
    assert "2 segments" in text and "-137.8735842° to 137.8735842°" in text
    with open(out) as fh:
        rows = list(csv.reader(fh))
    assert rows[0][:4] == ["segment", "input_deg", "phi3_deg", "phi4_deg"] and rows[0][4:] == ["B_x_mm", "B_y_mm"]
    seg = np.asarray([int(r[0]) for r in rows[1:]])
    inp = np.asarray([float(r[1]) for r in rows[1:]])
    limit = np.degrees(np.arccos((30.0**2 + 50.0**2 - 75.0**2) / (2 * 30.0 * 50.0)))
    assert set(seg) == {0, 1} and abs(inp.max() - limit) < 1e-9 and abs(inp.min() + limit) < 1e-9
    assert main(["kinematics", str(path), "--whole-curve", "--step", "3"]) == 2  # no grid in this mode
