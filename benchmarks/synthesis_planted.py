"""Path synthesis on planted linkages: is the curve traced by a random dyadic linkage found again?

Per case: a random linkage of a class — `4` the four-bar, `6w` a Watt six-bar, `6s` a Stephenson
six-bar (the built-in topologies of `jaxlink.synthesis.topology`, traced at their point E on the
last dyad's link, a random point of that link), `8` an eight-bar (a six-bar of at most 5 dyads
grown by one more dyad between two moving joints of different bodies that no dyad joins yet,
traced at the new joint; at most 10 joints) — drawn with every joint uniform in [−1, 1]², kept
when every dyad closes over the whole turn (`assembly.certify`, smallest margin ≥
`--min-margin`). Its traced joint's path (the project's exact tracer, `tracer.trace_exact`,
`--inputs` inputs) is the target: a closed one over the whole turn (even cases), or an open one
over a random sub-interval of a quarter to three quarters of the turn (odd cases).
`jaxlink.synthesize` then searches the default topologies (`--max-links`, 8: the four-bar, the
six six-bars and the nine eight-bars) within `--time-limit` seconds.

**The discretisation floor** of a target (docs/methods/synthesis.md): the distance D between two
samplings of the planted curve itself that are half a sample apart — the exact curve (traced at 20
× `--inputs` inputs) resampled by arclength to the n = 200 points of the distance, and the same
curve resampled at the arclength positions shifted by half a spacing (closed: s = (k + ½) L / n,
k = 0 … n − 1; open: s = (k + ½) L / (n − 1), k = 0 … n − 2), both normalised, at the best
rotation. A design is **recovered** when its D ≤ `--factor` × the floor (2 by default). D is the
synthesis's phase-free distance (to the other curve's polyline: the planted curve itself scores
near 0 whatever its samples' start); LInK's 2000-point metric of the same design is printed beside
it (`link2000`, `link_chamfer_2000` in the JSON).

The planted eight-bars' topology (their last dyad between two moving joints) is not among the
default set (whose eight-bars end their last dyad at a frame pivot or the crank pin); with
`--eight-given` each eight-bar case is searched once more with its own topology given
(`synthesize(topologies=[topology])`), which separates a search failure from a missing topology.

    python benchmarks/synthesis_planted.py [--count 4] [--time-limit 20] [--classes 4,6w,6s,8] [--cores 2]

Prints the table and writes benchmarks/results/synthesis_planted.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _cores import pin_from_argv  # noqa: E402

pin_from_argv()

import jax  # noqa: E402
import numpy as np  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jaxlink as jl  # noqa: E402
from jaxlink.synthesis import assembly, target, tracer  # noqa: E402
from jaxlink.synthesis import distance as D  # noqa: E402
from jaxlink.synthesis import topology as T  # noqa: E402

certify, arclength_resample, trace_exact = assembly.certify, target.arclength_resample, tracer.trace_exact

WATT = [t for t in T.topologies(6) if t.name.startswith("watt")]  # the six-bars (the eight-bars grow them)
STEPHENSON = [t for t in T.topologies(6) if t.name.startswith("stephenson")]


def eight_bar(rng: np.random.Generator) -> T.Topology:
    """A six-bar of at most 5 dyads grown by a dyad between two moving joints of different bodies,
    traced at the new joint (two new binary links: eight links); at most 10 joints."""
    six = [t for t in WATT + STEPHENSON if len(t.dyads) < T.MAX_DYADS]
    while True:
        base = six[rng.integers(len(six))]
        n = T.CRANK + 1 + len(base.dyads)
        p1, p2 = (int(j) for j in rng.choice(np.arange(T.CRANK, n), 2, replace=False))
        if any(p1 in b and p2 in b for b in T.bodies(base)) or {p1, p2} in [set(d) for d in base.dyads]:
            continue
        topo = T.grow(base, p1, p2, name=f"8:{base.name}+({p1},{p2})")
        if topo.n_joints <= 10 and topo.n_links == 8:
            return topo


def planted(cls: str, rng: np.random.Generator, min_margin: float, max_tries: int = 200000):
    """(topology, pose) of a random linkage of the class that assembles over the whole turn."""
    for _ in range(max_tries):
        if cls == "4":
            topo = T.topologies()[0]
        elif cls == "6w":
            topo = WATT[rng.integers(len(WATT))]
        elif cls == "6s":
            topo = STEPHENSON[rng.integers(len(STEPHENSON))]
        elif cls == "8":
            topo = eight_bar(rng)
        else:
            raise ValueError(cls)
        pose = rng.uniform(-1.0, 1.0, (T.CRANK + 1 + len(topo.dyads), 2))
        if trace_exact(topo, pose, np.linspace(0, 2 * np.pi, 65))[1].min() < min_margin:
            continue
        asm = certify(topo, pose, 0.0, 2 * np.pi)
        if asm.ok and asm.margin >= min_margin:
            return topo, pose
    raise RuntimeError(f"no assemblable {cls} linkage in {max_tries} draws")


def floor(curve: np.ndarray, closed: bool, n: int = D.N_POINTS) -> float:
    """The discretisation floor (module doc) of a densely traced curve (N, 2)."""
    pts = np.concatenate([curve, curve[:1]]) if closed else curve
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    q = (np.arange(n) + 0.5) * s[-1] / (n if closed else n - 1)
    shifted = np.stack([np.interp(q[:n if closed else n - 1], s, pts[:, i]) for i in range(2)], 1)
    a = D.normalise(arclength_resample(curve, n, closed))[0]
    b = D.normalise(shifted)[0]
    return D.best_rotation(a, b)[1]


def case(cls: str, k: int, rng: np.random.Generator, args) -> dict:
    topo, pose = planted(cls, rng, args.min_margin)
    closed = k % 2 == 0
    if closed:
        start, span = 0.0, 2 * np.pi
        th = 2 * np.pi * np.arange(args.inputs) / args.inputs
        dense = 2 * np.pi * np.arange(20 * args.inputs) / (20 * args.inputs)
    else:
        start, span = rng.uniform(0, 2 * np.pi), rng.uniform(0.5 * np.pi, 1.5 * np.pi)
        th = start + span * np.linspace(0, 1, args.inputs)
        dense = start + span * np.linspace(0, 1, 20 * args.inputs)
    curve = trace_exact(topo, pose, th)[0][:, topo.traced]
    fl = floor(trace_exact(topo, pose, dense)[0][:, topo.traced], closed)
    t0 = time.perf_counter()
    r = jl.synthesize(curve, closed=closed, time_limit=args.time_limit, seed=args.seed + k,
                      max_links=args.max_links, samples=args.samples, **_bounds(args))
    wall = time.perf_counter() - t0
    b = r.best
    row = {"class": cls, "case": k, "closed": closed, "planted": topo.name, "planted_joints": topo.n_joints,
           "planted_links": topo.n_links, "span_deg": float(np.degrees(span)),
           "found": b.topology, "found_joints": b.joints, "distance": b.distance,
           "link_chamfer_2000": b.link_chamfer_2000, "floor": fl,
           "ratio": b.distance / fl, "recovered": bool(b.distance <= args.factor * fl), "time_s": wall,
           "found_s": b.found_s, "meets": b.meets, "transmission_deg": b.transmission_deg, "size": b.size,
           "simplest": r.designs[r.simplest].topology if r.simplest is not None else None,
           # issue 47: the planted topology or a smaller one on the Pareto front within 10 % of the best
           "planted_or_smaller_on_front": any(d.pareto and d.joints <= topo.n_joints and d.distance <= 1.1 * b.distance
                                              for d in r.designs)}
    if cls == "8" and args.eight_given:
        t1 = time.perf_counter()
        g = jl.synthesize(curve, closed=closed, time_limit=args.time_limit, seed=args.seed + k,
                          topologies=[topo], samples=args.samples, **_bounds(args))
        row |= {"given_distance": g.best.distance, "given_ratio": g.best.distance / fl,
                "given_recovered": bool(g.best.distance <= args.factor * fl),
                "given_time_s": time.perf_counter() - t1}
    return row


def _bounds(args) -> dict:
    """The synthesis's bounds: its defaults (synthesis/bounds.py), or none (`--bounds off`)."""
    return {} if args.bounds == "default" else dict(min_transmission=None, max_size=None, max_pivot=None)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--classes", default="4,6w,6s,8", help="planted classes: 4, 6w, 6s, 8 (default all)")
    ap.add_argument("--count", type=int, default=4, help="cases per class, closed and open alternately (default 4)")
    ap.add_argument("--time-limit", type=float, default=20.0, help="seconds of search per case (default 20)")
    ap.add_argument("--inputs", type=int, default=400, help="target points: inputs traced (default 400)")
    ap.add_argument("--factor", type=float, default=2.0, help="recovered: D <= factor x floor (default 2)")
    ap.add_argument("--min-margin", type=float, default=0.01, help="planted: smallest dyad margin over the turn")
    ap.add_argument("--max-links", type=int, default=8)
    ap.add_argument("--samples", type=int, default=8192)
    ap.add_argument("--eight-given", action="store_true", help="search each eight-bar again with its own topology")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bounds", choices=("default", "off"), default="default",
                    help="the designer's bounds of synthesize (30°, 3 extents, 3 extents) or none (off)")
    ap.add_argument("--cores", type=int, default=None, help="pin to this many cores")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "synthesis_planted.json"))
    args = ap.parse_args()
    classes = args.classes.split(",")
    # compile both programs (closed, open) first, so that every case gets its whole time limit
    t0 = time.perf_counter()
    warm = trace_exact(T.topologies()[0], np.array([[0, 0], [1.0, 0], [0, 0], [0.3, 0], [1.1, 0.8], [0.5, 0.9]]),
                       np.linspace(0, 2 * np.pi, 100, endpoint=False))[0][:, 5]
    quick = args.time_limit <= 15.0  # the search's default, which selects the programs
    for closed in (True, False):
        jl.synthesize(warm if closed else warm[:60], closed=closed, rounds=1, max_links=args.max_links,
                      samples=args.samples, quick=quick, **_bounds(args))
        if args.eight_given and "8" in classes:
            jl.synthesize(warm if closed else warm[:60], closed=closed, rounds=1, samples=args.samples,
                          topologies=[eight_bar(np.random.default_rng(0))], quick=quick, **_bounds(args))
    compile_s = time.perf_counter() - t0
    given = ", eight-bar given" if args.eight_given else ""
    print(f"compiled (closed and open{given}) in {compile_s:.1f} s", flush=True)
    rows = []
    print(f"{'class':<6}{'case':<5}{'curve':<7}{'planted':<34}{'pj':>3}{'found':<27}{'fj':>3}"
          f"{'distance':>10}{'link2000':>10}{'floor':>9}{'ratio':>7}{'rec':>5}{'time_s':>8}")
    for ci, cls in enumerate(classes):
        rng = np.random.default_rng([args.seed, ci])
        for k in range(args.count):
            row = case(cls, k, rng, args)
            rows.append(row)
            extra = (f"  given: {row['given_distance']:.4f} ({row['given_ratio']:.2f}x)"
                     if "given_distance" in row else "")
            print(f"{cls:<6}{k:<5}{'closed' if row['closed'] else 'open':<7}{row['planted']:<34}"
                  f"{row['planted_joints']:>3} {row['found']:<26}{row['found_joints']:>3}{row['distance']:>10.4f}"
                  f"{row['link_chamfer_2000']:>10.4f}{row['floor']:>9.4f}{row['ratio']:>7.2f}"
                  f"{'yes' if row['recovered'] else 'no':>5}"
                  f"{row['time_s']:>8.1f}{extra}", flush=True)
    summary = {}
    for cls in classes:
        rs = [r for r in rows if r["class"] == cls]
        summary[cls] = {"cases": len(rs), "recovered": sum(r["recovered"] for r in rs),
                        "closed_recovered": sum(r["recovered"] for r in rs if r["closed"]),
                        "open_recovered": sum(r["recovered"] for r in rs if not r["closed"]),
                        "median_ratio": float(np.median([r["ratio"] for r in rs]))}
        if any("given_recovered" in r for r in rs):
            summary[cls]["given_recovered"] = sum(r.get("given_recovered", False) for r in rs)
        sm = summary[cls]
        print(f"class {cls}: recovered {sm['recovered']}/{len(rs)} (closed {sm['closed_recovered']}, "
              f"open {sm['open_recovered']}), median D/floor {sm['median_ratio']:.2f}"
              + (f", with its topology given {summary[cls]['given_recovered']}/{len(rs)}"
                 if "given_recovered" in summary[cls] else ""))
    total = sum(r["recovered"] for r in rows)
    print(f"recovered {total}/{len(rows)}; compile {compile_s:.1f} s; load average {os.getloadavg()[0]:.1f}")
    out = {"benchmark": "synthesis_planted", "settings": vars(args),
           "machine": {"cpus": len(os.sched_getaffinity(0)), "platform": platform.platform(),
                       "device": str(jax.devices()[0]), "load_average": os.getloadavg()},
           "compile_s": compile_s, "rows": rows, "summary": summary, "recovered": total, "cases": len(rows)}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
