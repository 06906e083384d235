"""Cost of an exact gradient against a forward solve, in the same run.

Path objective of the feed six-bar (spread of the feed-dog path, 72 angles) as a function of all
11 parameters, for B designs at once (vmap), written the two ways a user writes it: with the
points from the solve (`solve_path(..., points=True)`, the README's call) and with the points from
`transfer(..., order=0)` on the solved q. Timed in one interleaved run:

- `forward`: the objective's value. XLA computes only what it reads (one point's x and y, no
  angle), so this is less than a solve;
- `solve`: the forward solve itself, every output `solve` returns (q, every point, result codes);
- `grad`: `jax.grad` of the objective by jaxlink's implicit differentiation (custom JVP);
- the same two for the points by `transfer`;
- central finite differences (2 × 11 forward solves) as the baseline.

Reports seconds, the ratios gradient/forward and gradient/solve, and the gradient's agreement with
the finite differences (and with forward mode, `jax.jacfwd`). Above 512 designs the finite
differences (and forward mode) are evaluated on the first 512 designs only (`fd_designs`;
`fd_over_forward` is then per design: their seconds per design over the forward's). Run:

    python benchmarks/gradient_cost.py [--quick] [--designs B] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _cores import default_output  # noqa: E402

import jaxlink as jl  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def best_of(f, repeats):
    best, out = math.inf, None
    for _ in range(repeats):
        t = time.perf_counter()
        out = jax.block_until_ready(f())
        best = min(best, time.perf_counter() - t)
    return best, out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--designs", type=int, default=None, help="designs B (default 512; 64 with --quick)")
    ap.add_argument("--json", default=None, help="JSON output (default results/latest/gradient_cost.json)")
    args = ap.parse_args(argv)
    args.json = args.json or default_output("gradient_cost.json")
    B = args.designs or (64 if args.quick else 512)
    repeats = 3 if args.quick or B > 10_000 else 15
    B_fd = min(B, 512)
    mech = jl.load("sewing-feed")
    phis = jnp.asarray(mech.input_start + 2 * np.pi * np.arange(72) / 72)
    rng = np.random.default_rng(0)
    P = jnp.asarray(mech.parameters[None] * (1 + 0.005 * rng.uniform(-1, 1, (B, len(mech.parameters)))))

    def spread(p):  # the points from the solve (one call)
        xy = jl.solve_path(mech, phis, p, points=True).points[:, 0]
        return jnp.sum((xy - xy.mean(0)) ** 2)

    def spread_transfer(p):  # the points from q by a second call
        s = jl.solve_path(mech, phis, p)
        xy = jl.transfer(mech, phis, s.q, p, order=0).points[:, 0]
        return jnp.sum((xy - xy.mean(0)) ** 2)

    # the forward solve itself: every output a user gets from it (q, the points, the result codes)
    solve = jax.jit(jax.vmap(lambda p: jl.solve_path(mech, phis, p, points=True)))
    fwd = jax.jit(jax.vmap(spread))
    grad = jax.jit(jax.vmap(jax.grad(spread)))
    fwd_t = jax.jit(jax.vmap(spread_transfer))
    grad_t = jax.jit(jax.vmap(jax.grad(spread_transfer)))
    h = 1e-7
    eye = jnp.eye(P.shape[1])

    @jax.jit
    def fd(P):
        # all 2 × 11 perturbed copies of the batch in one vmapped call (one compilation)
        n = P.shape[1]
        scale = jnp.abs(P) + 1e-3  # (B, n)
        steps = h * scale[None] * eye[:, None, :]  # (n, B, n)
        pert = jnp.concatenate([P[None] + steps, P[None] - steps])  # (2n, B, n)
        vals = jax.vmap(jax.vmap(spread))(pert)  # (2n, B)
        return ((vals[:n] - vals[n:]) / (2 * h * scale.T)).T  # (B, n)

    out = {}
    runs = (("solve", solve, P), ("forward", fwd, P), ("grad_implicit", grad, P), ("forward_transfer", fwd_t, P),
            ("grad_transfer", grad_t, P), ("finite_differences", fd, P[:B_fd]))
    for name, f, x in runs:
        t = time.perf_counter()
        out[f"_{name}"] = jax.block_until_ready(f(x))
        out[name] = {"seconds": math.inf, "compile_s": time.perf_counter() - t}
    # interleaved (forward, gradient, differences, forward, ...): on a shared machine the three
    # see the same load, so their ratios hold even where the absolute times do not
    for _ in range(repeats):
        for name, f, x in runs:
            tb, _ = best_of(lambda: f(x), 1)
            out[name]["seconds"] = min(out[name]["seconds"], tb)
    for name, _, _ in runs:
        out[name]["compile_s"] -= out[name]["seconds"]
    out_g = np.asarray(out.pop("_grad_implicit"))
    g, gfd = out_g[:B_fd], np.asarray(out.pop("_finite_differences"))
    g_t = np.asarray(out.pop("_grad_transfer"))
    for k in ("_solve", "_forward", "_forward_transfer"):
        out.pop(k)
    gfwd = np.asarray(jax.jit(jax.vmap(jax.jacfwd(spread)))(P[:B_fd]))
    rel = float(np.max(np.abs(g - gfd)) / np.max(np.abs(g)))
    rel_fwd = float(np.max(np.abs(g - gfwd)) / np.max(np.abs(g)))
    fd_per_design = out["finite_differences"]["seconds"] / B_fd
    res = {"designs": B, "angles": 72, "parameters": int(P.shape[1]), "fd_designs": B_fd,
           "forward_s": out["forward"]["seconds"], "grad_s": out["grad_implicit"]["seconds"],
           "fd_s": out["finite_differences"]["seconds"],
           "grad_over_forward": out["grad_implicit"]["seconds"] / out["forward"]["seconds"],
           "solve_s": out["solve"]["seconds"],
           "grad_over_solve": out["grad_implicit"]["seconds"] / out["solve"]["seconds"],
           "transfer_forward_s": out["forward_transfer"]["seconds"], "transfer_grad_s": out["grad_transfer"]["seconds"],
           "transfer_grad_over_forward": out["grad_transfer"]["seconds"] / out["forward_transfer"]["seconds"],
           "transfer_vs_solve_points_max_rel_diff": float(np.max(np.abs(g_t - out_g)) / np.max(np.abs(out_g))),
           "fd_over_forward": fd_per_design / (out["forward"]["seconds"] / B),
           "grad_vs_fd_max_rel_diff": rel, "grad_vs_forward_mode_max_rel_diff": rel_fwd,
           "compile_s": {k: v["compile_s"] for k, v in out.items()}}
    print(f"gradient cost, feed six-bar path spread, {B} designs x 72 angles, 11 parameters")
    print(f"{'':22s} {'seconds':>10s} {'x forward':>10s}")
    print(f"{'forward':22s} {res['forward_s']:10.4g} {1.0:10.2f}   (the objective: one point's x, y)")
    print(f"{'grad (implicit)':22s} {res['grad_s']:10.4g} {res['grad_over_forward']:10.2f}"
          f"   ({res['grad_over_solve']:.2f}x the forward solve)")
    print(f"{'forward solve':22s} {res['solve_s']:10.4g} {res['solve_s'] / res['forward_s']:10.2f}"
          "   (q, every point, result codes)")
    print(f"{'forward, transfer':22s} {res['transfer_forward_s']:10.4g} {1.0:10.2f}   (points by transfer(order=0))")
    print(f"{'grad, transfer':22s} {res['transfer_grad_s']:10.4g} {res['transfer_grad_over_forward']:10.2f}")
    fd_label = "central FD (22 solves)" if B_fd == B else f"central FD, {B_fd} designs"
    print(f"{fd_label:22s} {res['fd_s']:10.4g} {res['fd_over_forward']:10.2f}"
          + ("" if B_fd == B else "  (per design)"))
    print(f"grad vs FD ({B_fd} designs): max rel diff {rel:.2e}; vs forward mode {rel_fwd:.2e}; "
          f"transfer vs solve points {res['transfer_vs_solve_points_max_rel_diff']:.1e}")
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as fh:
            json.dump(res, fh, indent=1)
    return res


if __name__ == "__main__":
    main()
