"""Morris, regression and DGSM speed (issue 25) on a 720-output path, beside SALib's Morris.

The four-bar-sketch scene, its coupler point P's x and y at 360 positions (720 outputs), four
lengths varied over ±5 % (as benchmarks/sensitivity.py):

- `jaxlink.study.morris` with r = 256 trajectories (1280 designs), `regression` with n = 4096
  designs, `dgsm` with n = 1024 designs and their exact Jacobians — each end to end, cold (built
  and compiled in the run) and warm (again);
- baseline: SALib's `morris.analyze` once per output column on jaxlink's own responses at the
  same trajectories (the model's time not counted); its μ, μ*, σ must equal jaxlink's.

Writes benchmarks/results/latest/screening.json. Run: `python benchmarks/screening.py [--columns K]`
(SALib on the first K columns, its time scaled to 720; default 72).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxlink as jl  # noqa: E402
from jaxlink import study as st  # noqa: E402

RANGES = {"crank": [19.0, 21.0], "coupler": [57.0, 63.0], "rocker": [42.75, 47.25], "B0_x": [52.25, 57.75]}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--columns", type=int, default=72)
    args = ap.parse_args()
    mech = jl.load("four-bar-sketch")
    out: dict = {"machine": platform.machine(), "cpus": os.cpu_count(), "outputs": 720}
    base = {"positions": 360, "points": ["P"], "metrics": [], "ranges": RANGES, "bootstrap": 100}
    study = None
    reps = {}
    for method, n in (("morris", 256), ("regression", 4096), ("dgsm", 1024)):
        inputs = st.read_study(mech, dict(base, method=method, samples=n))
        times = []
        for _ in range(2):
            t0 = time.perf_counter()
            s = st.Study(mech, inputs) if study is None else study.moved(inputs=inputs)
            rep = getattr(st, method)(mech, study=s)
            times.append(time.perf_counter() - t0)
            study = s
        reps[method] = rep
        designs = n * 5 if method == "morris" else n
        out[method] = {"samples": n, "designs": designs, "cold_s": round(times[0], 3), "warm_s": round(times[1], 3),
                       "designs_per_s_warm": round(designs / times[1])}
        print(f"{method:<10} n = {n:5d} ({designs} designs): cold {times[0]:.2f} s, warm {times[1]:.3f} s")
    try:
        from SALib.analyze import morris as sm
    except ImportError:
        print("SALib not installed: no baseline")
    else:
        m = reps["morris"]
        groups = [np.asarray([j]) for j in range(4)]
        u, order, sign = st.trajectories(groups, 256, 4, 0)
        x = st.box_values(m.inputs, study.x0, u.reshape(-1, 4))
        y, ok, _ = st.evaluate(st.Study(mech, m.inputs), x)
        problem = {"num_vars": 4, "names": list(RANGES), "bounds": list(RANGES.values())}
        k = min(args.columns, 720)
        t0 = time.perf_counter()
        worst = 0.0
        for c in range(k):
            s = sm.analyze(problem, x, y[:, c], num_levels=4, num_resamples=100, seed=1)
            worst = max(worst, float(np.max(np.abs(s["mu_star"] - m.indices.mu_star[c]))))
        t = (time.perf_counter() - t0) * 720 / k
        out["salib_morris_analyze_720_s"] = round(t, 3)
        out["salib_mu_star_max_abs_difference"] = worst
        out["ratio_salib_analyze_over_jaxlink_warm"] = round(t / out["morris"]["warm_s"], 1)
        print(f"SALib morris.analyze × 720 outputs: {t:.2f} s (model not counted); jaxlink Morris end to end warm "
              f"{out['morris']['warm_s']:.3f} s: {t / out['morris']['warm_s']:.1f}×; max |Δμ*| {worst:.2e}")
    d = pathlib.Path(__file__).resolve().parent / "results" / "latest"
    d.mkdir(parents=True, exist_ok=True)
    (d / "screening.json").write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
