"""Knitting sinker (issue 6): jamming thresholds, maxima tables and a stiffness study.

Prints, beside the seed's published numbers (Czech diploma thesis, seed 004) and the rebuilt
reference model of `shared/spec/sinker-cam.md`:

1. static and dynamic jamming thresholds of the six cam geometries (exact arc and the seed's
   0.1 mm chord polygon), dynamic ones by batched bisection;
2. the maxima of acceleration, velocity and lag (seed Tables 5.1-5.5), all geometries x
   friction coefficients in one vmapped call;
3. a stiffness study, C = 1e4 ... 1e7 N/m (and beyond unless --quick): accepted/rejected
   steps, function and Jacobian evaluations, wall time and max |y - y_ref| for the explicit
   (Dormand-Prince 5(4)) and implicit (Radau IIA 5) integrators against a tight scipy
   reference (DOP853, rtol 1e-12, max_step 2 us, exact contact events).

    python experiments/sinker_jamming.py [--quick] [--json OUT] [--plot-dir DIR]
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from jaxlink import cam as sk  # noqa: E402

SPEED = sk.butt_speed(350.0, 0.096)

# ---- seed (published) and spec (rebuilt reference model) numbers -------------------------
SEED_JAM = {45: (0.18, 0.19), 50: (0.16, 0.17), 55: (0.14, 0.145)}  # (last ok, first jammed)
SPEC_STATIC = {45: 0.1853, 50: 0.1627, 55: 0.1410}
SPEC_DYNAMIC = {"R10-45": 0.1856, "R20-45": 0.1858, "R10-50": 0.1636, "R20-50": 0.1636,
                "R10-55": 0.1425, "R20-55": 0.1429}
F_TABLE = [0.10, 0.12, 0.13, 0.14, 0.145, 0.15, 0.16, 0.17, 0.18, 0.19]
SEED_RISE_A = [3050, 2850, 2750, 2650, 2600, 2550, 2340, 2300, 2200, 2150]
SEED_RISE_V = [1.65, 1.64, 1.635, 1.63, 1.627, 1.625, 1.62, 1.615, 1.61, 1.58]
SPEC_RISE_A = [3296, 3067, 2947, 2823, 2759, 2694, 2559, 2418, 2270, 2113]
SPEC_RISE_V = [1.678, 1.660, 1.650, 1.639, 1.633, 1.627, 1.614, 1.599, 1.583, 1.564]
# (geometry, f): seed a/v, spec a/v (descent part)
DESC = {
    ("R10-45", 0.10): (700, 1.95, 728, 1.929), ("R10-45", 0.15): (650, 1.97, 675, 1.955),
    ("R10-45", 0.17): (550, 1.92, 482, 1.913), ("R10-45", 0.18): (400, 1.65, 328, 1.820),
    ("R20-45", 0.10): (375, 1.85, 439, 1.858), ("R20-45", 0.15): (390, 1.875, 284, 1.842),
    ("R20-45", 0.17): (450, 1.89, 324, 1.863), ("R20-45", 0.18): (350, 1.575, 290, 1.785),
    ("R10-50", 0.10): (750, 2.30, 719, 2.269), ("R10-50", 0.13): (700, 2.31, 621, 2.275),
    ("R10-50", 0.15): (550, 2.20, 430, 2.234), ("R10-50", 0.16): (250, 1.95, 220, 1.937),
    ("R20-50", 0.10): (520, 2.25, 560, 2.231), ("R20-50", 0.13): (450, 2.23, 406, 2.213),
    ("R20-50", 0.15): (400, 2.20, 317, 2.198), ("R20-50", 0.16): (200, 1.35, 207, 1.834),
    ("R10-55", 0.10): (800, 2.75, 927, 2.756), ("R10-55", 0.12): (600, 2.70, 647, 2.710),
    ("R10-55", 0.13): (500, 2.60, 446, 2.654), ("R10-55", 0.14): (100, 1.90, 108, 1.942),
    ("R20-55", 0.10): (580, 2.69, 670, 2.688), ("R20-55", 0.12): (480, 2.65, 472, 2.657),
    ("R20-55", 0.13): (400, 2.62, 344, 2.622), ("R20-55", 0.14): (100, 1.25, 105, 1.875),
}
# Table 5.5 (R20/55, f = 0.1, k/m = 1066 fixed): C -> seed (rise a, v, lag mm; desc a, v, lag)
SEED_T55 = {3.5e4: (3050, 1.65, 0.30, 580, 2.69, 0.29), 2e4: (2350, 1.60, 0.42, 600, 2.70, 0.50),
            1e4: (1550, 1.47, 0.65, 500, 2.65, 0.94)}
SPEC_T55 = {3.5e4: (3296, 1.678, 0.258, 670, 2.688, 0.206),
            2e4: (2357, 1.591, 0.343, 642, 2.705, 0.346),
            2.5e4: (2698, 1.628, 0.306, 592, 2.682, 0.271),
            1e4: (1527, 1.465, 0.489, 531, 2.682, 0.609)}


def _take(tree, i):
    return jax.tree.map(lambda x: x[i], tree)


def _timed(fn, repeat=3):
    """(result, first-call seconds incl. compile, best of `repeat` later calls)."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return out, first, best


