"""The eight four-bar path-synthesis cases of benchmarks/fourbar-path/ from *plain* files
(experiments/fourbar_plain/, generate.py: no placement, circuits, starts, presample, iterations or
budget keys), solved as a new user would: `jaxlink optimize FILE --method gradient --seed 0
--out R.json`, through the Python API in this process. Beside the tuned table
(experiments/literature_paths.py).

Each case's best design is then checked as the issue's acceptance does: the written best file
(`R.best.toml`) solved from its own guesses at 36000 inputs over a revolution (what `jaxlink
kinematics R.best.toml --start 0 --step 0.01 --count 36000` solves for a degree file), every
position converged, and the SSE of the targets to the nearest solved point against the
literature's reference.

    python experiments/literature_paths_plain.py [--cases mkh1,...] [--time SECONDS] [--json OUT.json]
"""

from __future__ import annotations

import argparse
import json
import pathlib
import tempfile
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
CASES_DIR = HERE / "fourbar_plain"
BENCH = HERE.parent / "benchmarks" / "fourbar-path" / "fourbar_path_benchmarks.json"
CASES = ("mkh1", "mkh2", "mkh3", "mcgarva", "ullah", "yu1", "yu2", "wu3")


def dense_check(best_file: str, count: int = 36000) -> tuple[float, bool]:
    """(SSE of the targets to the nearest of `count` solved points, every position converged) of
    the best file, solved from its own guesses as `jaxlink kinematics` does."""
    import jaxlink

    mech = jaxlink.load(best_file)
    phis = np.asarray(mech.input_start + 2 * np.pi * np.arange(count) / count)
    sol = jaxlink.solve(mech, phis)
    ok = bool(np.all(np.asarray(sol.result) == jaxlink.RESULTS.converged))
    k = mech.point_names.index(mech.tables["optimize"].get("point", mech.point_names[0]))
    xy = np.asarray(sol.points)[:, k] / mech.units.length
    t = np.asarray(mech.tables["optimize"]["targets"], dtype=float)
    d2 = np.min(np.sum((t[:, None, :] - xy[None]) ** 2, axis=-1), axis=1)
    return float(np.sum(d2)), ok


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--time", type=float, default=None, help="--time of each search (default: none)")
    ap.add_argument("--json", help="write the table here")
    args = ap.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxlink
    import jaxlink.optimize

    ref = json.loads(BENCH.read_text())
    rows = {}
    print(f"{'case':<9}{'reference':>11}{'reached':>11}{'dense':>11}{'ratio':>7}{'conv':>5}{'evals':>8}"
          f"{'wall s':>8}{'search s':>9}{'compile s':>10}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for case in args.cases.split(","):
            t0 = time.perf_counter()
            problem = jaxlink.optimize.problem_from(jaxlink.load(CASES_DIR / f"{case}.toml"))
            r = jaxlink.optimize.run(problem, "gradient", seed=args.seed, time=args.time,
                                     out=pathlib.Path(tmp) / f"{case}.json")
            wall = time.perf_counter() - t0
            refv = ref[case]["ref_sse_nearest"]
            dense, ok = dense_check(r.best_file) if r.best_file else (float("nan"), False)
            rows[case] = {"reference_sse": refv, "reached_sse": r.value, "dense_sse": dense, "converged": ok,
                          "evaluations": r.evaluations, "wall_s": wall, "search_wall_s": r.search_wall_s,
                          "compile_s": r.compile_s, "parameters": r.parameters, "circuit": r.circuit,
                          "trace": list(r.trace)}
            print(f"{case:<9}{refv:11.5g}{r.value:11.5g}{dense:11.5g}{dense / refv:7.3f}{'yes' if ok else 'NO':>5}"
                  f"{r.evaluations:8d}{wall:8.1f}{r.search_wall_s:9.1f}{r.compile_s:10.1f}", flush=True)
    good = sum(1 for v in rows.values() if v["converged"] and v["dense_sse"] <= 1.05 * v["reference_sse"])
    print(f"dense SSE <= 1.05 x reference, every position converged, on {good} of {len(rows)} cases; "
          f"slowest {max(v['wall_s'] for v in rows.values()):.1f} s (incl. compilation)")
    if args.json:
        pathlib.Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        with open(args.json, "w") as fh:
            json.dump({"cases": rows}, fh, indent=2)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
