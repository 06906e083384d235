"""The Strider walking linkage: jaxlink against pylinkage on pylinkage's own example, in the same run.

The mechanism is the Strider of pylinkage's documentation (`docs/examples/strider.py`: both legs,
a crank, four RRR dyads — the knees D, E and the feet H, I — and four fixed dyads — the frame
pivots B, B' and the ankles F, G, each a point fixed to a link). Its design vector is the
example's eight dimensions (triangle, aperture, femur, rockerL, rockerS, phi, tibia, f); each is
varied by ±3 % over the designs (as `fourbar_vs_pylinkage.py` varies the four-bar's). The crank
turns clockwise, as in the example, one degree per step, 360 steps from its pose at −90°.

In jaxlink the Strider is written as a sketch (`jl.Sketch`: joints in one pose, links, and the
ternary rockers C-E-F and C-D-G as plates; the frame pivots are frame joints), so it takes the
closed form (four RRR dyads). Its parameters are set from each design by name. Measured in this
run, on the same designs:

- **batch**: pylinkage's `Ensemble.simulate` (1.3; numba, a loop over designs in one call) on
  B designs × 360 positions, against `jl.solve(mech, phis, P, q0)` of the same designs and angles
  (every moving joint's position, `Solution.points`), float64;
- **one revolution**: pylinkage's `Linkage.step_fast(360)` against `jl.solve(mech, phis, p, q0)`
  of one design (the whole `Solution`: angles, positions, result codes, residuals) and against
  `jl.solve(..., unknowns=False)` (the positions, result codes and residuals without the angles:
  what `step_fast` returns is every joint's position), each called 200 times in a row from
  Python, the three taking turns in every round (`single_design_calls`, as in
  `fourbar_vs_pylinkage.py`: each result kept, and each dropped).

Error: max |Δ| (m) of the positions of every moving joint of both legs (C, D, E, F, G, H, I)
against an independent numpy reference (circle intersections on the sketch's branch, the fixed
dyads by rotation), over every design and position; pylinkage's positions against the same
reference. Time: best of repeats after compilation, spread (worst/best) reported. Run pinned to
one core (pylinkage's loops run on one):

    python benchmarks/strider_vs_pylinkage.py --cores 1 [--quick] [--designs B] [--json OUT]

Prints "pylinkage not installed" (and measures jaxlink only) when pylinkage or numba is missing.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _cores import cores, default_output, pin_from_argv  # noqa: E402

pin_from_argv()  # --cores N: before JAX starts its threads
import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxlink as jl  # noqa: E402

STEPS = 360
#: the example's design vector: triangle (|AB| = |AB'|), aperture (∠ of B, B' from the vertical),
#: femur (|B'D| = |BE|), rockerL (|CD| = |CE|), rockerS (|CF| = |CG|), phi (∠ of F from C→E, of G
#: from C→D), tibia (|DH| = |EI|), f (|FH| = |GI|)
DIM_NAMES = ("triangle", "aperture", "femur", "rockerL", "rockerS", "phi", "tibia", "f")
DIMENSIONS = (2.0, math.pi / 4, 1.8, 2.6, 1.4, math.pi + 0.2, 2.5, 1.8)
#: the example's rough initial coordinates (pylinkage takes the circle intersection nearest them)
INIT = {"A": (0, 0), "Y": (0, 1), "B": (1.41, 1.41), "Bp": (-1.41, 1.41), "C": (0, -1), "D": (-2.25, 0),
        "E": (2.25, 0), "F": (-1.4, -1.2), "G": (1.4, -1.2), "H": (-2.7, -2.7), "I": (2.7, -2.7)}
MOVING = ("C", "D", "E", "F", "G", "H", "I")
THETA0 = -math.pi / 2  # the crank's pose in the sketch (pylinkage starts C at (0, −1))


def designs(B, seed=0):
    """(B, 8) design vectors: the example's, each dimension × (1 ± 3 %); row 0 the example's."""
    rng = np.random.default_rng(seed)
    D = np.repeat(np.asarray(DIMENSIONS)[None], B, axis=0)
    D[1:] *= 1 + 0.03 * rng.uniform(-1, 1, (B - 1, len(DIMENSIONS)))
    return D


def crank_angles(n=STEPS):
    """The crank angle at each recorded step: pylinkage turns it by −1° before it records."""
    return THETA0 - 2 * np.pi * np.arange(1, n + 1) / n


# ----------------------------------------------------------------------------- numpy reference


def _circles(p0, r0, p1, r1, side):
    """The intersection of the circles (p0, r0), (p1, r1) on `side` (+1: left of p0 → p1)."""
    d = p1 - p0
    dd = np.hypot(d[..., 0], d[..., 1])
    a = (r0 * r0 - r1 * r1 + dd * dd) / (2 * dd)
    with np.errstate(invalid="ignore"):  # NaN where the circles do not meet
        h = np.sqrt(r0 * r0 - a * a)
    e = d / dd[..., None]
    m = p0 + a[..., None] * e
    n = np.stack([-e[..., 1], e[..., 0]], -1)
    return m + (side * h)[..., None] * n


def _fixed(p0, p1, r, ang):
    """pylinkage's fixed dyad: the point at distance r from p0, at `ang` from the direction p0 → p1."""
    b = np.arctan2(p1[..., 1] - p0[..., 1], p1[..., 0] - p0[..., 0]) + ang
    return p0 + r[..., None] * np.stack([np.cos(b), np.sin(b)], -1)