def thresholds_section(report):
    print("\n== 1. Jamming thresholds (C = 3.5e4 N/m, k/m = 1065.8 1/s, F_P = 0) ==")
    geoms = sk.seed_geometries()
    res = {}
    for arc in ("exact", "polygon"):
        cams = sk.make_cam([g._replace(arc=arc) for g in geoms], SPEED)
        t0 = time.perf_counter()
        th = sk.thresholds(sk.make_params(), cams, tol=1e-5)
        res[arc] = (th, time.perf_counter() - t0)
    print(f"{'geometry':>8} | {'seed: ok / jammed':>17} | {'static f* (spec)':>17} | "
          f"{'dynamic exact':>13} {'polygon':>8} {'(spec)':>7} | inside seed bracket")
    out = {}
    for i, g in enumerate(geoms):
        deg = round(math.degrees(g.descent_angle))
        s = float(res["exact"][0].static_f[i])
        d = float(res["exact"][0].dynamic_f[i])
        dp = float(res["polygon"][0].dynamic_f[i])
        lo, hi = SEED_JAM[deg]
        inside = lo < s <= hi and lo < d <= hi and lo < dp <= hi
        print(f"{g.name:>8} | {lo:>8.3f} / {hi:<6.3f} | {s:8.5f} ({SPEC_STATIC[deg]:.4f}) | "
              f"{d:13.5f} {dp:8.5f} ({SPEC_DYNAMIC[g.name]:.4f}) | {'yes' if inside else 'NO'}")
        out[g.name] = {"static_f": s, "dynamic_f": d, "dynamic_f_polygon": dp,
                       "seed_bracket": [lo, hi], "spec_static_f": SPEC_STATIC[deg],
                       "spec_dynamic_f": SPEC_DYNAMIC[g.name]}
    for arc in ("exact", "polygon"):
        th, wall = res[arc]
        print(f"  {arc}: bisection to a bracket width of 1e-5 in f, {th.num_batches} batched "
              f"simulations of 6 geometries, {wall:.1f} s including compilation")
    report["thresholds"] = out


