"""The feed-dog stroke of the built-in sewing-feed six-bar as a study response (issue 48): one
`jaxlink study` command — travel(Z, x), tolerances ±0.02 mm (normal, 3σ) on every link, spec
27.75 ± 0.08 mm, 1e5 Monte Carlo samples — against an independent numpy model
(tests/feed_sixbar.py: circle intersections, its own 1e5 draws) and a finite-difference σ.

    python benchmarks/feed_stroke.py [--samples 100000] [--positions 360]

Writes benchmarks/results/feed_stroke.json; docs/numbers.md quotes it.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
import feed_sixbar  # noqa: E402

LINKS = ("l2", "l22", "l3", "l4", "l44", "l5", "l6", "l66", "l7", "l8")
SPEC = (27.67, 27.83)
TOL = 0.02


def travel(p):
    out = []
    n = len(next(iter(p.values())))
    for s in range(0, n, 4096):
        out.append(feed_sixbar.travel({k: np.asarray(v, float)[s:s + 4096] for k, v in p.items()}))
    return np.concatenate(out)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=int, default=100000)
    ap.add_argument("--positions", type=int, default=360)
    a = ap.parse_args()
    tol = "\n".join(f"{n} = {TOL}" for n in LINKS)
    with tempfile.TemporaryDirectory() as tmp:
        src = pathlib.Path(tmp) / "feed.toml"
        src.write_text((ROOT / "jaxlink/scenes/sewing-feed.toml").read_text() + f"""
[study]
positions = {a.positions}
points = ["Z"]
metrics = ["travel(Z, x)"]
samples = {a.samples}
limits = {{ "travel(Z, x)" = [{SPEC[0]}, {SPEC[1]}] }}

[study.tolerances]
{tol}
""")
        out = pathlib.Path(tmp) / "out"
        cmd = [sys.executable, "-m", "jaxlink.cli", "study", str(src), "--out", str(out), "--no-plot"]
        t0 = time.perf_counter()
        run = subprocess.run(cmd, capture_output=True, text=True, check=True)
        wall = time.perf_counter() - t0
        print(run.stdout)
        d = np.load(out / "study.npz")
        with open(out / "tolerance.csv", newline="") as fh:
            labels = [r["output"] for r in csv.DictReader(fh)]
        i = labels.index("travel(Z, x)")
        nominal, sigma = float(d["nominal"][i]), float(d["first_order.sigma_rss"][i])
        out_pkg = int(d["monte_carlo.out_of_spec"][0])
        feasible = json.loads((out / "study.json").read_text())["monte_carlo"]["feasible"]
        cpk = float(d["monte_carlo.cpk"][0])
    x0 = dict(feed_sixbar.NOMINAL)
    ref = float(travel({k: np.asarray([v]) for k, v in x0.items()})[0])
    h = 1e-3
    g = []
    for n in LINKS:
        vals = []
        for s in (-2, -1, 1, 2):
            p = {k: np.asarray([v]) for k, v in x0.items()}
            p[n] = p[n] + s * h
            vals.append(float(travel(p)[0]))
        g.append((vals[0] - 8 * vals[1] + 8 * vals[2] - vals[3]) / (12 * h))
    sigma_fd = math.sqrt(float(np.sum((np.asarray(g) * TOL / 3) ** 2)))
    rng = np.random.default_rng(2026)
    t1 = time.perf_counter()
    p = {k: np.full(a.samples, v) for k, v in x0.items()}
    for n in LINKS:
        p[n] = x0[n] + rng.normal(0.0, TOL / 3, a.samples)
    t = travel(p)
    numpy_s = time.perf_counter() - t1
    out_np = int(np.count_nonzero((t < SPEC[0]) | (t > SPEC[1])))
    q1, q2 = out_pkg / feasible, out_np / a.samples
    qq = (out_pkg + out_np) / (feasible + a.samples)
    se = math.sqrt(qq * (1 - qq) * (1 / feasible + 1 / a.samples))
    mu, s = t.mean(), t.std(ddof=1)
    res = {"samples": a.samples, "positions": a.positions, "command_wall_s": round(wall, 1),
           "nominal_mm": nominal, "numpy_nominal_mm": ref, "nominal_rel_diff": abs(nominal - ref) / ref,
           "sigma_rss_mm": sigma, "sigma_fd_mm": sigma_fd, "sigma_rel_diff": abs(sigma - sigma_fd) / sigma_fd,
           "percent_out": 100 * q1, "numpy_percent_out": 100 * q2, "standard_error_percent": 100 * se,
           "difference_in_se": abs(q1 - q2) / se, "cpk": cpk,
           "numpy_cpk": min(SPEC[1] - mu, mu - SPEC[0]) / (3 * s), "numpy_wall_s": round(numpy_s, 1)}
    print(json.dumps(res, indent=2))
    (ROOT / "benchmarks/results/feed_stroke.json").write_text(json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
