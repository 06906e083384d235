"""Design-space studies on the batched evaluator: `sample` (random, Latin hypercube, scrambled
Sobol' or Halton designs over the ranges), `grid` (the full factorial) and `sensitivity` (Sobol'
S1 and ST of every response along the cycle at once, with bootstrap intervals, and of the
feasibility itself). docs/methods/sensitivity.md gives the formulas.

Every design is evaluated by the tolerance study's compiled batch (`Study`: `Responses.single`
`vmap`ped over `chunk` designs, the reach margin's screen, the certificate where it is below zero),
chunk by chunk: memory is bounded by the chunk (the `sample` and `grid` results keep only each
design's parameters, flag and scalar responses; `sensitivity` keeps only the estimators' sums).

**Feasibility** (a design assembles over the whole cycle on the nominal's branch, see
`responses`): an infeasible design is kept and flagged (`feasible` False), its responses are not
used (0 in the arrays, empty cells in study.csv), never dropped and never a NaN. In `sensitivity`:

- the indicator 1{feasible} is an output of its own: its Sobol' indices over all base samples say
  which parameters drive infeasibility; `feasible_fraction` is the fraction of the 2N independent
  draws (A and B) that are feasible — an estimate of the probability that a design drawn from the
  ranges assembles;
- the responses' indices are computed over the base samples whose D + 2 (2D + 2 with the second
  order) evaluations are all feasible (the others weigh 0): indices *conditional on feasibility*, with a warning — an
  approximation, the feasible region not being a product of the ranges; with fewer than two such
  base samples the responses' indices are not computed (a warning, no NaN).
"""

from __future__ import annotations

import time
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ..errors import MechanismError
from . import resources as _resources
from .correlation import correlate
from .design import grid_shape, grid_values, to_values, unit_blocks
from .inputs import StudyInputs
from .responses import outside_warning, unit_names
from .robust import RobustMap, robust_evaluator
from .sobol import SobolAccumulator, SobolIndices, bootstrap_counts
from .tolerance import Study, study_for


class SampleReport(NamedTuple):
    """The result of `sample` and `grid` (file units).

    - `inputs`; `parameters` (T,) names, `units` (T,) their unit names; `nominal_x` (T,);
    - `values` (n, T) every design's parameters; `feasible` (n,) bool;
    - `labels` (S,) `(output, unit)` of the scalar responses (the metrics' and each point's
      `deviation(P)`: max over the cycle of |P − P_nominal|); `responses` (n, S), 0 where infeasible;
      `nominal` (S,) the nominal's;
    - `grid_shape` (the levels per range for `grid`, else None); `certificate`; `warnings`;
      `timings` (seconds);
    - `robust` (`robust.RobustMap`, or None): the first-order tolerance report of every design.
    """

    inputs: StudyInputs
    parameters: tuple
    units: tuple
    nominal_x: np.ndarray
    values: np.ndarray
    feasible: np.ndarray
    labels: tuple
    responses: np.ndarray
    nominal: np.ndarray
    grid_shape: tuple | None
    certificate: str
    warnings: list
    timings: dict
    robust: RobustMap | None = None


class SensitivityReport(NamedTuple):
    """The result of `sensitivity` (file units).

    - `inputs`; `factors` (D,) the factors' names (a range's parameter, a tolerance's name);
    - `labels` (M,) `(output, unit, position index or None)` of every response (the points' x, y
      at every position, the metrics, each point's `deviation(P)`); `input_values` (N_pos,) the
      cycle's inputs (the input's file unit); `nominal` (M,);
    - `indices` (`SobolIndices` of the M responses, conditional on feasibility; None when fewer
      than two base samples are wholly feasible); `feasibility` (`SobolIndices` of the indicator,
      one output);
    - `samples` (base samples N), `evaluations` (N (D + 2), N (2D + 2) with `second_order`),
      `feasible_fraction` (of the 2N draws A and B), `complete` (base samples whose evaluations are
      all feasible);
    - `certificate`, `warnings`, `timings`.
    """

    inputs: StudyInputs
    factors: tuple
    labels: tuple
    input_values: np.ndarray
    nominal: np.ndarray
    indices: SobolIndices | None
    feasibility: SobolIndices
    samples: int
    evaluations: int
    feasible_fraction: float
    complete: int
    certificate: str
    warnings: list
    timings: dict


