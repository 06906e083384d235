"""Sobol' sensitivity speed (issue 25): indices with bootstrap intervals of a 720-output path.

The four-bar-sketch scene, its coupler point P's x and y at 360 positions (720 outputs), four
lengths varied over ±5 % (crank, coupler, rocker, B0_x), N = 4096 base samples of scrambled
Sobol' (N (D + 2) = 24 576 designs), S1 and ST of every output with 100 bootstrap resamples:

- jaxlink: `jaxlink.study.sensitivity` end to end — cold (the `Study` built and compiled in the
  run) and warm (the same study again); every design's whole-cycle feasibility included;
- baseline: the same designs evaluated by a numpy model of the same four-bar (the closed-form
  circle intersection, vectorized over designs and positions), then SALib's `sobol.analyze` once
  per output column (its API), with the same bootstrap draws — its indices must equal jaxlink's.

Prints a table and writes benchmarks/results/latest/sensitivity.json. Run:
`python benchmarks/sensitivity.py [--samples N] [--columns K]` (`--columns`: SALib on the first K
columns only, the time scaled to 720; default all). Skips the baseline with a message when SALib
is not installed (`pip install -e ".[bench]"`).
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


def numpy_four_bar(x, phi, q):
    """P.x, P.y (n, N) of the four-bar at designs x (n, 4: crank, coupler, rocker, B0_x), the other
    parameters `q` (coupler_P, coupler_P_angle in rad, A0_x, A0_y, B0_y) fixed: A on the crank, B the
    circles' intersection above A→B0 (the file's branch), P on the coupler plate."""
    a, b, c, bx = (x[:, k:k + 1] for k in range(4))
    p, gamma, ax0, ay0, by = q
    ax, ay = ax0 + a * np.cos(phi), ay0 + a * np.sin(phi)
    dx, dy = bx - ax, by - ay
    d = np.hypot(dx, dy)
    ex, ey = dx / d, dy / d
    ell = (b * b - c * c + d * d) / (2 * d)
    h = np.sqrt(np.maximum(b * b - ell * ell, 0.0))
    bxx, byy = ax + ell * ex - h * ey, ay + ell * ey + h * ex
    t = np.arctan2(byy - ay, bxx - ax) + gamma
    return ax + p * np.cos(t), ay + p * np.sin(t)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=4096)
    ap.add_argument("--columns", type=int, default=720)
    args = ap.parse_args()
    N = args.samples
    mech = jl.load("four-bar-sketch")
    table = {"method": "sensitivity", "positions": 360, "points": ["P"], "metrics": [], "samples": N, "seed": 1,
             "bootstrap": 100, "ranges": RANGES}
    inputs = st.read_study(mech, table)
    t = time.perf_counter()
    study = st.Study(mech, inputs)
    rep = st.sensitivity(mech, study=study)
    cold = time.perf_counter() - t
    t = time.perf_counter()
    rep = st.sensitivity(mech, study=study)
    warm = time.perf_counter() - t
    M = len(rep.labels)
    row = {"case": "four-bar-sketch P path", "outputs": M, "factors": 4, "samples": N, "designs": rep.evaluations,
           "bootstrap": 100, "jaxlink_cold_s": cold, "jaxlink_warm_s": warm, "jaxlink_timings_warm": rep.timings,
           "feasible_fraction": rep.feasible_fraction}
    try:
        from SALib.analyze import sobol as salib
    except ImportError:
        salib = None
        print("SALib is not installed: the baseline is skipped (pip install -e '.[bench]')")
    if salib is not None:
        # the same designs (the study's sampler and map), the same bootstrap draws
        T = 4
        u = np.concatenate(list(st.unit_blocks("sobol", 2 * T, N, 1)))
        a, b = st.to_values(inputs, study.x0, u[:, :T]), st.to_values(inputs, study.x0, u[:, T:])
        X = [a] + [np.where(np.arange(T) == j, b, a) for j in range(T)] + [b]  # SALib's order: A, AB_j, B
        names = mech.parameter_names
        pv = np.asarray(mech.parameters)
        lf = mech.units.length  # SI → file units (mm); the angle stays in rad
        q = (pv[names.index("coupler_P")] / lf, pv[names.index("coupler_P_angle")], pv[names.index("A0_x")] / lf,
             pv[names.index("A0_y")] / lf, pv[names.index("B0_y")] / lf)
        phi = np.deg2rad(rep.input_values)
        t = time.perf_counter()
        Y = np.stack([np.concatenate(numpy_four_bar(x, phi, q), axis=1) for x in X], axis=1)  # (N, D + 2, 720)
        model = time.perf_counter() - t
        nominal = np.concatenate(numpy_four_bar(study.x0[None], phi, q), axis=1)[0]
        model_error = float(np.abs(nominal - rep.nominal[:M]).max())
        problem = {"num_vars": T, "names": list(RANGES), "bounds": list(RANGES.values())}
        K = min(args.columns, M)
        t = time.perf_counter()
        err = 0.0
        for k in range(K):
            s = salib.analyze(problem, Y[:, :, k].ravel(), calc_second_order=False, seed=[1, 1])
            assert rep.indices is not None
            err = max(err, float(np.abs(s["S1"] - rep.indices.S1[k]).max()),
                      float(np.abs(s["ST"] - rep.indices.ST[k]).max()),
                      float(np.abs(s["ST_conf"] - (rep.indices.ST_high[k] - rep.indices.ST[k])).max()))
        analyze = (time.perf_counter() - t) * M / K
        base = model + analyze
        row.update(baseline_model_s=model, baseline_analyze_s=analyze, baseline_columns_timed=K, baseline_s=base,
                   ratio_warm=base / warm, ratio_cold=base / cold, max_index_difference=err,
                   numpy_model_vs_jaxlink_mm=model_error)
    print(f"{'case':<24} {'outputs':>7} {'designs':>8} {'jaxlink cold s':>15} {'warm s':>7} {'SALib+numpy s':>14} "
          f"{'ratio warm':>10} {'ratio cold':>10}")
    b = f"{row['baseline_s']:14.1f} {row['ratio_warm']:10.0f} {row['ratio_cold']:10.1f}" if "baseline_s" in row else \
        f"{'–':>14} {'–':>10} {'–':>10}"
    print(f"{row['case']:<24} {M:>7} {rep.evaluations:>8} {cold:15.2f} {warm:7.2f} {b}")
    if "max_index_difference" in row:
        print(f"largest |jaxlink − SALib| over S1, ST, ST interval: {row['max_index_difference']:.2g}; numpy model "
              f"vs jaxlink at the nominal: {row['numpy_model_vs_jaxlink_mm']:.2g} mm")
    out = pathlib.Path(__file__).parent / "results" / "latest" / "sensitivity.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"machine": platform.machine(), "cpus": os.cpu_count(), "jax": jax.__version__,
            "device": str(jax.devices()[0])}
    out.write_text(json.dumps({"meta": meta, "rows": [row]}, indent=2, default=float) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
