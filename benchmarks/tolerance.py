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

- against pylinkage 1.3's tolerance analysis (`pylinkage.linkage.analyze_tolerance`: a uniform
  Monte Carlo in a Python loop, one `Linkage.step` simulation per sample, unassemblable samples
  skipped) on the same four-bar (four-bar-sketch: crank, coupler, rocker and the coupler point's
  distance A→P each uniform ±0.05 mm — the parameters pylinkage can tolerance), the same number of
  samples and 360 positions; jaxlink's Monte Carlo warm (compiled) with its whole-cycle
  feasibility and streamed statistics; the two nominal paths compared (pylinkage records from
  the crank's first step, jaxlink's position 1). Interleaved: jaxlink, pylinkage, jaxlink; the
  ratio against the mean of the two jaxlink runs; the 1-minute load average recorded;
- streamed in flat memory (`--stream N1,N2,…`): each Monte Carlo of N samples in its own
  subprocess, its peak resident memory (`ru_maxrss`) after the compile and at the end.

Prints a table and writes benchmarks/results/latest/tolerance.json. Run:
`python benchmarks/tolerance.py [--samples N] [--designs N] [--pylinkage-samples N] [--stream N,…]`.
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
    st.tolerance(mech, study=study, samples=0)  # compile the true worst case's search too
    times, with_worst = [], []
    for _ in range(7):  # the first-order report alone (the goal's), then with the true worst case
        t = time.perf_counter()
        st.tolerance(mech, study=study, samples=0, worst=False)
        times.append(time.perf_counter() - t)
        t = time.perf_counter()
        st.tolerance(mech, study=study, samples=0)
        with_worst.append(time.perf_counter() - t)
    out = {"case": name, "parameters": len(inputs.parameters), "positions": 360, "responses": len(first.sigma_rss),
           "first_order_cold_s": cold_first, "first_order_warm_s": statistics.median(times),
           "with_worst_case_warm_s": statistics.median(with_worst)}
    if samples:
        study.monte_carlo(study.chunk, first)  # compile
        t = time.perf_counter()
        mc = study.monte_carlo(samples, first)
        dt = time.perf_counter() - t
        out.update(mc_samples=samples, mc_s=dt, mc_samples_per_s=samples / dt, mc_infeasible=mc.infeasible,
                   chunk=study.chunk)
    return out


PYL_TOLERANCES = {"crank": "crank_radius", "coupler": "rocker_dist1", "rocker": "rocker_dist2",
                  "coupler_P": "P_radius"}


def pylinkage_four_bar():
    """The four-bar-sketch scene in pylinkage 1.3 (its joints named so that the tolerances'
    names are crank_radius, rocker_dist1, rocker_dist2, P_radius)."""
    import math

    import pylinkage as pl

    a0, b0, a, b, p = (0.0, 0.0), (55.0, 0.0), (20.0, 0.0), (60.0, 44.721359549995796), (28.81966011250105,
                                                                                       32.3606797749979)
    o1, o2 = pl.Ground(*a0, name="A0"), pl.Ground(*b0, name="B0")
    crank = pl.Crank(anchor=o1, radius=20.0, angular_velocity=2 * math.pi / 360, initial_angle=0.0, name="crank")
    rocker = pl.RRRDyad(crank.output, o2, distance1=60.0, distance2=45.0, x=b[0], y=b[1], name="rocker")
    angle = math.atan2(p[1] - a[1], p[0] - a[0]) - math.atan2(b[1] - a[1], b[0] - a[0])
    point = pl.FixedDyad(crank.output, rocker, distance=math.hypot(p[0] - a[0], p[1] - a[1]), angle=angle, name="P")
    return pl.Linkage([o1, o2, crank, rocker, point])


