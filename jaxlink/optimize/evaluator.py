"""The one batched evaluator: designs → traced paths → objective, jitted, vmapped over designs,
sharded over devices.

A design is a vector u ∈ [0, 1]^V of normalized variables (x = lower + u (upper − lower) in file
units) and a circuit index c (which branch signs of the dyads; 0 = the file's). For each design:

1. p = the file's parameters with the variables replaced (SI);
2. a starting configuration at the first input on the circuit (`_start.py`), gradient stopped;
3. the path solve over the `samples` inputs (`jaxlink.solvers.assemble.solve_path`: closed-form dyads or
   Newton continuation; differentiable in p by implicit differentiation);
4. the point's path (and its input derivatives if the objective needs them, `_kinematics`),
   with the solved unknowns q and the parameters p (`PathData`);
5. the objective. A design is *feasible* iff every parameter is within its domain
   (`jaxlink.model.domains`, what the file reader and `--set` accept: bounds [-5, 5] on a link
   length evaluate no negative link), the start and every position converged, the
   path's pieces (points and their derivatives) are finite and, for a mechanism made of dyads,
   no dyad is about to open an unassemblable window between two checked positions (the reach
   margin interpolated between the samples stays ≥ 0: `jaxlink.analysis.feasibility.screen`);
   an infeasible design gets the value +inf (never NaN), and it is counted.

The design a search reports is *certified* (`Evaluator.report`): for a mechanism of dyads, the
reach margin's minimum over the whole revolution, refined between the samples
(`feasibility.certify`), is ≥ 0; for other mechanisms, and for a length input (whose samples run
from `start` to `stop`, not around a revolution), every position of the dense re-solve
(`report_samples`) converged.

One *mechanism evaluation* = one design solved over its revolution (on one circuit: with
`circuits = "all"` a design costs one evaluation per circuit).
"""

from __future__ import annotations

import copy

import jax
import jax.numpy as jnp
import numpy as np

from ..analysis import feasibility as _feasibility
from ..analysis.transfer import transfer_one
from ..errors import MechanismError
from ..model import domains as _domains
from ..solvers import dyads as _dyads
from ..solvers.assemble import solve_path
from ..solvers.options import NewtonOptions, default_rtol
from .objectives import OBJECTIVES, PathData, to_python
from .problem import INTEGER_DOMAINS, Problem, start_method
from .sharding import default_chunk, design_sharding, pad_rows, put
from .start import circuit_signs, closed_form_start, continuation_start, file_configuration

#: a mechanism not made of dyads is re-solved at this many times the search's samples (at least)
#: before its design is reported as turning fully (`Evaluator.certified`)
DENSE_FACTOR = 10


