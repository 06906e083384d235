"""Position-solve throughput on the sewing-machine feed six-bar (seed 000), all in one run.

Solves (design, crank angle) pairs of the feed six-bar's 4 unknown angles and compares, measured
in the same run on the same designs:

- jaxlink, float64 and float32, default method (closed-form dyads, `method="auto"`), and Newton
  with continuation (`method="continuation"`), `jit` + `vmap` over designs;
- a hand-written JAX kernel for this one mechanism (its two circle intersections, no generality);
- scipy `fsolve` per angle in a Python loop, each angle started from the previous solution
  (the MATLAB way of the seed);
- numpy Newton vectorized over designs (`np.linalg.solve` on the (B, 4, 4) stack), continuation
  over the angles.

Every method's error is the max |ΔZ| (m) of the feed-dog point against a tight float64 reference
(numpy Newton iterated to 1e-15 m), printed beside its time. Run:

    python benchmarks/throughput.py [--quick] [--designs B] [--json OUT]

Prints a table; `--json OUT` writes `positions_per_s`, `positions_per_s_f32`,
`fsolve_positions_per_s`, `numpy_positions_per_s`, `max_abs_error_m` and more.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _cores import cores, pin_from_argv, run_pinned  # noqa: E402

pin_from_argv()  # --cores N: before JAX starts its threads
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxlink as jl  # noqa: E402

NAMES = ("l2", "l22", "gamma", "l3", "l4", "l44", "l5", "l6", "l66", "l7", "l8")


# ----------------------------------------------------------------------------- the feed, by hand


def feed_residual_np(q, phi, P):
    """Φ of the feed six-bar (loop 1 with l44, loop 2 with +l22), numpy, batched over rows of P."""
    l2, l22, g, l3, l4, l44, l5, l6, _, l7, l8 = P.T
    f3, f4, f5, f6 = q.T
    c2, s2 = np.cos(phi), np.sin(phi)
    return np.stack([
        l2 * c2 + l3 * np.cos(f3) + l44 * np.cos(f4) - l8,
        l2 * s2 + l3 * np.sin(f3) + l44 * np.sin(f4) - l7,
        l2 * c2 + l3 * np.cos(f3) + l4 * np.cos(f4) + l5 * np.cos(f5) + l6 * np.cos(f6) + l22 * np.cos(phi + g),
        l2 * s2 + l3 * np.sin(f3) + l4 * np.sin(f4) + l5 * np.sin(f5) + l6 * np.sin(f6) + l22 * np.sin(phi + g),
    ], axis=-1)


def feed_jacobian_np(q, P):
    l2, l22, g, l3, l4, l44, l5, l6, _, l7, l8 = P.T
    f3, f4, f5, f6 = q.T
    z = np.zeros_like(f3)
    return np.stack([
        np.stack([-l3 * np.sin(f3), -l44 * np.sin(f4), z, z], -1),
        np.stack([l3 * np.cos(f3), l44 * np.cos(f4), z, z], -1),
        np.stack([-l3 * np.sin(f3), -l4 * np.sin(f4), -l5 * np.sin(f5), -l6 * np.sin(f6)], -1),
        np.stack([l3 * np.cos(f3), l4 * np.cos(f4), l5 * np.cos(f5), l6 * np.cos(f6)], -1),
    ], axis=-2)


def feed_point_np(q, phi, P):
    l2, l22, g, l3, l4, l44, l5, l6, l66, l7, l8 = P.T
    f3, f4, f5, f6 = q.T
    x = l2 * np.cos(phi) + l3 * np.cos(f3) + l4 * np.cos(f4) + (l6 + l66) * np.cos(f6)
    y = l2 * np.sin(phi) + l3 * np.sin(f3) + l4 * np.sin(f4) + (l6 + l66) * np.sin(f6)
    return np.stack([x, y], -1)


def numpy_newton(P, phis, q0, tol=1e-13, max_steps=30):
    """Newton vectorized over designs, continuation over the angles (previous solution = guess)."""
    B = P.shape[0]
    q = np.broadcast_to(q0, (B, 4)).copy()
    out = np.empty((B, len(phis), 4))
    for k, phi in enumerate(phis):
        for _ in range(max_steps):
            r = feed_residual_np(q, phi, P)
            if np.max(np.abs(r)) < tol:
                break
            q = q - np.linalg.solve(feed_jacobian_np(q, P), r[..., None])[..., 0]
        out[:, k] = q
    return out


def fsolve_loop(P, phis, q0):
    """scipy fsolve per angle in a Python loop (the seed's MATLAB way), per design."""
    from scipy.optimize import fsolve

    out = np.empty((P.shape[0], len(phis), 4))
    for b in range(P.shape[0]):
        q = np.array(q0, dtype=float)
        for k, phi in enumerate(phis):
            q = fsolve(lambda x: feed_residual_np(x[None], phi, P[b:b + 1])[0], q, xtol=1e-13)
            out[b, k] = q
    return out


def handwritten_closed_form(P, phis, sigma1, sigma2):
    """The feed's two dyads as circle intersections, written by hand in JAX (one mechanism only)."""

    def one(p, phi):
        l2, l22, g, l3, l4, l44, l5, l6, l66, l7, l8 = (p[i] for i in range(11))
        c2, s2 = jnp.cos(phi), jnp.sin(phi)
        bx, by = l2 * c2, l2 * s2
        # dyad 1: B + l3 e3 + l44 e4 = E
        wx, wy = l8 - bx, l7 - by
        w = jnp.sqrt(wx * wx + wy * wy)
        x = (w * w + l3 * l3 - l44 * l44) / (2 * w)
        h = jnp.sqrt(jnp.maximum(l3 * l3 - x * x, 0.0))
        ux, uy = (x * wx - sigma1 * h * wy) / w, (x * wy + sigma1 * h * wx) / w
        e3x, e3y = ux / l3, uy / l3
        e4x, e4y = (wx - ux) / l44, (wy - uy) / l44
        # dyad 2: B + l3 e3 + l4 e4 + l5 e5 + l6 e6 + l22 e(phi+g) = 0
        cg, sg = jnp.cos(g), jnp.sin(g)
        vx = -(bx + l3 * e3x + l4 * e4x + l22 * (c2 * cg - s2 * sg))
        vy = -(by + l3 * e3y + l4 * e4y + l22 * (s2 * cg + c2 * sg))
        v = jnp.sqrt(vx * vx + vy * vy)
        x2 = (v * v + l5 * l5 - l6 * l6) / (2 * v)
        h2 = jnp.sqrt(jnp.maximum(l5 * l5 - x2 * x2, 0.0))
        u2x, u2y = (x2 * vx - sigma2 * h2 * vy) / v, (x2 * vy + sigma2 * h2 * vx) / v
        return jnp.stack([jnp.arctan2(e3y, e3x), jnp.arctan2(e4y, e4x), jnp.arctan2(u2y, u2x),
                          jnp.arctan2(vy - u2y, vx - u2x)])

    return jax.vmap(lambda p: jax.vmap(lambda f: one(p, f))(phis))(P)


def feed_batch(B, N=72, seed=0):
    """The benchmarks' feed problem: the original design with l2, l22, gamma varied by ±1 % (B
    designs), N crank angles from the file's start, and the feed point Z of a numpy Newton
    reference iterated to 1e-15 m: `(mech, P (B, 11), phis (N,), Z (B·N, 2))`."""
    mech = jl.load("sewing-feed")
    rng = np.random.default_rng(seed)
    P = np.repeat(mech.parameters[None], B, axis=0)
    for name in ("l2", "l22", "gamma"):
        P[:, mech.parameter_index(name)] *= 1 + 0.01 * rng.uniform(-1, 1, B)
    phis = mech.input_start + 2 * np.pi * np.arange(N) / N
    q_ref = numpy_newton(P, phis, mech.guess, tol=1e-15, max_steps=40)
    return mech, P, phis, feed_point_np(q_ref.reshape(-1, 4), np.tile(phis, B), np.repeat(P, N, axis=0))


def handwritten_branches(p, phi, q):
    """The branch signs (sigma1, sigma2) of `handwritten_closed_form` at a solved position q =
    (phi3, phi4, phi5, phi6): the side of each dyad's base vector on which its first link lies."""
    l2, l22, g, l3, l4, l44, l5, l6, l66, l7, l8 = p
    bx, by = l2 * np.cos(phi), l2 * np.sin(phi)
    wx, wy = l8 - bx, l7 - by
    ux, uy = l3 * np.cos(q[0]), l3 * np.sin(q[0])
    vx = -(bx + ux + l4 * np.cos(q[1]) + l22 * np.cos(phi + g))
    vy = -(by + uy + l4 * np.sin(q[1]) + l22 * np.sin(phi + g))
    u2x, u2y = l5 * np.cos(q[2]), l5 * np.sin(q[2])
    return float(np.sign(wx * uy - wy * ux)), float(np.sign(vx * u2y - vy * u2x))


# ----------------------------------------------------------------------------- timing


def best_of(f, repeats):
    times = []
    out = None
    for _ in range(repeats):
        t = time.perf_counter()
        out = f()
        jax.block_until_ready(out)
        times.append(time.perf_counter() - t)
    return min(times), out


def z_error(q, phis, P, ref_xy):
    xy = feed_point_np(np.asarray(q, dtype=float).reshape(-1, 4), np.tile(phis, P.shape[0]),
                       np.repeat(P, len(phis), axis=0))
    return float(np.max(np.abs(xy - ref_xy.reshape(-1, 2))))


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="smaller batch, fewer repeats (< 1 minute)")
    ap.add_argument("--designs", type=int, default=None, help="designs in the batch (default 10000; quick 2000)")
    ap.add_argument("--angles", type=int, default=72, help="crank angles per design (default 72)")
    ap.add_argument("--fsolve-designs", type=int, default=None, help="designs for the fsolve loop (default 4; quick 1)")
    ap.add_argument("--json", metavar="OUT", help="write the results as JSON")
    ap.add_argument("--cores", type=int, default=None,
                    help="pin this run to N cores (default: all; without it, jaxlink is also measured "
                         "pinned to one core in a subprocess, like the single-threaded baselines)")
    ap.add_argument("--jaxlink-only", action="store_true", help="skip the numpy and fsolve baselines")
    args = ap.parse_args(argv)

    B = args.designs or (2000 if args.quick else 10000)
    n_fs = args.fsolve_designs or (1 if args.quick else 4)
    repeats = 2 if args.quick else 5
    mech = jl.load("sewing-feed")
    assert mech.parameter_names == NAMES
    rng = np.random.default_rng(0)
    # designs: the seed's original with l2, l22, gamma varied by ±1 % (all assemblable)
    P = np.repeat(mech.parameters[None], B, axis=0)
    for name in ("l2", "l22", "gamma"):
        i = mech.parameter_index(name)
        P[:, i] *= 1 + 0.01 * rng.uniform(-1, 1, B)
    phis = mech.input_start + 2 * np.pi * np.arange(args.angles) / args.angles
    q0 = mech.guess
    pos = B * args.angles
    rows = []

    # tight reference (numpy Newton to 1e-15 m), independent of jaxlink
    q_ref = numpy_newton(P, phis, q0, tol=1e-15, max_steps=40)
    ref_xy = feed_point_np(q_ref.reshape(-1, 4), np.tile(phis, B), np.repeat(P, len(phis), axis=0))
    ref_xy = ref_xy.reshape(B, len(phis), 2)
    import scipy.optimize  # noqa: F401  (imported before timing)

    if args.jaxlink_only:
        t_np = t_fs = float("nan")
    else:
        # numpy batched Newton at the working tolerance, timed
        t_np, q_np = best_of(lambda: numpy_newton(P, phis, q0, tol=1e-13), 1 if args.quick else 2)
        rows.append(("numpy batched Newton (continuation)", "float64", t_np, pos, z_error(q_np, phis, P, ref_xy),
                     None))
        # fsolve loop on a few designs
        t_fs, q_fs = best_of(lambda: fsolve_loop(P[:n_fs], phis, q0), 1)
        rows.append(("scipy fsolve per angle (loop)", "float64", t_fs, n_fs * len(phis),
                     z_error(q_fs, phis, P[:n_fs], ref_xy[:n_fs]), None))

    results = {}
    for method in ("auto", "continuation"):
        for dtype in (np.float64, np.float32):
            opts = jl.NewtonOptions(method=method)
            Pd = jnp.asarray(P, dtype=dtype)
            ph = jnp.asarray(phis, dtype=dtype)
            qd = jnp.asarray(q0, dtype=dtype)
            f = lambda: jl.solve(mech, ph, Pd, qd, options=opts, points=False)  # noqa: E731 (q only, as numpy)
            t = time.perf_counter()
            sol = f()
            jax.block_until_ready(sol)
            t_first = time.perf_counter() - t
            t_run, sol = best_of(f, repeats)
            conv = float(np.mean(np.asarray(sol.converged)))
            err = z_error(sol.q, phis, P, ref_xy)
            label = "closed-form dyads (auto)" if method == "auto" else "Newton + continuation"
            rows.append((f"jaxlink {label}", np.dtype(dtype).name, t_run, pos, err, t_first - t_run))
            results[(method, np.dtype(dtype).name)] = (pos / t_run, err, conv, t_first - t_run)

    # hand-written kernel for this mechanism only
    s1, s2 = handwritten_branches(P[0], phis[0], q_ref[0, 0])
    hw = jax.jit(lambda Pd, ph: handwritten_closed_form(Pd, ph, s1, s2))
    Pj, phj = jnp.asarray(P), jnp.asarray(phis)
    t = time.perf_counter()
    jax.block_until_ready(hw(Pj, phj))
    t_first = time.perf_counter() - t
    t_hw, q_hw = best_of(lambda: hw(Pj, phj), repeats)
    rows.append(("hand-written JAX closed form (feed only)", "float64", t_hw, pos, z_error(q_hw, phis, P, ref_xy),
                 t_first - t_hw))

    np_rate = pos / t_np
    fs_rate = n_fs * len(phis) / t_fs
    one_core = None
    if args.cores is None:  # jaxlink pinned to one core, in a subprocess (the baselines use one)
        extra = ["--jaxlink-only", "--designs", str(B), "--angles", str(args.angles)]
        extra += ["--quick"] if args.quick else []
        one_core = run_pinned(os.path.abspath(__file__), extra, 1)
        if one_core:
            rows.append(("jaxlink closed-form dyads (auto), 1 core", "float64", pos / one_core["positions_per_s"], pos,
                         one_core["max_abs_error_m"], None))
            rows.append(("jaxlink closed-form dyads (auto), 1 core", "float32",
                         pos / one_core["positions_per_s_f32"], pos, one_core["max_abs_error_m_f32"], None))
            rows.append(("hand-written JAX closed form, 1 core", "float64",
                         pos / one_core["handwritten_positions_per_s"], pos, float("nan"), None))
    print(f"feed six-bar, {B} designs x {args.angles} angles = {pos} positions; "
          f"{cores()} cores, jax {jax.__version__} on {jax.devices()[0].platform}")
    print(f"{'method':44s} {'dtype':8s} {'positions/s':>12s} {'× numpy':>8s} {'× fsolve':>9s} "
          f"{'max|ΔZ| m':>10s} {'compile s':>9s}")
    for name, dt, t, n, err, comp in rows:
        rate = n / t
        print(f"{name:44s} {dt:8s} {rate:12.4g} {rate / np_rate:8.2f} {rate / fs_rate:9.1f} {err:10.2e} "
              f"{'' if comp is None else f'{comp:9.2f}'}")
    out = {
        "positions_per_s": results[("auto", "float64")][0],
        "positions_per_s_f32": results[("auto", "float32")][0],
        "fsolve_positions_per_s": fs_rate,
        "numpy_positions_per_s": np_rate,
        "max_abs_error_m": results[("auto", "float64")][1],
        "max_abs_error_m_f32": results[("auto", "float32")][1],
        "continuation_positions_per_s": results[("continuation", "float64")][0],
        "continuation_positions_per_s_f32": results[("continuation", "float32")][0],
        "continuation_max_abs_error_m": results[("continuation", "float64")][1],
        "handwritten_positions_per_s": pos / t_hw,
        "converged_fraction": results[("auto", "float64")][2],
        "ratio_vs_numpy": results[("auto", "float64")][0] / np_rate,
        "ratio_vs_fsolve": results[("auto", "float64")][0] / fs_rate,
        "ratio_vs_handwritten": results[("auto", "float64")][0] / (pos / t_hw),
        "numpy_max_abs_error_m": None if args.jaxlink_only else rows[0][4],
        "fsolve_max_abs_error_m": None if args.jaxlink_only else rows[1][4],
        "cores": cores(),
        "designs": B,
        "angles": args.angles,
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "jax": jax.__version__},
    }
    if one_core:
        out["positions_per_s_1core"] = one_core["positions_per_s"]
        out["positions_per_s_f32_1core"] = one_core["positions_per_s_f32"]
        out["handwritten_positions_per_s_1core"] = one_core["handwritten_positions_per_s"]
        out["ratio_vs_numpy_1core"] = one_core["positions_per_s"] / np_rate
    print(f"jaxlink float64: {out['ratio_vs_fsolve']:.0f}× the fsolve loop, {out['ratio_vs_numpy']:.1f}× numpy, "
          f"{out['ratio_vs_handwritten']:.2f}× the hand-written kernel")
    if one_core:
        print(f"pinned to 1 core: {out['positions_per_s_1core']:.3g} positions/s = "
              f"{out['ratio_vs_numpy_1core']:.1f}× numpy (numpy and fsolve run on one core)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)
        print(f"wrote {args.json}")
    return out


if __name__ == "__main__":
    main()
