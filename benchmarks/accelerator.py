"""The feed six-bar on whatever device JAX finds (GPU, TPU or CPU): batch scaling, memory,
gradients and Monte Carlo, with a hand-written kernel of the same mechanism in the same run.

For each batch of B positions (designs × 72 crank angles), 1e3 … 1e8 (`--quick`: … 1e6), float64
and float32, every configuration in its own subprocess (so that its peak device memory is its own):

- jaxlink `jl.solve(mech, phis, P, q0, points=False)` — the README's call — closed form (default)
  and Newton continuation (`NewtonOptions(method="continuation")`);
- the hand-written JAX kernel of `throughput.py` (the feed's two circle intersections, nothing
  general), jitted, on the same designs;
- the error: max |Δq| (rad) against the hand-written kernel in float64 (the same branch);
- peak device memory (`Device.memory_stats()["peak_bytes_in_use"]`, GPU/TPU; None on the CPU) and
  whether the configuration ran out of memory (recorded, not fatal).

Then, in one more subprocess each: the gradient of a path objective (sum of the feed point's
squared coordinates over the revolution) with respect to every design's parameters against the
forward solve (every output: the goal's denominator) and against the objective's value (which
reads one point: XLA computes less), at 1e3 and 1e5 designs; Monte Carlo designs/s of `jaxlink.optimize.run` on
`sewing-feed-opt` (36 samples) at the default chunk and at a large one. Run:

    python benchmarks/accelerator.py [--quick] [--json OUT]

Writes `benchmarks/results/latest/accelerator.json` by default (`--json` elsewhere).
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
import json, math, sys, time
sys.path.insert(0, HERE)
import jax
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp, numpy as np
import jaxlink as jl
from throughput import handwritten_branches, handwritten_closed_form

kind, positions, dtype = sys.argv[1], int(float(sys.argv[2])), sys.argv[3]
dt = jnp.float64 if dtype == "float64" else jnp.float32
mech = jl.load("sewing-feed")
N = 72
B = max(1, positions // N)
rng = np.random.default_rng(0)
P = np.repeat(mech.parameters[None], B, axis=0)
for name in ("l2", "l22", "gamma"):
    P[:, mech.parameter_index(name)] *= 1 + 0.01 * rng.uniform(-1, 1, B)
phis = mech.input_start + 2 * np.pi * np.arange(N) / N
dev = jax.devices()[0]


def peak():
    try:
        return int(dev.memory_stats()["peak_bytes_in_use"])
    except Exception:
        return None


def timed(f, reps):
    t = time.perf_counter(); out = jax.block_until_ready(f()); first = time.perf_counter() - t
    best = math.inf
    for _ in range(reps):
        t = time.perf_counter(); out = jax.block_until_ready(f()); best = min(best, time.perf_counter() - t)
    return best, first - best, out


reps = 5 if B * N <= 1e6 else 2
out = {"kind": kind, "positions": B * N, "designs": B, "dtype": dtype, "device": str(dev.device_kind),
       "platform": dev.platform}
try:
    Pd = jnp.asarray(P, dt); ph = jnp.asarray(phis, dt); q0 = jnp.asarray(mech.guess, dt)
    s1, s2 = handwritten_branches(P[0], phis[0], np.asarray(jl.solve(mech, phis[:1], P[0], mech.guess).q[0]))
    hw = jax.jit(lambda Pd, ph: handwritten_closed_form(Pd, ph, s1, s2))
    if kind == "handwritten":
        t, c, q = timed(lambda: hw(Pd, ph), reps)
        ref = q
    else:
        opts = jl.NewtonOptions(method="continuation") if kind == "continuation" else jl.NewtonOptions()
        t, c, sol = timed(lambda: jl.solve(mech, ph, Pd, q0, options=opts, points=False), reps)
        q = sol.q
        out["converged_fraction"] = float(jnp.mean(sol.converged))
        del sol
        ref = hw(jnp.asarray(P), jnp.asarray(phis))
    d = jnp.abs(jnp.angle(jnp.exp(1j * (q.astype(jnp.float64) - ref.astype(jnp.float64)))))
    out.update(seconds=t, compile_s=c, positions_per_s=B * N / t, max_abs_error_rad=float(jnp.max(d)))
except Exception as exc:  # out of memory (recorded: the goal is that it never happens)
    msg = str(exc)
    out.update(error=("out_of_memory" if "RESOURCE_EXHAUSTED" in msg or "out of memory" in msg.lower()
                      else type(exc).__name__), message=msg[:300])
out["peak_device_bytes"] = peak()
print("RESULT " + json.dumps(out))
"""