def evaluate(study: Study, x) -> tuple:
    """The responses of designs `x` (n, T: the study's parameters in file units) as `sample` computes
    them: (responses (n, M) in the labels' units — with each point's path deviation appended when the
    study asks for it —, feasible (n,) over the whole cycle, labels (M,)). The file's design is the
    reference of the deviations; infeasible rows are kept (flagged), never dropped."""
    ev = _Evaluator(study)
    v, ok = ev(np.asarray(x, dtype=float))
    return v, ok, ev.labels


class _Evaluator:
    """Batches of designs → (responses (n, M) with each point's path deviation appended, feasible
    (n,)); the nominal's responses from the first call (its first row)."""

    def __init__(self, study: Study):
        self.study = study
        r = study.responses
        self.n_curve = r.n_curve
        self.K = len(study.inputs.points)
        self.N = study.inputs.positions
        self.deviation = "deviation" in study.inputs.metrics and self.K > 0
        lu = unit_names(study.mech)[0]
        self.labels = tuple(r.labels) + (tuple((f"deviation({p})", lu, None) for p in study.inputs.points)
                                          if self.deviation else ())
        self.nominal: np.ndarray | None = None
        self.seconds = 0.0
        self._submitted = False

    def __call__(self, x):
        return self.finish(self.submit(x))

    def submit(self, x):
        """Dispatch the batches of designs `x` (n, T) and return at once (JAX runs them
        asynchronously); `finish` waits for them and returns what `__call__` does. Calls are
        finished in the order they were submitted (the first one carries the nominal)."""
        t0 = time.perf_counter()
        s = self.study
        first = self.nominal is None and not self._submitted
        self._submitted = True
        if first:
            x = np.concatenate([s.x0[None], x])
        n = x.shape[0]
        batches = []
        for a in range(0, n, s.chunk):
            k = min(s.chunk, n - a)
            xp = np.empty((s.chunk, x.shape[1]))
            xp[:] = s.x0
            xp[:k] = x[a:a + k]
            batches.append((xp, k, s._batch(jnp.asarray(xp))))
        self.seconds += time.perf_counter() - t0
        return first, batches

    def finish(self, pending):
        t0 = time.perf_counter()
        s = self.study
        first, batches = pending
        vals, oks = [], []
        for xp, k, (v, ok, est) in batches:
            ok = s._certified(xp[:k], np.asarray(ok)[:k], np.asarray(est)[:k])
            vals.append(np.asarray(v)[:k])
            oks.append(ok)
        v = np.concatenate(vals) if len(vals) > 1 else vals[0]  # one batch: no copy
        ok = np.concatenate(oks) if len(oks) > 1 else oks[0]
        if first:
            if not ok[0]:
                raise MechanismError("the file's design does not assemble over its whole cycle: a study needs an "
                                     "assemblable design (its branch is the reference)", file=s.mech.file, key="study")
            self.nominal = np.concatenate([v[0], np.zeros(self.K if self.deviation else 0)])
            v, ok = v[1:], ok[1:]
        if self.deviation:
            assert self.nominal is not None
            d = (v[:, :self.n_curve] - self.nominal[:self.n_curve]).reshape(-1, self.K, 2, self.N)
            v = np.concatenate([v, np.hypot(d[:, :, 0], d[:, :, 1]).max(axis=2)], axis=1)
        if not ok.all():
            v = np.where(ok[:, None], v, 0.0)
        self.seconds += time.perf_counter() - t0
        return v, ok