def maxima_section(report, plot_dir):
    print("\n== 2. Maxima (C = 3.5e4 N/m, exact arc): seed / spec reference model / jaxlink ==")
    geoms = sk.seed_geometries()
    cams = sk.make_cam(geoms, SPEED)
    pb, cb, shape = sk.product_cases(sk.make_params(), cams, f=F_TABLE)
    sol, first, best = _timed(lambda: sk.simulate_batch(pb, cb, n_out=4001), repeat=1)
    sol = jax.tree.map(np.asarray, sol)
    n_f, n_g, _ = shape
    print(f"  {n_f} f x {n_g} geometries = {n_f * n_g} cases in one vmapped call: "
          f"{first:.2f} s with compilation, {best:.3f} s after")
    mx = {(gi, fi): sk.maxima(_take(sol, fi * n_g + gi), _take(cams, gi))
          for gi in range(n_g) for fi in range(n_f)}
    print("\nTable 5.1, rise part (all geometries equal): a_max (m/s^2), v_max (m/s)")
    print(f"{'f':>6} | {'a seed':>6} {'spec':>6} {'ours':>7} {'ours/spec':>9} | "
          f"{'v seed':>6} {'spec':>6} {'ours':>6} {'ours/spec':>9} | lag max mm | bounce mm / ms")
    rise = []
    for fi, f in enumerate(F_TABLE):
        m = mx[(0, fi)]
        print(f"{f:6.3f} | {SEED_RISE_A[fi]:6d} {SPEC_RISE_A[fi]:6d} {m.rise_a:7.1f} "
              f"{m.rise_a / SPEC_RISE_A[fi]:9.4f} | {SEED_RISE_V[fi]:6.3f} {SPEC_RISE_V[fi]:6.3f}"
              f" {m.rise_v:6.3f} {m.rise_v / SPEC_RISE_V[fi]:9.4f} | {m.rise_lag * 1e3:10.4f} | "
              f"{m.bounce_depth * 1e3:.4f} / {m.bounce_time * 1e3:.3f}")
        rise.append({"f": f, "a": m.rise_a, "v": m.rise_v, "lag": m.rise_lag,
                     "bounce_depth": m.bounce_depth, "bounce_time": m.bounce_time})
    print("  seed bounce: f=0.10 0.04 mm / 0.47 ms, f=0.12 0.016 / 0.28, f=0.13 0.0022 / 0.10;"
          " spec: 0.123 / 1.09, 0.084 / 0.82, 0.065 / 0.70")
    print("\nTables 5.2-5.4, descent part: a_max (m/s^2), v_max (m/s); '/' = jammed")
    print(f"{'geometry':>8} {'f':>6} | {'a seed':>6} {'spec':>6} {'ours':>7} {'ours/spec':>9} | "
          f"{'v seed':>6} {'spec':>6} {'ours':>6} {'ours/spec':>9} | jammed")
    names = [g.name for g in geoms]
    desc = []
    for (name, f), (sa, sv, ra, rv) in DESC.items():
        gi, fi = names.index(name), F_TABLE.index(f)
        m = mx[(gi, fi)]
        jam = bool(sol.jammed[fi * n_g + gi])
        print(f"{name:>8} {f:6.3f} | {sa:6d} {ra:6d} {m.desc_a:7.1f} {m.desc_a / ra:9.4f} | "
              f"{sv:6.3f} {rv:6.3f} {m.desc_v:6.3f} {m.desc_v / rv:9.4f} | "
              f"{'yes' if jam else 'no'}")
        desc.append({"geometry": name, "f": f, "a": m.desc_a, "v": m.desc_v, "jammed": jam})
    report["rise_maxima"] = rise
    report["descent_maxima"] = desc

    print("\nTable 5.5, stiffness (R20-55, f = 0.1, k/m = 1066 1/s held fixed as in the seed):")
    print(f"{'C N/m':>8} | {'source':>6} | {'rise a':>7} {'v':>6} {'lag mm':>7} | "
          f"{'desc a':>7} {'v':>6} {'lag mm':>7}")
    cs = [3.5e4, 2.5e4, 2e4, 1e4]
    cam = _take(cams, names.index("R20-55"))
    pb, cb, _ = sk.product_cases(sk.make_params(f=0.1), cam, C=cs, k_over_m=[1066.0] * 4)
    sol5 = jax.tree.map(np.asarray, sk.simulate_batch(pb, cb, n_out=4001))
    t55 = []
    for i, c in enumerate(cs):
        m = sk.maxima(_take(sol5, i), cam)
        for src, row in (("seed", SEED_T55.get(c)), ("spec", SPEC_T55.get(c))):
            if row:
                print(f"{c:8.2g} | {src:>6} | {row[0]:7.0f} {row[1]:6.3f} {row[2]:7.3f} | "
                      f"{row[3]:7.0f} {row[4]:6.3f} {row[5]:7.3f}")
        print(f"{c:8.2g} | {'ours':>6} | {m.rise_a:7.1f} {m.rise_v:6.3f} {m.rise_lag * 1e3:7.3f}"
              f" | {m.desc_a:7.1f} {m.desc_v:6.3f} {m.desc_lag * 1e3:7.3f}")
        t55.append({"C": c, **m._asdict()})
    report["table_5_5"] = t55
    if plot_dir:
        _plots(plot_dir, sol, cams, geoms, shape)


def _plots(plot_dir, sol, cams, geoms, shape):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plot_dir = pathlib.Path(plot_dir)
    plot_dir.mkdir(parents=True, exist_ok=True)
    n_f, n_g, _ = shape
    for gi, g in enumerate(geoms):
        cam = _take(cams, gi)
        fig, axes = plt.subplots(2, 2, figsize=(12, 8), sharex=True)
        for fi, f in enumerate(F_TABLE):
            s = _take(sol, fi * n_g + gi)
            for ax, data in zip(axes.flat, (s.a, s.v, s.y * 1e3, s.lag * 1e3)):
                ax.plot(s.t * 1e3, data, lw=0.9, label=f"f = {f:g}")
        labels = ("acceleration y'' (m/s²)  [graph 5.1]", "velocity y' (m/s)  [graph 5.2]",
                  "lift y (mm)  [graph 5.3]", "lag y_z − y (mm)  [graph 5.4]")
        for ax, lab in zip(axes.flat, labels):
            ax.set_ylabel(lab)
            ax.axvline(float(cam.t_rise) * 1e3, color="0.5", lw=0.6)
            ax.axvline(float(cam.t_descent) * 1e3, color="0.5", lw=0.6)
            ax.grid(alpha=0.3)
        axes.flat[1].set_ylim(-3, 3.5)
        axes.flat[3].set_ylim(-0.5, 8)
        for ax in axes[1]:
            ax.set_xlabel("time t (ms)")
        axes.flat[0].legend(fontsize=7, ncol=2)
        fig.suptitle(f"sinker on cam {g.name}, C = 3.5e4 N/m (rise | arc | descent)")
        fig.tight_layout()
        path = plot_dir / f"sinker_{g.name}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        print(f"  wrote {path}")