GRAD = r"""
import json, math, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp, numpy as np
import jaxlink as jl

B = int(float(sys.argv[1]))
mech = jl.load("sewing-feed")
N = 72
rng = np.random.default_rng(0)
P = np.repeat(mech.parameters[None], B, axis=0)
for name in ("l2", "l22", "gamma"):
    P[:, mech.parameter_index(name)] *= 1 + 0.01 * rng.uniform(-1, 1, B)
P = jnp.asarray(P)
phis = jnp.asarray(mech.input_start + 2 * np.pi * np.arange(N) / N)
k = mech.point_names.index("Z")


def objective(P):
    sol = jl.solve(mech, phis, P, jnp.asarray(mech.guess))
    return jnp.sum(sol.points[..., k, :] ** 2)


fwd = jax.jit(objective)
grad = jax.jit(jax.grad(objective))
# the forward solve itself: every output `solve` returns (q, every point, the result codes), the
# goal's denominator (issue 12: gradient <= 2x the forward solve); `fwd` reads one point only
solve = jax.jit(lambda P: jl.solve(mech, phis, P, jnp.asarray(mech.guess)))


def timed(f, reps=3):
    jax.block_until_ready(f(P))
    best = math.inf
    for _ in range(reps):
        t = time.perf_counter(); jax.block_until_ready(f(P)); best = min(best, time.perf_counter() - t)
    return best


tf, tg, ts = timed(fwd), timed(grad), timed(solve)
# the gradient against central differences in one parameter of one design (float64)
g = np.asarray(grad(P))
i, j, h = 0, mech.parameter_index("l3"), 1e-7
e = jnp.zeros_like(P).at[i, j].set(h)
fd = float((objective(P + e) - objective(P - e)) / (2 * h))
print("RESULT " + json.dumps({"designs": B, "positions": B * N, "forward_s": tf, "solve_s": ts, "gradient_s": tg,
                              "gradient_over_forward": tg / tf, "gradient_over_solve": tg / ts,
                              "fd_rel_error": abs(g[i, j] - fd) / abs(fd)}))
"""

MONTECARLO = r"""
import json, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import jaxlink as jl
from jaxlink.optimize import Evaluator, problem_from, run

budget, chunk = int(float(sys.argv[1])), sys.argv[2]
problem = problem_from(jl.load("sewing-feed-opt"))
kw = {} if chunk == "default" else {"chunk": int(float(chunk))}
ev = Evaluator(problem, **kw)
# the warm-up covers two whole chunks: a smaller one compiles only a smaller batch's shape, and the
# timed search would then compile the full chunk inside its time
warm = min(budget, 2 * ev.chunk)
run(problem, "montecarlo", budget=warm, seed=1, **kw)
# a search on a new Problem builds a new Evaluator: its batch, report and certificate compile
# again (a second search on the same Problem reuses its Evaluator)
t = time.perf_counter()
res = run(problem_from(jl.load("sewing-feed-opt")), "montecarlo", budget=budget, seed=0, **kw)
wall_new = time.perf_counter() - t
# the steady rate: one Evaluator, warmed by a first search (its compiled functions reused)
run(ev, "montecarlo", budget=warm, seed=1)
t = time.perf_counter()
res = run(ev, "montecarlo", budget=budget, seed=0)
wall = time.perf_counter() - t
doc = res.to_json()
print("RESULT " + json.dumps({"chunk": chunk, "evaluations": doc["evaluations"], "wall_s": wall,
                              "wall_new_evaluator_s": wall_new, "chunk_designs": ev.chunk,
                              "samples": len(problem.phis), "designs_per_s": doc["evaluations"] / wall,
                              "best": doc.get("best", {}).get("objective")}))
"""