def reference(D, thetas, sides):
    """Every joint's position, (B, N, 2) per name, for designs D (B, 8) at the crank angles
    `thetas` (N,) on the dyads' `sides` (dict D, E, H, I -> ±1), in numpy float64."""
    tri, ap, fem, rl, rs, phi, tib, f = (D[:, i][:, None] for i in range(8))
    shape = np.broadcast_shapes(tri.shape, thetas[None].shape)
    A = np.zeros(shape + (2,))
    Y = A + np.array([0.0, 1.0])
    pos = {"A": A}
    pos["B"] = _fixed(A, Y, tri + 0 * A[..., 0], -ap + 0 * A[..., 0])
    pos["Bp"] = _fixed(A, Y, tri + 0 * A[..., 0], ap + 0 * A[..., 0])
    pos["C"] = np.stack([np.cos(thetas) + 0 * tri, np.sin(thetas) + 0 * tri], -1)
    pos["D"] = _circles(pos["Bp"], fem, pos["C"], rl, sides["D"])
    pos["E"] = _circles(pos["B"], fem, pos["C"], rl, sides["E"])
    pos["F"] = _fixed(pos["C"], pos["E"], rs + 0 * A[..., 0], -phi + 0 * A[..., 0])
    pos["G"] = _fixed(pos["C"], pos["D"], rs + 0 * A[..., 0], phi + 0 * A[..., 0])
    pos["H"] = _circles(pos["D"], tib, pos["F"], f, sides["H"])
    pos["I"] = _circles(pos["E"], tib, pos["G"], f, sides["I"])
    return pos


def sketch_pose(dims=DIMENSIONS):
    """The example's design at the crank's start (−90°), each dyad on the side nearest the
    example's initial coordinates (as pylinkage chooses): (positions by name, sides)."""
    D = np.asarray(dims, float)[None]
    th = np.array([THETA0])
    sides = {}
    pos = None
    for j in ("D", "E", "H", "I"):  # each dyad's side in turn (later ones use earlier joints)
        best = None
        for s in (1, -1):
            trial = reference(D, th, {**{k: 1 for k in "DEHI"}, **sides, j: s})
            dist = math.dist(trial[j][0, 0], INIT[j])
            if best is None or dist < best[0]:
                best = (dist, s, trial)
        sides[j] = best[1]
        pos = best[2]
    return {k: tuple(float(c) for c in v[0, 0]) for k, v in pos.items()}, sides


# ----------------------------------------------------------------------------- jaxlink


