"""Tolerance study of the sewing feed's feed-dog path (issue 25): the `sewing-feed-opt` scene (the
seed's design l2 = 2.1, l22 = 0.9 mm, gamma = 2°) with every length made to ±0.02 mm and gamma to
±0.1° (normal, ±t = 3σ), the frame pivot E = (l8, l7) included through its two lengths.

`jaxlink study` on the scene with a `[study]` table: first order (σ_RSS, linear worst case and
importance factors of the feed dog Z at 360 crank positions, and the rockers' swings), Monte Carlo
(20000 samples), the true worst case over the tolerance box. Writes into OUT (created): the study
file, tolerance.csv, importance.csv, tolerance.png (the band around the feed-dog path), study.json,
study.npz; `jaxlink study OUT/feed-tolerance.toml --replot OUT` redraws the plot.

    python experiments/feed_tolerance.py OUT [--samples N]
"""

from __future__ import annotations

import argparse
import pathlib
import subprocess
import sys

import jaxlink as jl

STUDY = """
[study]
method = "tolerance"
positions = 360
points = ["Z"]
metrics = ["stroke", "deviation"]
samples = {samples}
seed = 1
distribution = "normal"
k = 3

[study.tolerances]
{tolerances}
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="output folder")
    ap.add_argument("--samples", type=int, default=20000)
    args = ap.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    mech = jl.load("sewing-feed-opt")
    tol = "\n".join(f"{p} = {0.1 if p == 'gamma' else 0.02}" for p in mech.parameter_names)
    src = out / "feed-tolerance.toml"
    src.write_text(pathlib.Path(mech.file).read_text() + STUDY.format(samples=args.samples, tolerances=tol))
    subprocess.run([sys.executable, "-m", "jaxlink.cli", "study", str(src), "--out", str(out)], check=True)


if __name__ == "__main__":
    main()
