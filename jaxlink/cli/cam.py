"""`jaxlink simulate` and `jaxlink jamming`: the cam-follower (knitting sinker) commands.

The scene format: `docs/reference/file-format.md` (section 14); the model: `docs/methods/sinker.md`.
"""

from __future__ import annotations

import csv
import json
import math
import sys

from ..errors import MechanismError
from .mechanism import writing

_FILE_HELP = ("cam-follower scene: a TOML file with kind = \"cam-follower\", or the built-in "
              "scene name 'sinker-cam'")
_SET_HELP = ("override a scene value, e.g. --set C=1e6, --set f=[0.1,0.15], "
             "--set cam.arc=polygon, --set simulate.geometry=R20-55 (TABLE.KEY or a key unique "
             "across tables; VALUE in TOML syntax; repeatable)")


def register(subparsers) -> None:
    """Add the `simulate` and `jamming` sub-commands."""
    p = subparsers.add_parser(
        "simulate",
        help="simulate a cam follower (knitting sinker) for each friction coefficient",
        description=(
            "Integrate the sinker's equation of motion (docs/methods/sinker.md) over one cam passage "
            "for every friction coefficient f of the scene and every geometry listed in "
            "[simulate].geometry, in one batched (vmapped) JAX call. Prints the rise and "
            "descent maxima; writes the time histories as CSV (long format, one block per "
            "geometry and f; columns geometry, f, t_s, yz_m, y_m, v_m_s, a_m_s2, lag_m, N_N, "
            "contact) and a figure like the thesis's graphs 5.1-5.4 (acceleration, velocity, "
            "lift, lag; one curve per f). Exit status 1 if an integration failed."),
    )
    p.add_argument("file", metavar="FILE", help=_FILE_HELP)
    p.add_argument("--set", dest="overrides", action="append", metavar="NAME=VALUE",
                   default=[], help=_SET_HELP)
    p.add_argument("--csv", metavar="OUT", help="write the time histories to this CSV file")
    p.add_argument("--plot", metavar="OUT.png", help="write the figure to this PNG file")
    p.add_argument("--method", choices=("auto", "explicit", "implicit"),
                   help="integrator (default: [simulate].method of the scene): explicit "
                        "Dormand-Prince 5(4), implicit Radau IIA 5, or auto (implicit above "
                        "C = 3e6 N/m)")
    p.set_defaults(func=_simulate_cmd)

    q = subparsers.add_parser(
        "jamming",
        help="static and dynamic jamming thresholds of each cam geometry",
        description=(
            "For every [[cam.geometry]] of the scene: the static self-locking threshold "
            "static_f (closed form of D(alpha2, f) = 0) and the dynamic threshold dynamic_f "
            "(smallest f for which the simulated sinker's velocity turns negative after the "
            "rise, or its lag runs away past 20 mm), found by batched bisection to "
            "[jamming].tol. Writes JSON {\"R10-45\": {\"static_f\": ..., \"dynamic_f\": ...}, "
            "...}."),
    )
    q.add_argument("file", metavar="FILE", help=_FILE_HELP)
    q.add_argument("--set", dest="overrides", action="append", metavar="NAME=VALUE",
                   default=[], help=_SET_HELP)
    q.add_argument("--out", metavar="OUT.json", help="write the thresholds to this JSON file")
    q.add_argument("--tol", type=float, metavar="TOL",
                   help="bisection bracket width in f (default: [jamming].tol, 1e-4)")
    q.add_argument("--method", choices=("auto", "explicit", "implicit"),
                   help="integrator (default: [simulate].method of the scene)")
    q.set_defaults(func=_jamming_cmd)


def _method(scene, override):
    from ..cam import auto_method

    m = override or scene.method
    return auto_method(float(scene.params.C)) if m == "auto" else m


def _simulate_cmd(args) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    from ..cam import RESULTS, make_cam, maxima, product_cases, simulate_batch
    from ..cam.scene import load_scene
    from .mechanism import CSV_FORMATS, PLOT_FORMATS, check_output

    check_output("--csv", args.csv, CSV_FORMATS)
    check_output("--plot", args.plot, PLOT_FORMATS)
    scene = load_scene(args.file, args.overrides)
    geoms = [scene.geometry(n) for n in scene.sim_geometries]
    cam = make_cam(geoms, scene.speed)
    method = _method(scene, args.method)
    pb, cb, shape = product_cases(scene.params, cam, f=scene.f_values)
    sol = simulate_batch(pb, cb, n_out=scene.points, method=method, rtol=scene.rtol,
                         atol=scene.atol)
    sol = jax.tree.map(np.asarray, sol)
    n_f, n_g, _ = shape

    def case(i_f, i_g):
        return jax.tree.map(lambda x: x[(i_f * n_g + i_g)], sol)

    print(f"{scene.name}: C = {float(scene.params.C):.4g} N/m, k/m = "
          f"{float(scene.params.k_over_m):.1f} 1/s, method = {method}, rtol = {scene.rtol:g}")
    print(f"{'geometry':>8} {'f':>6} | {'rise a_max':>10} {'v_max':>6} {'lag_max':>8} | "
          f"{'desc a_max':>10} {'v_max':>6} | {'jammed':>6} {'steps':>6}")
    print(f"{'':>8} {'':>6} | {'m/s^2':>10} {'m/s':>6} {'mm':>8} | {'m/s^2':>10} {'m/s':>6} |")
    failed = 0
    for i_g, g in enumerate(geoms):
        cam_g = jax.tree.map(lambda x: x[i_g], cam)
        for i_f, f in enumerate(scene.f_values):
            s = case(i_f, i_g)
            mx = maxima(s, cam_g)
            ok = int(s.result) == RESULTS.converged
            failed += not ok
            print(f"{g.name:>8} {f:6.3f} | {mx.rise_a:10.1f} {mx.rise_v:6.3f} "
                  f"{mx.rise_lag * 1e3:8.4f} | {mx.desc_a:10.1f} {mx.desc_v:6.3f} | "
                  f"{'yes' if s.jammed else 'no':>6} {int(s.stats.num_steps):6d}"
                  + ("" if ok else f"  FAILED: {RESULTS.messages[int(s.result)]}"))
    if args.csv:
        with writing("--csv", args.csv), open(args.csv, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["geometry", "f", "t_s", "yz_m", "y_m", "v_m_s", "a_m_s2", "lag_m",
                        "N_N", "contact"])
            for i_g, g in enumerate(geoms):
                for i_f, f in enumerate(scene.f_values):
                    s = case(i_f, i_g)
                    for row in zip(s.t, s.yz, s.y, s.v, s.a, s.lag, s.N, s.contact):
                        w.writerow([g.name, repr(f)] + [f"{x:.15g}" for x in row])
        print(f"wrote {args.csv}")
    if args.plot:
        with writing("--plot", args.plot):
            _plot(args.plot, scene, geoms, cam, case, n_f)
        print(f"wrote {args.plot}")
    return 1 if failed else 0


