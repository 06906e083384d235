"""Every jaxlink benchmark in one command; results in `benchmarks/results/` (JSON + PNG) and a
Markdown summary `benchmarks/results/SUMMARY.md`.

Runs, each as a subprocess (so one failure does not stop the rest, and each has its own process
for timing and memory):

- `throughput.py` — feed six-bar positions/s vs scipy fsolve, numpy batched Newton, hand kernel;
- `gradient_cost.py` — implicit gradient vs forward solve vs finite differences;
- optimizer evaluations per second — `jaxlink optimize --method montecarlo` on the literature
  four-bar case mkh1 against pylinkage's PSO objective (its own simulated path, 360 steps) on
  the same case (`experiments/literature_paths.py`), same run;
- `fourbar_vs_pylinkage.py` — four-bar + coupler point vs pylinkage's numba solver;
- `error_vs_runtime.py` — error against run time for every accuracy knob (+ PNG);
- `scaling.py` — batch size 1e2…1e6, 1 vs 2 host devices, peak memory.

Not in the suite (run on their own): `accelerator.py` (batch scaling to 1e8 positions, memory,
gradient/forward, Monte Carlo designs/s on whatever device JAX finds: meant for a GPU) and
`system.py` (command latency cold/warm with the compilation cache; a 3e6-design Monte Carlo
search's peak memory and rate against the raw solve rate).

    python benchmarks/suite.py [--quick] [--only NAME,...]

`--quick` (smaller batches, fewer repeats and settings) finishes in under 5 minutes on 2 cores and
writes to `benchmarks/results/quick/` instead.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
RES = os.path.join(HERE, "results", "latest")  # untracked; --update writes the recorded results/
PY = sys.executable


def sh(args, timeout=1800):
    t = time.perf_counter()
    r = subprocess.run(args, capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    return r.returncode, r.stdout, r.stderr, time.perf_counter() - t


OPT_CHILD = r"""
import json, math, sys, time
import numpy as np
sys.path.insert(0, sys.argv[1])
import jax
jax.config.update("jax_enable_x64", True)
from literature_paths import pylinkage_objective, CASES_DIR
from jaxlink import load
from jaxlink.optimize import problem_from
n = int(sys.argv[2])
pr = problem_from(load(CASES_DIR / "mkh1.toml"))
one, evals = pylinkage_objective(pr, 360)
rng = np.random.default_rng(0)
lo, hi = np.append(pr.lower, 0.0), np.append(pr.upper, 1.0)
X = lo + (hi - lo) * rng.uniform(size=(n, len(lo)))
one(X[0])
t = time.perf_counter(); v = np.array([one(x) for x in X]); dt = time.perf_counter() - t
print(json.dumps({"evaluations": n, "seconds": dt, "evals_per_s": n / dt,
                  "unbuildable_fraction": float(np.mean(v >= 1e9))}))
