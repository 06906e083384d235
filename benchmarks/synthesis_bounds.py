"""The default `jaxlink.synthesize` on two project-made closed curves, with its buildability bounds
and without: LInK's metric, the least transmission angle, the size, the time (docs/numbers.md,
"Buildable by default").

- `limacon`: r = 1 + 0.6 cos k, 120 points (tests/test_synthesis_resume.py's target);
- `fourbar`: the coupler curve of a planted crank-rocker (crank 1, coupler 3, rocker 2.5, frame 3;
  the point 1 off the coupler's middle), traced with NumPy at 120 crank angles; its least
  transmission angle is 41.4° (closed form: cos μ = (b² + c² − (d − a)²) / 2bc = 0.75).

    python benchmarks/synthesis_bounds.py [--bounds default|off] [--curves limacon,fourbar]
        [--out results/synthesis_bounds.json]

`--bounds off`: min_transmission, max_size (and max_pivot, where the API has it) None: the search
of before the defaults. Prints one line per curve: the best design's topology, joints, distance,
link_chamfer_2000, least transmission angle (deg), size (extents), whether it meets the default
bounds, the simplest topology within 10 % (where reported) and the wall time (s)."""

from __future__ import annotations

import argparse
import inspect
import json
import time
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)


def limacon(n: int = 120) -> np.ndarray:
    k = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = 1 + 0.6 * np.cos(k)
    return np.stack([r * np.cos(k), r * np.sin(k)], axis=1)


def fourbar(n: int = 120, a=1.0, b=3.0, c=2.5, d=3.0, off=1.0) -> np.ndarray:
    """The coupler point of a crank-rocker: crank pivot (0, 0), rocker pivot (d, 0), by circle intersection."""
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    A = np.stack([a * np.cos(th), a * np.sin(th)], axis=1)
    D = np.array([d, 0.0])
    v = D - A
    r = np.hypot(*v.T)
    x = (b * b - c * c + r * r) / (2 * r)
    h = np.sqrt(b * b - x * x)
    u = v / r[:, None]
    n_ = np.stack([-u[:, 1], u[:, 0]], axis=1)
    B = A + x[:, None] * u + h[:, None] * n_
    e = (B - A) / b
    en = np.stack([-e[:, 1], e[:, 0]], axis=1)
    return A + 0.5 * b * e + off * en


CURVES = {"limacon": limacon, "fourbar": fourbar}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--bounds", choices=("default", "off"), default="default")
    p.add_argument("--curves", default="limacon,fourbar")
    p.add_argument("--out", default=None)
    args = p.parse_args()
    from jaxlink.synthesis import synthesize

    off: dict = {}
    if args.bounds == "off":
        off = dict(min_transmission=None, max_size=None)
        if "max_pivot" in inspect.signature(synthesize).parameters:
            off["max_pivot"] = None
    rows = []
    for name in args.curves.split(","):
        t0 = time.perf_counter()
        r = synthesize(CURVES[name](), closed=True, **off)
        wall = time.perf_counter() - t0
        b = r.best
        mu, size = b.transmission_deg, b.size
        meets = bool(mu >= 30.0 - 1e-9 and size <= 3.0)
        simplest = getattr(r, "simplest", None)
        row = dict(curve=name, bounds=args.bounds, topology=b.topology, joints=b.joints, distance=b.distance,
                   link_chamfer_2000=b.link_chamfer_2000, transmission_deg=mu, size=size, meets_default=meets,
                   simplest=None if simplest is None else r.designs[simplest].topology,
                   designs=len(r.designs), wall_s=wall,
                   all=[dict(topology=d.topology, distance=d.distance, link_chamfer_2000=d.link_chamfer_2000,
                             transmission_deg=d.transmission_deg, size=d.size) for d in r.designs])
        rows.append(row)
        print(f"{name:8} {args.bounds:8} {b.topology:24} {b.joints:3d} d={b.distance:.5f} "
              f"link2000={b.link_chamfer_2000:.5f} mu={mu:5.1f} size={size:5.2f} meets={meets} "
              f"simplest={row['simplest']} designs={len(r.designs)} {wall:6.1f} s", flush=True)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
