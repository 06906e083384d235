"""Four-bar with a coupler point: jaxlink against pylinkage's numba solver, in the same run.

The task: many four-bar designs (the built-in `four-bar` scene, a, b, c, d, cx, cy each varied by
±3 %, all Grashof crank-rockers), 360 crank steps per revolution, every joint position and the
coupler point P. Measured in this run, on the same designs:

- **pylinkage `Linkage.step_fast`** (1.3; its public numba path: `solver.simulation.simulate`,
  circle intersections, nearest-to-previous branch), one design, 360 iterations per call, against
  jaxlink's `jl.solve` of one design over the same 360 angles (points included), 200 calls in a
  row from Python, the two taking turns in every round; each result kept, and each dropped;
- **pylinkage numba core over many designs**: the same compiled `simulate` called in a Python loop
  over designs, with each design's constraint array and start positions written directly (no
  `Linkage` rebuild: the fastest way pylinkage can sweep designs; single-threaded, as pylinkage is);
- **jaxlink** `jl.solve(mech, phis, P, q0)` (default `method="auto"`: closed-form dyads), which
  returns the coupler point too (`Solution.points`): the call the README shows, one call for all
  designs, float64 and float32.

Error: max |ΔP| (m) of the coupler point against the Freudenstein closed form (numpy, float64) on
the start branch, over every design and angle. Time: best of repeats after compilation. Run:

    python benchmarks/fourbar_vs_pylinkage.py [--quick] [--designs B] [--json OUT]

Prints "pylinkage not installed" (and measures jaxlink only) when pylinkage or numba is missing.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _cores import cores, default_output, pin_from_argv, run_pinned  # noqa: E402

pin_from_argv()  # --cores N: before JAX starts its threads
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxlink as jl  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))
from closed_forms import fourbar_freudenstein  # noqa: E402

STEPS = 360


def designs(mech, B, seed=0):
    rng = np.random.default_rng(seed)
    P = np.repeat(mech.parameters[None], B, axis=0)
    for name in ("a", "b", "c", "d", "cx", "cy"):
        P[:, mech.parameter_index(name)] *= 1 + 0.03 * rng.uniform(-1, 1, B)
    return P


def closed_form_points(mech, P, phis, branch):
    ix = {n: mech.parameter_index(n) for n in ("a", "b", "c", "d", "cx", "cy")}
    a, b, c, d, cx, cy = (P[:, ix[n]][:, None] for n in ("a", "b", "c", "d", "cx", "cy"))
    phi3, phi4 = fourbar_freudenstein(a, b, c, d, phis[None], branch)
    x = a * np.cos(phis) + cx * np.cos(phi3) - cy * np.sin(phi3)
    y = a * np.sin(phis) + cx * np.sin(phi3) + cy * np.cos(phi3)
    return np.stack([x, y], -1), phi3, phi4


def best_of(f, repeats):
    best, out = math.inf, None
    for _ in range(repeats):
        t = time.perf_counter()
        out = f()
        jax.block_until_ready(out)
        best = min(best, time.perf_counter() - t)
    return best, out


# ----------------------------------------------------------------------------- pylinkage


def pylinkage_available():
    try:
        import numba  # noqa: F401
        import pylinkage  # noqa: F401
        from pylinkage._numba_compat import HAS_NUMBA
    except ImportError:
        return False
    return bool(HAS_NUMBA)


def pylinkage_linkage(p, branch_xy):
    """pylinkage four-bar (+ coupler point) of one design p = (a, b, c, d, cx, cy) in metres."""
    import pylinkage as pl

    a, b, c, d, cx, cy = p
    O1, O2 = pl.Ground(0.0, 0.0), pl.Ground(float(d), 0.0)
    crank = pl.Crank(anchor=O1, radius=float(a), angular_velocity=2 * math.pi / STEPS, initial_angle=0.0)
    rocker = pl.RRRDyad(crank.output, O2, distance1=float(b), distance2=float(c),
                        x=float(branch_xy[0]), y=float(branch_xy[1]))
    point = pl.FixedDyad(crank.output, rocker, distance=float(math.hypot(cx, cy)), angle=float(math.atan2(cy, cx)))
    return pl.Linkage([O1, O2, crank, rocker, point])


def run_pylinkage(P6, B_joint0, repeats, log):
    """Returns dict of rates and the coupler-point trajectory (B, STEPS, 2) at φ_k = (k+1)·Δ
    (pylinkage steps the crank before it records)."""
    from pylinkage.solver.simulation import simulate

    out = {}
    # 1. the public API, one design, step_fast(360) per call: timed beside jaxlink's single-design
    # call (`single_design_calls`)
    lk = pylinkage_linkage(P6[0], B_joint0[0])
    lk.step_fast(iterations=STEPS)  # compile (numba cache) and build solver data

    # 2. the numba core over many designs, constraint arrays written directly
    sd = lk._solver_data
    base_pos = np.array(sd.positions)
    base_con = np.array(sd.constraints)
    B = len(P6)
    cons = np.repeat(base_con[None], B, axis=0)
    pos0 = np.repeat(base_pos[None], B, axis=0)
    a, b, c, d, cx, cy = P6.T
    cons[:, 0], cons[:, 2], cons[:, 3] = a, b, c
    cons[:, 4], cons[:, 5] = np.hypot(cx, cy), np.arctan2(cy, cx)
    pos0[:, 1] = np.stack([d, 0 * d], 1)
    pos0[:, 2] = np.stack([a, 0 * a], 1)
    pos0[:, 3] = B_joint0
    args = (sd.joint_types, sd.parent_indices, sd.constraint_offsets, sd.solve_order)

    def sweep():
        traj = np.empty((B, STEPS, 2))
        for i in range(B):
            tr = simulate(pos0[i].copy(), cons[i], *args, STEPS, 1.0)
            traj[i] = tr[:, 4]
        return traj

    sweep()
    t, traj = best_of(sweep, repeats)
    out["core_positions_per_s"] = B * STEPS / t
    out["core_seconds"] = t
    log(f"pylinkage numba core, loop over {B} designs", "float64", B * STEPS / t, None)
    return out, traj, lk


def single_design_calls(calls: dict, n_calls: int, rounds: int) -> dict:
    """Seconds per call of each `calls[name]()` (one design over one revolution), called
    `n_calls` times in a row from Python, best of `rounds` rounds; the callables take turns within
    every round (the same machine state for each). Two ways a user loops, each timed:

    - `kept`: every result kept (`[f() for _ in range(n)]`);
    - `dropped`: each result replaced by the next (`for _ in range(n): r = f()`), so that its
      buffers are freed and reused.
    """
    def kept(f):
        return [f() for _ in range(n_calls)][-1]

    def dropped(f):
        r = None
        for _ in range(n_calls):
            r = f()
        return r

    best = {(k, m): math.inf for k in calls for m in ("kept", "dropped")}
    for f in calls.values():
        jax.block_until_ready(f())
    for _ in range(rounds):
        for (k, m) in best:
            t = time.perf_counter()
            jax.block_until_ready((kept if m == "kept" else dropped)(calls[k]))
            best[k, m] = min(best[k, m], (time.perf_counter() - t) / n_calls)
    return best


# ----------------------------------------------------------------------------- main


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer designs and repeats (< 1 minute)")
    ap.add_argument("--designs", type=int, default=None, help="designs (default 5000; quick 1000)")
    ap.add_argument("--json", default=None, help="JSON output (default results/latest/fourbar_vs_pylinkage.json)")
    ap.add_argument("--cores", type=int, default=None,
                    help="pin this run to N cores (default: all; without it, jaxlink is also measured "
                         "pinned to one core in a subprocess: pylinkage's numba loop runs on one)")
    ap.add_argument("--jaxlink-only", action="store_true", help="skip pylinkage")
    args = ap.parse_args(argv)
    args.json = args.json or default_output("fourbar_vs_pylinkage.json")
    B = args.designs or (1000 if args.quick else 5000)
    repeats = 3 if args.quick else 7
    mech = jl.load("four-bar")
    names = ("a", "b", "c", "d", "cx", "cy")
    assert tuple(mech.parameter_names) == names
    P = designs(mech, B)
    # the start branch: the file's guess at φ = 0 (the Freudenstein branch it selects)
    phis_all = 2 * np.pi * np.arange(STEPS + 1) / STEPS  # 0 … 360°, pylinkage uses 1 … 360
    sol0 = jl.solve(mech, phis_all[:1])
    ref_m, _, phi4m = closed_form_points(mech, mech.parameters[None], phis_all[:1], -1)
    branch = -1 if abs(float(np.angle(np.exp(1j * (float(sol0.q[0, 1]) - phi4m[0, 0]))))) < 1e-9 else 1
    ref_xy, phi3, phi4 = closed_form_points(mech, P, phis_all, branch)
    rows = []

    def log(name, dtype, rate, err):
        rows.append((name, dtype, rate, err))
        e = "" if err is None else f"{err:10.2e}"
        print(f"  {name:56s} {dtype:8s} {rate:12.4g} pos/s {e}", flush=True)

    results = {"designs": B, "steps": STEPS, "branch": branch}
    lk = None
    if pylinkage_available() and not args.jaxlink_only:
        import pylinkage

        # rocker pin B at φ = 0 on the start branch, the nearest-point seed of pylinkage
        bx = P[:, 3] + P[:, 2] * np.cos(phi4[:, 0])
        by = P[:, 2] * np.sin(phi4[:, 0])
        pl_out, traj, lk = run_pylinkage(P, np.stack([bx, by], 1), repeats, log)
        pl_err = float(np.nanmax(np.abs(traj - ref_xy[:, 1:])))
        pl_nan = float(np.mean(~np.isfinite(traj)))
        rows[-1] = rows[-1][:3] + (pl_err,)
        results.update({f"pylinkage_{k}": v for k, v in pl_out.items()})
        results["pylinkage_max_abs_error_m"] = pl_err
        results["pylinkage_nan_fraction"] = pl_nan
        results["pylinkage_version"] = pylinkage.__version__
        print(f"  pylinkage error max|ΔP| = {pl_err:.2e} m (nan fraction {pl_nan:.3g})")
    else:
        print("pylinkage not installed (pip install -e '.[bench]' numba): measuring jaxlink only")

    phis = phis_all[1:]
    for dtype in (np.float64, np.float32):
        Pd = jnp.asarray(P, dtype=dtype)
        ph = jnp.asarray(phis, dtype=dtype)

        q0 = jnp.asarray(mech.guess, dtype=dtype)

        def f(Pd, ph=ph, q0=q0):  # the call the README shows: one jitted solve, points included
            sol = jl.solve(mech, ph, Pd, q0)
            return sol.points[:, :, 0], sol.converged

        t = time.perf_counter()
        jax.block_until_ready(f(Pd))
        compile_s = time.perf_counter() - t
        tbest, (xy, conv) = best_of(lambda: f(Pd), repeats)
        err = float(np.max(np.abs(np.asarray(xy, dtype=float) - ref_xy[:, 1:])))
        name = np.dtype(dtype).name
        log(f"jaxlink solve with points ({B} designs)", name, B * STEPS / tbest, err)
        results[f"jaxlink_{name}_positions_per_s"] = B * STEPS / tbest
        results[f"jaxlink_{name}_max_abs_error_m"] = err
        results[f"jaxlink_{name}_compile_s"] = compile_s - tbest
        results[f"jaxlink_{name}_converged_fraction"] = float(np.mean(np.asarray(conv)))

    # one design over one revolution, called repeatedly from Python (the README's call, points
    # included), against pylinkage's step_fast: per-call latency, not batch throughput; the two
    # take turns in every round, each result kept and each dropped (`single_design_calls`)
    ph1 = jnp.asarray(phis, dtype=np.float64)
    p1 = jnp.asarray(P[0], dtype=np.float64)
    q01 = jnp.asarray(mech.guess, dtype=np.float64)
    one = jl.solve(mech, ph1, p1, q01)
    err1 = float(np.max(np.abs(np.asarray(one.points[:, 0], dtype=float) - ref_xy[0, 1:])))
    calls = {"jaxlink": lambda: jl.solve(mech, ph1, p1, q01)}
    if lk is not None:
        calls["pylinkage"] = lambda: lk.step_fast(iterations=STEPS)
    n_calls = 200
    per_call = single_design_calls(calls, n_calls, 15 if args.quick else 30)
    for m in ("kept", "dropped"):
        sfx = "" if m == "kept" else "_dropped"
        t1 = per_call["jaxlink", m]
        log(f"jaxlink solve, 1 design per call ({m})", "float64", STEPS / t1, err1)
        results[f"jaxlink_single_design_positions_per_s{sfx}"] = STEPS / t1
        results[f"jaxlink_single_design_call_ms{sfx}"] = 1e3 * t1
        if lk is not None:
            t2 = per_call["pylinkage", m]
            log(f"pylinkage Linkage.step_fast, 1 design per call ({m})", "float64", STEPS / t2, None)
            results[f"pylinkage_step_fast_positions_per_s{sfx}"] = STEPS / t2
            results[f"pylinkage_step_fast_call_ms{sfx}"] = 1e3 * t2
            results[f"ratio_single_design_vs_step_fast{sfx}"] = t2 / t1
    results["jaxlink_single_design_max_abs_error_m"] = err1

    if args.cores is None:  # jaxlink pinned to one core, like pylinkage's numba loop
        extra = ["--jaxlink-only", "--designs", str(B)] + (["--quick"] if args.quick else [])
        one = run_pinned(os.path.abspath(__file__), extra, 1)
        if one:
            for k in ("float64", "float32"):
                rate = one[f"jaxlink_{k}_positions_per_s"]
                results[f"jaxlink_{k}_positions_per_s_1core"] = rate
                log("jaxlink solve with points, 1 core", k, rate, one[f"jaxlink_{k}_max_abs_error_m"])
    if "pylinkage_core_positions_per_s" in results:
        for k in ("float64", "float32"):
            if f"jaxlink_{k}_positions_per_s_1core" in results:
                results[f"ratio_{k}_1core_vs_pylinkage_core"] = (results[f"jaxlink_{k}_positions_per_s_1core"]
                                                                 / results["pylinkage_core_positions_per_s"])
            results[f"ratio_{k}_vs_pylinkage_core"] = (results[f"jaxlink_{k}_positions_per_s"]
                                                      / results["pylinkage_core_positions_per_s"])
            results[f"ratio_{k}_vs_pylinkage_step_fast"] = (results[f"jaxlink_{k}_positions_per_s"]
                                                           / results["pylinkage_step_fast_positions_per_s"])
    print(f"\nfour-bar + coupler point, {B} designs x {STEPS} steps; {cores()} cores, jax {jax.__version__}")
    print(f"{'method':56s} {'dtype':8s} {'positions/s':>12s} {'max|ΔP| m':>10s}")
    for name, dt, rate, err in rows:
        print(f"{name:56s} {dt:8s} {rate:12.4g} {'' if err is None else f'{err:10.2e}'}")
    if "ratio_float64_vs_pylinkage_core" in results:
        print(f"jaxlink float64 = {results['ratio_float64_vs_pylinkage_core']:.2f}x pylinkage's numba core "
              f"over designs "
              f"({results['ratio_float64_vs_pylinkage_step_fast']:.2f}x its step_fast); float32 "
              f"{results['ratio_float32_vs_pylinkage_core']:.2f}x")
    if "ratio_single_design_vs_step_fast" in results:
        print(f"one design x {STEPS} positions per call, {n_calls} calls in a row: jaxlink "
              f"{results['jaxlink_single_design_call_ms']:.3f} ms per call (results kept) = "
              f"{results['ratio_single_design_vs_step_fast']:.2f}x pylinkage's step_fast; "
              f"{results['jaxlink_single_design_call_ms_dropped']:.3f} ms (each dropped) = "
              f"{results['ratio_single_design_vs_step_fast_dropped']:.2f}x")
    if "ratio_float64_1core_vs_pylinkage_core" in results:
        print(f"pinned to 1 core (as pylinkage): jaxlink float64 = "
              f"{results['ratio_float64_1core_vs_pylinkage_core']:.2f}x pylinkage's numba core")
    results["cores"] = cores()
    results["machine"] = {"cpus": os.cpu_count(), "platform": platform.platform(), "jax": jax.__version__}
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)
        print(f"wrote {args.json}")
    return results


if __name__ == "__main__":
    main()
