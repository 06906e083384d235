"""Do the built-in eight-bars (ten-bars) pay? The same search (seed 0, a fixed number of rounds, so
the same work whatever the machine) with the four-bar and six-bars only (`max_links=6`) and with
the eight-bars too (`max_links=8`) — or, `--links 8,10`, with the ten-bars too — on LINK-ABC
letters (never stored here: `--letters PATH`).

    python experiments/synthesis_eight_bars.py --letters /work/data/linkabc/alphabet.npy \
        --only WMEHABKNRX --rounds 4 [--links 8,10]

Prints per letter the best distance and topology of each, and the time (the eight-bars' rounds
screen 16 topologies against 7: about twice as long on a CPU; the ten-bars' 43).
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import jaxlink as jl  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--letters", required=True, help="alphabet.npy (26, 200, 2)")
    ap.add_argument("--only", default="WMEHABKNRX")
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--links", default="6,8", help="the max_links compared (default 6,8)")
    args = ap.parse_args()
    try:
        compared = [int(x) for x in args.links.split(",")]
    except ValueError:
        ap.error(f"--links {args.links!r}: whole numbers of links separated by commas, e.g. 8,10")
    if any(k < 4 for k in compared):
        ap.error(f"--links {args.links!r}: each at least 4 (the four-bar, the frame counted)")
    letters = np.load(args.letters)
    print(f"{'letter':<7}{'max_links':>10}{'distance':>10}  {'topology':<40}{'time_s':>8}")
    means: dict[int, list[float]] = {k: [] for k in compared}
    for ch in args.only:
        for links in compared:
            t0 = time.perf_counter()
            r = jl.synthesize(letters[ord(ch) - 65], rounds=args.rounds, seed=0, max_links=links)
            means[links].append(r.best.distance)
            print(f"{ch:<7}{links:>10}{r.best.distance:>10.4f}  {r.best.topology:<40}"
                  f"{time.perf_counter() - t0:>8.1f}", flush=True)
    print("mean: " + ", ".join(f"max_links {k}: {np.mean(v):.4f}" for k, v in means.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