class Evaluator:
    """Batched, jitted, sharded evaluation of designs for a `Problem`.

    **Arguments:**

    - `problem`: the parsed `[optimize]` problem.
    - `chunk`: designs per compiled batch (keyword-only; default: from the device and the
      problem's size, `sharding.default_chunk`: 4096 designs of 36 samples on a CPU).
    - `devices`: the devices to shard over (default: all).
    """

    def __init__(self, problem: Problem, *, chunk: int | None = None, devices=None,
                 options: NewtonOptions = NewtonOptions()):
        self.problem = problem
        mech = problem.mech
        self.mech = mech
        lo, hi = INTEGER_DOMAINS["chunk"]
        if chunk is not None and (isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer))
                                  or not lo <= chunk <= hi):
            # (a chunk ≤ 0 would make every batch loop empty: a search that never advances)
            raise MechanismError(f"chunk = {chunk!r}: designs per batch must be an integer from {lo} to {hi}",
                                 file=mech.file, key="optimize.chunk")
        self.objective = OBJECTIVES.build(problem)
        self.options = options
        self.sharding = design_sharding(devices)
        self.n_devices = len(self.sharding.mesh.devices.flat)
        phi0 = float(problem.phis[0])
        self.phi0 = phi0
        self.q_file = file_configuration(mech, phi0)
        self.dyads, method = start_method(problem)
        self.start_method = method
        # "auto": every circuit when the objective is the untimed path (`points`): which branch
        # traces the shape is part of the answer; the file's otherwise
        self.circuits = problem.circuits
        if self.circuits == "auto":
            self.circuits = "all" if problem.objective == "points" and method == "closed_form" else "file"
        # the reach margin between samples (screen, certificate) is for a revolution; a length
        # input's design is certified by the dense re-solve
        self.between = self.dyads is not None and problem.periodic
        if self.dyads is not None:
            self.sigmas = circuit_signs(mech, self.q_file, phi0, all_circuits=self.circuits == "all")
        else:
            self.sigmas = np.zeros((1, 0))
        self.n_circuits = len(self.sigmas)
        if chunk is None:
            per = len(problem.phis) * (self.n_circuits if problem.circuits == "all" else 1)
            chunk = default_chunk(per, len(mech.guess) + 2 * len(mech.point_names),
                                  list(self.sharding.mesh.devices.flat))
        self.chunk = -(-int(chunk) // self.n_devices) * self.n_devices
        default_report = 7200 if problem.objective == "points" else len(problem.phis)
        self.report_samples = int(problem.option("report_samples", default_report))
        self.evaluations = 0  # mechanism evaluations made through this object
        self.infeasible = 0
        self._compiled: dict = {}

    def padded_size(self, n: int) -> int:
        """Rows a batch of `n` designs is padded to: the next power of two (at least 8 per
        device), at most `chunk`. Few shapes (one compilation each), and a small batch (the
        gradient search's starts) is not padded to a large chunk."""
        m = 8 * self.n_devices
        while m < n and m < self.chunk:
            m *= 2
        return min(m, self.chunk)

    def compiled(self, key, build):
        """`build()` made once per evaluator under `key` (a hashable tuple): every jitted batch
        function of the evaluator and of the searches run on it is kept here, so a second search
        on the same evaluator compiles nothing."""
        if key not in self._compiled:
            self._compiled[key] = build()
        return self._compiled[key]

    # ------------------------------------------------------------------ single design (traced)
    def params(self, u):
        pr = self.problem
        x = jnp.asarray(pr.lower, u.dtype) + u * jnp.asarray(pr.upper - pr.lower, u.dtype)
        p = jnp.asarray(self.mech.parameters, dtype=u.dtype)
        return p.at[jnp.asarray(pr.index)].set(x * jnp.asarray(pr.factor, u.dtype))

    def start(self, p, c):
        dtype = p.dtype
        tol = default_rtol(dtype) * self.mech.length_scale(p)
        if self.start_method == "closed_form":
            sigma = jnp.asarray(self.sigmas, dtype)[c]
            return closed_form_start(self.mech, self.dyads, self.q_file, self.phi0, p, sigma, tol)
        return continuation_start(self.mech, self.q_file, self.mech.parameters, self.phi0, p, tol)

    def path(self, u, c, phis, order: int, screen: bool = True):
        """(PathData in file units, feasible) of one design at the equally spaced inputs `phis`
        of a revolution; `screen`: a dyad mechanism's reach margin interpolated between them must
        stay ≥ 0 (see the module doc; off for a handful of samples too coarse to interpolate)."""
        p = self.params(u)
        q0, ok0 = self.start(p, c)
        q0 = jax.lax.stop_gradient(q0)
        sol = solve_path(self.mech, phis, p, q0, options=self.options)
        feasible = ok0 & jnp.all(sol.converged) & _domains.inside(self.mech, p)  # a value the file could hold
        if screen and self.between:  # no window opening between two checked positions
            feasible = feasible & self._screened(jax.lax.stop_gradient(p), q0, phis)
        lf = self.mech.units.length
        k = self.problem.point
        t = jax.vmap(lambda q, ph: transfer_one(self.mech, q, ph, p, order))(sol.q, phis)
        xy = t.points[:, k] / lf
        dxy = None if t.dpoints is None else t.dpoints[:, k] / lf
        ddxy = None if t.ddpoints is None else t.ddpoints[:, k] / lf
        # finiteness is part of convergence: a path with non-finite pieces is infeasible
        for piece in (xy, dxy, ddxy):
            if piece is not None:
                feasible = feasible & jnp.all(jnp.isfinite(piece))
        return PathData(xy, dxy, ddxy, sol.q, p), feasible

    def _branches(self, p, q0):
        """σ of the dyads at the design's start configuration q0 (the branches its path keeps)."""
        phi0 = jnp.asarray(self.phi0, p.dtype)
        return jax.lax.stop_gradient(_dyads.solve_nearest(self.mech, self.dyads, q0, phi0, p)[3])

    def _screened(self, p, q0, phis):
        """Whether the reach margin interpolated between the equally spaced `phis` stays ≥ 0."""
        est = _feasibility.screen(self.mech, self.dyads, self._branches(p, q0), q0, phis, p)
        return jnp.all(est >= -_feasibility.MARGIN_SLACK)

    def margin_single(self, u, c):
        """The screen's smallest conservative estimate of the reach margin between the search's
        samples (`feasibility.screen`) of one design on circuit `c`, differentiable in u: the
        design is screened feasible iff it is ≥ −`MARGIN_SLACK` (a mechanism of dyads on a
        revolution only: `between`). The polish follows the feasibility boundary on it
        (`searches/boundary.py`)."""
        p = self.params(u)
        q0 = jax.lax.stop_gradient(self.start(p, c)[0])
        phis = jnp.asarray(self.problem.phis, u.dtype)
        sigma = self._branches(jax.lax.stop_gradient(p), q0)
        return _feasibility.least(_feasibility.screen(self.mech, self.dyads, sigma, q0, phis, p))

    def certificate_single(self, u, c):
        """The feasibility certificate (`feasibility.Certificate`) of one design on circuit `c` over
        the search's samples (a mechanism of dyads only)."""
        p = self.params(u)
        q0 = jax.lax.stop_gradient(self.start(p, c)[0])
        phis = jnp.asarray(self.problem.phis, u.dtype)
        return _feasibility.certify(self.mech, self.dyads, self._branches(p, q0), q0, phis, p)

    def value_single(self, u, c, rank: bool = False):
        """Exact objective of one design (+inf if infeasible) and its feasibility; with `rank`
        also the objective's start-ranking value (`Objective.rank`, default the value)."""
        phis = jnp.asarray(self.problem.phis, u.dtype)
        path, feas = self.path(u, c, phis, self.objective.order)
        if rank and self.objective.rank is not None:
            v, r = self.objective.rank(path)
        else:
            v = r = self.objective.value(path)
        ok = feas & jnp.isfinite(v)
        out = (jnp.where(ok, v, jnp.inf), ok)
        return out + (jnp.where(feas & jnp.isfinite(r), r, jnp.inf),) if rank else out

    def smooth_single(self, u, c):
        """Smoothed objective of one design (+inf if infeasible): what the gradient search uses."""
        phis = jnp.asarray(self.problem.phis, u.dtype)
        path, feas = self.path(u, c, phis, self.objective.order)
        v = self.objective.smooth(path)
        ok = feas & jnp.isfinite(v)
        return jnp.where(ok, v, jnp.inf)

    def smooth_exact_single(self, u, c):
        """(smoothed objective, exact objective) of one design from one path solve, each +inf
        where infeasible: the gradient search differentiates the first and keeps the second."""
        phis = jnp.asarray(self.problem.phis, u.dtype)
        path, feas = self.path(u, c, phis, self.objective.order)
        v = self.objective.smooth(path)
        e = jax.lax.stop_gradient(self.objective.value(path))
        return (jnp.where(feas & jnp.isfinite(v), v, jnp.inf), jnp.where(feas & jnp.isfinite(e), e, jnp.inf))

    def constrained_single(self, u, c):
        """For the constrained gradient solver: (f, constraint values (K,), exact value, feasible)
        of one design from one path solve (`Objective.constraints`)."""
        phis = jnp.asarray(self.problem.phis, u.dtype)
        path, feas = self.path(u, c, phis, self.objective.order)
        f, cons, v = self.objective.constraints(path)
        return f, cons, jnp.where(feas & jnp.isfinite(v), v, jnp.inf), feas

    # ------------------------------------------------------------------ batched (jitted)
    def _values(self, all_circuits: bool, rank: bool):
        """Jitted batch of `value_single`: (U) -> (value, ok, circuit[, rank]), the best of every
        circuit of each design, or (U, circuits) -> (value, ok[, rank])."""

        def build():
            if not all_circuits:
                return jax.jit(jax.vmap(lambda u, c: self.value_single(u, c, rank)))

            def one(u):
                out = jax.vmap(lambda c: self.value_single(u, c, rank))(jnp.arange(self.n_circuits))
                i = jnp.argmin(out[0])
                return (out[0][i], out[1][i], i) + tuple(o[i] for o in out[2:])

            return jax.jit(jax.vmap(one))

        return self.compiled(("values", bool(all_circuits), bool(rank)), build)

    def evaluate(self, U, circuits=None, *, rank: bool = False):
        """Objective of a batch of designs.

        **Arguments:** `U` (B, V) normalized designs; `circuits` (B,) circuit indices, or None:
        the file's circuit, or with `circuits = "all"` the best circuit of each design; `rank`:
        also return the objective's start-ranking value (`Objective.rank`; the gradient
        search's presample).

        **Returns:** dict of numpy arrays `value` (B,) (+inf if infeasible), `feasible` (B,),
        `circuit` (B,) (and `rank` (B,)). Counts `B × circuits tried` mechanism evaluations.
        """
        U = np.asarray(U, dtype=float)
        B = len(U)
        if jax.process_count() > 1:  # several processes: each evaluates its share (distributed.py)
            from .distributed import gathered, process_share

            a, b, _ = process_share(B)
            out = gathered(self._evaluated(U[a:b], None if circuits is None else np.asarray(circuits)[a:b], rank), B)
        else:
            out = self._evaluated(U, circuits, rank)
        self.evaluations += B * (self.n_circuits if circuits is None and self.n_circuits > 1 else 1)
        self.infeasible += int(np.count_nonzero(~np.asarray(out["feasible"], dtype=bool)))
        return out

    def _evaluated(self, U, circuits, rank: bool) -> dict:
        """`evaluate` on this process's devices, uncounted."""
        B = len(U)
        vals, oks, cs, rs = [], [], [], []
        for s in range(0, B, self.chunk):
            part = U[s:s + self.chunk]
            padded, n = pad_rows(part, self.padded_size(len(part)))
            if circuits is None and self.n_circuits > 1:
                v, ok, c, *r = self._values(True, rank)(put(jnp.asarray(padded), self.sharding))
            else:
                cc = np.zeros(len(part), int) if circuits is None else np.asarray(circuits[s:s + self.chunk])
                cc, _ = pad_rows(cc, len(padded))
                v, ok, *r = self._values(False, rank)(*put((jnp.asarray(padded), jnp.asarray(cc)), self.sharding))
                c = cc
            vals.append(np.asarray(v)[:n])
            oks.append(np.asarray(ok)[:n])
            cs.append(np.asarray(c)[:n])
            if rank:
                rs.append(np.asarray(r[0])[:n])
        out = {
            "value": np.concatenate(vals) if vals else np.zeros(0),
            "feasible": np.concatenate(oks) if oks else np.zeros(0, bool),
            "circuit": np.concatenate(cs) if cs else np.zeros(0, int),
        }
        if rank:
            out["rank"] = np.concatenate(rs) if rs else np.zeros(0)
        return out

    # ------------------------------------------------------------------ reports
    def report(self, u, c: int = 0) -> dict:
        """The exact objective and metrics of one design, re-solved with `report_samples` inputs
        (the objective's own samples unless it is `points`). Jitted; the last reports are cached
        (a search's runner reports its best design after every chunk)."""
        key = (np.asarray(u, dtype=float).tobytes(), int(c))
        cache = self.__dict__.setdefault("_report_cache", {})
        if key not in cache:
            cache.clear() if len(cache) >= 64 else None
            cache[key] = self._report(u, c)
        return copy.deepcopy(cache[key])

    def _report(self, u, c: int) -> dict:
        u = jnp.asarray(u, dtype=float)
        pr = self.problem
        order = max(self.objective.order, self.objective.report_order)
        feas, value, metrics = self._report_fn(self.report_samples, order)(u, jnp.asarray(int(c)))
        x = pr.to_file_units(np.asarray(u))
        out = {
            "parameters": {n: float(v) for n, v in zip(pr.names, x)},
            "feasible": bool(feas),
            "circuit": int(c),
        }
        out.update(self.certified(u, c, bool(feas)))
        if bool(feas):
            out["objective"] = float(value)
            out["metrics"] = to_python(metrics)
        else:
            out["objective"] = None
            out["metrics"] = {}
        return out

    def certified(self, u, c: int, dense_feasible: bool) -> dict:
        """What certifies that design `u` on circuit `c` assembles over its whole revolution:
        `certificate` ("reach margin": the dyads' margin refined between the search's samples,
        `feasibility.certify`; "dense re-solve": for a mechanism not made of dyads, every one of
        `dense_positions` = max(`report_samples`, `DENSE_FACTOR` × the search's samples) positions
        converged — finer sampling, not a proof between them), `certified` (bool), and for the
        reach margin `margin` (the smallest, dimensionless) and `margin_at` (its input value, file
        units)."""
        if not self.between:
            n = max(self.report_samples, DENSE_FACTOR * len(self.problem.phis))
            ok = bool(dense_feasible)
            if ok and n != self.report_samples:
                order = max(self.objective.order, self.objective.report_order)
                ok = bool(self._report_fn(n, order)(jnp.asarray(u, dtype=float), jnp.asarray(int(c)))[0])
            return {"certificate": "dense re-solve", "certified": ok, "dense_positions": int(n)}
        fn = self.compiled(("certificate",), lambda: jax.jit(self.certificate_single))
        cert = fn(jnp.asarray(u, dtype=float), jnp.asarray(int(c)))
        name = self.mech.input_name
        return {"certificate": "reach margin", "certified": bool(cert.certified) and bool(dense_feasible),
                "margin": float(cert.margin), "margin_at": float(self.mech.from_si(name, float(cert.where)))}

    def _report_fn(self, samples: int, order: int):
        """Jitted (u, circuit) → (feasible, value, metrics) at `samples` inputs; the circuit is
        an argument (one compilation for every circuit)."""
        phis = self.problem.inputs(samples)

        def one(uu, c):
            path, feas = self.path(uu, c, jnp.asarray(phis, uu.dtype), order)
            return feas, self.objective.value(path), self.objective.metrics(path)

        return self.compiled(("report", samples, order), lambda: jax.jit(one))

    def _paths_batch(self):
        def one(u, c):
            path, feas = self.path(u, c, jnp.asarray(self.problem.phis, u.dtype), 0)
            return path.xy, feas

        return self.compiled(("paths",), lambda: jax.jit(jax.vmap(one)))

    def paths(self, U, circuits) -> tuple[np.ndarray, np.ndarray]:
        """(B, N, 2) paths at the search samples (file units) and (B,) feasibility; counts B
        evaluations."""
        U = np.asarray(U, dtype=float)
        xs, oks = [], []
        for s in range(0, len(U), self.chunk):
            part, n = pad_rows(U[s:s + self.chunk], self.padded_size(len(U[s:s + self.chunk])))
            cc, _ = pad_rows(np.asarray(circuits[s:s + self.chunk]), len(part))
            xy, ok = self._paths_batch()(*put((jnp.asarray(part), jnp.asarray(cc)), self.sharding))
            xs.append(np.asarray(xy)[:n])
            oks.append(np.asarray(ok)[:n])
            self.evaluations += n
        return np.concatenate(xs), np.concatenate(oks)

    def path_points(self, u, c: int = 0, samples: int | None = None) -> np.ndarray:
        """(N, 2) path of the point (file units) for plots."""
        n = samples or self.report_samples
        path, _ = self._path_fn(n, 0)(jnp.asarray(u, dtype=float), jnp.asarray(int(c)))
        return np.asarray(path.xy)

    def _path_fn(self, samples: int, order: int):
        phis = self.problem.inputs(samples)
        return self.compiled(("path", samples, order),
                             lambda: jax.jit(lambda uu, c: self.path(uu, c, jnp.asarray(phis, uu.dtype), order)))

