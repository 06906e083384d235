"""The synthesis search's blocks on this machine's device: one letter (or a planted curve), exactly
`--rounds` rounds, with the platform's block caps (`jaxlink.synthesis.block_caps`) and with
another platform's (`--as cpu` on a GPU: the CPU's small blocks), each round's phases (screen,
rank, refinement, exact scoring) from the search's log, the best distance and the wall time (the
compiling of each caps' programs included).

    python benchmarks/synthesis_blocks.py --letters PATH --letter E --max-links 10 --rounds 2 --as cpu

The same seed and rounds with either caps: the designs differ only through the blocks' rounding
(`docs/methods/synthesis.md`, "Spread"), the time through how the device runs the blocks.
Writes benchmarks/results/synthesis_blocks.json.
"""

from __future__ import annotations

import argparse
import json
import platform
import re
import time
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import jaxlink as jl  # noqa: E402
from jaxlink.synthesis import block_caps, default_blocks  # noqa: E402


def run(target, caps: tuple[int, int, int] | None, rounds: int, max_links: int, time_limit: float) -> dict:
    """One search with these block caps (None: this device's own)."""
    lines: list[str] = []
    t0 = time.perf_counter()
    # the time limit only chooses the programs (a cap would stop the rounds: `quick` instead)
    r = jl.synthesize(target, quick=time_limit <= 15.0, rounds=rounds, max_links=max_links, blocks=caps,
                      log=lambda s: (lines.append(s), print("  " + s, flush=True)))
    wall = time.perf_counter() - t0
    phases = []
    for s in lines:
        if s.startswith("round"):
            phases.append({k: float(v) for k, v in re.findall(r"(screen|rank|refine|score) ([0-9.]+) s", s)})
    return dict(caps=list(caps or default_blocks(time_limit <= 15.0)), wall_s=wall, distance=float(r.best.distance),
                link_chamfer_2000=float(r.best.link_chamfer_2000), topology=r.best.topology, rounds=phases)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--letters", required=True, help="LINK-ABC's alphabet.npy (never stored here)")
    ap.add_argument("--letter", default="E")
    ap.add_argument("--max-links", type=int, default=10)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--time-limit", type=float, default=60.0, help="only chooses the compile level (>15: full)")
    ap.add_argument("--as", dest="other", default="cpu", help="the other platform whose caps to compare")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "synthesis_blocks.json"))
    args = ap.parse_args()
    target = np.load(args.letters)[ord(args.letter) - 65]
    rows = []
    quick = args.time_limit <= 15.0
    for caps in (None, block_caps(args.other, quick)):
        print(f"caps {list(caps or default_blocks(quick))}", flush=True)
        rows.append(run(target, caps, args.rounds, args.max_links, args.time_limit))
        print(f"  -> {rows[-1]['distance']:.4f} (LInK's metric {rows[-1]['link_chamfer_2000']:.4f}) "
              f"{rows[-1]['topology']}, {rows[-1]['wall_s']:.1f} s", flush=True)
    print(f"{'caps':>18} {'wall s':>7} {'distance':>9} {'link2000':>9}  per round: screen+rank / refine / score (s)")
    for r in rows:
        per = "  ".join(f"{p.get('screen', 0) + p.get('rank', 0):.1f}/{p.get('refine', 0):.1f}/{p.get('score', 0):.1f}"
                        for p in r["rounds"])
        print(f"{str(r['caps']):>18} {r['wall_s']:7.1f} {r['distance']:9.4f} {r['link_chamfer_2000']:9.4f}  {per}")
    out = dict(benchmark="synthesis_blocks", settings=dict(letter=args.letter, max_links=args.max_links,
                                                             rounds=args.rounds, time_limit=args.time_limit),
               machine=dict(platform=platform.platform(), device=str(jax.devices()[0]),
                            jax=jax.__version__), rows=rows)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