def _study(mech, inputs, study, chunk, options):
    """`study`, else the `Study` of `mech` and `inputs` (default its `[study]` table) kept for reuse
    (`reuse.study_for`: a second identical call compiles nothing)."""
    from .inputs import read_study

    if study is not None:
        return study
    inputs = read_study(mech) if inputs is None else inputs
    return study_for(mech, inputs, options=options, chunk=chunk)


def _units(mech, inputs) -> tuple:
    lu, au = unit_names(mech)
    return tuple({"length": lu, "angle": au}.get(mech.kinds[p], "1") for p in inputs.parameters)


def sample(mech, inputs: StudyInputs | None = None, *, samples: int | None = None, grid: bool = False, chunk=None,
           options=None, progress=None, study: Study | None = None, checkpoint=None) -> SampleReport:
    """Evaluate `samples` designs drawn by the study's `sampler` over its ranges (or its
    tolerances' distributions), or with `grid=True` the full factorial over the ranges; with
    `inputs.robust`, the first-order tolerance report at every design (`robust`).

    **Arguments:** as `tolerance` (`inputs`, `samples`, `chunk`, `options`, `progress` called with
    the designs done after each batch, `study` a compiled `Study` whose parameters are the ranges'),
    `checkpoint` (a `checkpoint.Checkpoint`: every batch's rows written as they come, a saved
    study resumed; a sample of a sequence — Sobol', Halton, random — resumed with more samples
    reuses its whole chunks done and evaluates the rest: incremental refinement, the same designs
    and rows as a study run at once with that many samples).

    **Returns:** a `SampleReport` (see the module doc for what is done with infeasible designs).
    """
    t0 = time.perf_counter()
    study = _study(mech, inputs, study, chunk, options)
    inputs = study.inputs
    ev = _Evaluator(study)
    rob = robust_evaluator(study) if inputs.robust else None
    T = len(inputs.parameters)
    if grid:
        if not inputs.ranges:
            raise MechanismError("the grid method needs [study.ranges]", file=mech.file, key="study.ranges")
        shape = grid_shape(inputs)
        n = int(np.prod(shape))
        _resources.check(study, "grid", n, checkpoint=checkpoint, option="levels")
        blocks = ((grid_values(inputs, a, min(n, a + study.chunk))) for a in range(0, n, study.chunk))
    else:
        shape = None
        n = inputs.samples if samples is None else int(samples)
        _resources.check(study, "sample", n, checkpoint=checkpoint)
        blocks = (to_values(inputs, study.x0, correlate(inputs, u, [inputs.seed, 2, i]))
                  for i, u in enumerate(unit_blocks(inputs.sampler, T, n, inputs.seed, study.chunk)))
    done = 0
    saved = None if checkpoint is None else checkpoint.load()
    if saved is not None:
        done, state = saved
        ev.nominal = state["nominal"]
    xs, oks, vs, rs = [], [], [], []
    scalar = np.asarray([k is None for (_, _, k) in ev.labels], bool)
    for c, x in enumerate(blocks):
        z = None
        if c < done:
            assert checkpoint is not None
            z = checkpoint.load_chunk(c)
            if len(z["x"]) != len(x):  # a sample resumed with more or fewer samples: this chunk's rows differ
                z = None
        if z is not None:
            x, ok, v, rv = z["x"], z["feasible"], z["responses"], z["robust"]
        else:
            v, ok = ev(x)
            v = v[:, scalar]
            rv = rob(x, ok) if rob is not None else np.zeros((len(x), 0))
            if checkpoint is not None:
                checkpoint.save_chunk(c, x=x, feasible=ok, responses=v, robust=rv)
                checkpoint.save(c + 1, {"nominal": ev.nominal})
        xs.append(x)
        oks.append(ok)
        vs.append(v)
        rs.append(rv)
        if progress is not None:
            progress(len(x))
    if ev.nominal is None:  # no design: the nominal alone
        ev(np.zeros((0, T)))
    assert ev.nominal is not None
    values = np.concatenate(xs) if xs else np.zeros((0, T))
    feasible = np.concatenate(oks) if oks else np.zeros(0, bool)
    responses = np.concatenate(vs) if vs else np.zeros((0, int(scalar.sum())))
    warnings = []
    outside = study.responses.outside(values)
    bad = int(np.count_nonzero(~feasible)) - outside  # the others are outside the domain: their own warning
    if bad:
        warnings.append(f"{bad} of {len(feasible)} designs ({100 * bad / len(feasible):.3g} %) do not assemble over "
                        f"the whole cycle on the nominal's branch ({study.responses.certificate}): kept and flagged "
                        "(feasible = 0), their responses left empty")
    if outside:
        warnings.append(outside_warning(outside, len(values)))
    labels = tuple((name, unit) for (name, unit, k) in ev.labels if k is None)
    timings = {"evaluate": ev.seconds, "total": time.perf_counter() - t0}
    robust = None
    if rob is not None:
        timings["robust"] = rob.seconds
        robust = RobustMap(rob.labels, np.concatenate(rs) if rs else np.zeros((0, len(rob.labels))),
                           tuple(p for t in inputs.tolerances for p in t.parameters), rob.limits)
    return SampleReport(inputs, inputs.parameters, _units(mech, inputs), np.asarray(study.x0), values, feasible,
                        labels, responses, ev.nominal[scalar], shape, study.responses.certificate, warnings, timings,
                        robust)


