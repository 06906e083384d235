"""Own hand-written solvers against well-kept libraries (diffrax, optimistix), all in one run.

Each comparison runs the project's own code and the library on the same problem in the same run;
every row has its error and its time (best of interleaved repeats after compilation; compilation
apart) and a ratio against the own code:

- **sinker ODE**: `jaxlink.cam.simulate` (Dormand-Prince 5(4) or Radau IIA 5 with its own event
  location) against diffrax 0.7 `Dopri5`, `Tsit5` and `Kvaerno5` with `PIDController(jump_ts=cam
  piece starts)` and a contact `Event` located by bisection. Problems: `error_vs_runtime.py`'s
  sinker runs (R20-55, f = 0.1, C = 3.5e4; knobs rtol, max_step, method), a short contact loss
  (R10-45, f = 0.16, also at the loose rtol 1e-3), a stiff case (C = 1e7) and a batch (the
  maxima table, friction values x the six cams: `simulate_batch` against diffrax under `vmap`).
  Error: max abs(Δy) (m) against scipy (`jaxlink.cam.reference_solution`: DOP853 at rtol 1e-12;
  1e-10 for the batch).
- **jamming thresholds**: `jaxlink.cam.thresholds` (batched bisection over the six seed cams)
  against the same bisection with diffrax simulating each batch (`thresholds(jammed=...)`), exact
  arc (and the chord polygon in the full run), tol 1e-4 (`jaxlink jamming`) and 1e-5. Error: max
  abs(Δf) against the same bisection on scipy runs. Also the wall time of a fresh process
  (`jaxlink jamming sinker-cam` against the same thresholds by diffrax), compilation included.
- **Newton**: `jaxlink.solve(method="continuation")` against `optimistix.root_find(
  optimistix.Newton)` in a `lax.scan` over the angles with jaxlink's quadratic predictor, on the
  sewing-feed six-bar (B designs x 72 angles). Error: max abs(ΔZ) (m) of the feed dog against
  numpy Newton to 1e-15 m.

"Equal-error ratio" of an own row with error e and time t: the least time of any row of one
library solver on the same case with error <= e, divided by t (inf: no row reaches e). The rule
(docs/methods/cam-integrators.md): adopt the library where this is <= 1.2. Run:

    python benchmarks/libraries.py [--quick] [--json OUT]

Writes `benchmarks/results/libraries.json` by default.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import platform
import sys
import time
from typing import Callable

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

try:
    import diffrax as dfx
    import optimistix as optx
except ImportError:  # the libraries measured here are not jaxlink dependencies
    sys.exit("benchmarks/libraries.py needs diffrax and optimistix: pip install diffrax optimistix")

import jaxlink as jl  # noqa: E402
from jaxlink import cam as sk  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from throughput import feed_batch, feed_point_np  # noqa: E402

RESULTS_DIR = os.path.join(HERE, "results")
SPEED = sk.butt_speed(350.0, 0.096)
ADOPT_RATIO = 1.2


def race(fns, repeats):
    """Interleaved timing of the callables `fns` (name -> callable): each is called once (compile
    and first run), then `repeats` rounds call each in turn, so that load changes on a shared
    machine hit all alike. Returns name -> (first call seconds, best later call seconds, output)."""
    first, best, out = {}, {}, {}
    for k, f in fns.items():
        t = time.perf_counter()
        out[k] = jax.block_until_ready(f())
        first[k] = time.perf_counter() - t
        best[k] = math.inf
    for _ in range(repeats):
        for k, f in fns.items():
            t = time.perf_counter()
            jax.block_until_ready(f())
            best[k] = min(best[k], time.perf_counter() - t)
    return {k: (first[k], best[k], out[k]) for k in fns}


# ----------------------------------------------------------------------------- the sinker in diffrax

DIFFRAX_SOLVERS = {"dopri5": dfx.Dopri5, "tsit5": dfx.Tsit5, "kvaerno5": dfx.Kvaerno5}
CONTACT_OFFSET = 1e-12  # m


class SummedBisection(optx.AbstractRootFinder):
    """`optimistix.Bisection` (decreasing function: `flip=True`) on the sum of the values of a
    list of event conditions. diffrax root-finds the list `[c_0(t), c_1(t), ...]` in which the
    condition that triggered has its value and the others are exactly 0 (a boolean condition: the
    distance to the step end), so the sum is the triggered condition's value; `Bisection` alone
    accepts only a scalar function."""

    rtol: float
    atol: float
    norm: Callable = jnp.abs

    def _inner(self):
        return optx.Bisection(rtol=self.rtol, atol=self.atol, flip=True)

    @staticmethod
    def _summed(fn):
        def g(y, args):
            f, aux = fn(y, args)
            return sum(jax.tree.leaves(f)), aux
        return g

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        scalar = jax.ShapeDtypeStruct((), jnp.result_type(y))
        return self._inner().init(self._summed(fn), y, args, options, scalar, aux_struct, tags)

    def step(self, fn, y, args, options, state, tags):
        return self._inner().step(self._summed(fn), y, args, options, state, tags)

    def terminate(self, fn, y, args, options, state, tags):
        return self._inner().terminate(self._summed(fn), y, args, options, state, tags)

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        return y, aux, {}


def _diffrax_sinker(params, cam, knobs, *, solver, n_out, stop_on_jam, max_steps=10000, max_segments=64):
    """The sinker's hybrid ODE (`jaxlink.cam.vector_field`, contact law in mode 1, free flight in
    mode 0) integrated by diffrax from rest over the cam passage.

    Cam pieces: `PIDController(jump_ts=piece starts)` (steps end just before a piece boundary,
    restart just after it, so each step's right-hand side is smooth). Contact changes: a
    directional `diffrax.Event` on the lag `y_z - y` (sign-flipped in flight), located by bisection
    (`SummedBisection`; `optimistix.Newton` from the step end fails when the lag has its minimum
    inside the step); diffrax checks an event's condition at step ends. At an event the solve ends;
    a `lax.while_loop` flips the mode and restarts from there. Output: dense interpolation at
    `n_out` times. With `stop_on_jam` a second, boolean condition ends the run at the first step
    end with a jam (after the straight rise: y' < 0 or lag > lag_limit, as `jaxlink.cam.simulate`).
    """
    rtol, atol, max_step, lag_limit = knobs
    dtype = cam.t0.dtype
    t_end = cam.t_end
    ts = jnp.linspace(0.0, 1.0, n_out, dtype=dtype) * t_end
    term = dfx.ODETerm(lambda t, u, mode: sk.vector_field(params, cam, t, u, mode, sk.cam_segment(cam, t)))

    def contact(t, y, args, **kwargs):
        # > 0 while the mode holds. The offset (1e-12 m) makes the value at a restart, where the
        # lag is 0 to rounding, positive: a directional event needs a positive value before a
        # step to fire at its end, so without it a contact regained within the first step of a
        # flight is never seen (measured: 11 mm off at max_step 0.3 ms).
        lg = sk.lag(cam, t, y, sk.cam_segment(cam, t))
        return jnp.where(args > 0.5, lg, -lg) + CONTACT_OFFSET

    def jam(t, y, args, **kwargs):
        return (t > cam.t_rise) & ((y[1] < 0) | (sk.lag(cam, t, y) > lag_limit))

    conds = [contact, jam] if stop_on_jam else [contact]
    event = dfx.Event(conds, root_finder=SummedBisection(rtol=1e-13, atol=1e-15),
                      direction=[False] + [None] * (len(conds) - 1))
    controller = dfx.PIDController(rtol=rtol, atol=atol, dtmax=max_step, jump_ts=cam.t0[1:])
    dense = n_out > 2
    saveat = dfx.SaveAt(t1=True, dense=dense)
    slv = DIFFRAX_SOLVERS[solver]()

    def body(c):
        t, u, mode, out, n_seg, _, jammed, steps, rejected, failed = c
        sol = dfx.diffeqsolve(term, slv, t0=t, t1=t_end, dt0=None, y0=u, args=mode, saveat=saveat,
                              stepsize_controller=controller, event=event, max_steps=max_steps, throw=False)
        t1, u1 = sol.ts[-1], sol.ys[-1]
        if dense:
            inside = (ts >= t) & (ts <= t1)
            out = jnp.where(inside[:, None], jax.vmap(sol.evaluate)(jnp.clip(ts, t, t1)), out)
        event_now = sol.result == dfx.RESULTS.event_occurred
        flip = event_now & sol.event_mask[0]
        jam_now = event_now & sol.event_mask[1] if stop_on_jam else jnp.asarray(False)
        ok = event_now | (sol.result == dfx.RESULTS.successful)
        n_seg = n_seg + flip
        done = jam_now | ~ok | (t1 >= t_end) | (n_seg >= max_segments)
        return (t1, u1, jnp.where(flip, 1.0 - mode, mode), out, n_seg, done, jammed | jam_now,
                steps + sol.stats["num_accepted_steps"], rejected + sol.stats["num_rejected_steps"], failed | ~ok)

    zero = jnp.asarray(0)
    init = (jnp.asarray(0.0, dtype), jnp.zeros(2, dtype), jnp.asarray(1.0, dtype),
            jnp.full((n_out, 2), jnp.nan, dtype), zero, jnp.asarray(False), jnp.asarray(False), zero, zero,
            jnp.asarray(False))
    t, _, _, out, n_ev, _, jammed, steps, rejected, failed = jax.lax.while_loop(lambda c: ~c[5], body, init)
    return dict(y=out[:, 0], v=out[:, 1], events=n_ev, jammed=jammed, steps=steps, rejected=rejected,
                failed=failed | ((t < t_end) & ~jammed))


_STATIC = ("solver", "n_out", "stop_on_jam")
diffrax_simulate = jax.jit(_diffrax_sinker, static_argnames=_STATIC)


@functools.partial(jax.jit, static_argnames=_STATIC)
def _diffrax_batch(params, cam, knobs, **kw):
    return jax.vmap(lambda p, c: _diffrax_sinker(p, c, knobs, **kw))(params, cam)


def diffrax_knobs(rtol=1e-6, atol=1e-10, max_step=1e-4, lag_limit=0.02):
    return tuple(jnp.asarray(float(x)) for x in (rtol, atol, max_step, lag_limit))


def diffrax_jammed(solver, **kw):
    """A `jammed(params, cam, f)` predicate for `jaxlink.cam.thresholds` simulated by diffrax."""
    knobs = diffrax_knobs(**kw)

    def jammed(params, cam, f):
        n = cam.t0.shape[0]
        f = jnp.broadcast_to(jnp.asarray(f, dtype=float), (n,))
        pb = jax.tree.map(lambda x: jnp.broadcast_to(jnp.asarray(x), (n,)), params)._replace(f=f)
        out = _diffrax_batch(pb, cam, knobs, solver=solver, n_out=2, stop_on_jam=True)
        return np.asarray(out["jammed"])
    return jammed


def reference_jammed(rtol, max_step, n_grid=20001):
    """A `jammed(params, cam, f)` predicate from scipy (`jaxlink.cam.reference_solution`): jammed
    when, after the straight rise, y' < 0 or the lag exceeds 20 mm on a grid of `n_grid` times."""

    def jammed(params, cam, f):
        out = []
        for i in range(cam.t0.shape[0]):
            c = jax.tree.map(lambda x: x[i], cam)
            ts = np.linspace(0.0, float(c.t_end), n_grid)
            arc = "exact" if float(c.is_arc[1]) > 0.5 else "polygon"
            _, Y, _ = sk.reference_solution(
                radius=float(c.radius), rise_deg=math.degrees(float(c.alpha0[0])),
                descent_deg=math.degrees(float(c.descent_angle)), f=float(f[i]), C=float(params.C),
                k_over_m=float(params.k_over_m), m=float(params.m), R_sum=float(params.R_sum),
                F_P=float(params.F_P), g=float(params.g), arc=arc, ts=ts, rtol=rtol, atol=1e-15,
                max_step=max_step)
            lag = np.asarray(sk.cam_profile(c, ts)[0]) - Y[:, 0]
            after = ts > float(c.t_rise)
            out.append(bool(np.any(after & ((Y[:, 1] < 0) | (lag > 0.02)))))
        return np.asarray(out)
    return jammed


# ----------------------------------------------------------------------------- part (a): error vs time


def _row(part, case, problem, code, solver, knob, setting, error, seconds, first, default=False, **extra):
    return dict(part=part, case=case, problem=problem, code=code, solver=solver, knob=knob, setting=setting,
                error=error, seconds=seconds, compile_s=first - seconds, default=default, **extra)


def sinker_problem(case, geometry, f, C, quick, settings, repeats, log):
    """Own vs diffrax on one sinker case. `settings`: (knob, label, simulate kwargs, default?)."""
    km = float(sk.damping_from_log_decrement(C, 1.5e-3))
    geom = [g for g in sk.seed_geometries() if g.name == geometry][0]
    cam = sk.make_cam(geom, SPEED)
    n_out = 2001
    ts = np.linspace(0.0, float(cam.t_end), n_out)
    _, yref, info = sk.reference_solution(radius=geom.radius, descent_deg=round(math.degrees(geom.descent_angle)),
                                          f=f, C=C, k_over_m=km, ts=ts, rtol=1e-12,
                                          max_step=1e-5 if quick else 2e-6)
    params = sk.make_params(f=f, C=C)
    problem = f"sinker {geometry}, f={f:g}, C={C:.3g}"
    rows = []
    for knob, label, kw, default in settings:
        own_kw = {**dict(rtol=1e-6, atol=1e-10, max_step=1e-4, method="explicit"), **kw}
        knobs = diffrax_knobs(own_kw["rtol"], own_kw["atol"], own_kw["max_step"])
        explicit = own_kw["method"] == "explicit"
        fns = {"own": lambda: sk.simulate(params, cam, n_out=n_out, **own_kw)}
        for solver in ("dopri5", "tsit5") if explicit else ("kvaerno5",):
            fns[solver] = functools.partial(diffrax_simulate, params, cam, knobs, solver=solver, n_out=n_out,
                                            stop_on_jam=False)
        res = race(fns, repeats)
        first, best, sol = res.pop("own")
        ok = int(sol.result) == sk.RESULTS.converged
        err = float(np.max(np.abs(np.asarray(sol.y) - yref[:, 0]))) if ok else math.inf
        own = _row("sinker", case, problem, "own", "DormandPrince5" if explicit else "RadauIIA5", knob, label, err,
                   best, first, default, steps=int(sol.stats.num_steps), events=int(sol.stats.num_events),
                   ref_events=info["events"])
        log(own)
        rows.append(own)
        for solver, (first, best, d) in res.items():
            ok = not bool(d["failed"])
            err = float(np.max(np.abs(np.asarray(d["y"]) - yref[:, 0]))) if ok else math.inf
            r = _row("sinker", case, problem, "diffrax", solver, knob, label, err, best, first, default,
                     steps=int(d["steps"]), events=int(d["events"]), ref_events=info["events"],
                     time_ratio=best / own["seconds"], error_ratio=err / own["error"] if own["error"] > 0 else math.inf)
            log(r)
            rows.append(r)
    return rows


def batch_problem(quick, repeats, log):
    """Own `simulate_batch` vs diffrax under `vmap` on the seed's maxima table (friction values x
    the six cams, as `experiments/sinker_jamming.py`; `jaxlink simulate` runs such batches).
    Error: max abs(Δy) over the cases that do not jam in the reference (a jammed sinker runs away:
    its trajectory after the jam is ill-conditioned)."""
    geoms = sk.seed_geometries()
    f_values = [0.10, 0.12, 0.14, 0.145] if quick else [0.10, 0.12, 0.13, 0.14, 0.145, 0.15, 0.16, 0.17, 0.18, 0.19]
    cams = sk.make_cam(geoms, SPEED)
    params = sk.make_params()
    pb, cb, shape = sk.product_cases(params, cams, f=f_values)
    n_out = 2001
    refs, keep = [], []
    for f in f_values:  # row-major (f, geometry), as product_cases
        for g in geoms:
            cam = sk.make_cam(g, SPEED)
            ts = np.linspace(0.0, float(cam.t_end), n_out)
            _, Y, _ = sk.reference_solution(radius=g.radius, descent_deg=round(math.degrees(g.descent_angle)), f=f,
                                            C=float(params.C), k_over_m=float(params.k_over_m), ts=ts,
                                            rtol=1e-10, atol=1e-15, max_step=1e-5)
            lag = np.asarray(sk.cam_profile(cam, ts)[0]) - Y[:, 0]
            keep.append(not np.any((ts > float(cam.t_rise)) & ((Y[:, 1] < 0) | (lag > 0.02))))
            refs.append(Y[:, 0])
    refs, keep = np.asarray(refs), np.asarray(keep)
    problem = f"batch {len(f_values)} f x 6 cams ({int(keep.sum())} not jammed), C=3.5e4"
    rows = []
    for rt in (1e-5, 1e-6, 1e-7):
        knobs = diffrax_knobs(rtol=rt)
        fns = {"own": functools.partial(sk.simulate_batch, pb, cb, n_out=n_out, rtol=rt)}
        for solver in ("dopri5", "tsit5"):
            fns[solver] = functools.partial(_diffrax_batch, pb, cb, knobs, solver=solver, n_out=n_out,
                                            stop_on_jam=False)
        res = race(fns, repeats)
        own = None
        for name, (first, best, out) in res.items():
            y = np.asarray(out.y if name == "own" else out["y"])
            err = float(np.max(np.abs(y - refs)[keep]))
            r = _row("sinker", "batch", problem, "own" if name == "own" else "diffrax",
                     "DormandPrince5" if name == "own" else name, "batch_rtol", f"{rt:g}", err, best, first,
                     default=rt == 1e-6, cases=int(y.shape[0]))
            if own is None:
                own = r
            else:
                r["time_ratio"] = best / own["seconds"]
                r["error_ratio"] = err / own["error"] if own["error"] > 0 else math.inf
            log(r)
            rows.append(r)
    return rows


def sinker_rows(quick, repeats, log):
    inf = math.inf

    def step_label(ms):
        return "inf" if ms == inf else f"{ms:g} s"

    rtols = (1e-3, 1e-6, 1e-10) if quick else (1e-3, 1e-4, 1e-5, 1e-6, 1e-8, 1e-10)
    steps = (inf, 1e-4, 2e-5) if quick else (inf, 3e-4, 1e-4, 2e-5, 5e-6)
    main = ([("sinker_rtol", f"{rt:g}", dict(rtol=rt), rt == 1e-6) for rt in rtols]
            + [("sinker_max_step", step_label(ms), dict(max_step=ms), ms == 1e-4) for ms in steps]
            + [("sinker_method", "implicit", dict(method="implicit"), False)])
    rows = sinker_problem("error_vs_runtime", "R20-55", 0.1, 3.5e4, quick, main, repeats, log)
    # a contact lost for ~0.2 ms only (tests/test_sinker.py::test_short_bounce_not_skipped), at the
    # default rtol and at the test's loose rtol = 1e-3, where one step can hold the whole loss
    bounce_steps = (inf, 1e-4, 2e-5) if quick else (inf, 3e-4, 1e-4, 5e-5, 2e-5)
    short = ([("short_bounce_max_step", step_label(ms), dict(max_step=ms), ms == 1e-4) for ms in bounce_steps]
             + [("short_bounce_loose", f"rtol 1e-3, {step_label(ms)}", dict(rtol=1e-3, max_step=ms), False)
                for ms in bounce_steps])
    rows += sinker_problem("short bounce", "R10-45", 0.16, 3.5e4, quick, short, repeats, log)
    # stiff: the implicit methods' case (`auto` picks the implicit one above 3e6 N/m)
    stiff = [("stiff_rtol", f"{m}, rtol {rt:g}", dict(method=m, rtol=rt), m == "implicit" and rt == 1e-6)
             for m in ("explicit", "implicit") for rt in ((1e-6,) if quick else (1e-4, 1e-6, 1e-8))]
    rows += sinker_problem("stiff", "R20-55", 0.1, 1e7, quick, stiff, min(repeats, 3), log)
    rows += batch_problem(quick, min(repeats, 3), log)
    return rows


def equal_error_ratios(rows):
    """For every own row: per library solver, the least time of that solver's rows of the same
    case with error <= the own row's error, divided by the own row's time (inf: none reaches it)."""
    for r in rows:
        if r["code"] != "own":
            continue
        same = [o for o in rows if o["code"] != "own" and o["case"] == r["case"]]
        ratios = {}
        for solver in sorted({o["solver"] for o in same}):
            t = [o["seconds"] for o in same if o["solver"] == solver and o["error"] <= r["error"]]
            ratios[solver] = min(t) / r["seconds"] if t else math.inf
        r["equal_error_ratio"] = ratios
    return rows


# ----------------------------------------------------------------------------- part (b): jamming


def jamming_rows(quick, repeats, log):
    params = sk.make_params()
    geoms = sk.seed_geometries()
    tols = (1e-4,) if quick else (1e-4, 1e-5)
    arcs = ("exact",) if quick else ("exact", "polygon")
    variants = ([("dopri5", 1e-4), ("tsit5", 1e-4), ("dopri5", 2.5e-5)] if quick else
                [("dopri5", 1e-4), ("tsit5", 1e-4), ("dopri5", 5e-5), ("tsit5", 5e-5), ("dopri5", 2.5e-5),
                 ("dopri5", 1.25e-5)])
    rows = []
    for arc in arcs:
        cams = sk.make_cam([g._replace(arc=arc) for g in geoms], SPEED)
        problem = f"6 seed cams, {arc} arc"
        # the reference: the same bisection on scipy runs, to well below the tolerances measured
        t = time.perf_counter()
        ref = sk.thresholds(params, cams, tol=1e-5 if quick else 2e-6, half_width=0.003,
                            jammed=reference_jammed(rtol=1e-9 if quick else 1e-10, max_step=1e-5))
        ref_f = np.asarray(ref.dynamic_f)
        ref_half = 0.5 * float(np.max(ref.hi - ref.lo))
        print(f"  reference thresholds ({arc}): {np.round(ref_f, 6)} (+-{ref_half:.1e}, "
              f"{time.perf_counter() - t:.0f} s)", flush=True)
        for tol in tols:
            fns = {("own", None): functools.partial(sk.thresholds, params, cams, tol=tol)}
            for solver, ms in variants:
                fns[(solver, ms)] = functools.partial(sk.thresholds, params, cams, tol=tol,
                                                      jammed=diffrax_jammed(solver, max_step=ms))
            res = race(fns, repeats)
            first, best, th = res.pop(("own", None))
            err = float(np.max(np.abs(np.asarray(th.dynamic_f) - ref_f)))
            case = f"jamming {arc}"
            own = _row("jamming", case, problem, "own", "DormandPrince5", "tol", f"{tol:g}, 1e-4 s", err, best,
                       first, default=tol == 1e-4, tol=tol, max_step=1e-4, within_tol=err <= tol,
                       dynamic_f=np.asarray(th.dynamic_f).tolist(), reference_f=ref_f.tolist(),
                       reference_half_width=ref_half, batches=th.num_batches)
            log(own)
            rows.append(own)
            for (solver, ms), (first, best, th) in res.items():
                err = float(np.max(np.abs(np.asarray(th.dynamic_f) - ref_f)))
                r = _row("jamming", case, problem, "diffrax", solver, "tol, max_step", f"{tol:g}, {ms:g} s", err,
                         best, first, tol=tol, max_step=ms, within_tol=err <= tol,
                         dynamic_f=np.asarray(th.dynamic_f).tolist(), batches=th.num_batches,
                         time_ratio=best / own["seconds"])
                log(r)
                rows.append(r)
    return rows


def jamming_wall(solver, max_step, tol):
    """Thresholds of the `sinker-cam` scene as `jaxlink jamming` computes them, by diffrax (for
    a fresh-process wall time); prints them as JSON."""
    cams = sk.make_cam(sk.seed_geometries(), SPEED)
    th = sk.thresholds(sk.make_params(), cams, tol=tol, jammed=diffrax_jammed(solver, max_step=max_step))
    print(json.dumps({"dynamic_f": np.asarray(th.dynamic_f).tolist()}))


def jamming_wall_rows(tol, log):
    """Wall time of a fresh process computing the thresholds: `jaxlink jamming sinker-cam` (own
    code) and the same thresholds by diffrax (this script, `--wall-jamming`); imports and
    compilation included."""
    import subprocess

    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([os.path.dirname(HERE)] + [p for p in [env.get("PYTHONPATH")] if p])
    cmds = {("own", 1e-4): [sys.executable, "-m", "jaxlink.cli", "jamming", "sinker-cam", "--tol", f"{tol:g}"]}
    for solver, ms in (("tsit5", 1e-4), ("dopri5", 2.5e-5)):
        cmds[(solver, ms)] = [sys.executable, os.path.abspath(__file__), "--wall-jamming", solver,
                              "--max-step", f"{ms:g}", "--tol", f"{tol:g}"]
    rows = []
    for (solver, ms), cmd in cmds.items():
        t = time.perf_counter()
        subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wall = time.perf_counter() - t
        r = dict(part="jamming_wall", case="jamming wall", problem="sinker-cam scene, fresh process",
                 code="own" if solver == "own" else "diffrax", solver="DormandPrince5" if solver == "own" else solver,
                 knob="tol, max_step", setting=f"{tol:g}, {ms:g} s", error=math.nan, seconds=wall, compile_s=math.nan,
                 default=solver == "own", tol=tol, max_step=ms)
        log(r)
        rows.append(r)
    own = rows[0]["seconds"]
    for r in rows[1:]:
        r["time_ratio"] = r["seconds"] / own
    return rows


# ----------------------------------------------------------------------------- part (c): Newton


def newton_rows(B, quick, repeats, log):
    mech, P, phis, ref = feed_batch(B)
    N = len(phis)
    pos = B * N
    Pd, ph, q0 = (jnp.asarray(x) for x in (P, phis, mech.guess))
    problem = f"sewing-feed {B}x{N}, continuation"

    def error(q):
        xy = feed_point_np(np.asarray(q, dtype=float).reshape(-1, 4), np.tile(phis, B), np.repeat(P, N, axis=0))
        return float(np.max(np.abs(xy - ref)))

    @functools.partial(jax.jit, static_argnames=("max_steps",))
    def optx_solve(P, phis, q0, rtol, atol, max_steps=60):
        """optimistix Newton (library defaults: Jacobian by forward AD, lineax LU) at every angle,
        from the previous solutions by the quadratic predictor jaxlink uses (`predictor_order=2`
        on equally spaced inputs), the first angle from the file's guess; `vmap` over designs."""
        solver = optx.Newton(rtol=rtol, atol=atol)

        def fn(q, args):
            phi, p = args
            return mech.residual(q, phi, p)

        def one(p):
            first = optx.root_find(fn, solver, q0, args=(phis[0], p), max_steps=max_steps, throw=False)

            def step(carry, phi):
                q1, q2, q3, n = carry
                guess = jnp.where(n >= 3, 3 * q1 - 3 * q2 + q3, jnp.where(n >= 2, 2 * q1 - q2, q1))
                s = optx.root_find(fn, solver, guess, args=(phi, p), max_steps=12, throw=False)
                return (s.value, q1, q2, n + 1), (s.value, s.result == optx.RESULTS.successful)

            q = first.value
            _, (qs, oks) = jax.lax.scan(step, (q, q, q, jnp.asarray(1)), phis[1:])
            return (jnp.concatenate([q[None], qs]),
                    jnp.concatenate([(first.result == optx.RESULTS.successful)[None], oks]))
        return jax.vmap(one)(P)

    own_rtols = (1e-3, 1e-8, None) if quick else (1e-3, 1e-5, 1e-8, None)
    optx_tols = (1e-4, 1e-8, 1e-12) if quick else (1e-3, 1e-5, 1e-8, 1e-10, 1e-12)
    fns = {}
    for rt in own_rtols:
        opts = jl.NewtonOptions(method="continuation", rtol=rt)
        fns[("own", rt)] = functools.partial(jl.solve, mech, ph, p=Pd, q0=q0, options=opts)
    for tol in optx_tols:
        fns[("optx", tol)] = functools.partial(optx_solve, Pd, ph, q0, tol, tol)
    res = race(fns, repeats)
    rows = []
    for (code, tol), (first, best, out) in res.items():
        if code == "own":
            r = _row("newton", "sewing-feed", problem, "own", "jaxlink Newton", "rtol",
                     "default (1000 eps)" if tol is None else f"{tol:g}", error(out.q), best, first,
                     default=tol is None, positions_per_s=pos / best,
                     converged_fraction=float(np.mean(np.asarray(out.converged))))
        else:
            q, ok = out
            r = _row("newton", "sewing-feed", problem, "optimistix", "optimistix.Newton", "rtol = atol", f"{tol:g}",
                     error(q), best, first, positions_per_s=pos / best,
                     converged_fraction=float(np.mean(np.asarray(ok))))
        log(r)
        rows.append(r)
    own_default = [r for r in rows if r["code"] == "own" and r["default"]][0]
    for r in rows:
        if r["code"] != "own":
            r["time_ratio"] = r["seconds"] / own_default["seconds"]
    return rows


# ----------------------------------------------------------------------------- decisions, output


def decide(rows):
    """The 1.2x rule on the shipped defaults, per code path (sinker: rtol 1e-6, max_step 1e-4,
    explicit below 3e6 N/m and implicit above, one case or a batch; jamming: tol 1e-4 and 1e-5,
    warm and in a fresh process; Newton: default rtol)."""
    out = {}
    for r in rows:
        if r["code"] != "own" or not r["default"] or "equal_error_ratio" not in r:
            continue
        best = min(r["equal_error_ratio"].items(), key=lambda kv: kv[1])
        out[f"{r['case']}: {r['knob']} = {r['setting']}"] = dict(
            own_error=r["error"], own_seconds=r["seconds"], best_library=best[0], equal_error_ratio=best[1],
            meets_rule=best[1] <= ADOPT_RATIO)
    for own in [r for r in rows if r["part"] == "jamming" and r["code"] == "own"]:
        # a library run counts when its thresholds are as close to the reference as the own ones
        # or within the bisection tolerance
        lib = [r for r in rows if r["case"] == own["case"] and r["code"] != "own" and r["tol"] == own["tol"]
               and r["error"] <= max(own["error"], own["tol"])]
        best = min(lib, key=lambda r: r["seconds"]) if lib else None
        ratio = best["seconds"] / own["seconds"] if best else math.inf
        out[f"{own['case']}: tol = {own['tol']:g} (warm)"] = dict(
            own_error=own["error"], own_seconds=own["seconds"],
            best_library=f"{best['solver']}, max_step {best['max_step']:g} s" if best else None,
            library_error=best["error"] if best else None, equal_error_ratio=ratio, meets_rule=ratio <= ADOPT_RATIO)
    wall = [r for r in rows if r["part"] == "jamming_wall"]
    if wall:
        lib = min(wall[1:], key=lambda r: r["seconds"])
        out["jamming wall: fresh process, tol = 1e-4"] = dict(
            own_seconds=wall[0]["seconds"], best_library=f"{lib['solver']}, max_step {lib['max_step']:g} s",
            equal_error_ratio=lib["time_ratio"], meets_rule=lib["time_ratio"] <= ADOPT_RATIO)
    return out


def fmt_ratio(x):
    return "inf" if not math.isfinite(x) else f"{x:.2f}"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer settings, looser references (a few minutes)")
    ap.add_argument("--designs", type=int, default=None, help="feed designs, Newton part (default 2000; quick 500)")
    ap.add_argument("--json", default=os.path.join(RESULTS_DIR, "libraries.json"))
    ap.add_argument("--only", default=None, help="comma-separated parts: sinker,jamming,wall,newton")
    ap.add_argument("--wall-jamming", metavar="SOLVER", help=argparse.SUPPRESS)
    ap.add_argument("--max-step", type=float, default=1e-4, help=argparse.SUPPRESS)
    ap.add_argument("--tol", type=float, default=1e-4, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.wall_jamming:
        jamming_wall(args.wall_jamming, args.max_step, args.tol)
        return {}
    repeats = 3 if args.quick else 7
    B = args.designs or (500 if args.quick else 2000)
    parts = set((args.only or "sinker,jamming,wall,newton").split(","))

    def log(r):
        extra = f"  time x{r['time_ratio']:.2f}" if "time_ratio" in r else ""
        print(f"  {r['part']:8s} {r['code']:10s} {r['solver']:18s} {r['knob']:22s} {r['setting']:>26s}"
              f"{' *' if r['default'] else '  '} error {r['error']:10.3e}  {r['seconds'] * 1e3:10.2f} ms{extra}",
              flush=True)

    t0 = time.perf_counter()
    rows, sections = [], {}
    for name, fn in (("sinker", lambda: sinker_rows(args.quick, repeats, log)),
                     ("jamming", lambda: jamming_rows(args.quick, 2 if args.quick else 3, log)),
                     ("wall", lambda: jamming_wall_rows(1e-4, log)),
                     ("newton", lambda: newton_rows(B, args.quick, repeats, log))):
        if name in parts:
            t = time.perf_counter()
            rows += fn()
            sections[name] = time.perf_counter() - t
            print(f"[{name}: {sections[name]:.1f} s]", flush=True)
    equal_error_ratios([r for r in rows if r["part"] in ("sinker", "newton")])
    decisions = decide(rows)

    print(f"\nown code vs libraries ({os.cpu_count()} cores, jax {jax.__version__}, diffrax {dfx.__version__}, "
          f"optimistix {optx.__version__}); * = shipped default; x own = time / own time at the same setting")
    print(f"{'case':16s} {'code':10s} {'solver':18s} {'setting':>28s}   {'error':>10s} {'time ms':>9s} {'x own':>6s}"
          f"  equal-error ratio (library time / own time)")
    for r in rows:
        eq = ", ".join(f"{k} {fmt_ratio(v)}" for k, v in r.get("equal_error_ratio", {}).items())
        print(f"{r['case'][:16]:16s} {r['code']:10s} {r['solver'][:18]:18s} {r['setting'][:28]:>28s} "
              f"{'*' if r['default'] else ' ':1s} {r['error']:10.3e} {r['seconds'] * 1e3:9.2f} "
              f"{fmt_ratio(r['time_ratio']) if 'time_ratio' in r else '':>6s}  {eq}")
    print(f"\nthe rule per code path and default (the library reaches the own error within {ADOPT_RATIO}x the own "
          f"time; the decision for the package: docs/methods/cam-integrators.md):")
    for k, d in decisions.items():
        print(f"  {k}: best {d['best_library']}, ratio {fmt_ratio(d['equal_error_ratio'])} -> "
              f"{'meets the rule' if d['meets_rule'] else 'does not meet the rule'}")
    out = {"rows": rows, "decisions": decisions, "adopt_ratio": ADOPT_RATIO, "repeats": repeats, "feed_designs": B,
           "quick": args.quick, "wall_s": time.perf_counter() - t0, "section_wall_s": sections,
           "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "jax": jax.__version__,
                       "diffrax": dfx.__version__, "optimistix": optx.__version__}}
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1, default=float)
        print(f"wrote {args.json}")
    return out


if __name__ == "__main__":
    main()
