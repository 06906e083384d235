"""Sobol' sensitivity speed (issue 25): indices with bootstrap intervals of a 720-output path.

Two cases, each against its baseline measured in the same run (interleaved: jaxlink warm before
the baseline, between its model and its `analyze`, and after it; the ratio against the median of
the three; the 1-minute load average recorded at each):

- `four-bar`: the four-bar-sketch scene against SALib + a numpy closed-form model (below);
- `six-bar`: the sewing-feed scene, its feed-dog point Z's x and y at 360 positions, four
  parameters varied (l2 ∈ [12.5, 13.5] mm, l22 ∈ [8.75, 9.25] mm, γ ∈ [97.5°, 102.5°], l3 ∈
  [59.5, 60.5] mm: every design assembles), against SALib + a numpy batched Newton model of the
  same six-bar (`numpy_sewing_feed`: the two loop equations of the scene file, Newton on (φ3, φ4,
  φ5, φ6) vectorized over the designs — `numpy.linalg.solve` of the batch's 4 × 4 systems — and
  continued position by position from the file's guess at the input's start, to 1e-11 mm).

The four-bar-sketch scene, its coupler point P's x and y at 360 positions (720 outputs), four
lengths varied over ±5 % (crank, coupler, rocker, B0_x), N = 4096 base samples of scrambled
Sobol' (N (D + 2) = 24 576 designs), S1 and ST of every output with 100 bootstrap resamples:

- jaxlink: `jaxlink.study.sensitivity` end to end — cold (the `Study` built and compiled in the
  run) and warm (the same study again); every design's whole-cycle feasibility included; each
  warm run followed by one with `overlap=False` (the batches not overlapped: the same indices);
- baseline: the same designs evaluated by a numpy model of the same four-bar (the closed-form
  circle intersection, vectorized over designs and positions), then SALib's `sobol.analyze` once
  per output column (its API), with the same bootstrap draws — its indices must equal jaxlink's.

Prints a table and writes benchmarks/results/latest/sensitivity.json. Run:
`python benchmarks/sensitivity.py [--samples N] [--columns K] [--cases four-bar,six-bar]`
(`--columns`: SALib on the first K columns only, the time scaled to 720; default all). Skips the
baseline with a message when SALib is not installed (`pip install -e ".[bench]"`).
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


SIX_RANGES = {"l2": [12.5, 13.5], "l22": [8.75, 9.25], "gamma": [97.5, 102.5], "l3": [59.5, 60.5]}
SIX_ORDER = ("l2", "l22", "gamma", "l3", "l4", "l44", "l5", "l6", "l66", "l7", "l8")


def numpy_sewing_feed(P, phi, q0, tol=1e-11, max_steps=30):
    """Z.x, Z.y (n, N) of the sewing-feed six-bar at designs P (n, 11: `SIX_ORDER`, mm, γ in rad)
    over the inputs `phi` (N,) (rad, in continuation order): Newton on (φ3, φ4, φ5, φ6) of the
    loops l2 e2 + l3 e3 + l44 e4 = (l8, l7) and l2 e2 + l3 e3 + l4 e4 + l6 e6 + l5 e5 + l22 e(φ2 + γ)
    = 0, batched over the designs, from `q0` at phi[0] and each position's solution at the next."""
    l2, l22, g, l3, l4, l44, l5, l6, l66, l7, l8 = P.T
    n = P.shape[0]
    q = np.broadcast_to(np.asarray(q0, float), (n, 4)).copy()
    zx, zy = np.empty((n, len(phi))), np.empty((n, len(phi)))
    J = np.zeros((n, 4, 4))
    for k, ph in enumerate(phi):
        c2, s2 = np.cos(ph), np.sin(ph)
        cg, sg = np.cos(ph + g), np.sin(ph + g)
        for _ in range(max_steps):
            c, s = np.cos(q), np.sin(q)
            F = np.stack([l2 * c2 + l3 * c[:, 0] + l44 * c[:, 1] - l8,
                          l2 * s2 + l3 * s[:, 0] + l44 * s[:, 1] - l7,
                          l2 * c2 + l3 * c[:, 0] + l4 * c[:, 1] + l5 * c[:, 2] + l6 * c[:, 3] + l22 * cg,
                          l2 * s2 + l3 * s[:, 0] + l4 * s[:, 1] + l5 * s[:, 2] + l6 * s[:, 3] + l22 * sg], axis=1)
            if np.abs(F).max() < tol:
                break
            J[:, 0, 0], J[:, 0, 1] = -l3 * s[:, 0], -l44 * s[:, 1]
            J[:, 1, 0], J[:, 1, 1] = l3 * c[:, 0], l44 * c[:, 1]
            J[:, 2] = np.stack([-l3 * s[:, 0], -l4 * s[:, 1], -l5 * s[:, 2], -l6 * s[:, 3]], 1)
            J[:, 3] = np.stack([l3 * c[:, 0], l4 * c[:, 1], l5 * c[:, 2], l6 * c[:, 3]], 1)
            q -= np.linalg.solve(J, F[..., None])[..., 0]
        c, s = np.cos(q), np.sin(q)
        zx[:, k] = l2 * c2 + l3 * c[:, 0] + l4 * c[:, 1] + (l6 + l66) * c[:, 3]
        zy[:, k] = l2 * s2 + l3 * s[:, 0] + l4 * s[:, 1] + (l6 + l66) * s[:, 3]
    return zx, zy