def strider_sketch(dims=DIMENSIONS) -> jl.Sketch:
    """The Strider as joints and links (the rockers C-E-F, C-D-G as plates)."""
    pose, _ = sketch_pose(dims)
    sk = jl.Sketch("strider", description="pylinkage's Strider walking linkage (both legs)")
    for n in ("A", "B", "Bp"):
        sk.frame(n, *pose[n])
    for n in MOVING:
        sk.joint(n, *pose[n])
    sk.link("crank", "A", "C")
    sk.link("femur_r", "B", "E").link("femur_l", "Bp", "D")
    sk.link("rocker_r", "C", "E", "F").link("rocker_l", "C", "D", "G")
    sk.link("tibia_l", "D", "H").link("foot_l", "F", "H")
    sk.link("tibia_r", "E", "I").link("foot_r", "G", "I")
    return sk.crank("crank").points(*MOVING)


def jaxlink_parameters(mech, D):
    """(B, P) jaxlink parameters of designs D (B, 8), set by name."""
    tri, ap, fem, rl, rs, phi, tib, f = D.T
    wrap = lambda x: np.remainder(x + np.pi, 2 * np.pi) - np.pi  # noqa: E731 (the sketch's angles)
    by_name = {
        "A_x": 0 * tri, "A_y": 0 * tri,
        "B_x": tri * np.cos(np.pi / 2 - ap), "B_y": tri * np.sin(np.pi / 2 - ap),
        "Bp_x": tri * np.cos(np.pi / 2 + ap), "Bp_y": tri * np.sin(np.pi / 2 + ap),
        "crank": 1 + 0 * tri, "femur_r": fem, "femur_l": fem, "rocker_r": rl, "rocker_l": rl,
        "rocker_r_F": rs, "rocker_r_F_angle": wrap(-phi), "rocker_l_G": rs, "rocker_l_G_angle": wrap(phi),
        "tibia_l": tib, "foot_l": f, "tibia_r": tib, "foot_r": f,
    }
    assert set(by_name) == set(mech.parameter_names), mech.parameter_names
    return np.stack([by_name[n] for n in mech.parameter_names], 1)


def jaxlink_positions(mech, sol_points):
    """(…, N, 7, 2) points of `Solution.points` in the order of MOVING."""
    return np.asarray(sol_points)[..., [list(mech.point_names).index(n) for n in MOVING], :]


# ----------------------------------------------------------------------------- pylinkage


def pylinkage_available():
    try:
        import numba  # noqa: F401
        import pylinkage  # noqa: F401
        from pylinkage._numba_compat import HAS_NUMBA
    except ImportError:
        return False
    return bool(HAS_NUMBA)


def pylinkage_dimensions(D):
    """The example's `param2dimensions(…, flat=True)`: (B, 17) constraints, in its components' order."""
    tri, ap, fem, rl, rs, phi, tib, f = D.T
    one = np.ones_like(tri)
    return np.stack([tri, -ap, tri, ap, one, fem, rl, fem, rl, rs, -phi, rs, phi, tib, f, tib, f], 1)


def pylinkage_strider(dims=DIMENSIONS):
    """The example's `complete_strider`, built with pylinkage's public classes (the crank turning
    clockwise by 2π/STEPS per step); components in the example's order A, Y, B, B', C, D, E, F, G, H, I."""
    import pylinkage as pl

    c = pylinkage_dimensions(np.asarray(dims, float)[None])[0]
    A = pl.Ground(*INIT["A"], name="A")
    Y = pl.Ground(*INIT["Y"], name="Y")
    B = pl.FixedDyad(anchor1=A, anchor2=Y, distance=c[0], angle=c[1], name="B")
    Bp = pl.FixedDyad(anchor1=A, anchor2=Y, distance=c[2], angle=c[3], name="Bp")
    C = pl.Crank(anchor=A, radius=c[4], angular_velocity=-2 * np.pi / STEPS, name="C")
    Dj = pl.RRRDyad(anchor1=Bp, anchor2=C.output, distance1=c[5], distance2=c[6], name="D")
    E = pl.RRRDyad(anchor1=B, anchor2=C.output, distance1=c[7], distance2=c[8], name="E")
    F = pl.FixedDyad(anchor1=C.output, anchor2=E, distance=c[9], angle=c[10], name="F")
    G = pl.FixedDyad(anchor1=C.output, anchor2=Dj, distance=c[11], angle=c[12], name="G")
    H = pl.RRRDyad(anchor1=Dj, anchor2=F, distance1=c[13], distance2=c[14], name="H")
    I_ = pl.RRRDyad(anchor1=E, anchor2=G, distance1=c[15], distance2=c[16], name="I")
    lk = pl.Linkage([A, Y, B, Bp, C, Dj, E, F, G, H, I_], name="Strider")
    lk.set_coords([INIT[n] for n in ("A", "Y", "B", "Bp", "C", "D", "E", "F", "G", "H", "I")])
    return lk