def run_pylinkage(samples: int) -> dict:
    """jaxlink's Monte Carlo against pylinkage's `analyze_tolerance` (see the module doc)."""
    import numpy as np

    try:
        from pylinkage.linkage import analyze_tolerance
    except ImportError:
        print("pylinkage is not installed: its tolerance analysis is skipped (pip install -e '.[bench]')")
        return {}
    mech = jl.load("four-bar-sketch")
    tol = {p: {"tol": 0.05, "distribution": "uniform"} for p in PYL_TOLERANCES}
    inputs = st.read_study(mech, {"positions": 360, "points": ["P"], "metrics": ["deviation"], "samples": samples,
                                  "tolerances": tol})
    t = time.perf_counter()
    study = st.Study(mech, inputs)
    first = study.first_order()
    study.monte_carlo(samples, first)
    cold = time.perf_counter() - t

    def jaxlink_mc():
        t = time.perf_counter()
        mc = study.monte_carlo(samples, first)
        return time.perf_counter() - t, mc

    lk = pylinkage_four_bar()
    tols = {PYL_TOLERANCES[p]: 0.05 for p in PYL_TOLERANCES}
    analyze_tolerance(lk, tols, iterations=360, n_samples=2, seed=1)  # warm its simulation path
    j1, mc = jaxlink_mc()
    load = [os.getloadavg()[0]]
    t = time.perf_counter()
    res = analyze_tolerance(lk, tols, iterations=360, n_samples=samples, seed=1)
    pyl = time.perf_counter() - t
    load.append(os.getloadavg()[0])
    j2, _ = jaxlink_mc()
    load.append(os.getloadavg()[0])
    warm = 0.5 * (j1 + j2)
    nominal = study.nominal()[0]
    path = np.stack([np.roll(nominal[:360], -1), np.roll(nominal[360:720], -1)], axis=1)  # from position 1
    return {"case": "four-bar-sketch P path", "samples": samples, "positions": 360,
            "toleranced": list(PYL_TOLERANCES), "half_width_mm": 0.05, "distribution": "uniform",
            "jaxlink_cold_s": cold, "jaxlink_warm_s": [j1, j2], "jaxlink_samples_per_s": samples / warm,
            "jaxlink_infeasible": mc.infeasible, "pylinkage_s": pyl, "pylinkage_samples_per_s": samples / pyl,
            "pylinkage_kept": int(res.output_cloud.shape[0]), "ratio_warm": pyl / warm, "ratio_cold": pyl / cold,
            "nominal_path_difference_mm": float(np.abs(path - res.nominal_path).max()),
            "jaxlink_max_deviation_mm": float(mc.deviation_max[0]),
            "pylinkage_max_mean_deviation_mm": res.max_deviation, "load_1min": load}