def four_bar_case(mech):
    """(ranges, point, model(x (n, 4), phi) → (x, y)) of the four-bar case."""
    names = mech.parameter_names
    pv = np.asarray(mech.parameters)
    lf = mech.units.length  # SI → file units (mm); the angle stays in rad
    q = (pv[names.index("coupler_P")] / lf, pv[names.index("coupler_P_angle")], pv[names.index("A0_x")] / lf,
         pv[names.index("A0_y")] / lf, pv[names.index("B0_y")] / lf)
    return RANGES, "P", lambda x, phi: numpy_four_bar(x, phi, q)


def six_bar_case(mech):
    """(ranges, point, model) of the six-bar case: the file's other parameters fixed."""
    names = mech.parameter_names
    pv = np.asarray(mech.parameters)
    base = np.asarray([pv[names.index(k)] / (1.0 if mech.kinds[k] == "angle" else mech.units.length)
                       for k in SIX_ORDER])
    cols = [SIX_ORDER.index(k) for k in SIX_RANGES]
    q0 = np.asarray(mech.guess)

    def model(x, phi):
        P = np.repeat(base[None], len(x), axis=0)
        P[:, cols] = x
        P[:, SIX_ORDER.index("gamma")] = np.deg2rad(P[:, SIX_ORDER.index("gamma")])  # the file's deg → rad
        return numpy_sewing_feed(P, phi, q0)

    return SIX_RANGES, "Z", model


CASES = {"four-bar": ("four-bar-sketch", four_bar_case), "six-bar": ("sewing-feed", six_bar_case)}


