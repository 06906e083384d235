"""Write one *plain* mechanism file per four-bar path-synthesis case of benchmarks/fourbar-path/:
what a user writes from the docs, with no search knobs.

Each file holds a generic crank-rocker placed at the targets' box (not the literature solution),
its guesses, and an `[optimize]` section with only the problem: the point, the nine variables
(ground pivot p1x/p1y, frame angle a, lengths l1..l4, coupler point l5/g) with bounds from the
targets' bounding box (centre c, diagonal D: pivot c ± 4D, lengths 0.05 D … 5 D, angles ±180°),
`objective = "points"`, `samples = 360` and the targets. No `placement`, `circuits`, `starts`,
`presample`, `iterations` or `budget`: the search chooses them (docs/reference/file-format.md).

    python experiments/fourbar_plain/generate.py [BENCHMARK_DIR]
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


def guesses(p1, a, l1, l2, l3, l4):
    """(th3, th4) of the four-bar at phi = 0 (the rocker joint on the + side of p3 -> p2)."""
    p2 = p1 + l1 * np.array([math.cos(a), math.sin(a)])
    p3 = p1 + l2 * np.array([math.cos(a), math.sin(a)])
    r = np.linalg.norm(p2 - p3)
    u = (p2 - p3) / r
    c = (l3**2 - l4**2 + r**2) / (2 * r)
    p4 = p3 + c * u + math.sqrt(l3**2 - c**2) * np.array([-u[1], u[0]])
    return math.atan2(*(p4 - p3)[::-1]), math.atan2(*(p4 - p2)[::-1])


def plain_text(name: str, targets, *, angle_unit: str = "deg", frame_angle: float = 0.0) -> str:
    """The plain file of a case: a crank-rocker (crank 0.3 D, frame, coupler and rocker D) with its
    ground pivot at the targets' centre and frame angle `frame_angle` (degrees)."""
    t = np.asarray(targets, dtype=float)
    lo, hi = t.min(0), t.max(0)
    c, D = 0.5 * (lo + hi), float(np.hypot(*(hi - lo)))
    a = math.radians(frame_angle)
    l1, l2, l3, l4, l5 = D, 0.3 * D, D, D, 0.5 * D
    th3, th4 = guesses(c, a, l1, l2, l3, l4)
    deg = angle_unit == "deg"
    ang = (lambda x: math.degrees(x)) if deg else (lambda x: x)  # noqa: E731
    half = 180.0 if deg else math.pi
    f = lambda v: f"{v:.6g}"  # noqa: E731
    bounds = {"p1x": (c[0] - 4 * D, c[0] + 4 * D), "p1y": (c[1] - 4 * D, c[1] + 4 * D), "a": (-half, half),
              **{k: (0.05 * D, 5 * D) for k in ("l1", "l2", "l3", "l4", "l5")}, "g": (-half, half)}
    variables = ", ".join(f"{k} = [{f(lo_)}, {f(hi_)}]" for k, (lo_, hi_) in bounds.items())
    pts = ",\n    ".join(f"[{float(x)!r}, {float(y)!r}]" for x, y in t)
    return f'''# Four-bar path synthesis, case "{name}": a plain file (no search knobs).
[mechanism]
name = "fourbar-{name}-plain"
length_unit = "mm"
angle_unit = "{angle_unit}"

[parameters]
p1x = {f(c[0])}        # ground pivot of the crank
p1y = {f(c[1])}
a = {f(ang(a))}          # frame angle
l1 = {f(l1)}       # frame
l2 = {f(l2)}       # crank
l3 = {f(l3)}       # coupler
l4 = {f(l4)}       # rocker
l5 = {f(l5)}       # coupler point: distance from the crank tip
g = 0.0            # and angle from the coupler

[input]
name = "phi"
body = "crank"
start = 0.0

[unknowns]
th3 = {f(ang(th3))}
th4 = {f(ang(th4))}

[loops]
main = ["l2 @ a + phi", "l3 @ th3", "-l4 @ th4", "-l1 @ a"]

[points]
P = ["(p1x, p1y)", "l2 @ a + phi", "l5 @ th3 + g"]

[optimize]
point = "P"
objective = "points"
samples = 360
variables = {{ {variables} }}
targets = [
    {pts},
]
'''


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    bench = pathlib.Path(argv[0]) if argv else DEFAULT
    data = json.loads((bench / "fourbar_path_benchmarks.json").read_text())
    for name in CASES:
        (HERE / f"{name}.toml").write_text(plain_text(name, data[name]["target"]), encoding="utf-8")
        print(f"wrote {HERE / (name + '.toml')}")


if __name__ == "__main__":
    main()