def sensitivity(mech, inputs: StudyInputs | None = None, *, samples: int | None = None, chunk=None, options=None,
                progress=None, study: Study | None = None, checkpoint=None, overlap: bool = True) -> SensitivityReport:
    """Sobol' S1 and ST of every response (and of the feasibility) with bootstrap intervals,
    from N = `samples` base samples of the study's `sampler` (2d columns: A and B) over its ranges
    (or its tolerances' distributions; a circular zone is one factor of two parameters).

    With `inputs.second_order`, the designs BA_j too and the second-order indices S2.

    **Arguments:** as `sample` (`checkpoint`: the estimators' sums saved after every batch, a
    saved study resumed); `overlap` (default True): batch k + 1 dispatched to JAX before batch k's
    estimator sums are taken, the same numbers as without. **Returns:** a `SensitivityReport` (see the module doc; the
    estimators in `jaxlink.study.sobol`).
    """
    t0 = time.perf_counter()
    study = _study(mech, inputs, study, chunk, options)
    inputs = study.inputs
    ev = _Evaluator(study)
    factors = inputs.factors
    D = len(factors)
    T = len(inputs.parameters)
    cols = []
    j = 0
    for f in factors:
        cols.append(np.arange(j, j + len(f.parameters)))
        j += len(f.parameters)
    N = inputs.samples if samples is None else int(samples)
    if N < 2:
        raise MechanismError(f"a sensitivity study needs at least 2 base samples, got {N}", file=mech.file,
                             key="study.samples")
    _resources.check(study, "sensitivity", N, checkpoint=checkpoint)
    counts = bootstrap_counts(N, inputs.bootstrap, [inputs.seed, 1])
    second = bool(inputs.second_order)
    E = 2 * D + 2 if second else D + 2  # designs per base sample: A, B, AB_j (and BA_j)
    per = max(1, study.chunk // E)
    resp: SobolAccumulator | None = None
    feas = SobolAccumulator(1, D, counts, second_order=second)
    drawn = ok_draws = complete = outside = 0
    t_est = 0.0
    start = 0
    done = 0
    saved = None if checkpoint is None else checkpoint.load()
    if saved is not None:
        done, state = saved
        ev.nominal = state["nominal"]
        resp = SobolAccumulator(len(ev.labels), D, counts, second_order=second)
        resp.restore(state["responses"])
        feas.restore(state["feasibility"])
        drawn, ok_draws, complete, start = state["drawn"], state["ok_draws"], state["complete"], state["start"]
        outside = int(state.get("outside", 0))
        if progress is not None:
            progress(start * E)
    def designs(u):
        a = to_values(inputs, study.x0, u[:, :T])
        b = to_values(inputs, study.x0, u[:, T:])
        ab = np.repeat(a[None], D, axis=0)
        for k, c in enumerate(cols):
            ab[k][:, c] = b[:, c]
        x = [a, b, ab.reshape(-1, T)]
        if second:
            ba = np.repeat(b[None], D, axis=0)
            for k, c in enumerate(cols):
                ba[k][:, c] = a[:, c]
            x.append(ba.reshape(-1, T))
        return np.concatenate(x)

    def estimate(job):
        nonlocal resp, drawn, ok_draws, complete, start, t_est, outside
        ci, n, submitted, out = job
        y, ok = ev.finish(submitted)
        t1 = time.perf_counter()
        if resp is None:
            assert ev.nominal is not None
            resp = SobolAccumulator(len(ev.labels), D, counts, shift=ev.nominal, second_order=second)
        okb = ok.reshape(E, n)
        w = okb.all(axis=0)
        ba = y[(D + 2) * n:].reshape(D, n, -1) if second else None
        resp.update(start, y[:n], y[n:2 * n], y[2 * n:(D + 2) * n].reshape(D, n, -1), w, yba=ba)
        f = ok.astype(float)[:, None]
        feas.update(start, f[:n], f[n:2 * n], f[2 * n:(D + 2) * n].reshape(D, n, 1),
                    yba=f[(D + 2) * n:].reshape(D, n, 1) if second else None)
        drawn += 2 * n
        ok_draws += int(okb[:2].sum())
        complete += int(w.sum())
        outside += out
        start += n
        t_est += time.perf_counter() - t1
        if checkpoint is not None:
            checkpoint.save(ci + 1, {"nominal": ev.nominal, "responses": resp.state(), "feasibility": feas.state(),
                                    "drawn": drawn, "ok_draws": ok_draws, "complete": complete, "start": start,
                                    "outside": outside})
        if progress is not None:
            progress(n * E)

    # batch k + 1 is dispatched (JAX runs it asynchronously) before batch k's estimator terms are
    # summed (numpy, outside the GIL in its BLAS): the same operations in the same order as without
    # the overlap, so the same numbers bit for bit
    pending = None
    for ci, u in enumerate(unit_blocks(inputs.sampler, 2 * T, N, inputs.seed, per)):
        if ci < done:
            continue
        xd = designs(u)
        job = (ci, len(u), ev.submit(xd), study.responses.outside(xd))
        if not overlap:
            estimate(job)
            continue
        if pending is not None:
            estimate(pending)
        pending = job
    if pending is not None:
        estimate(pending)
    assert resp is not None and ev.nominal is not None
    t1 = time.perf_counter()
    warnings = []
    indices = None
    if complete >= 2:
        indices = resp.result(inputs.confidence)
    else:
        warnings.append(f"only {complete} of {N} base samples have all their {E} designs feasible: the responses' "
                        "Sobol' indices are not computed (only the feasibility's)")
    if 2 <= complete < N:
        warnings.append(
            f"{N - complete} of {N} base samples have an infeasible design among their {E}: the responses' indices "
            f"are computed over the {complete} others — conditional on feasibility, an approximation (the feasible "
            "region is not a product of the ranges); the feasibility's own indices say which parameters drive it")
    if outside:
        warnings.append(outside_warning(outside, N * E))
    fi = feas.result(inputs.confidence)
    t_est += time.perf_counter() - t1
    timings = {"evaluate": ev.seconds, "estimate": t_est, "total": time.perf_counter() - t0}
    r = study.responses
    return SensitivityReport(inputs, tuple(f.name for f in factors), ev.labels, r.input_values, ev.nominal, indices,
                             fi, N, N * E, ok_draws / max(drawn, 1), complete, r.certificate, warnings, timings)
