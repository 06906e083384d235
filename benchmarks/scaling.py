"""Batch-size and device scaling of the feed six-bar position solve, with peak memory.

Each configuration runs in its own subprocess (so that `XLA_FLAGS` takes effect and the peak
resident memory, `resource.getrusage(RUSAGE_SELF).ru_maxrss`, belongs to that configuration):
batch of B positions (designs × 72 angles) for B = 1e2 … 1e6, float64, on 1 host device and on
2 (`XLA_FLAGS=--xla_force_host_platform_device_count=2`, designs sharded over the devices with
`jax.sharding`). Run:

    python benchmarks/scaling.py [--quick] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

from _cores import default_output

HERE = os.path.dirname(os.path.abspath(__file__))

CHILD = r"""
import json, math, resource, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp, numpy as np
import jaxlink as jl
positions, devices = int(sys.argv[1]), int(sys.argv[2])
mech = jl.load("sewing-feed")
N = 72
B = max(devices, positions // N)
B -= B % devices
phis = jnp.asarray(mech.input_start + 2 * np.pi * np.arange(N) / N)
rng = np.random.default_rng(0)
P = mech.parameters[None] * (1 + 0.002 * rng.uniform(-1, 1, (B, len(mech.parameters))))
P = jnp.asarray(P)
if devices > 1:
    from jax.sharding import Mesh, NamedSharding, PartitionSpec as PS
    mesh = Mesh(np.array(jax.devices()[:devices]), ("d",))
    P = jax.device_put(P, NamedSharding(mesh, PS("d", None)))
f = jax.jit(lambda P: jl.solve(mech, phis, P, jnp.asarray(mech.guess)).q)
t = time.perf_counter(); jax.block_until_ready(f(P)); first = time.perf_counter() - t
best = math.inf
reps = 5 if B * N <= 1e5 else 3
for _ in range(reps):
    t = time.perf_counter(); jax.block_until_ready(f(P)); best = min(best, time.perf_counter() - t)
print(json.dumps({"positions": B * N, "devices": len(jax.devices()) if devices > 1 else 1, "seconds": best,
                  "positions_per_s": B * N / best, "compile_s": first - best,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def run(positions, devices):
    env = dict(os.environ)
    if devices > 1:
        env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + f" --xla_force_host_platform_device_count={devices}").strip()
    r = subprocess.run([sys.executable, "-c", CHILD, str(positions), str(devices)], env=env,
                       capture_output=True, text=True, timeout=900)
    if r.returncode != 0:
        return {"positions": positions, "devices": devices, "error": r.stderr.strip().splitlines()[-1:]}
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="1e2, 1e4, 1e6 only")
    ap.add_argument("--json", default=None, help="JSON output (default results/latest/scaling.json)")
    args = ap.parse_args(argv)
    args.json = args.json or default_output("scaling.json")
    sizes = [100, 10_000, 1_000_000] if args.quick else [100, 1_000, 10_000, 100_000, 1_000_000]
    rows = []
    print(f"{'positions':>10s} {'devices':>7s} {'positions/s':>12s} {'seconds':>9s} {'peak RSS MB':>11s}")
    for dev in (1, 2):
        for n in sizes:
            r = run(n, dev)
            rows.append(r)
            if "error" in r:
                print(f"{n:10d} {dev:7d} failed: {r['error']}")
            else:
                print(f"{r['positions']:10d} {r['devices']:7d} {r['positions_per_s']:12.4g} {r['seconds']:9.4f} "
                      f"{r['peak_rss_mb']:11.0f}", flush=True)
    out = {"rows": rows}
    big = {r["devices"]: r for r in rows if "error" not in r and r["positions"] >= 0.9 * max(sizes)}
    if 1 in big and 2 in big:
        out["two_device_speedup_at_largest"] = big[2]["positions_per_s"] / big[1]["positions_per_s"]
        print(f"2 host devices / 1 at the largest batch: {out['two_device_speedup_at_largest']:.2f}x")
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)
    return out


if __name__ == "__main__":
    main()
