"""Tolerance study speed (issue 25): the full-cycle first-order report and Monte Carlo throughput.

- first order: the exact Jacobian of every point's x, y at 360 positions (and the stroke/swing
  metrics) with respect to every toleranced parameter, and σ_RSS, the linear worst case and the
  importance factors from it — warm (compiled), median of 7 calls; goal ≤ 0.2 s for ≤ 20
  parameters × 360 positions;
- Monte Carlo: samples per second of the four-bar over 360 positions, warm, every sample's
  whole-cycle feasibility included (screen, certificate where needed) and the statistics streamed
  (moments, extremes, histograms); goal ≥ 1e4 samples/s.

Prints a table and writes benchmarks/results/latest/tolerance.json. Run:
`python benchmarks/tolerance.py [--samples N]`.
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=32768)
    args = ap.parse_args()
    rows = [run_case("four-bar-sketch", args.samples), run_case("sewing-feed", 0)]
    print(f"{'case':<16} {'T':>3} {'M':>6} {'1st order cold s':>17} {'warm s':>8} {'MC samples/s':>13}")
    for r in rows:
        mc = f"{r['mc_samples_per_s']:13.0f}" if "mc_samples_per_s" in r else f"{'–':>13}"
        print(f"{r['case']:<16} {r['parameters']:>3} {r['responses']:>6} {r['first_order_cold_s']:17.2f} "
              f"{r['first_order_warm_s']:8.4f} {mc}")
    out = pathlib.Path(__file__).parent / "results" / "latest" / "tolerance.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"machine": platform.machine(), "cpus": os.cpu_count(), "jax": jax.__version__,
            "device": str(jax.devices()[0])}
    out.write_text(json.dumps({"meta": meta, "rows": rows}, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