def child(code: str, args: list[str], timeout: float = 900) -> dict:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([HERE, os.path.dirname(HERE), os.environ.get("PYTHONPATH", "")]))
    try:
        r = subprocess.run([sys.executable, "-c", code.replace("HERE", repr(HERE)), *args], env=env,
                           capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": "timeout", "args": args}
    for line in r.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    tail = (r.stderr or r.stdout).strip().splitlines()[-3:]
    oom = any("RESOURCE_EXHAUSTED" in t or "out of memory" in t.lower() for t in tail)
    return {"error": "out_of_memory" if oom else f"exit {r.returncode}", "message": " | ".join(tail)[:300],
            "args": args}


def fmt(x, spec=".3g"):
    return "-" if x is None else format(x, spec)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="sizes up to 1e6 positions, small Monte Carlo")
    ap.add_argument("--max-positions", type=float, default=None, help="largest batch (default 1e8; quick 1e6)")
    ap.add_argument("--min-positions", type=float, default=0, help="smallest batch (default 1e3)")
    ap.add_argument("--only", choices=("scaling", "gradient", "montecarlo"), action="append",
                    help="run only these parts (repeatable; default all three)")
    ap.add_argument("--continuation-max", type=float, default=None,
                    help="largest batch for Newton continuation (default 1e8; quick 1e5)")
    ap.add_argument("--mc-budget", type=float, default=None,
                    help="Monte Carlo designs per timed search (default 2e6; quick 20000)")
    ap.add_argument("--mc-chunks", default=None,
                    help="comma-separated Monte Carlo chunks ('default': the Evaluator's own; "
                         "default: default,100000)")
    ap.add_argument("--json", metavar="OUT", help="write the results as JSON (default: benchmarks/results/latest/)")
    args = ap.parse_args(argv)
    top = args.max_positions or (1e6 if args.quick else 1e8)
    cont_top = args.continuation_max or (1e5 if args.quick else 1e8)
    sizes = [s for s in (1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 3e8) if args.min_positions <= s <= top]
    parts = set(args.only or ("scaling", "gradient", "montecarlo"))

    import jax

    dev = jax.devices()[0]
    print(f"device: {dev.platform} {dev.device_kind} ({len(jax.devices())} device(s)), jax {jax.__version__}")
    rows = []
    print(f"{'positions':>10} {'dtype':>8} {'method':>13} {'pos/s':>10} {'vs hand':>8} {'compile s':>9} "
          f"{'peak MB':>9} {'max err rad':>11}")
    for s in (sizes if "scaling" in parts else ()):
        for dtype in ("float64", "float32"):
            per = {}
            for kind in ("handwritten", "closed_form", "continuation"):
                if kind == "continuation" and s > cont_top:
                    continue
                r = child(CHILD, [kind, str(int(s)), dtype])
                r.setdefault("kind", kind)
                r.setdefault("dtype", dtype)
                r.setdefault("positions", int(s))
                per[kind] = r
                hand = per.get("handwritten", {}).get("positions_per_s")
                if r.get("positions_per_s") and hand:
                    r["ratio_vs_handwritten"] = r["positions_per_s"] / hand
                rows.append(r)
                peak = r.get("peak_device_bytes")
                print(f"{r['positions']:>10.3g} {dtype:>8} {kind:>13} {fmt(r.get('positions_per_s')):>10} "
                      f"{fmt(r.get('ratio_vs_handwritten'), '.2f'):>8} {fmt(r.get('compile_s'), '.1f'):>9} "
                      f"{fmt(None if peak is None else peak / 2**20, '.0f'):>9} "
                      f"{fmt(r.get('max_abs_error_rad'), '.1e'):>11} {r.get('error', '')}", flush=True)

    grads = []
    for B in ((1e3, 1e4) if args.quick else (1e3, 1e5)) if "gradient" in parts else ():
        g = child(GRAD, [str(int(B))])
        grads.append(g)
        print(f"gradient at {int(B)} designs: {fmt(g.get('gradient_over_solve'), '.2f')}× the forward solve "
              f"({fmt(g.get('solve_s'))} s), {fmt(g.get('gradient_over_forward'), '.2f')}× the objective's value "
              f"({fmt(g.get('forward_s'))} s); FD rel. error {fmt(g.get('fd_rel_error'), '.1e')} "
              f"{g.get('error', '')}", flush=True)

    mcs = []
    budget = int(args.mc_budget or (20000 if args.quick else 2_000_000))
    chunks = args.mc_chunks.split(",") if args.mc_chunks else ["default", "16384" if args.quick else "100000"]
    for chunk in chunks if "montecarlo" in parts else ():
        m = child(MONTECARLO, [str(budget), chunk])
        mcs.append(m)
        print(f"Monte Carlo (sewing-feed-opt, chunk {chunk}): {fmt(m.get('designs_per_s'))} designs/s "
              f"({m.get('evaluations')} evaluations in {fmt(m.get('wall_s'))} s on a warm evaluator; "
              f"{fmt(m.get('wall_new_evaluator_s'))} s as a new run) {m.get('error', '')}", flush=True)

    out = {"device": {"platform": dev.platform, "kind": dev.device_kind, "count": len(jax.devices())},
           "jax": jax.__version__, "quick": args.quick, "scaling": rows, "gradient": grads, "montecarlo": mcs}
    path = args.json or default_output("accelerator.json")
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, "w") as f:
        json.dump(out, f, indent=1)
    print(f"wrote {path}")
    return out


if __name__ == "__main__":
    main()