PL_ORDER = ("A", "Y", "B", "Bp", "C", "D", "E", "F", "G", "H", "I")


def pylinkage_ensemble(D):
    """pylinkage's `Ensemble` of the designs D (each starting from the example's coordinates)."""
    from pylinkage.population import Ensemble

    lk = pylinkage_strider()
    dims = pylinkage_dimensions(D)
    assert dims.shape[1] == len(lk.get_constraints()), (dims.shape, len(lk.get_constraints()))
    assert np.allclose(dims[0], lk.get_constraints()) or not np.allclose(D[0], DIMENSIONS)
    pos0 = np.repeat(np.array([INIT[n] for n in PL_ORDER], float)[None], len(D), axis=0)
    return Ensemble(lk, dims, pos0), lk


# ----------------------------------------------------------------------------- timing


def timed(f, repeats):
    """(best, worst) seconds of `f()` over `repeats` calls after one warm-up, and its last result."""
    out = f()
    jax.block_until_ready(out)
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = f()
        jax.block_until_ready(out)
        ts.append(time.perf_counter() - t)
    return min(ts), max(ts), out


def alternating(calls: dict, repeats: int):
    """Best and worst seconds of each `calls[name]()`, the callables taking turns in every round."""
    ts = {k: [] for k in calls}
    for f in calls.values():
        jax.block_until_ready(f())
    for _ in range(repeats):
        for k, f in calls.items():
            t = time.perf_counter()
            jax.block_until_ready(f())
            ts[k].append(time.perf_counter() - t)
    return {k: (min(v), max(v)) for k, v in ts.items()}


def single_design_calls(calls: dict, n_calls: int, rounds: int) -> dict:
    """Seconds per call of each `calls[name]()`, called `n_calls` times in a row, (best, worst) of
    `rounds` rounds, the callables taking turns in every round; each result kept (`kept`) or each
    replaced by the next (`dropped`), as in `fourbar_vs_pylinkage.py`."""
    def kept(f):
        return [f() for _ in range(n_calls)][-1]

    def dropped(f):
        r = None
        for _ in range(n_calls):
            r = f()
        return r

    ts = {(k, m): [] for k in calls for m in ("kept", "dropped")}
    for f in calls.values():
        jax.block_until_ready(f())
    for _ in range(rounds):
        for (k, m) in ts:
            t = time.perf_counter()
            jax.block_until_ready((kept if m == "kept" else dropped)(calls[k]))
            ts[k, m].append((time.perf_counter() - t) / n_calls)
    return {k: (min(v), max(v)) for k, v in ts.items()}