def run_stream(samples: int) -> dict:
    """One Monte Carlo of `samples` in this process: its peak resident memory after compiling and
    at the end (`ru_maxrss`, KiB on Linux), and the time."""
    import resource

    mech = jl.load("four-bar-sketch")
    tol = {p: 0.05 for p in mech.parameter_names}
    inputs = st.read_study(mech, {"positions": 360, "points": ["P"], "metrics": ["deviation"], "samples": samples,
                                  "tolerances": tol})
    study = st.Study(mech, inputs)
    first = study.first_order()
    study.monte_carlo(study.chunk, first)  # compile
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t = time.perf_counter()
    mc = study.monte_carlo(samples, first)
    dt = time.perf_counter() - t
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    try:  # GPU/TPU: the device's own peak (None on the CPU)
        dev_peak = int(jax.devices()[0].memory_stats()["peak_bytes_in_use"]) / 2**20
    except Exception:
        dev_peak = None
    return {"samples": samples, "peak_device_mib": dev_peak, "device": str(jax.devices()[0].device_kind),
            "seconds": dt, "samples_per_s": samples / dt, "peak_rss_after_compile_mib": rss0 / 1024,
            "peak_rss_end_mib": rss1 / 1024, "feasible": mc.feasible, "chunk": study.chunk,
            "load_1min": os.getloadavg()[0]}


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
    ap.add_argument("--pylinkage-samples", type=int, default=2048,
                    help="samples of the comparison with pylinkage's tolerance analysis (0: skip)")
    ap.add_argument("--stream", default="", help="comma-separated sample counts: the flat-memory runs (1e6,1e7)")
    ap.add_argument("--stream-only", action="store_true", help="only the --stream runs")
    ap.add_argument("--stream-timeout", type=float, default=None, help="seconds allowed each --stream run")
    ap.add_argument("--json", default=None, help="where to write the JSON (default benchmarks/results/latest/)")
    ap.add_argument("--stream-one", type=float, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.stream_one is not None:  # a subprocess of --stream
        print(json.dumps(run_stream(int(args.stream_one))))
        return
    only = args.robust_only or args.stream_only
    rows = [] if only else [run_case("four-bar-sketch", args.samples), run_case("sewing-feed", 0)]
    pyl = run_pylinkage(args.pylinkage_samples) if args.pylinkage_samples and not only else {}
    stream = []
    for n in filter(None, args.stream.split(",")):
        import subprocess
        import sys

        try:
            out = subprocess.run([sys.executable, __file__, "--stream-one", n], capture_output=True, text=True,
                                 check=True, timeout=args.stream_timeout)
        except subprocess.TimeoutExpired:
            print(f"stream {float(n):.0e} samples: not finished in {args.stream_timeout} s", flush=True)
            stream.append({"samples": int(float(n)), "error": "timeout", "timeout_s": args.stream_timeout})
            continue
        stream.append(json.loads(out.stdout.strip().splitlines()[-1]))
        r = stream[-1]
        print(f"stream {r['samples']:.0e} samples: {r['samples_per_s']:.0f}/s, "
              f"peak RSS {r['peak_rss_end_mib']:.0f} MiB, device peak {r['peak_device_mib']} MiB", flush=True)
    robust = [run_robust(name, args.designs) for name in ROBUST_CASES] if args.designs and not args.stream_only else []
    print(f"{'case':<16} {'T':>3} {'M':>6} {'1st order cold s':>17} {'warm s':>8} {'+worst s':>9} {'MC samples/s':>13}")
    for r in rows:
        mc = f"{r['mc_samples_per_s']:13.0f}" if "mc_samples_per_s" in r else f"{'–':>13}"
        print(f"{r['case']:<16} {r['parameters']:>3} {r['responses']:>6} {r['first_order_cold_s']:17.2f} "
              f"{r['first_order_warm_s']:8.4f} {r['with_worst_case_warm_s']:9.4f} {mc}")
    if pyl:
        print(f"\nMonte Carlo of {pyl['samples']} samples × 360 positions, four lengths uniform ±0.05 mm: jaxlink "
              f"{pyl['jaxlink_samples_per_s']:.0f} samples/s warm, pylinkage analyze_tolerance "
              f"{pyl['pylinkage_samples_per_s']:.0f} samples/s: {pyl['ratio_warm']:.0f}× warm, "
              f"{pyl['ratio_cold']:.1f}× cold; nominal paths differ by {pyl['nominal_path_difference_mm']:.1e} mm; "
              f"load {pyl['load_1min']}")
    for r in (r for r in stream if "error" not in r):
        print(f"stream {r['samples']:.0e} samples: {r['samples_per_s']:.0f}/s, peak RSS "
              f"{r['peak_rss_after_compile_mib']:.0f} MiB after compile, {r['peak_rss_end_mib']:.0f} MiB at the end")
    if robust:
        print(f"\n{'robust map':<16} {'designs':>8} {'T':>3} {'cold s':>8} {'warm s':>8} {'of it robust s':>15} "
              f"{'check rel.':>11}")
        for r in robust:
            print(f"{r['case']:<16} {r['designs']:>8} {r['parameters']:>3} {r['robust_cold_s']:8.2f} "
                  f"{r['robust_warm_s']:8.2f} {r['robust_only_warm_s']:15.2f} "
                  f"{r['check_max_relative_difference']:11.1e}")
    out = pathlib.Path(args.json or pathlib.Path(__file__).parent / "results" / "latest" / "tolerance.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"machine": platform.machine(), "cpus": os.cpu_count(), "jax": jax.__version__,
            "device": str(jax.devices()[0])}
    out.write_text(json.dumps({"meta": meta, "rows": rows, "robust": robust, "pylinkage": pyl, "stream": stream},
                              indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
