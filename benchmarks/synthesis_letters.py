"""Path synthesis on the LINK-ABC letters (Nobari et al. 2024): per letter the best design found
within a time limit, its distance (jaxlink.synthesis.match: the phase-free chamfer — each curve's
2000 arclength-resampled, normalised points to the other's polyline, at the best rotation — what
the search ranks by) and LInK's metric of the same curve (jaxlink.synthesis.link_chamfer: the point
chamfer of both curves at 2000 points, at the best rotation), joints and time; beside it LInK's
published mechanism for the letter (`alpha_res.npy`: adjacency, joint positions, frame flags, θ0,
θ1), traced here from θ0 to θ1 (2000 inputs, the crank's absolute angle, each dyad on the branch of
the stored pose) and scored with both, and the chamfer distance LInK stored for it. "Better than
LInK" is counted under both metrics. (The stored (2000, 2) curve beside them is not the mechanism's path: it lies within
0.0000–0.0008 of the closed letters, the target as LInK transformed it.)

The letters have no licence: they are read from a path (`--letters`, default `$JAXLINK_LINKABC`,
e.g. /work/data/linkabc/alphabet.npy, a (26, 200, 2) array, A..Z) and never copied into the
repository; LInK's mechanisms from `alpha_res.npy` beside it when present. The four-bar is
always searched, so the answer is never worse than the best four-bar found. The search keeps the
designer's default bounds (30°, links and frame pivots within 3 extents: synthesis/bounds.py;
`--bounds off`: none); each row records the best design's least transmission angle, size, whether
it meets the default bounds, and the simplest topology within 10 %; the summary counts the letters
whose best meets them.

    python benchmarks/synthesis_letters.py --letters /work/data/linkabc/alphabet.npy \
        --only CDILOSUV --time-limit 100 [--cores 2]

Writes benchmarks/results/synthesis_letters.json (the table, the settings, the machine).
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
from jaxlink.synthesis import MAX_PIVOT, MAX_SIZE, MIN_TRANSMISSION, link_chamfer, match  # noqa: E402

#: every designer's bound off (`--bounds off`): the search of before the defaults
BOUNDS_OFF = dict(min_transmission=None, max_size=None, max_pivot=None)


def link_curve(entry, n: int = 2000):
    """The path of LInK's mechanism (its last joint) for θ from θ0 to θ1: (n, 2), and whether every
    dyad closed. Joint 0 the crank's pivot, joint 1 the crank at angle θ; each later moving joint on
    its first two earlier neighbours, on the side (cross-product sign) of the stored pose."""
    a, x, nt = (np.asarray(v, float) for v in entry[0][:3])
    th0, th1 = float(entry[0][3]), float(entry[0][4])
    nj = int((a.sum(-1) > 0).sum())
    a, x, fixed = a[:nj, :nj], x[:nj], nt[:nj, 0] > 0
    th = np.linspace(th0, th1, n)
    pos = np.repeat(x[None], n, 0)
    pos[:, 1] = x[0] + np.hypot(*(x[1] - x[0])) * np.stack([np.cos(th), np.sin(th)], -1)
    ok = True
    for k in range(2, nj):
        if fixed[k]:
            continue
        i, j = np.flatnonzero(a[k, :k])[:2]
        l1, l2 = np.hypot(*(x[k] - x[i])), np.hypot(*(x[k] - x[j]))
        w0, v0 = x[j] - x[i], x[k] - x[i]
        sg = 1.0 if w0[0] * v0[1] - w0[1] * v0[0] >= 0 else -1.0
        w = pos[:, j] - pos[:, i]
        d2 = (w * w).sum(-1)
        d = np.sqrt(d2)
        aa = (l1 * l1 - l2 * l2 + d2) / (2 * d)
        h2 = l1 * l1 - aa * aa
        ok &= bool(np.all(h2 >= 0))
        perp = np.stack([-w[:, 1], w[:, 0]], -1)
        pos[:, k] = pos[:, i] + (aa / d)[:, None] * w + (sg * np.sqrt(np.maximum(h2, 0)) / d)[:, None] * perp
    return pos[:, nj - 1], ok


def summarise(rows: list[dict]) -> dict:
    """The letter table's summary (mean, median, against LInK and the four-bar), printed."""
    d = np.array([r["distance"] for r in rows if r["distance"] is not None])
    ld = np.array([r["link_distance"] for r in rows if r["link_distance"] is not None])
    d2 = np.array([r["link_chamfer_2000"] for r in rows if r.get("link_chamfer_2000") is not None])
    ld2 = np.array([r["link_link_chamfer_2000"] for r in rows if r.get("link_link_chamfer_2000") is not None])
    summary = {"letters": len(rows), "mean": float(d.mean()) if len(d) else None,
               "median": float(np.median(d)) if len(d) else None,
               "link_mean": float(ld.mean()) if len(ld) else None,
               "link_median": float(np.median(ld)) if len(ld) else None,
               "mean_link_chamfer_2000": float(d2.mean()) if len(d2) else None,
               "link_mean_link_chamfer_2000": float(ld2.mean()) if len(ld2) else None,
               "better_than_link_2000": int(sum(r["link_chamfer_2000"] < r["link_link_chamfer_2000"] for r in rows
                                                if r.get("link_chamfer_2000") is not None
                                                and r.get("link_link_chamfer_2000") is not None)),
               "four_bar_mean": float(np.mean([r["four_bar"] for r in rows if r["four_bar"] is not None] or [np.nan])),
               "worse_than_four_bar": int(sum(r["distance"] > r["four_bar"] for r in rows
                                              if r["distance"] is not None and r["four_bar"] is not None)),
               "better_than_link": int(sum(r["distance"] < r["link_distance"] for r in rows
                                           if r["distance"] is not None and r["link_distance"] is not None)),
               "meets_default_bounds": int(sum(bool(r.get("meets_default")) for r in rows)),
               "max_time_s": max(r["time_s"] for r in rows)}
    print(f"mean {summary['mean']:.4f}  median {summary['median']:.4f}  (LInK's mechanisms, same metric: mean "
          f"{summary['link_mean']}, median {summary['link_median']}); better than LInK on "
          f"{summary['better_than_link']}/{len(rows)}; LInK's metric at 2000 points: mean "
          f"{summary['mean_link_chamfer_2000']} against {summary['link_mean_link_chamfer_2000']}, better on "
          f"{summary['better_than_link_2000']}/{len(rows)}; meeting the default bounds (30°, 3 extents) "
          f"{summary['meets_default_bounds']}/{len(rows)}; slowest {summary['max_time_s']:.1f} s")
    return summary


