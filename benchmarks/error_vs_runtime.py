"""Error against run time for every knob that trades accuracy for time, all in one run.

Each knob is swept over a few settings with everything else at jaxlink's defaults; for every
setting the error against a tight float64 reference and the run time (best of repeats, after
compilation) are measured in this run:

| knob | problem | reference | error |
|---|---|---|---|
| `newton_max_steps`, `newton_rtol`, `predictor_order` | feed six-bar, B designs × 72 angles, `method="continuation"` | numpy Newton to 1e-15 m | max abs(ΔZ) of the feed dog, m |
| `method` (closed form / continuation / independent) | same | same | same |
| `dtype` (float64 / float32) | same, default method | same | same |
| `path_samples` (samples per revolution of a path objective) | four-bar coupler path, 200 designs, "points" objective | the same objective at 20000 samples | max abs(ΔJ) / J_ref |
| `dwell_samples` (samples per revolution of the dwell metrics) | needle-arachne, 64 designs, `dwell_05pct_deg` | 28800 samples | max abs(Δ) in crank degrees |
| `sinker_rtol`, `sinker_max_step`, `sinker_method` | sinker R20/55, f = 0.1, C = 3.5e4 | scipy DOP853, rtol 1e-12 | max abs(Δy), m |

A setting is on the Pareto front of its knob when no other setting of the same knob is both at
least as accurate and at least as fast, and better in one by more than the noise (> 10 % faster or
> 2× more accurate; `pareto_strict` in the JSON drops the noise margins). The defaults jaxlink ships are
marked `default`; the script says which are on their front. Run:

    python benchmarks/error_vs_runtime.py [--quick] [--json OUT] [--png OUT]

Writes `benchmarks/results/error_vs_runtime.json` (`{"cases": [{"knob", "setting", "error",
"seconds", "default", "pareto", ...}]}`) and `.png` (log-log, one curve per knob) by default.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _cores import default_output  # noqa: E402

import jaxlink as jl  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from throughput import feed_batch, feed_point_np  # noqa: E402

RESULTS_DIR = os.path.join(HERE, "results")
QUICK = False  # --quick: fewer settings per knob, smaller references (set by main)


def timed(f, repeats):
    """(compile + first run seconds, best of `repeats` seconds, output)."""
    t = time.perf_counter()
    out = f()
    jax.block_until_ready(out)
    first = time.perf_counter() - t
    best = math.inf
    for _ in range(repeats):
        t = time.perf_counter()
        out = f()
        jax.block_until_ready(out)
        best = min(best, time.perf_counter() - t)
    return first, best, out


TIME_NOISE = 0.10  # timings on this shared machine are ±10 % at best
ERROR_NOISE = 2.0  # errors within a factor 2 are the same (e.g. both at the rounding floor)


def dominates(o, c, strict=False):
    """o is at least as good as c in both and better in one. With `strict=False` "better" must
    exceed the noise: > 10 % faster or > 2× more accurate."""
    if strict:
        return (o["error"] <= c["error"] and o["seconds"] <= c["seconds"]
                and (o["error"] < c["error"] or o["seconds"] < c["seconds"]))
    return ((o["error"] <= c["error"] and o["seconds"] < (1 - TIME_NOISE) * c["seconds"])
            or (o["error"] < c["error"] / ERROR_NOISE and o["seconds"] <= (1 + TIME_NOISE) * c["seconds"]))


def pareto(cases):
    """Mark each case on the front of its knob: `pareto` (beyond noise), `pareto_strict`."""
    for c in cases:
        same = [o for o in cases if o["knob"] == c["knob"] and o is not c]
        c["pareto"] = not any(dominates(o, c) for o in same)
        c["pareto_strict"] = not any(dominates(o, c, strict=True) for o in same)
    return cases


# ----------------------------------------------------------------------------- feed six-bar knobs


def feed_cases(B, repeats, log):
    mech, P, phis, ref = feed_batch(B)
    N = len(phis)
    pos = B * N

    def run(knob, setting, default, dtype=np.float64, **opts):
        o = jl.NewtonOptions(**opts)
        Pd, ph, q0 = (jnp.asarray(x, dtype=dtype) for x in (P, phis, mech.guess))
        first, best, sol = timed(lambda: jl.solve(mech, ph, Pd, q0, options=o), repeats)
        q = np.asarray(sol.q, dtype=float).reshape(-1, 4)
        xy = feed_point_np(q, np.tile(phis, B), np.repeat(P, N, axis=0))
        err = float(np.max(np.abs(xy - ref)))
        case = dict(knob=knob, setting=setting, error=err, seconds=best, default=default,
                    compile_s=first - best, positions_per_s=pos / best,
                    converged_fraction=float(np.mean(np.asarray(sol.converged))),
                    problem=f"sewing-feed {B}x{N}", error_unit="m (max |ΔZ|)")
        log(case)
        return case

    cases = []
    for ms in ((1, 3, 12) if QUICK else (1, 2, 3, 5, 12)):
        cases.append(run("newton_max_steps", str(ms), ms == 12, method="continuation", max_steps=ms))
    for rt in ((1e-3, 1e-8, None) if QUICK else (1e-3, 1e-5, 1e-8, 1e-11, None)):
        cases.append(run("newton_rtol", "default (1000 eps)" if rt is None else f"{rt:g}", rt is None,
                         method="continuation", rtol=rt))
    for order in ((0, 2) if QUICK else (0, 1, 2)):
        cases.append(run("predictor_order", str(order), order == 2, method="continuation", predictor_order=order))
    for m in ("auto", "continuation", "independent"):
        cases.append(run("method", "auto (closed form)" if m == "auto" else m, m == "auto", method=m))
    for dt in (np.float64, np.float32):
        cases.append(run("dtype", np.dtype(dt).name, dt == np.float64, dtype=dt))
    return cases


# ----------------------------------------------------------------------------- path objective samples


def path_cases(repeats, log, designs=200):
    mech = jl.load("four-bar")
    rng = np.random.default_rng(1)
    P = np.repeat(mech.parameters[None], designs, axis=0)
    for name in ("a", "b", "c", "d", "cx", "cy"):
        P[:, mech.parameter_index(name)] *= 1 + 0.03 * rng.uniform(-1, 1, designs)
    # targets: points near the file design's coupler curve (the "points" objective of [optimize])
    phis_t = np.deg2rad(np.arange(0.0, 360.0, 45.0))
    base = jl.solve(mech, phis_t)
    tgt = np.asarray(jl.transfer(mech, phis_t, base.q, mech.parameters, order=0).points[:, 0])
    tgt = tgt + 1e-3 * rng.standard_normal(tgt.shape)
    T = jnp.asarray(tgt)

    def objective(n):
        phis = 2 * np.pi * np.arange(n) / n

        @jax.jit
        def f(Pd):
            sol = jl.solve(mech, phis, Pd)
            xy = jax.vmap(lambda q, p: jl.transfer(mech, phis, q, p, order=0).points[:, 0])(sol.q, Pd)
            a = xy
            ab = jnp.roll(xy, -1, axis=1) - a

            def one(a, ab):
                ap = T[:, None, :] - a[None]
                t = jnp.clip(jnp.sum(ap * ab[None], -1) / jnp.maximum(jnp.sum(ab * ab, -1), 1e-300)[None], 0, 1)
                d = ap - t[..., None] * ab[None]
                return jnp.sum(jnp.min(jnp.sum(d * d, -1), axis=1))

            return jax.vmap(one)(a, ab)

        return f

    Pd = jnp.asarray(P)
    ref = np.asarray(objective(20000)(Pd))
    cases = []
    for n in (12, 18, 36, 72, 144, 360, 720):
        f = objective(n)
        first, best, J = timed(lambda: f(Pd), repeats)
        err = float(np.max(np.abs(np.asarray(J) - ref) / ref))
        case = dict(knob="path_samples", setting=str(n), error=err, seconds=best, default=n == 72,
                    compile_s=first - best, problem=f"four-bar 'points' objective, {designs} designs",
                    error_unit="relative (max |ΔJ|/J)")
        log(case)
        cases.append(case)
    return cases


# ----------------------------------------------------------------------------- dwell metric samples


def dwell_cases(repeats, log, designs=64):
    mech = jl.load("needle-arachne")
    rng = np.random.default_rng(2)
    P = np.repeat(mech.parameters[None], designs, axis=0)
    P *= 1 + 0.002 * rng.uniform(-1, 1, P.shape)
    P[0] = mech.parameters
    key = "dwell_05pct_deg"

    def metric(n):
        rows = jl.dwell_metrics(mech, P, samples=n)
        return np.array([r.get(key, np.nan) if r.get("converged") else np.nan for r in rows])

    ref = metric(14400 if QUICK else 28800)
    ok = np.isfinite(ref)
    cases = []
    for n in ((360, 1440, 7200) if QUICK else (360, 720, 1440, 3600, 7200)):
        first, best, v = timed(lambda: metric(n), repeats)
        err = float(np.nanmax(np.abs(v[ok] - ref[ok])))
        case = dict(knob="dwell_samples", setting=str(n), error=err, seconds=best, default=n == 7200,
                    compile_s=first - best, problem=f"needle-arachne {key}, {int(ok.sum())} designs",
                    error_unit="crank degrees")
        log(case)
        cases.append(case)
    return cases


# ----------------------------------------------------------------------------- sinker ODE knobs


def sinker_cases(repeats, log):
    from jaxlink import cam as sk
    reference_solution = sk.reference_solution

    C, f = 3.5e4, 0.1
    km = float(sk.damping_from_log_decrement(C, 1.5e-3))
    geom = [g for g in sk.seed_geometries() if g.name == "R20-55"][0]
    speed = sk.butt_speed(350.0, 0.096)
    cam = sk.make_cam(geom, speed)
    n_out = 2001
    ts = np.linspace(0.0, float(cam.t_end), n_out)
    _, yref, _ = reference_solution(radius=0.02, descent_deg=55, f=f, C=C, k_over_m=km, ts=ts,
                                    rtol=1e-12, max_step=1e-5 if QUICK else 2e-6)
    params = sk.make_params(f=f, C=C)

    def run(knob, setting, default, **kw):
        first, best, sol = timed(lambda: sk.simulate(params, cam, n_out=n_out, **kw), repeats)
        ok = int(sol.result) == sk.RESULTS.converged
        err = float(np.max(np.abs(np.asarray(sol.y) - yref[:, 0]))) if ok else math.inf
        case = dict(knob=knob, setting=setting, error=err, seconds=best, default=default, compile_s=first - best,
                    steps=int(sol.stats.num_steps), problem="sinker R20-55, f=0.1, C=3.5e4", error_unit="m (max |Δy|)")
        log(case)
        return case

    cases = []
    for rt in ((1e-3, 1e-6, 1e-10) if QUICK else (1e-3, 1e-4, 1e-5, 1e-6, 1e-8, 1e-10)):
        cases.append(run("sinker_rtol", f"{rt:g}", rt == 1e-6, method="explicit", rtol=rt))
    for ms in ((math.inf, 1e-4, 2e-5) if QUICK else (math.inf, 3e-4, 1e-4, 2e-5, 5e-6)):
        cases.append(run("sinker_max_step", "inf" if ms == math.inf else f"{ms:g} s", ms == 1e-4,
                         method="explicit", max_step=ms))
    for m in ("explicit", "implicit"):
        cases.append(run("sinker_method", m, m == sk.auto_method(C), method=m))
    return cases


# ----------------------------------------------------------------------------- output


KNOB_ORDER = ("newton_max_steps", "newton_rtol", "predictor_order", "method", "dtype", "path_samples",
              "dwell_samples", "sinker_rtol", "sinker_max_step", "sinker_method")


def plot(cases, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2), dpi=80)
    groups = [("Newton / method / dtype (feed six-bar, m)", KNOB_ORDER[:5]),
              ("samples per revolution (relative / deg)", KNOB_ORDER[5:7]),
              ("sinker ODE (m)", KNOB_ORDER[7:])]
    for ax, (title, knobs) in zip(axes, groups):
        for k in knobs:
            cs = [c for c in cases if c["knob"] == k]
            if not cs:
                continue
            cs_sorted = sorted(cs, key=lambda c: c["seconds"])
            x = [c["seconds"] for c in cs_sorted]
            y = [max(c["error"], 1e-17) for c in cs_sorted]
            (line,) = ax.loglog(x, y, "o-", ms=4, label=k)
            for c in cs_sorted:
                if c["default"]:
                    ax.loglog(c["seconds"], max(c["error"], 1e-17), "*", ms=13, color=line.get_color(),
                              markeredgecolor="k")
        from matplotlib.ticker import NullFormatter

        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("run time, s (best of repeats)")
        ax.set_ylabel("error")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("jaxlink: error against run time (★ = shipped default)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="smaller batches, fewer repeats (~1-2 minutes)")
    ap.add_argument("--designs", type=int, default=None, help="feed designs (default 4000; quick 1000)")
    ap.add_argument("--json", default=None, help="JSON output (default results/latest/error_vs_runtime.json)")
    ap.add_argument("--png", default=None, help="plot (default results/latest/error_vs_runtime.png)")
    ap.add_argument("--only", default=None, help="comma-separated groups: feed,path,dwell,sinker")
    args = ap.parse_args(argv)
    args.json = args.json or default_output("error_vs_runtime.json")
    args.png = args.png or default_output("error_vs_runtime.png")
    global QUICK
    QUICK = args.quick
    B = args.designs or (1000 if args.quick else 4000)
    repeats = 2 if args.quick else 5
    groups = set((args.only or "feed,path,dwell,sinker").split(","))

    def log(c):
        print(f"  {c['knob']:18s} {c['setting']:>20s}{' *' if c['default'] else '  '} "
              f"error {c['error']:10.3e}  {c['seconds'] * 1e3:10.2f} ms", flush=True)

    t0 = time.perf_counter()
    cases = []
    sections = {}
    for name, fn in (("feed", lambda: feed_cases(B, repeats, log)),
                     ("path", lambda: path_cases(repeats, log, designs=100 if args.quick else 200)),
                     ("dwell", lambda: dwell_cases(repeats, log, designs=8 if args.quick else 64)),
                     ("sinker", lambda: sinker_cases(repeats, log))):
        if name in groups:
            t = time.perf_counter()
            cases += fn()
            sections[name] = time.perf_counter() - t
            print(f"[{name}: {sections[name]:.1f} s]", flush=True)
    pareto(cases)

    print(f"\nerror against run time ({os.cpu_count()} cores, jax {jax.__version__}); "
          "* = default, P = on its knob's front")
    print(f"{'knob':18s} {'setting':>20s} {'':2s} {'error':>10s} {'seconds':>10s} {'front':>5s}  unit")
    for c in cases:
        print(f"{c['knob']:18s} {c['setting']:>20s} {'*' if c['default'] else ' ':2s} {c['error']:10.3e} "
              f"{c['seconds']:10.4g} {'P' if c['pareto'] else '':>5s}  {c['error_unit']}")
    for c in cases:
        if c["default"] and c["pareto"] and not c["pareto_strict"]:
            print(f"note: default {c['knob']}={c['setting']} is dominated only within the noise margins")
    defaults = [c for c in cases if c["default"]]
    on = [c["knob"] for c in defaults if c["pareto"]]
    off = [c["knob"] for c in defaults if not c["pareto"]]
    print(f"\ndefaults on their front: {', '.join(on) or '-'}")
    print(f"defaults NOT on their front: {', '.join(off) or '-'}")
    out = {"cases": cases, "defaults_on_front": on, "defaults_off_front": off, "feed_designs": B,
           "repeats": repeats, "wall_s": time.perf_counter() - t0, "section_wall_s": sections,
           "time_noise": TIME_NOISE, "error_noise": ERROR_NOISE,
           "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "jax": jax.__version__}}
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1, default=float)
        print(f"wrote {args.json}")
    if args.png:
        plot(cases, args.png)
        print(f"wrote {args.png}")
    return out


if __name__ == "__main__":
    main()
