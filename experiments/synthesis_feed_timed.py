"""Timed path synthesis on a real machine's path: the feed-dog point Z of the sewing-machine bottom
feed (the built-in scene `sewing-feed`, the seed's six-bar) at 72 crank angles 5° apart, as a
timed target — the feed dog must be at each point when the crank is at its angle — searched with
the built-in topologies (`jaxlink.synthesize`, seed 0), and the same points untimed (the path's
shape only, the chamfer distance) beside it.

    python experiments/synthesis_feed_timed.py [--time-limit 60] [--topologies NAMES] [--max-links 8]
        [--max-size K] [--min-transmission DEG] [--timed-only]

Prints each search's best designs (topology, joints, distance, size in extents of the path:
`jaxlink.synthesis.size`; `--max-size` bounds it) and, for the timed one, the RMS
error in mm at the 72 inputs (the ordered distance times the path's RMS radius) and the largest.
The seed's own mechanism is a `stephenson-rocker-crank` (the lever's point F and the crank's second
arm C joined by the carrier F-H-Z and the link H-C).
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import jaxlink as jl  # noqa: E402
from jaxlink.synthesis import make_target  # noqa: E402


def feed_path(step_deg: float = 5.0):
    """The feed-dog point Z (mm) at the crank angles 0, step, … < 360° and those angles (rad)."""
    mech = jl.load("sewing-feed")
    phis = np.radians(step_deg * np.arange(int(round(360 / step_deg))))
    sol = jl.solve(mech, phis)
    z = np.asarray(sol.points)[:, mech.point_names.index("Z")]
    return 1e3 * z, phis  # the solve's SI metres in the scene's millimetres


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--time-limit", type=float, default=60.0)
    ap.add_argument("--topologies", default=None, help="comma-separated names (default: the built-ins)")
    ap.add_argument("--max-links", type=int, default=8)
    ap.add_argument("--max-size", type=float, default=None, help="the designs' size bound, in extents of the path")
    ap.add_argument("--min-transmission", type=float, default=None, help="the designs' least transmission angle (deg)")
    ap.add_argument("--timed-only", action="store_true", help="skip the untimed search")
    args = ap.parse_args()
    pts, phis = feed_path()
    names = args.topologies.split(",") if args.topologies else None
    radius = float(np.sqrt(np.mean(np.sum((pts - pts.mean(0)) ** 2, axis=1))))
    print(f"feed-dog path: {len(pts)} points, RMS radius {radius:.3f} mm, "
          f"extent {np.ptp(pts[:, 0]):.3f} x {np.ptp(pts[:, 1]):.3f} mm")
    for timed in (True,) if args.timed_only else (True, False):
        tgt = make_target(pts, inputs=phis if timed else None, closed=True, unit="mm", source="sewing-feed Z")
        t0 = time.perf_counter()
        res = jl.synthesize(tgt, time_limit=args.time_limit, topologies=names, max_links=args.max_links,
                            max_size=args.max_size, max_pivot=args.max_size,  # links and pivots, as before
                            min_transmission=args.min_transmission)
        wall = time.perf_counter() - t0
        print(f"\n{'timed (ordered distance)' if timed else 'untimed (chamfer distance)'}: {wall:.1f} s")
        for d in res.designs[:5]:
            print(f"  {d.topology:<40}{d.joints:>4} joints  distance {d.distance:.5f}  size {d.size:.2f}  "
                  f"mu {d.transmission_deg:.1f} deg")
        if timed:
            b = res.best
            err = np.sqrt(np.sum((b.at_inputs - pts) ** 2, axis=1))
            print(f"  best: RMS error {np.sqrt(np.mean(err ** 2)) * 1e3:.1f} µm, largest {err.max() * 1e3:.1f} µm "
                  f"at the 72 inputs (placed by the similarity of the ordered match)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
