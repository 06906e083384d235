"""Time to a design from a cold start: `jaxlink synthesize` on a four-bar path-synthesis problem
from the literature (benchmarks/fourbar-path/: the target points of a published case), the
four-bar topology only, a short time limit, in a fresh process with a fresh compilation cache
(`JAXLINK_CACHE_DIR` an empty temporary folder), so that starting Python, importing JAX and
compiling all count; then once more with that cache filled (a warm start: what a second command
on the same machine costs).

Per case: the wall time and the CPU time (user + system) of the command, where its own time went
(the search's log: the rounds; the rest is start-up and compiling), and the error two ways:

- the distance it reports (jaxlink.synthesis.distance.match: the phase-free chamfer, normalised, at
  the best rotation) and LInK's 2000-point metric of the same design (`link_chamfer_2000`);
- the case's own measure: the SSE, Σ over the target points of the squared distance to the
  nearest point of the traced coupler curve (the mechanism written to `synthesized.toml`, placed
  in the target's unit, traced here in NumPy at 72,000 crank positions over its interval), beside
  `ref_sse_nearest`, the published mechanism's SSE computed the same way
  (benchmarks/fourbar-path/fourbar_path_benchmarks.json).

Beside them, pyslvs (not installed here): issue 26 measured its best algorithm, differential
evolution, at about 2.4 s wall on 2 cores on its own four-bar test problem (2.4–21 s over its
problems) and, on pyslvs's 30-point closed test path, an SSE of 69.7–83.1 over 720 crank
positions; the issue's goal is less wall time than that, with a lower error. `sse_720` is that
measure (the target points to the nearest of 720 traced positions).

`--target FILE.csv` runs another target (columns x, y) instead of the cases, e.g. pyslvs's
30-point path (`PATH` of its test/test_planar_linkage.py, AGPL: copy the points yourself, the
closing repeat of the first left out; not stored here).

    python benchmarks/synthesis_coldstart.py [--case mkh1 | --case all | --target FILE] [--time-limit 2]

The machine's load average is printed and stored: on a shared machine, wall time far above CPU
time means waiting for a core. Writes benchmarks/results/synthesis_coldstart.json.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
CASES = HERE / "fourbar-path"
#: issue 26: pyslvs's differential evolution, its own four-bar test problem, 2 cores (wall, s)
PYSLVS_DE_S = 2.4


def case_points(name: str) -> np.ndarray:
    with open(CASES / "fourbar_path_targets.csv") as f:
        rows = [r for r in csv.DictReader(f) if r["case"] == name]
    if not rows:
        raise SystemExit(f"no case {name!r} in {CASES / 'fourbar_path_targets.csv'}")
    return np.array([[float(r["x"]), float(r["y"])] for r in sorted(rows, key=lambda r: int(r["i"]))])


def four_bar_curve(joints: dict, start_deg: float, stop_deg: float, n: int = 72000) -> np.ndarray:
    """The traced point P of the written four-bar (joints F0, F1, C, J4, P at the file's start)
    over crank angles start..stop: C turns about F0, J4 closes C–J4–F1 on the written branch, P
    rides on the rigid link C–J4–P. Points where the dyad does not close are dropped."""
    f0, f1, c0, b0, p0 = (np.asarray(joints[k], float) for k in ("F0", "F1", "C", "J4", "P"))
    r = np.hypot(*(c0 - f0))
    th = np.radians(np.linspace(start_deg, stop_deg, n))
    c = f0 + r * np.stack([np.cos(th), np.sin(th)], -1)
    l1, l2 = np.hypot(*(b0 - c0)), np.hypot(*(b0 - f1))
    w0, v0 = f1 - c0, b0 - c0
    sg = 1.0 if w0[0] * v0[1] - w0[1] * v0[0] >= 0 else -1.0
    w = f1 - c
    d2 = np.sum(w * w, -1)
    d = np.sqrt(d2)
    a = (l1 * l1 - l2 * l2 + d2) / (2 * d)
    h2 = l1 * l1 - a * a
    ok = h2 >= 0
    perp = np.stack([-w[:, 1], w[:, 0]], -1)
    b = c + (a / d)[:, None] * w + (sg * np.sqrt(np.maximum(h2, 0.0)) / d)[:, None] * perp
    ang = np.arctan2(*(b - c).T[::-1]) - np.arctan2(*(b0 - c0)[::-1])
    q = p0 - c0
    p = c + np.stack([np.cos(ang) * q[0] - np.sin(ang) * q[1], np.sin(ang) * q[0] + np.cos(ang) * q[1]], -1)
    return p[ok]


def sse_nearest(points: np.ndarray, curve: np.ndarray) -> float:
    from scipy.spatial import cKDTree

    return float(np.sum(cKDTree(curve).query(points)[0] ** 2))


def run_once(target: Path, out: Path, cache: Path, time_limit: float | None, seed: int) -> dict:
    beside = Path(sys.executable).with_name("jaxlink")  # the command installed with this Python
    exe = str(beside) if beside.exists() else shutil.which("jaxlink")
    if exe is None:
        raise SystemExit("the jaxlink command is not installed (pip install -e .)")
    # the default: one round of the quick programs (a time limit is a cap: one shorter than the compiling
    # gives no design)
    limit = ["--rounds", "1", "--quick"] if time_limit is None else ["--time-limit", str(time_limit)]
    cmd = [exe, "synthesize", str(target), "--topologies", "four-bar", *limit,
            "--seed", str(seed), "--out", str(out), "--no-plot"]
    env = dict(os.environ, JAXLINK_CACHE_DIR=str(cache))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"jaxlink synthesize failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    rounds = [float(m) for m in re.findall(r"round \d+: .*?, ([0-9.]+) s", proc.stderr)]
    res = json.loads((out / "synthesis.json").read_text())
    best = res["designs"][0]
    return {"wall_s": wall, "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            "search_s": res["wall_s"], "rounds": len(rounds), "first_round_done_s": rounds[0] if rounds else None,
            "distance": best["distance"], "link_chamfer_2000": best.get("link_chamfer_2000"), "best": best}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", default="mkh1", help="a case of benchmarks/fourbar-path (default mkh1), or 'all'")
    ap.add_argument("--target", help="a CSV of target points (columns x, y) to run instead of the cases")
    ap.add_argument("--time-limit", type=float, default=None,
                    help="the search's --time-limit (s, a cap; default none: --rounds 1 --quick, one round of the "
                         "quick programs, the time to a first answer)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(HERE / "results" / "synthesis_coldstart.json"))
    args = ap.parse_args()
    refs = json.loads((CASES / "fourbar_path_benchmarks.json").read_text())
    names = [k for k, v in refs.items() if isinstance(v, dict) and "ref_sse_nearest" in v] if args.case == "all" \
        else [args.case]
    if args.target:
        names = [Path(args.target).stem]
    rows = []
    print(f"pyslvs differential evolution (issue 26's measurement, its own four-bar problem, 2 cores): "
          f"about {PYSLVS_DE_S} s wall")
    print(f"{'case':<9}{'points':>7}{'closed':>8}{'cold_s':>8}{'cpu_s':>7}{'search_s':>9}{'warm_s':>8}"
          f"{'distance':>10}{'link2000':>10}{'SSE':>12}{'SSE@720':>10}{'ref SSE':>12}")
    with tempfile.TemporaryDirectory(prefix="jaxlink-coldstart-") as tmp:
        for name in names:
            pts = (np.loadtxt(args.target, delimiter=",", skiprows=1, ndmin=2)[:, :2] if args.target
                   else case_points(name))
            tdir = Path(tmp) / name
            tdir.mkdir()
            target = tdir / "target.csv"
            target.write_text("x,y\n" + "".join(f"{float(x)!r},{float(y)!r}\n" for x, y in pts))
            cache = tdir / "cache"  # fresh: empty
            cold = run_once(target, tdir / "cold", cache, args.time_limit, args.seed)
            warm = run_once(target, tdir / "warm", cache, args.time_limit, args.seed)
            b = cold["best"]
            curve = four_bar_curve(b["joint_positions"], b["start_deg"], b["stop_deg"])
            sse = sse_nearest(pts, curve)
            sse_720 = sse_nearest(pts, four_bar_curve(b["joint_positions"], b["start_deg"], b["stop_deg"], 720))
            ref = float("nan") if args.target else refs[name]["ref_sse_nearest"]
            closed = json.loads((tdir / "cold" / "synthesis.json").read_text())["target"]["closed"]
            row = {"case": name, "points": len(pts), "closed": closed,
                   "cold": {k: v for k, v in cold.items() if k != "best"},
                   "warm": {k: v for k, v in warm.items() if k != "best"}, "sse": sse, "sse_720": sse_720,
                   "ref_sse_nearest": None if args.target else ref,
                   "lengths": b["lengths"]}
            rows.append(row)
            print(f"{name:<9}{len(pts):>7}{str(closed):>8}{cold['wall_s']:>8.1f}{cold['cpu_s']:>7.1f}"
                  f"{cold['search_s']:>9.1f}{warm['wall_s']:>8.1f}{cold['distance']:>10.4f}"
                  f"{cold['link_chamfer_2000'] or float('nan'):>10.4f}{sse:>12.4g}{sse_720:>10.4g}"
                  f"{ref:>12.4g}",
                  flush=True)
    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {len(os.sched_getaffinity(0))} cores")
    out = {"benchmark": "synthesis_coldstart", "settings": vars(args),
           "pyslvs_de_wall_s": {"value": PYSLVS_DE_S, "source": "issue 26 (pyslvs's own four-bar test problem, "
                                                               "2 cores; pyslvs not installed here)"},
           "machine": {"cpus": len(os.sched_getaffinity(0)), "platform": platform.platform(), "loadavg": load},
           "rows": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