def stiffness_section(report, quick):
    print("\n== 3. Stiffness study (R20-55, f = 0.1, k/m = ln2 sqrt(C/m)/pi, rtol 1e-6, "
          "atol 1e-10) ==")
    print("   reference: scipy DOP853, rtol 1e-12, atol 1e-15, max_step 2 us, exact contact "
          "events, restarted at cam breakpoints")
    cs = [1e4, 3.5e4, 1e5, 3e5, 1e6, 3e6, 1e7] + ([] if quick else [3e7, 1e8])
    cam = sk.make_cam(sk.seed_geometries()[5], SPEED)
    n_out = 2001
    ts = np.linspace(0.0, float(cam.t_end), n_out)
    print(f"{'C N/m':>7} {'omega':>7} | {'method':>8} {'steps':>5} {'rej':>4} {'nfev':>5} "
          f"{'njev':>5} {'events':>6} {'run ms':>7} {'max|y-yref| m':>13} | "
          f"{'ref nfev':>8} {'events':>6}")
    rows = []
    for c in cs:
        km = float(sk.damping_from_log_decrement(c, 1.5e-3))
        _, yref, info = sk.reference_solution(radius=0.02, descent_deg=55, f=0.1, C=c,
                                              k_over_m=km, ts=ts)
        p = sk.make_params(C=c, f=0.1)
        omega = math.sqrt(c * float(sk.drive_fraction(math.radians(30), 0.1))
                          / (1.5e-3 * math.cos(math.radians(30))))
        for method in ("explicit", "implicit"):
            sol, first, best = _timed(lambda: sk.simulate(p, cam, n_out=n_out, method=method))
            err = float(np.max(np.abs(np.asarray(sol.y) - yref[:, 0])))
            st = sol.stats
            print(f"{c:7.1e} {omega:7.2g} | {method:>8} {int(st.num_steps):5d} "
                  f"{int(st.num_rejected):4d} {int(st.num_fev):5d} {int(st.num_jev):5d} "
                  f"{int(st.num_events):6d} {best * 1e3:7.2f} {err:13.2e} | "
                  f"{info['nfev']:8d} {info['events']:6d}"
                  + ("" if int(sol.result) == 0 else f"  FAILED ({int(sol.result)})"))
            rows.append({"C": c, "method": method, "steps": int(st.num_steps),
                         "rejected": int(st.num_rejected), "nfev": int(st.num_fev),
                         "njev": int(st.num_jev), "events": int(st.num_events),
                         "run_s": best, "first_call_s": first, "max_err_m": err,
                         "result": int(sol.result), "ref_events": info["events"]})
    print(f"  (run ms = best of 3 jitted calls after compilation; auto picks implicit above "
          f"C = {sk.AUTO_IMPLICIT_ABOVE:.0e} N/m)")
    # one vmapped call over all stiffnesses
    km = np.asarray(sk.damping_from_log_decrement(np.asarray(cs), 1.5e-3))
    pb, cb, _ = sk.product_cases(sk.make_params(f=0.1), cam, C=cs, k_over_m=km)
    for method in ("explicit", "implicit"):
        _, first, best = _timed(lambda: sk.simulate_batch(pb, cb, n_out=n_out, method=method))
        print(f"  all {len(cs)} stiffnesses in one vmapped call, {method}: {best * 1e3:.1f} ms "
              f"({first:.1f} s with compilation)")
    report["stiffness"] = rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer stiffnesses (up to 1e7)")
    ap.add_argument("--json", metavar="OUT", help="write all numbers to this JSON file")
    ap.add_argument("--plot-dir", metavar="DIR", help="write graphs 5.1-5.4 per geometry here")
    args = ap.parse_args(argv)
    report = {}
    t0 = time.perf_counter()
    thresholds_section(report)
    maxima_section(report, args.plot_dir)
    stiffness_section(report, args.quick)
    print(f"\ntotal {time.perf_counter() - t0:.1f} s")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(report, fh, indent=1)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