def merge(paths: list[str], out: str) -> int:
    """One table from the JSONs of several runs (e.g. groups of letters run side by side on one device)."""
    runs = [json.loads(Path(p).read_text()) for p in paths]
    rows = sorted((r for run in runs for r in run["rows"]), key=lambda r: r["letter"])
    if not rows:
        raise SystemExit("no letter finished yet")
    merged = {"benchmark": "synthesis_letters", "settings": runs[0]["settings"] | {
                  "only": "".join(r["letter"] for r in rows), "out": out, "merged": len(runs)},
              "machine": runs[0]["machine"], "rows": rows, "summary": summarise(rows)}
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text(json.dumps(merged, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--letters", default=os.environ.get("JAXLINK_LINKABC"), help="alphabet.npy (26, 200, 2)")
    ap.add_argument("--only", default=None, help="letters to run, e.g. CDILOSUV (default all)")
    ap.add_argument("--time-limit", type=float, default=100.0, help="seconds per letter (default 100)")
    ap.add_argument("--max-links", type=int, default=8)
    ap.add_argument("--samples", type=int, default=8192)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bounds", choices=("default", "off"), default="default",
                    help="the designer's bounds (synthesis/bounds.py: 30°, 3 extents, 3 extents) or none (off)")
    ap.add_argument("--cores", type=int, default=None, help="pin to this many cores")
    ap.add_argument("--cache", action="store_true",
                    help="jaxlink's persistent compilation cache on (as `jaxlink synthesize` has it): a warm start")
    ap.add_argument("--log", action="store_true", help="print each round (its best distance and time)")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "synthesis_letters.json"))
    ap.add_argument("--merge", nargs="+", metavar="JSON", help="only merge these runs' tables into --out")
    args = ap.parse_args()
    if args.merge:
        return merge(args.merge, args.out)
    if not args.letters:
        ap.error("give --letters PATH or set JAXLINK_LINKABC")
    if args.cache:
        jl.enable_compilation_cache()
    letters = np.load(args.letters)
    res_path = Path(args.letters).with_name("alpha_res.npy")
    link = np.load(res_path, allow_pickle=True) if res_path.exists() else None
    which = [c for c in (args.only or "ABCDEFGHIJKLMNOPQRSTUVWXYZ")]
    rows = []

    def save(rows, summary=None):  # after every letter too: a run cut short keeps what it measured
        out = {"benchmark": "synthesis_letters", "settings": vars(args) | {"letters": "LINK-ABC (not stored)"},
               "machine": {"cpus": len(os.sched_getaffinity(0)), "platform": platform.platform(),
                           "device": str(jax.devices()[0])},
               "rows": rows, "summary": summary}
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(out, indent=2) + "\n")

    print(f"{'letter':<7}{'closed':<7}{'topology':<38}{'joints':>7}{'distance':>10}{'link2000':>10}{'four-bar':>10}"
          f"{'time_s':>8}{'LInK':>9}{'LInK2000':>10}{'joints':>7}{'stored':>8}")
    for ch in which:
        i = ord(ch) - 65
        t0 = time.perf_counter()
        r = jl.synthesize(letters[i], time_limit=args.time_limit, seed=args.seed, max_links=args.max_links,
                          samples=args.samples, **({} if args.bounds == "default" else BOUNDS_OFF),
                          log=(lambda m, ch=ch: print(f"  {ch} {m}", flush=True)) if args.log else None)
        wall = time.perf_counter() - t0
        tgt = r.target
        fb = [d for d in r.designs if d.topology == "four-bar"]
        theirs = theirs2 = stored = None
        if link is not None:
            curve, ok = link_curve(link[i])
            theirs = match(curve, letters[i], closed=tgt.closed).distance if ok else None
            theirs2 = link_chamfer(curve, letters[i], closed=tgt.closed) if ok else None
            stored = float(link[i][1][0])
        b = r.best if r.designs else None
        row = {"letter": ch, "closed": tgt.closed, "topology": b.topology if b else None,
               "joints": b.joints if b else None, "links": b.links if b else None,
               "distance": b.distance if b else None, "link_chamfer_2000": b.link_chamfer_2000 if b else None,
               "four_bar": fb[0].distance if fb else None,
               "time_s": wall, "found_s": b.found_s if b else None, "link_distance": theirs,
               "link_link_chamfer_2000": theirs2,
               "link_stored_chamfer": stored,
               "transmission_deg": b.transmission_deg if b else None, "size": b.size if b else None,
               # with the default bounds the design's own exact check; off, its angle and sizes against them
               "meets_default": bool(b and (b.meets if args.bounds == "default" else (
                   b.transmission_deg >= MIN_TRANSMISSION and b.link_size <= MAX_SIZE and b.pivot_size <= MAX_PIVOT))),
               "simplest": r.designs[r.simplest].topology if r.simplest is not None else None,
               "link_joints": int((np.asarray(link[i][0][0]).sum(-1) > 0).sum()) if link is not None else None}
        rows.append(row)
        save(rows)
        print(f"{ch:<7}{str(tgt.closed):<7}{row['topology'] or '-':<38}{row['joints'] or 0:>7}"
              f"{row['distance'] or float('nan'):>10.4f}{row['link_chamfer_2000'] or float('nan'):>10.4f}"
              f"{row['four_bar'] or float('nan'):>10.4f}{wall:>8.1f}"
              f"{theirs if theirs is not None else float('nan'):>9.4f}"
              f"{theirs2 if theirs2 is not None else float('nan'):>10.4f}{row['link_joints'] or 0:>7}"
              f"{stored if stored is not None else float('nan'):>8.4f}", flush=True)
    summary = summarise(rows)
    save(rows, summary)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