def run(case: str, N: int, columns: int) -> dict:
    import statistics

    scene, make = CASES[case]
    mech = jl.load(scene)
    ranges, point, model = make(mech)
    table = {"method": "sensitivity", "positions": 360, "points": [point], "metrics": [], "samples": N, "seed": 1,
             "bootstrap": 100, "ranges": ranges}
    inputs = st.read_study(mech, table)
    t = time.perf_counter()
    study = st.Study(mech, inputs)
    rep = st.sensitivity(mech, study=study)
    cold = time.perf_counter() - t
    warm, load = [], []

    plain: list = []

    def jaxlink_warm():
        t = time.perf_counter()
        r = st.sensitivity(mech, study=study)
        warm.append(time.perf_counter() - t)
        load.append(os.getloadavg()[0])
        t = time.perf_counter()
        p = st.sensitivity(mech, study=study, overlap=False)  # the plain loop: the same numbers, slower
        plain.append(time.perf_counter() - t)
        assert p.indices is not None and r.indices is not None and np.array_equal(p.indices.ST, r.indices.ST)
        return r

    rep = jaxlink_warm()
    M = len(rep.labels)
    row = {"case": f"{scene} {point} path", "outputs": M, "factors": len(ranges), "samples": N,
           "designs": rep.evaluations, "bootstrap": 100, "chunk": study.chunk, "jaxlink_cold_s": cold,
           "feasible_fraction": rep.feasible_fraction, "ranges": ranges}
    try:
        from SALib.analyze import sobol as salib
    except ImportError:
        salib = None
        print("SALib is not installed: the baseline is skipped (pip install -e '.[bench]')")
    if salib is not None:
        # the same designs (the study's sampler and map), the same bootstrap draws
        T = len(ranges)
        u = np.concatenate(list(st.unit_blocks("sobol", 2 * T, N, 1)))
        a, b = st.to_values(inputs, study.x0, u[:, :T]), st.to_values(inputs, study.x0, u[:, T:])
        X = [a] + [np.where(np.arange(T) == j, b, a) for j in range(T)] + [b]  # SALib's order: A, AB_j, B
        phi = np.deg2rad(rep.input_values)
        t = time.perf_counter()
        Y = np.stack([np.concatenate(model(x, phi), axis=1) for x in X], axis=1)  # (N, D + 2, 720)
        t_model = time.perf_counter() - t
        nominal = np.concatenate(model(study.x0[None], phi), axis=1)[0]
        model_error = float(np.abs(nominal - rep.nominal[:M]).max())
        jaxlink_warm()
        problem = {"num_vars": T, "names": list(ranges), "bounds": list(ranges.values())}
        K = min(columns, M)
        t = time.perf_counter()
        err = 0.0
        for k in range(K):
            s = salib.analyze(problem, Y[:, :, k].ravel(), calc_second_order=False, seed=[1, 1])
            assert rep.indices is not None
            err = max(err, float(np.abs(s["S1"] - rep.indices.S1[k]).max()),
                      float(np.abs(s["ST"] - rep.indices.ST[k]).max()),
                      float(np.abs(s["ST_conf"] - (rep.indices.ST_high[k] - rep.indices.ST[k])).max()))
        analyze = (time.perf_counter() - t) * M / K
        base = t_model + analyze
        row.update(baseline_model_s=t_model, baseline_analyze_s=analyze, baseline_columns_timed=K, baseline_s=base,
                   max_index_difference=err, numpy_model_vs_jaxlink_mm=model_error)
    rep = jaxlink_warm()
    med = statistics.median(warm)
    row.update(jaxlink_warm_s=warm, jaxlink_warm_median_s=med, jaxlink_warm_not_overlapped_s=plain,
               jaxlink_warm_not_overlapped_median_s=statistics.median(plain), jaxlink_timings_warm=rep.timings,
               load_1min=load)
    if "baseline_s" in row:
        row.update(ratio_warm=row["baseline_s"] / med, ratio_cold=row["baseline_s"] / cold)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=4096)
    ap.add_argument("--columns", type=int, default=720)
    ap.add_argument("--cases", default="four-bar,six-bar")
    args = ap.parse_args()
    rows = [run(c, args.samples, args.columns) for c in args.cases.split(",")]
    print(f"{'case':<24} {'outputs':>7} {'designs':>8} {'jaxlink cold s':>15} {'warm s':>7} {'SALib+numpy s':>14} "
          f"{'ratio warm':>10} {'ratio cold':>10}")
    for row in rows:
        b = (f"{row['baseline_s']:14.1f} {row['ratio_warm']:10.1f} {row['ratio_cold']:10.1f}" if "baseline_s" in row
             else f"{'–':>14} {'–':>10} {'–':>10}")
        print(f"{row['case']:<24} {row['outputs']:>7} {row['designs']:>8} {row['jaxlink_cold_s']:15.2f} "
              f"{row['jaxlink_warm_median_s']:7.2f} {b}")
        if "max_index_difference" in row:
            print(f"  largest |jaxlink − SALib| over S1, ST, ST interval: {row['max_index_difference']:.2g}; numpy "
                  f"model vs jaxlink at the nominal: {row['numpy_model_vs_jaxlink_mm']:.2g} mm; warm runs "
                  f"{', '.join(f'{w:.2f}' for w in row['jaxlink_warm_s'])} s (not overlapped "
                  f"{', '.join(f'{w:.2f}' for w in row['jaxlink_warm_not_overlapped_s'])} s); load "
                  f"{row['load_1min']}")
    out = pathlib.Path(__file__).parent / "results" / "latest" / "sensitivity.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"machine": platform.machine(), "cpus": os.cpu_count(), "jax": jax.__version__,
            "device": str(jax.devices()[0])}
    out.write_text(json.dumps({"meta": meta, "rows": rows}, indent=2, default=float) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
