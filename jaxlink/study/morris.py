"""Morris elementary effects (Morris 1991; μ* of Campolongo et al. 2007) of many outputs at once:
the trajectories, the estimator with bootstrap intervals, and the study on the batched evaluator.
docs/methods/sensitivity.md gives the formulas.

**The grid.** Each of the D factors takes p levels (`levels`, even) of the unit interval, 0,
1/(p − 1), …, 1; the step is Δ = p / (2 (p − 1)).

**A trajectory** (D + 1 points of the unit cube; r trajectories, `samples`): a base point x* whose
every column is drawn uniformly from the levels 0 … 1 − Δ, a direction d_j = ±1 per factor and an
order π (a random permutation of the factors), all from `numpy.random.default_rng(seed)`. The
trajectory starts at x* (+Δ in the columns of the factors with d_j = −1) and step k moves factor
π(k) by d Δ: every point lies on the grid, each factor moves exactly once. A factor of several
columns (a circular zone) moves them together (Morris with groups).

**The unit cube → the design** (`box_values`): a range x = low + u (high − low); a tolerance
(whatever its distribution) x = x₀ + t (2u − 1) over its box ±t; a circular zone the uniform disc
of `design.to_values`. Morris screens over the box, not over the distribution.

**Elementary effects and the indices** (per output y, factor j, trajectory i):

    EE_ij = (y(x + d Δ e_j) − y(x)) / (d Δ)
    μ_j = (1/r) Σ_i EE_ij,   μ*_j = (1/r) Σ_i |EE_ij|,   σ_j = √(Σ_i (EE_ij − μ_j)² / (r − 1))

EE is in the output's unit per unit of the unit cube: for a linear y = Σ a_j x_j over ranges,
EE_ij = a_j (high_j − low_j) exactly, and so are μ_j and μ*_j (σ_j = 0). These are SALib's
`morris.analyze` numbers on the same trajectories.

The sums are streamed over batches of trajectories (of EE − s, s the first batch's mean effect:
no cancellation in σ); with a checkpoint they are saved after every batch and a resumed study
evaluates only the batches after the last saved one (the same sums in the same order).

**Bootstrap.** The trajectories resampled with replacement R times (`bootstrap`; counts as in
`sobol.bootstrap_counts`); each interval is the estimate ± z σ_boot (as SALib's `mu_star_conf`).

**Feasibility.** An elementary effect needs both its points feasible; one that is not weighs 0
(the indices of each factor are over its r' ≤ r effects, conditional on feasibility). The
indicator 1{feasible} is an output of its own, over every trajectory: its μ* says which factor
moves a design across the assembly limit. A factor with fewer than two effects gets 0 (never a
NaN) and `effects` says so.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from ..errors import MechanismError
from . import resources as _resources
from .design import to_values
from .inputs import StudyInputs
from .responses import outside_warning
from .sobol import bootstrap_counts
from .streamed import Streamed


class MorrisIndices(NamedTuple):
    """Morris indices of M outputs and D factors (the outputs' units): `mu`, `mu_star`, `sigma`
    and their intervals `*_low`, `*_high` (M, D); `effects` (M, D) the elementary effects used (of
    `trajectories`); `confidence`."""

    mu: np.ndarray
    mu_low: np.ndarray
    mu_high: np.ndarray
    mu_star: np.ndarray
    mu_star_low: np.ndarray
    mu_star_high: np.ndarray
    sigma: np.ndarray
    sigma_low: np.ndarray
    sigma_high: np.ndarray
    effects: np.ndarray
    trajectories: int
    confidence: float


def trajectories(groups, r: int, levels: int, seed) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """r Morris trajectories (see the module doc) of the factors `groups` (a list of column-index
    arrays, T columns in all): (u (r, D + 1, T) the points, order (r, D) the factor moved at each
    step, sign (r, D) its direction ±1)."""
    rng = np.random.default_rng(seed)
    D = len(groups)
    T = sum(len(g) for g in groups)
    delta = levels / (2.0 * (levels - 1))
    grid = np.arange(levels // 2) / (levels - 1)  # the base levels: 0 … 1 − Δ
    base = grid[rng.integers(0, len(grid), size=(r, T))]
    sign = rng.choice(np.asarray([-1.0, 1.0]), size=(r, D))
    order = np.argsort(rng.random((r, D)), axis=1)
    col_sign = np.empty((r, T))
    for j, g in enumerate(groups):
        col_sign[:, g] = sign[:, j:j + 1]
    u = np.empty((r, D + 1, T))
    u[:, 0] = base + delta * (col_sign < 0)
    for k in range(D):
        u[:, k + 1] = u[:, k]
        for i in range(r):
            j = order[i, k]
            u[i, k + 1, groups[j]] += sign[i, j] * delta
    return np.round(u * (levels - 1)) / (levels - 1), order, sign  # exactly on the grid


def elementary_effects(y, order, sign, levels: int, weight=None) -> tuple[np.ndarray, np.ndarray]:
    """(EE (r, D, M), weight (r, D)) of the outputs `y` (r, D + 1, M) on the trajectories
    (`order`, `sign` of `trajectories`): EE_ij = (y after − y before) / (d Δ) of the step that
    moves factor j; `weight` (r, D + 1) of 0 and 1 (a point's feasibility), an effect's the
    product of its two points'."""
    y = np.asarray(y, float)
    r, d1, m = y.shape
    D = d1 - 1
    delta = levels / (2.0 * (levels - 1))
    step = (y[:, 1:] - y[:, :-1])  # (r, D, M): step k
    rows = np.arange(r)[:, None]
    ee = np.empty((r, D, m))
    w = np.ones((r, D))
    ok = np.ones((r, d1)) if weight is None else np.asarray(weight, float)
    ee[rows, order] = step / (sign[rows, order][..., None] * delta)
    w[rows, order] = ok[:, 1:] * ok[:, :-1]
    return np.where(w[..., None] > 0, ee, 0.0), w


class MorrisAccumulator(Streamed):
    """Streamed sums of the Morris estimators (see the module doc) over batches of trajectories.

    **Arguments:** `m` (outputs), `d` (factors), `counts` (R, r) the bootstrap counts."""

    def __init__(self, m: int, d: int, counts):
        self.m, self.d = int(m), int(d)
        self.counts = np.asarray(counts)
        self.r = self.counts.shape[0]
        self.sums = np.zeros((self.r + 1, 3, self.d, self.m))
        self.n = np.zeros((self.r + 1, self.d))
        self.trajectories = 0
        self.shift: np.ndarray | None = None  # (D, M): the first batch's mean effect (no cancellation in σ)

    FIELDS = ("sums", "n", "trajectories", "shift")
    COUNT = "trajectories"

    def update(self, start: int, ee, weight) -> None:
        """Add trajectories `start` … `start + n − 1`: `ee` (n, D, M), `weight` (n, D)."""
        n = ee.shape[0]
        if n == 0:
            return
        c = np.empty((self.r + 1, n))
        c[0] = 1.0
        c[1:] = self.counts[:, start:start + n]
        w = np.asarray(weight, float)
        cw = c[:, :, None] * w[None]  # (R + 1, n, D)
        if self.shift is None:
            self.shift = (w[..., None] * ee).sum(axis=0) / np.maximum(w.sum(axis=0), 1.0)[:, None]
        e = ee - self.shift
        terms = np.stack([e, np.abs(ee), e * e])  # (3, n, D, M)
        self.sums += np.einsum("bnd,kndm->bkdm", cw, terms)
        self.n += cw.sum(axis=1)
        self.trajectories += n

    def result(self, confidence: float = 0.95) -> MorrisIndices:
        from scipy.stats import norm

        n = self.n[:, :, None]  # (R + 1, D, 1)
        few = n < 2
        safe = np.where(few, 2.0, n)
        shift = np.zeros((self.d, self.m)) if self.shift is None else self.shift
        dmu = self.sums[:, 0] / safe  # the mean effect − shift
        mu = np.where(few, 0.0, shift + dmu)
        mu_star = np.where(few, 0.0, self.sums[:, 1] / safe)
        var = (self.sums[:, 2] - safe * dmu * dmu) / (safe - 1.0)
        sigma = np.where(few, 0.0, np.sqrt(np.maximum(var, 0.0)))
        z = float(norm.ppf(0.5 + confidence / 2))
        out = []
        for est in (mu, mu_star, sigma):
            v = est[0].T  # (M, D)
            half = z * est[1:].std(axis=0, ddof=1).T if self.r > 1 else np.zeros_like(v)
            out += [v, v - half, v + half]
        count = np.broadcast_to(self.n[0][None], (self.m, self.d)).astype(int)
        return MorrisIndices(out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7], out[8], count,
                             self.trajectories, confidence)


def morris_indices(y, order, sign, levels: int, *, weight=None, resamples: int = 100, confidence: float = 0.95,
                   seed=None) -> MorrisIndices:
    """μ, μ* and σ of every output column of `y` (r, D + 1, M) or (r, D + 1) on the trajectories
    (`order`, `sign`, `levels` of `trajectories`), with bootstrap intervals of `resamples`
    replicates of the trajectories drawn with `seed`; `weight` (r, D + 1) of 0 and 1."""
    y = np.asarray(y, float)
    if y.ndim == 2:
        y = y[..., None]
    ee, w = elementary_effects(y, order, sign, levels, weight)
    acc = MorrisAccumulator(y.shape[2], y.shape[1] - 1, bootstrap_counts(y.shape[0], resamples, seed))
    acc.update(0, ee, w)
    return acc.result(confidence)


def box_values(inputs: StudyInputs, x0, u) -> np.ndarray:
    """(n, T) the designs at unit-cube points `u` over the factors' boxes (see the module doc)."""
    box = inputs._replace(tolerances=tuple(t._replace(distribution="uniform") for t in inputs.tolerances))
    return to_values(box, x0, u)


class MorrisReport(NamedTuple):
    """The result of `morris` (the outputs' file units): `inputs`; `factors` (D,); `labels` (M,)
    `(output, unit, position index or None)`; `input_values`; `nominal` (M,); `indices`
    (`MorrisIndices` of the responses, conditional on feasibility); `feasibility`
    (`MorrisIndices` of the indicator, over every trajectory); `trajectories`, `evaluations`
    (r (D + 1)), `levels`, `feasible_fraction` (of the evaluations); `certificate`, `warnings`,
    `timings`."""

    inputs: StudyInputs
    factors: tuple
    labels: tuple
    input_values: np.ndarray
    nominal: np.ndarray
    indices: MorrisIndices
    feasibility: MorrisIndices
    trajectories: int
    evaluations: int
    levels: int
    feasible_fraction: float
    certificate: str
    warnings: list
    timings: dict


def morris(mech, inputs: StudyInputs | None = None, *, samples: int | None = None, chunk=None, options=None,
           progress=None, study=None, checkpoint=None) -> MorrisReport:
    """Morris μ, μ* and σ of every response along the cycle (and of the feasibility) from r =
    `samples` trajectories (r (D + 1) designs) over the study's ranges (or its tolerances' boxes).

    **Arguments:** as `sample` (`checkpoint`: a `checkpoint.Checkpoint`, the streamed sums saved
    after every batch of trajectories, a saved study resumed: the batches done skipped, the same
    result bit for bit). **Returns:** a `MorrisReport` (see the module doc).
    """
    from .sampling import _Evaluator, _study

    t0 = time.perf_counter()
    study = _study(mech, inputs, study, chunk, options)
    inputs = study.inputs
    ev = _Evaluator(study)
    groups, j = [], 0
    for f in inputs.factors:
        groups.append(np.arange(j, j + len(f.parameters)))
        j += len(f.parameters)
    D, T = len(groups), j
    r = inputs.samples if samples is None else int(samples)
    if r < 2:
        raise MechanismError(f"a Morris study needs at least 2 trajectories, got {r}", file=mech.file,
                             key="study.samples")
    p = inputs.morris_levels
    _resources.check(study, "morris", r, checkpoint=checkpoint)
    u, order, sign = trajectories(groups, r, p, inputs.seed)
    counts = bootstrap_counts(r, inputs.bootstrap, [inputs.seed, 1])
    per = max(1, study.chunk // (D + 1))
    resp: MorrisAccumulator | None = None
    feas = MorrisAccumulator(1, D, counts)
    ok_total = 0
    done = 0
    saved = None if checkpoint is None else checkpoint.load()
    if saved is not None:
        done, state = saved
        ev.nominal = state["nominal"]
        resp = MorrisAccumulator(len(ev.labels), D, counts)
        resp.restore(state["responses"])
        feas.restore(state["feasibility"])
        ok_total = int(state["ok_total"])
        if progress is not None:
            progress(min(r, done * per) * (D + 1))
    for c, a in enumerate(range(0, r, per)):
        if c < done:
            continue
        ub = u[a:a + per]
        n = len(ub)
        x = box_values(inputs, study.x0, ub.reshape(-1, T))
        y, ok = ev(x)
        y = y.reshape(n, D + 1, -1)
        okb = ok.reshape(n, D + 1).astype(float)
        if resp is None:
            resp = MorrisAccumulator(y.shape[2], D, counts)
        ee, w = elementary_effects(y, order[a:a + n], sign[a:a + n], p, okb)
        resp.update(a, ee, w)
        fe, fw = elementary_effects(okb[..., None], order[a:a + n], sign[a:a + n], p)
        feas.update(a, fe, fw)
        ok_total += int(okb.sum())
        if checkpoint is not None:
            checkpoint.save(c + 1, {"nominal": ev.nominal, "responses": resp.state(), "feasibility": feas.state(),
                                    "ok_total": ok_total})
        if progress is not None:
            progress(n * (D + 1))
    assert resp is not None and ev.nominal is not None
    ind = resp.result(inputs.confidence)
    warnings = []
    lost = r * D - int(ind.effects[0].sum()) if len(ind.effects) else 0
    if lost:
        warnings.append(f"{lost} of the {r * D} elementary effects have an infeasible end: the responses' Morris "
                        "indices are over the others (conditional on feasibility); the feasibility's own μ* says "
                        "which factors drive it")
    if len(ind.effects) and int(ind.effects[0].min()) < 2:
        warnings.append("a factor has fewer than two feasible elementary effects: its indices are 0 (not computed)")
    rr = study.responses
    outside = rr.outside(box_values(inputs, study.x0, u.reshape(-1, T)))
    if outside:
        warnings.append(outside_warning(outside, r * (D + 1)))
    timings = {"evaluate": ev.seconds, "total": time.perf_counter() - t0}
    return MorrisReport(inputs, tuple(f.name for f in inputs.factors), ev.labels, rr.input_values, ev.nominal, ind,
                        feas.result(inputs.confidence), r, r * (D + 1), p, ok_total / (r * (D + 1)),
                        rr.certificate, warnings, timings)