"""


def optimizer_rates(quick):
    """jaxlink's batched evaluator (through the CLI) vs pylinkage's objective, designs/s."""
    out = {}
    budget = 20000 if quick else 200000
    case = os.path.join(ROOT, "experiments", "fourbar_cases", "mkh1.toml")
    import tempfile

    tmp = tempfile.mkdtemp(prefix="jaxlink_suite_")  # the optimizer's checkpoint files stay out of results/
    js = os.path.join(tmp, "optimize_mkh1.json")
    jaxlink_bin = os.path.join(os.path.dirname(PY), "jaxlink")
    rc, so, se, wall = sh([jaxlink_bin, "optimize", case, "--method", "montecarlo", "--budget", str(budget),
                           "--seed", "0", "--out", js])
    if rc == 0 and os.path.exists(js):
        r = json.load(open(js))
        out["jaxlink"] = {"evaluations": r.get("evaluations"), "wall_s": r.get("wall_s"), "process_s": wall,
                          "evals_per_s": r["evaluations"] / r["wall_s"],
                          "infeasible_fraction": r.get("infeasible_fraction")}
    else:
        out["jaxlink"] = {"error": (se or so).strip().splitlines()[-3:]}
    import shutil

    shutil.rmtree(tmp, ignore_errors=True)
    try:
        import pylinkage  # noqa: F401

        rc, so, se, _ = sh([PY, "-c", OPT_CHILD, os.path.join(ROOT, "experiments"), "300" if quick else "2000"])
        out["pylinkage"] = (json.loads(so.strip().splitlines()[-1]) if rc == 0
                            else {"error": se.strip().splitlines()[-3:]})
    except ImportError:
        out["pylinkage"] = {"error": "pylinkage not installed"}
    if "evals_per_s" in out["jaxlink"] and "evals_per_s" in out.get("pylinkage", {}):
        out["ratio"] = out["jaxlink"]["evals_per_s"] / out["pylinkage"]["evals_per_s"]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="under 5 minutes on 2 cores")
    ap.add_argument("--update", action="store_true",
                    help="write the recorded results (benchmarks/results/, quoted by the docs) instead of "
                         "benchmarks/results/latest/ (untracked)")
    ap.add_argument("--only", default=None, help="comma-separated: throughput,gradient,optimizer,fourbar,error,scaling")
    args = ap.parse_args(argv)
    global RES
    if args.update:
        RES = os.path.join(HERE, "results")
        os.environ["JAXLINK_BENCH_UPDATE"] = "1"
    if args.quick:  # quick results go to their own folder: they never overwrite the full ones
        RES = os.path.join(RES, "quick")
    os.makedirs(RES, exist_ok=True)
    q = ["--quick"] if args.quick else []
    want = set((args.only or "throughput,gradient,optimizer,fourbar,error,scaling").split(","))
    t0 = time.perf_counter()
    status = {}

    def script(name, file, extra):
        if name not in want:
            return
        print(f"== {name}: {file} {' '.join(q + extra)}", flush=True)
        rc, so, se, wall = sh([PY, os.path.join(HERE, file)] + q + extra)
        print(so[-3000:])
        if rc != 0:
            print(se[-2000:])
        status[name] = {"returncode": rc, "wall_s": wall}

    script("throughput", "throughput.py", ["--json", os.path.join(RES, "throughput.json")])
    script("gradient", "gradient_cost.py", ["--json", os.path.join(RES, "gradient_cost.json")])
    if "optimizer" in want:
        print("== optimizer evaluations per second (mkh1)", flush=True)
        t = time.perf_counter()
        opt = optimizer_rates(args.quick)
        json.dump(opt, open(os.path.join(RES, "optimizer_rate.json"), "w"), indent=1)
        print(json.dumps(opt, indent=1))
        status["optimizer"] = {"returncode": 0, "wall_s": time.perf_counter() - t}
    script("fourbar", "fourbar_vs_pylinkage.py", ["--json", os.path.join(RES, "fourbar_vs_pylinkage.json")])
    script("error", "error_vs_runtime.py", ["--json", os.path.join(RES, "error_vs_runtime.json"),
                                           "--png", os.path.join(RES, "error_vs_runtime.png")])
    script("scaling", "scaling.py", ["--json", os.path.join(RES, "scaling.json")])
    wall = time.perf_counter() - t0

    def load(name):
        p = os.path.join(RES, name)
        return json.load(open(p)) if os.path.exists(p) else {}

    ran = ""
    if args.only:  # a partial update keeps the other benchmarks' runs (their JSON files stay too)
        status = {**load("suite.json").get("status", {}), **status}
        ran = f" (this update re-ran {args.only} in {wall:.0f} s)"
        wall = sum(v["wall_s"] for v in status.values())

    tp, gc, fb, ev, sc, op = (load(n) for n in ("throughput.json", "gradient_cost.json", "fourbar_vs_pylinkage.json",
                                                 "error_vs_runtime.json", "scaling.json", "optimizer_rate.json"))
    L = [f"# jaxlink benchmark summary ({'quick' if args.quick else 'full'})", "",
         f"{os.cpu_count()} cores, {platform.platform()}; suite wall time {wall:.0f} s{ran}. "
         "Ratios are against baselines measured in the same run (each script's own run).", ""]
    if tp:
        L += ["## Throughput, feed six-bar (`throughput.json`)", "",
              "| variant | positions/s | max abs ΔZ, m |", "|---|---|---|",
              f"| jaxlink float64 (auto) | {tp['positions_per_s']:.3g} | {tp['max_abs_error_m']:.1e} |",
              f"| jaxlink float32 (auto) | {tp['positions_per_s_f32']:.3g} | {tp['max_abs_error_m_f32']:.1e} |",
              f"| jaxlink continuation float64 | {tp['continuation_positions_per_s']:.3g} | "
              f"{tp['continuation_max_abs_error_m']:.1e} |",
              f"| numpy batched Newton | {tp['numpy_positions_per_s']:.3g} | {tp['numpy_max_abs_error_m']:.1e} |",
              f"| scipy fsolve loop | {tp['fsolve_positions_per_s']:.3g} | {tp['fsolve_max_abs_error_m']:.1e} |",
              f"| hand-written JAX kernel (feed only) | {tp['handwritten_positions_per_s']:.3g} | |"]
        if "positions_per_s_1core" in tp:
            L += [f"| jaxlink float64 (auto), pinned to 1 core | {tp['positions_per_s_1core']:.3g} | |",
                  f"| jaxlink float32 (auto), pinned to 1 core | {tp['positions_per_s_f32_1core']:.3g} | |",
                  f"| hand-written JAX kernel, pinned to 1 core | {tp['handwritten_positions_per_s_1core']:.3g} | |"]
        L += ["", f"float64 = **{tp['ratio_vs_numpy']:.1f}×** numpy batched Newton (goal ≥ 15×), "
              f"{tp['ratio_vs_fsolve']:.0f}× fsolve, {tp['ratio_vs_handwritten']:.2f}× the hand-written kernel"
              + (f"; pinned to one core (numpy and fsolve use one) {tp['ratio_vs_numpy_1core']:.1f}× numpy"
                 if "ratio_vs_numpy_1core" in tp else "") + ".", ""]
    if fb:
        L += ["## Four-bar + coupler point vs pylinkage (`fourbar_vs_pylinkage.json`)", ""]
        if "pylinkage_core_positions_per_s" in fb:
            L += ["| solver | positions/s | max abs ΔP, m |", "|---|---|---|",
                  f"| pylinkage {fb.get('pylinkage_version', '')} `step_fast`, 1 design | "
                  f"{fb['pylinkage_step_fast_positions_per_s']:.3g} | |",
                  f"| pylinkage numba core, loop over designs | {fb['pylinkage_core_positions_per_s']:.3g} | "
                  f"{fb['pylinkage_max_abs_error_m']:.1e} |",
                  f"| jaxlink float64 | {fb['jaxlink_float64_positions_per_s']:.3g} | "
                  f"{fb['jaxlink_float64_max_abs_error_m']:.1e} |",
                  f"| jaxlink float32 | {fb['jaxlink_float32_positions_per_s']:.3g} | "
                  f"{fb['jaxlink_float32_max_abs_error_m']:.1e} |", "",
                  *([f"One design × {fb['steps']} positions per `jl.solve` call, 200 calls in a row: "
                     f"{fb['jaxlink_single_design_call_ms']:.3f} ms per call = "
                     f"**{fb['ratio_single_design_vs_step_fast']:.2f}×** pylinkage's `step_fast` with every "
                     f"result kept, {fb['jaxlink_single_design_call_ms_dropped']:.3f} ms = "
                     f"**{fb['ratio_single_design_vs_step_fast_dropped']:.2f}×** with each dropped (goal ≥ 1×).",
                     ""] if "ratio_single_design_vs_step_fast_dropped" in fb else []),
                  f"jaxlink float64 = **{fb['ratio_float64_vs_pylinkage_core']:.2f}×** pylinkage's numba core "
                  f"(goal ≥ 2×)"
                  + (f"; pinned to one core like pylinkage: **{fb['ratio_float64_1core_vs_pylinkage_core']:.2f}×**"
                     if "ratio_float64_1core_vs_pylinkage_core" in fb else "") + ".", ""]
        else:
            L += ["pylinkage not installed.", ""]
    if gc:
        L += ["## Gradient cost (`gradient_cost.json`)", "",
              f"{gc['designs']} designs × 72 angles, 11 parameters: gradient (implicit) = "
              f"{gc['grad_over_forward']:.2f}× the objective's value with the points from the solve"
              + (f" ({gc['grad_over_solve']:.2f}× the forward solve)" if "grad_over_solve" in gc else "")
              + (f", {gc['transfer_grad_over_forward']:.2f}× with the points by `transfer`"
                 if "transfer_grad_over_forward" in gc else "")
              + f"; central differences {gc['fd_over_forward']:.1f}×; "
              f"max relative difference {gc['grad_vs_fd_max_rel_diff']:.1e}.", ""]
    if op:
        L += ["## Optimizer evaluations per second (`optimizer_rate.json`, case mkh1)", ""]
        for k in ("jaxlink", "pylinkage"):
            v = op.get(k, {})
            L.append(f"- {k}: " + (f"{v['evals_per_s']:.4g} designs/s" if "evals_per_s" in v else str(v.get("error"))))
        if "ratio" in op:
            L.append(f"- ratio: **{op['ratio']:.0f}×**")
        L.append("")
    if ev:
        L += ["## Error against run time (`error_vs_runtime.json`, `error_vs_runtime.png`)", "",
              "| knob | setting | error | seconds | Pareto |", "|---|---|---|---|---|"]
        for c in ev["cases"]:
            L.append(f"| {c['knob']} | {c['setting']}{' (default)' if c['default'] else ''} | {c['error']:.2e} | "
                     f"{c['seconds']:.4g} | {'yes' if c['pareto'] else 'no'} |")
        L += ["", f"Defaults on their front: {', '.join(ev['defaults_on_front']) or '-'}; "
              f"not: {', '.join(ev['defaults_off_front']) or '-'}.", ""]
    if sc:
        L += ["## Scaling (`scaling.json`)", "", "| positions | devices | positions/s | peak RSS MB |",
              "|---|---|---|---|"]
        for r in sc["rows"]:
            if "error" not in r:
                L.append(f"| {r['positions']} | {r['devices']} | {r['positions_per_s']:.3g} | {r['peak_rss_mb']:.0f} |")
        if "two_device_speedup_at_largest" in sc:
            L += ["", f"2 devices / 1 at the largest batch: {sc['two_device_speedup_at_largest']:.2f}×."]
        L.append("")
    L += ["## Runs", "", "| benchmark | exit | wall s |", "|---|---|---|"]
    L += [f"| {k} | {v['returncode']} | {v['wall_s']:.0f} |" for k, v in status.items()]
    name = "SUMMARY.md"
    with open(os.path.join(RES, name), "w") as fh:
        fh.write("\n".join(L) + "\n")
    json.dump({"status": status, "wall_s": wall, "quick": args.quick},
              open(os.path.join(RES, "suite.json"), "w"), indent=1)
    print(f"suite done in {wall:.0f} s; wrote {os.path.join(RES, name)}")
    return 0 if all(v["returncode"] == 0 for v in status.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
