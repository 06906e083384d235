"""Tolerance study speed (issue 25): the full-cycle first-order report and Monte Carlo throughput.

- first order: the exact Jacobian of every point's x, y at 360 positions (and the stroke/swing
  metrics) with respect to every toleranced parameter, and σ_RSS, the linear worst case and the
  importance factors from it — warm (compiled), median of 7 calls; goal ≤ 0.2 s for ≤ 20
  parameters × 360 positions;
- Monte Carlo: samples per second of the four-bar over 360 positions, warm, every sample's
  whole-cycle feasibility included (screen, certificate where needed) and the statistics streamed
  (moments, extremes, histograms); goal ≥ 1e4 samples/s.

- robust-design map: the full first-order report (σ_RSS, linear worst case of every response at
  every position, reduced per design, `jaxlink.study.robust`) at every design of a 100 × 100 grid
  over two ranges (10⁴ designs), every parameter toleranced (≤ 20 × 360 positions); cold (compile
  included) and warm; goal ≤ 10 s. One design is checked against the single-design tolerance
  report (`tolerance`, the same design as the nominal): the largest relative difference of its
  columns, goal ≤ 1e-12.

Prints a table and writes benchmarks/results/latest/tolerance.json. Run:
`python benchmarks/tolerance.py [--samples N] [--designs N]`.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import jaxlink as jl  # noqa: E402
from jaxlink import study as st  # noqa: E402


def run_case(name: str, samples: int) -> dict:
    mech = jl.load(name)
    # every parameter (at most 20) made to ±0.05 in its file unit (mm or deg), normal with ±t = 3σ
    tol = {p: 0.05 for p in mech.parameter_names[:20]}
    inputs = st.read_study(mech, {"positions": 360, "samples": samples, "metrics": ["stroke"],
                                  "tolerances": tol})
    t0 = time.perf_counter()
    study = st.Study(mech, inputs)
    first = study.first_order()
    cold_first = time.perf_counter() - t0
    times = []
    for _ in range(7):
        t = time.perf_counter()
        st.tolerance(mech, study=study, samples=0)
        times.append(time.perf_counter() - t)
    out = {"case": name, "parameters": len(inputs.parameters), "positions": 360, "responses": len(first.sigma_rss),
           "first_order_cold_s": cold_first, "first_order_warm_s": statistics.median(times)}
    if samples:
        study.monte_carlo(study.chunk, first)  # compile
        t = time.perf_counter()
        mc = study.monte_carlo(samples, first)
        dt = time.perf_counter() - t
        out.update(mc_samples=samples, mc_s=dt, mc_samples_per_s=samples / dt, mc_infeasible=mc.infeasible,
                   chunk=study.chunk)
    return out


ROBUST_CASES = {"four-bar-sketch": ("crank", (18.0, 22.0), "rocker", (42.0, 48.0)),
                "sewing-feed-opt": ("l2", (1.5, 2.7), "gamma", (-10.0, 14.0))}


def run_robust(name: str, designs: int) -> dict:
    """The robust-design map of scene `name` over a √designs × √designs grid (see the module doc)."""
    import math

    import numpy as np

    mech = jl.load(name)
    a, (alo, ahi), b, (blo, bhi) = ROBUST_CASES[name]
    side = int(round(math.sqrt(designs)))
    tol = {p: 0.05 for p in mech.parameter_names[:20]}
    levels = {p: 1 for p in (a, b)}
    levels.update({a: side, b: side})
    ranges = {a: [alo, ahi], b: [blo, bhi]}
    inputs = st.read_study(mech, {"method": "grid", "positions": 360, "metrics": ["stroke"], "tolerances": tol,
                                  "ranges": ranges, "levels": levels, "robust": True})
    t0 = time.perf_counter()
    study = st.Study(mech, inputs)
    small = inputs._replace(ranges=tuple(r._replace(levels=2) for r in inputs.ranges))
    st.sample(mech, grid=True, study=study.moved(inputs=small))  # compile the batch and the robust map
    cold = time.perf_counter() - t0
    t = time.perf_counter()
    rep = st.sample(mech, grid=True, study=study)
    warm = time.perf_counter() - t
    rob = rep.robust
    # one design against the single-design tolerance report
    i = int(np.flatnonzero(rep.feasible)[len(np.flatnonzero(rep.feasible)) // 3])
    tin = st.read_study(mech, {"positions": 360, "metrics": ["stroke"], "samples": 0, "tolerances": tol})
    one_study = st.Study(mech, tin)
    x0 = one_study.x0.copy()
    for j, p in enumerate(inputs.parameters):
        x0[list(tin.parameters).index(p)] = rep.values[i, j]
    one = st.tolerance(mech, study=one_study.moved(x0=x0), samples=0, worst=False)
    f = one.first_order
    ref = {}
    for k, (nm, _u, pos) in enumerate(one.labels):
        if pos is None:
            ref[f"sigma_rss({nm})"], ref[f"worst_case_linear({nm})"] = f.sigma_rss[k], f.worst_case[k]
    for j, p in enumerate(tin.points):
        for c in ("x", "y"):
            rows = [k for k, lab in enumerate(one.labels) if lab[0] == f"{p}.{c}"]
            ref[f"sigma_rss({p}.{c})"] = f.sigma_rss[rows].max()
            ref[f"worst_case_linear({p}.{c})"] = f.worst_case[rows].max()
        ref[f"worst_case_linear({p})"] = one.deviation_bound[j]
    col = {nm: j for j, (nm, _u) in enumerate(rob.labels)}
    rel = max(abs(rob.values[i, col[k]] - v) / max(abs(v), 1e-300) for k, v in ref.items())
    return {"case": name, "designs": len(rep.feasible), "feasible": int(rep.feasible.sum()),
            "parameters": len(tin.parameters), "positions": 360, "ranges": [a, b], "robust_cold_s": cold,
            "robust_warm_s": warm, "robust_only_warm_s": rep.timings["robust"],
            "evaluate_warm_s": rep.timings["evaluate"],
            "robust_batch": int(st.robust.robust_evaluator(study).chunk), "check_design": i,
            "check_max_relative_difference": float(rel), "columns_checked": len(ref)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=32768)
    ap.add_argument("--designs", type=int, default=10000, help="robust-design map: designs of the grid")
    ap.add_argument("--robust-only", action="store_true", help="only the robust-design map")
    args = ap.parse_args()
    rows = [] if args.robust_only else [run_case("four-bar-sketch", args.samples), run_case("sewing-feed", 0)]
    robust = [run_robust(name, args.designs) for name in ROBUST_CASES] if args.designs else []
    print(f"{'case':<16} {'T':>3} {'M':>6} {'1st order cold s':>17} {'warm s':>8} {'MC samples/s':>13}")
    for r in rows:
        mc = f"{r['mc_samples_per_s']:13.0f}" if "mc_samples_per_s" in r else f"{'–':>13}"
        print(f"{r['case']:<16} {r['parameters']:>3} {r['responses']:>6} {r['first_order_cold_s']:17.2f} "
              f"{r['first_order_warm_s']:8.4f} {mc}")
    if robust:
        print(f"\n{'robust map':<16} {'designs':>8} {'T':>3} {'cold s':>8} {'warm s':>8} {'of it robust s':>15} "
              f"{'check rel.':>11}")
        for r in robust:
            print(f"{r['case']:<16} {r['designs']:>8} {r['parameters']:>3} {r['robust_cold_s']:8.2f} "
                  f"{r['robust_warm_s']:8.2f} {r['robust_only_warm_s']:15.2f} "
                  f"{r['check_max_relative_difference']:11.1e}")
    out = pathlib.Path(__file__).parent / "results" / "latest" / "tolerance.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"machine": platform.machine(), "cpus": os.cpu_count(), "jax": jax.__version__,
            "device": str(jax.devices()[0])}
    out.write_text(json.dumps({"meta": meta, "rows": rows, "robust": robust}, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
