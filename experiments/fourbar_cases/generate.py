"""Write one mechanism file per four-bar path-synthesis case of benchmarks/fourbar-path/.

Each file's design is the literature solution (so `jaxlink kinematics` shows it and its untimed
error reproduces the benchmark's `ref_sse_nearest`); its `[optimize]` section makes the ground
pivot (p1x, p1y), the frame angle a, the four lengths l1..l4 and the coupler point (l5, g)
variables, with bounds from the targets' bounding box (centre c, diagonal D): pivot c ± 4D,
l1..l4 in [0.02 D, 4 D], l5 in [0, 4 D], a and g in [−π, π]; both circuits are searched.

Convention (the benchmark JSON): p2 = p1 + l1 e(a); p3 = p1 + l2 e(a + φ); p4 the rocker joint
(|p4 − p3| = l3, |p4 − p2| = l4), on the +sin side of p3→p2 for circuit c1; coupler point
p5 = p3 + l5 e(g + angle(p4 − p3)).

    python experiments/fourbar_cases/generate.py [BENCHMARK_DIR]
"""

from __future__ import annotations

import json
import math
import pathlib
import sys

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
DEFAULT = HERE.parents[1] / "benchmarks" / "fourbar-path"
CASES = ("mkh1", "mkh2", "mkh3", "mcgarva", "ullah", "yu1", "yu2", "wu3")


def wrap(x):
    return (x + math.pi) % (2 * math.pi) - math.pi


def configuration(m, phi, circuit):
    """(th3, th4) of the reference mechanism at crank angle phi (relative to the frame)."""
    p1 = np.array([m["p1x"], m["p1y"]])
    p2 = p1 + m["l1"] * np.array([math.cos(m["a"]), math.sin(m["a"])])
    p3 = p1 + m["l2"] * np.array([math.cos(m["a"] + phi), math.sin(m["a"] + phi)])
    r = np.linalg.norm(p2 - p3)
    u = (p2 - p3) / r
    c = (m["l3"] ** 2 - m["l4"] ** 2 + r**2) / (2 * r)
    s = math.sqrt(m["l3"] ** 2 - c**2) * (1 if circuit == "c1" else -1)
    p4 = p3 + c * u + s * np.array([-u[1], u[0]])
    th3 = math.atan2(*(p4 - p3)[::-1])
    th4 = math.atan2(*(p4 - p2)[::-1])
    return th3, th4


def write_case(name, case, out_dir):
    m = dict(case["reference_mechanism"])
    m["a"], m["g"] = wrap(m["a"]), wrap(m["g"])
    circuit = m["stat"][:2]
    th3, th4 = configuration(m, 0.0, circuit)
    t = np.asarray(case["target"], dtype=float)
    lo, hi = t.min(0), t.max(0)
    c, D = 0.5 * (lo + hi), float(np.hypot(*(hi - lo)))
    f = lambda v: f"{v:.6g}"  # noqa: E731
    targets = ",\n    ".join(f"[{float(x)!r}, {float(y)!r}]" for x, y in t)
    src = case["source"].split(".")[0]
    # 360 crank positions; 180 where many targets make the nearest-point objective the cost
    samples = 180 if len(t) >= 30 else 360
    text = f'''# Four-bar path synthesis, benchmark case "{name}" ({case["n_points"]} target points).
# Source: {src}.
# The design below is the literature solution (stat {m["stat"]}); its untimed error is
# ref_sse_nearest = {case["ref_sse_nearest"]:.6g} (benchmarks/fourbar-path). Written by
# experiments/fourbar_cases/generate.py: p2 = p1 + l1 e(a); crank tip p3 = p1 + l2 e(a + phi);
# rocker joint p4 (|p4 - p3| = l3, |p4 - p2| = l4); coupler point P = p3 + l5 e(th3 + g).
[mechanism]
name = "fourbar-{name}"
description = "Four-bar path synthesis case {name} ({case['n_points']} points)"
length_unit = "mm"
angle_unit = "rad"

[parameters]
p1x = {m["p1x"]!r}
p1y = {m["p1y"]!r}
a = {m["a"]!r}
l1 = {m["l1"]!r}
l2 = {m["l2"]!r}
l3 = {m["l3"]!r}
l4 = {m["l4"]!r}
l5 = {m["l5"]!r}
g = {m["g"]!r}

[input]
name = "phi"
body = "crank"
start = 0.0

[unknowns]
th3 = {float(th3)!r}
th4 = {float(th4)!r}

[loops]
main = ["l2 @ a + phi", "l3 @ th3", "-l4 @ th4", "-l1 @ a"]

[points]
P = ["(p1x, p1y)", "l2 @ a + phi", "l5 @ th3 + g"]

[optimize]
point = "P"
objective = "points"
samples = {samples}
circuits = "all"
placement = {{ x = "p1x", y = "p1y", angle = "a" }}   # gradient starts: presampled shapes placed by ICP
starts = 48
presample = 8192
iterations = 200
variables = {{ p1x = [{f(c[0] - 4 * D)}, {f(c[0] + 4 * D)}], p1y = [{f(c[1] - 4 * D)}, {f(c[1] + 4 * D)}], a = [-3.14159265, 3.14159265], l1 = [{f(0.02 * D)}, {f(4 * D)}], l2 = [{f(0.02 * D)}, {f(4 * D)}], l3 = [{f(0.02 * D)}, {f(4 * D)}], l4 = [{f(0.02 * D)}, {f(4 * D)}], l5 = [0.0, {f(4 * D)}], g = [-3.14159265, 3.14159265] }}
targets = [
    {targets},
]
'''
    (out_dir / f"{name}.toml").write_text(text, encoding="utf-8")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    bench = pathlib.Path(argv[0]) if argv else DEFAULT
    data = json.loads((bench / "fourbar_path_benchmarks.json").read_text())
    for name in CASES:
        write_case(name, data[name], HERE)
        print(f"wrote {HERE / (name + '.toml')}")


if __name__ == "__main__":
    main()