def _plot(path, scene, geoms, cam, case, n_f):
    import jax
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8), sharex=True)
    panels = [("a", 1.0, "sinker acceleration y'' (m/s²)", "graph 5.1"),
              ("v", 1.0, "sinker velocity y' (m/s)", "graph 5.2"),
              ("y", 1e3, "sinker lift y (mm)", "graph 5.3"),
              ("lag", 1e3, "lag y_z − y (mm)", "graph 5.4")]
    for i_g, g in enumerate(geoms):
        for i_f, f in enumerate(scene.f_values):
            s = case(i_f, i_g)
            label = f"f = {f:g}" if len(geoms) == 1 else f"{g.name}, f = {f:g}"
            for ax, (field, scale, _, _) in zip(axes.flat, panels):
                ax.plot(s.t * 1e3, getattr(s, field) * scale, lw=1.0, label=label)
    s0 = case(0, 0)
    axes.flat[2].plot(s0.t * 1e3, s0.yz * 1e3, "k--", lw=0.8, label="cam y_z")
    cam0 = jax.tree.map(lambda x: x[0], cam)
    t1, t2, t_end = (float(cam0.t_rise) * 1e3, float(cam0.t_descent) * 1e3,
                     float(cam0.t_end) * 1e3)
    for ax, (_, _, ylabel, title) in zip(axes.flat, panels):
        ax.axvline(t1, color="0.5", lw=0.6)
        ax.axvline(t2, color="0.5", lw=0.6)
        ax.axhline(0.0, color="0.8", lw=0.5)
        ax.set_ylabel(ylabel)
        ax.set_title(f"{ylabel.split(' (')[0]} (cf. thesis {title})", fontsize=9)
        ax.grid(alpha=0.3)
        for x, txt in (((0 + t1) / 2, "rise"), ((t1 + t2) / 2, "arc"),
                       ((t2 + t_end) / 2, "descent")):
            ax.text(x, 0.97, txt, transform=ax.get_xaxis_transform(), ha="center",
                    va="top", fontsize=8, color="0.4")
    for ax in axes[1]:
        ax.set_xlabel("time t (ms)")
    axes.flat[0].legend(fontsize=8)
    axes.flat[2].legend(fontsize=8)
    names = ", ".join(g.name for g in geoms)
    fig.suptitle(f"{scene.name}: {names}, C = {float(scene.params.C):.3g} N/m", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _jamming_cmd(args) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from ..cam import make_cam, thresholds
    from ..cam.jamming import bisection_steps
    from ..cam.scene import load_scene
    from .mechanism import check_output

    check_output("--out", args.out, ("json",))
    scene = load_scene(args.file, args.overrides)
    tol = scene.jam_tol if args.tol is None else args.tol
    if not (math.isfinite(tol) and 0 < tol < 0.1):
        raise MechanismError(f"--tol must be in (0, 0.1), got {tol!r}", key="--tol")
    cam = make_cam(scene.geometries, scene.speed)
    method = _method(scene, args.method)
    bar = None
    progress = None
    if sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=2 + bisection_steps(0.02, tol), desc="batched simulations",
                   unit="batch", leave=False)
        progress = bar.update
    try:
        th = thresholds(scene.params, cam, tol=tol, method=method, rtol=scene.rtol,
                        atol=scene.atol, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    out = {g.name: {"static_f": round(float(s), 6), "dynamic_f": round(float(d), 6)}
           for g, s, d in zip(scene.geometries, th.static_f, th.dynamic_f)}
    print(f"{scene.name}: C = {float(scene.params.C):.4g} N/m, method = {method}, "
          f"bracket width <= {tol:g}, {th.num_batches} batched simulations")
    print(f"{'geometry':>10} {'static_f':>9} {'dynamic_f':>9}  dynamic bracket")
    for g, s, d, lo, hi in zip(scene.geometries, th.static_f, th.dynamic_f, th.lo, th.hi):
        print(f"{g.name:>10} {s:9.5f} {d:9.5f}  ({lo:.5f}, {hi:.5f}]")
    if args.out:
        with writing("--out", args.out), open(args.out, "w") as fh:
            json.dump(out, fh, indent=2)
            fh.write("\n")
        print(f"wrote {args.out}")
    return 0