# ----------------------------------------------------------------------------- main


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer repeats (< 1 minute)")
    ap.add_argument("--designs", type=int, default=1000, help="designs in the batch (default 1000)")
    ap.add_argument("--json", default=None, help="JSON output (default results/latest/strider_vs_pylinkage.json)")
    ap.add_argument("--cores", type=int, default=None, help="pin this run to N cores (the comparison: 1)")
    ap.add_argument("--jaxlink-only", action="store_true", help="skip pylinkage")
    args = ap.parse_args(argv)
    args.json = args.json or default_output("strider_vs_pylinkage.json")
    B = args.designs
    repeats = 5 if args.quick else 15
    rounds = 10 if args.quick else 30
    n_calls = 200

    sk = strider_sketch()
    mech = sk.mechanism()
    Dv = designs(B)
    P = jaxlink_parameters(mech, Dv)
    # the parameters derived from the sketch (written to 15 digits) are the example's design
    param_err = float(np.max(np.abs(P[0] - mech.parameters)))
    assert param_err < 1e-12, param_err
    thetas = crank_angles()
    _, sides = sketch_pose()
    ref = reference(Dv, thetas, sides)
    ref7 = np.stack([ref[n] for n in MOVING], -2)  # (B, N, 7, 2)
    rows = []

    def log(name, rate, err, spread):
        rows.append((name, rate, err, spread))
        e = "" if err is None else f"{err:10.2e}"
        print(f"  {name:58s} {rate:12.4g} pos/s {e} (worst/best {spread:.2f})", flush=True)

    results = {"designs": B, "steps": STEPS, "parameter_error": param_err,
               "dimensions": dict(zip(DIM_NAMES, DIMENSIONS)), "variation": 0.03}
    have_pl = pylinkage_available() and not args.jaxlink_only
    if not have_pl:
        print("pylinkage not installed (pip install -e '.[bench]' numba): measuring jaxlink only")

    # ---- the batch: B designs × 360 positions
    ph = jnp.asarray(thetas)
    Pd = jnp.asarray(P)
    q0 = jnp.asarray(mech.guess)

    def jl_batch():
        return jl.solve(mech, ph, Pd, q0).points

    t = time.perf_counter()
    jax.block_until_ready(jl_batch())
    compile_s = time.perf_counter() - t
    calls = {"jaxlink": jl_batch}
    if have_pl:
        import pylinkage

        ens, lk = pylinkage_ensemble(Dv)
        calls["pylinkage"] = lambda: ens.simulate(iterations=STEPS, store=False)
        results["pylinkage_version"] = pylinkage.__version__
    best = alternating(calls, repeats)
    sol = jl.solve(mech, ph, Pd, q0)
    xy = jaxlink_positions(mech, sol.points)
    err = float(np.max(np.abs(xy - ref7)))
    conv = float(np.mean(np.asarray(sol.result) == jl.RESULTS.converged))
    tb, tw = best["jaxlink"]
    log(f"jaxlink solve, {B} designs (points)", B * STEPS / tb, err, tw / tb)
    results.update({"jaxlink_batch_s": tb, "jaxlink_batch_worst_s": tw, "jaxlink_batch_positions_per_s": B * STEPS / tb,
                    "jaxlink_batch_max_abs_error_m": err, "jaxlink_batch_converged_fraction": conv,
                    "jaxlink_batch_compile_s": compile_s - tb})
    if have_pl:
        traj = ens.simulate(iterations=STEPS, store=False)  # (B, N, 11, 2)
        pl7 = traj[:, :, [PL_ORDER.index(n) for n in MOVING]]
        pl_err = float(np.nanmax(np.abs(pl7 - ref7)))
        pl_nan = float(np.mean(~np.isfinite(pl7)))
        tb2, tw2 = best["pylinkage"]
        log("pylinkage Ensemble.simulate", B * STEPS / tb2, pl_err, tw2 / tb2)
        results.update({"pylinkage_batch_s": tb2, "pylinkage_batch_worst_s": tw2,
                        "pylinkage_batch_positions_per_s": B * STEPS / tb2, "pylinkage_batch_max_abs_error_m": pl_err,
                        "pylinkage_nan_fraction": pl_nan, "ratio_batch": tb2 / tb,
                        "jaxlink_vs_pylinkage_batch_max_abs_m": float(np.nanmax(np.abs(pl7 - xy)))})

    # ---- one design, one revolution, 200 calls in a row: the whole Solution (angles, positions,
    # result codes, residuals), and the positions alone with their result codes and residuals
    # (`unknowns=False`: what step_fast returns, every joint's position, without the angles)
    p1 = jnp.asarray(P[0])

    def jl_one():
        return jl.solve(mech, ph, p1, q0)

    def jl_pos():
        return jl.solve(mech, ph, p1, q0, unknowns=False)

    one, pos = jl_one(), jl_pos()
    err1 = float(np.max(np.abs(jaxlink_positions(mech, one.points) - ref7[0])))
    same = bool(np.array_equal(np.asarray(one.points), np.asarray(pos.points)))
    results["positions_alone_identical"] = same
    calls = {"jaxlink": jl_one, "jaxlink_positions": jl_pos}
    if have_pl:
        lk1 = pylinkage_strider()
        lk1.step_fast(iterations=STEPS)  # compile (numba cache) and build solver data
        lk1.set_coords([INIT[n] for n in PL_ORDER])
        tr = lk1.step_fast(iterations=STEPS)
        err1_pl = float(np.nanmax(np.abs(tr[:, [PL_ORDER.index(n) for n in MOVING]] - ref7[0])))
        calls["pylinkage"] = lambda: lk1.step_fast(iterations=STEPS)
    per_call = single_design_calls(calls, n_calls, rounds)
    for m in ("kept", "dropped"):
        sfx = "" if m == "kept" else "_dropped"
        t1, w1 = per_call["jaxlink", m]
        t3, w3 = per_call["jaxlink_positions", m]
        log(f"jaxlink solve, 1 design per call ({m})", STEPS / t1, err1, w1 / t1)
        log(f"jaxlink solve(unknowns=False), 1 design per call ({m})", STEPS / t3, err1, w3 / t3)
        results[f"jaxlink_single_call_ms{sfx}"] = 1e3 * t1
        results[f"jaxlink_single_call_worst_ms{sfx}"] = 1e3 * w1
        results[f"jaxlink_positions_call_ms{sfx}"] = 1e3 * t3
        results[f"jaxlink_positions_call_worst_ms{sfx}"] = 1e3 * w3
        if have_pl:
            t2, w2 = per_call["pylinkage", m]
            log(f"pylinkage Linkage.step_fast, 1 design per call ({m})", STEPS / t2, err1_pl, w2 / t2)
            results[f"pylinkage_step_fast_call_ms{sfx}"] = 1e3 * t2
            results[f"pylinkage_step_fast_call_worst_ms{sfx}"] = 1e3 * w2
            results[f"ratio_single{sfx}"] = t2 / t1
            results[f"ratio_positions{sfx}"] = t2 / t3
    results["jaxlink_single_max_abs_error_m"] = err1
    if have_pl:
        results["pylinkage_single_max_abs_error_m"] = err1_pl

    print(f"\nStrider (both legs), {B} designs x {STEPS} steps; {cores()} core(s), jax {jax.__version__}")
    print(f"{'method':58s} {'positions/s':>12s} {'max|Δ| m':>10s} {'worst/best':>10s}")
    for name, rate, err_, spread in rows:
        print(f"{name:58s} {rate:12.4g} {'' if err_ is None else f'{err_:10.2e}'} {spread:10.2f}")
    if "ratio_batch" in results:
        print(f"batch: jaxlink = {results['ratio_batch']:.2f}x pylinkage's Ensemble.simulate; one revolution: "
              f"{results['ratio_single']:.2f}x its step_fast (results kept), "
              f"{results['ratio_single_dropped']:.2f}x (each dropped); the positions alone (unknowns=False, "
              f"the same points bit for bit: {results['positions_alone_identical']}): "
              f"{results['ratio_positions']:.2f}x kept, {results['ratio_positions_dropped']:.2f}x dropped")
    results["cores"] = cores()
    results["machine"] = {"cpus": os.cpu_count(), "platform": platform.platform(), "jax": jax.__version__}
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)
        print(f"wrote {args.json}")
    return results


if __name__ == "__main__":
    main()
