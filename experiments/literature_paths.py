"""The eight four-bar path-synthesis cases of benchmarks/fourbar-path/, solved by
`jaxlink optimize --method gradient` from random starts, against the literature's untimed error;
and pylinkage's own optimizer (particle swarm) on the same objective and budget for some cases.

Case files: experiments/fourbar_cases/<case>.toml (generate.py): ground pivot, frame angle, four
lengths and the coupler point are the variables, both circuits are searched.

    python experiments/literature_paths.py [--cases mkh1,mkh2,...] [--budget N] [--pylinkage mkh1,yu1]
        [--pylinkage-budget N] [--json OUT.json]
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import tempfile
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
CASES_DIR = HERE / "fourbar_cases"
BENCH = HERE.parent / "benchmarks" / "fourbar-path" / "fourbar_path_benchmarks.json"
CASES = ("mkh1", "mkh2", "mkh3", "mcgarva", "ullah", "yu1", "yu2", "wu3")


def run_cli(case: str, budget: int, seed: int, out: pathlib.Path) -> tuple[dict, float]:
    """What `jaxlink optimize CASE --method gradient` runs, through the Python API in this process;
    returns (the JSON document, wall s incl. compilation)."""
    import jaxlink
    import jaxlink.optimize

    t0 = time.perf_counter()
    problem = jaxlink.optimize.problem_from(jaxlink.load(CASES_DIR / f"{case}.toml"))
    result = jaxlink.optimize.run(problem, "gradient", budget=budget, seed=seed, out=out)
    wall = time.perf_counter() - t0
    return result.to_json(), wall


# ----------------------------------------------------------------------------- pylinkage


def _segment_sse(path, targets):
    a, b = path, np.roll(path, -1, axis=0)
    ab = b - a
    ab2 = np.maximum(np.sum(ab * ab, 1), 1e-300)
    ap = targets[:, None, :] - a[None]
    t = np.clip(np.sum(ap * ab[None], -1) / ab2[None], 0, 1)
    d = ap - t[..., None] * ab[None]
    return float(np.sum(np.min(np.sum(d * d, -1), 1)))


def pylinkage_case(case: str, budget: int, seed: int, steps: int = 360):
    """pylinkage's local-best particle swarm (its `particle_swarm_optimization` core) on the same
    objective: the SSE of the targets to the closed polyline of pylinkage's own simulated
    coupler path (`steps` crank positions), the same bounds, both circuits (one more dimension:
    circuit c2 when > 0.5). Unbuildable designs cost +inf... as pylinkage's examples do, a large
    penalty. Budget = particles × iterations = our evaluations."""
    try:
        from pylinkage.optimization.particle_swarm import _local_best_pso
    except ImportError:
        return None
    from jaxlink import load
    from jaxlink.optimize import problem_from

    pr = problem_from(load(CASES_DIR / f"{case}.toml"))
    one, evals = pylinkage_objective(pr, steps)
    lo = np.append(pr.lower, 0.0)
    hi = np.append(pr.upper, 1.0)
    n_particles = 100
    iterations = max(1, budget // n_particles)
    np.random.seed(seed)
    t0 = time.perf_counter()
    best, x = _local_best_pso(lambda X: np.array([one(xx) for xx in X]), len(lo), (lo, hi),
                              n_particles=n_particles, iterations=iterations, verbose=False)
    return {"sse": float(best), "evaluations": evals[0], "wall_s": time.perf_counter() - t0,
            "parameters": dict(zip(list(pr.names) + ["circuit"], map(float, x)))}


def pylinkage_objective(pr, steps: int = 360):
    """x = (variables in file units, circuit flag) → SSE of pylinkage's simulated path."""
    import pylinkage as pl

    targets = np.asarray(pr.option("targets"), dtype=float)
    names = list(pr.names)
    evals = [0]

    def one(x):
        d = dict(zip(names, x[:-1]))
        c2 = x[-1] > 0.5
        evals[0] += 1
        try:
            p1 = np.array([d["p1x"], d["p1y"]])
            p2 = p1 + d["l1"] * np.array([math.cos(d["a"]), math.sin(d["a"])])
            p3 = p1 + d["l2"] * np.array([math.cos(d["a"]), math.sin(d["a"])])
            r = np.linalg.norm(p2 - p3)
            u = (p2 - p3) / r
            cc = (d["l3"] ** 2 - d["l4"] ** 2 + r * r) / (2 * r)
            h2 = d["l3"] ** 2 - cc * cc
            if h2 < 0:
                return 1e9
            p4 = p3 + cc * u + (-1 if c2 else 1) * math.sqrt(h2) * np.array([-u[1], u[0]])
            O1 = pl.Ground(float(p1[0]), float(p1[1]))
            O2 = pl.Ground(float(p2[0]), float(p2[1]))
            crank = pl.Crank(anchor=O1, radius=d["l2"], angular_velocity=2 * math.pi / steps,
                             initial_angle=d["a"])
            rocker = pl.RRRDyad(crank.output, O2, distance1=d["l3"], distance2=d["l4"],
                                x=float(p4[0]), y=float(p4[1]))
            point = pl.FixedDyad(crank.output, rocker, distance=d["l5"], angle=d["g"])
            linkage = pl.Linkage([O1, O2, crank, rocker, point])
            path = np.array([coords[-1] for coords in linkage.step(iterations=steps)], dtype=float)
        except Exception:  # pylinkage raises UnbuildableError (and friends) for unbuildable designs
            return 1e9
        if path.shape != (steps, 2) or not np.all(np.isfinite(path)):
            return 1e9
        return _segment_sse(path, targets)

    return one, evals


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--budget", type=int, default=60000, help="evaluations per case (gradient search)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pylinkage", default="mkh1,yu1", help="cases also solved by pylinkage's optimizer")
    ap.add_argument("--pylinkage-budget", type=int, default=5000,
                    help="evaluations for the pylinkage comparison (both optimizers get this budget)")
    ap.add_argument("--json", help="write the table here")
    args = ap.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    ref = json.loads(BENCH.read_text()) if BENCH.exists() else {}
    rows = {}
    print(f"{'case':<9}{'reference SSE':>15}{'reached SSE':>15}{'ratio':>8}{'evaluations':>13}{'wall s':>8}"
          f"{'infeasible':>11}")
    with tempfile.TemporaryDirectory() as tmp:
        for case in args.cases.split(","):
            r, wall = run_cli(case, args.budget, args.seed, pathlib.Path(tmp) / f"{case}.json")
            refv = ref.get(case, {}).get("ref_sse_nearest", float("nan"))
            got = r["best"]["objective"]
            rows[case] = {"reference_sse": refv, "reached_sse": got, "evaluations": r["evaluations"],
                          "wall_s": wall, "search_wall_s": r["wall_s"], "infeasible_fraction": r["infeasible_fraction"],
                          "parameters": r["best"]["parameters"], "circuit": r["best"].get("circuit")}
            print(f"{case:<9}{refv:15.6g}{got:15.6g}{got / refv:8.3f}{r['evaluations']:13d}{wall:8.1f}"
                  f"{100 * r['infeasible_fraction']:10.1f}%", flush=True)
        ok = sum(1 for v in rows.values() if v["reached_sse"] is not None and v["reached_sse"] <= v["reference_sse"])
        print(f"reached SSE <= reference SSE on {ok} of {len(rows)} cases; "
              f"slowest {max(v['wall_s'] for v in rows.values()):.1f} s (incl. compilation)")

        comparison = {}
        if args.pylinkage:
            print(f"\nSame objective and budget ({args.pylinkage_budget} evaluations): jaxlink gradient vs "
                  "pylinkage particle swarm")
            for case in args.pylinkage.split(","):
                pyl = pylinkage_case(case, args.pylinkage_budget, args.seed)
                if pyl is None:
                    print("pylinkage not installed (pip install pylinkage, or the bench extra)")
                    break
                r, wall = run_cli(case, args.pylinkage_budget, args.seed, pathlib.Path(tmp) / f"{case}-pl.json")
                comparison[case] = {"jaxlink": {"sse": r["best"]["objective"], "evaluations": r["evaluations"],
                                                "wall_s": wall}, "pylinkage": pyl}
                print(f"{case:<9} jaxlink SSE {r['best']['objective']:.6g} ({r['evaluations']} evals, {wall:.1f} s)"
                      f" | pylinkage PSO SSE {pyl['sse']:.6g} ({pyl['evaluations']} evals, {pyl['wall_s']:.1f} s)"
                      f" | reference {ref.get(case, {}).get('ref_sse_nearest', float('nan')):.6g}", flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"cases": rows, "pylinkage_comparison": comparison}, fh, indent=2)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
