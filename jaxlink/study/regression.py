"""Correlation and regression coefficients of many outputs at once (Pearson, Spearman, standardized
regression SRC, standardized rank regression SRRC, partial PCC and partial rank PRCC), with
confidence intervals, and the study on a `sample` study's designs. docs/methods/sensitivity.md
gives the formulas.

**The coefficients**, per output y and input x_j from n designs (s the sample standard
deviations, X_c the centred inputs (n × T), C = (X_cᵀ X_c)⁻¹):

    Pearson  r_j = Σ (x_j − x̄_j)(y − ȳ) / ((n − 1) s_xj s_y)
    Spearman ρ_j = the Pearson coefficient of the ranks
    SRC_j = b_j s_xj / s_y,  b = C X_cᵀ (y − ȳ)   (least squares y ≈ ȳ + X_c b)
    PCC_j = b_j / √(b_j² + RSS C_jj)              (RSS = ‖y − ȳ − X_c b‖²)
    SRRC, PRCC: SRC and PCC of the ranks; R² = 1 − RSS / Σ (y − ȳ)² (of the values, of the ranks)

PCC_j is the correlation of x_j and y once the other inputs' linear effects are removed from
both (the identity PCC = t / √(t² + n − T − 1) with t the regression's t-statistic). One matrix
C serves every output: all M outputs in a few matrix products. For a linear y of independent
inputs SRC_j² is the share of the variance due to x_j (= Sobol' S1 = ST, and the tolerance
study's importance factors): Σ SRC_j² = R² = 1. SRC is to be trusted where R² is near 1, SRRC
where the rank R² is (a monotonic response); PCC/PRCC rank the inputs without saying shares.

**Intervals** at `confidence` (z its normal quantile): Fisher's transform for the correlations,
tanh(atanh(r) ± z √(v / (n − 3 − k))) with k = 0 (Pearson, v = 1; Spearman, v = 1.06) or
k = T − 1 controlled inputs (PCC, PRCC, v = 1); SRC_j ± z se(b_j) s_xj / s_y from the regression's
standard errors (se(b_j)² = RSS C_jj / (n − T − 1)).

**Feasibility.** The responses' coefficients are over the feasible designs (conditional, with a
warning); the indicator 1{feasible} is an output of its own over all the designs (its
coefficients say which inputs drive the assembly). An output that does not vary over the designs
used gets 0, an interval [0, 0] and `constant` True, never a NaN; with fewer than T + 3 designs
nothing is computed (a warning).
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from ..errors import MechanismError
from . import resources as _resources
from .correlation import correlate
from .design import to_values, unit_blocks
from .inputs import StudyInputs
from .responses import outside_warning

#: the coefficients, in the order of `RegressionIndices`
COEFFICIENTS = ("pearson", "spearman", "src", "srrc", "pcc", "prcc")


class RegressionIndices(NamedTuple):
    """Coefficients of M outputs on T inputs: for each of `COEFFICIENTS` a dict entry of
    `values`, `low`, `high` ((M, T) each); `r2`, `rank_r2` (M,); `samples` (the designs used);
    `constant` (M,); `confidence`."""

    values: dict
    low: dict
    high: dict
    r2: np.ndarray
    rank_r2: np.ndarray
    samples: int
    constant: np.ndarray
    confidence: float


def _fisher(r, n_eff, z, v=1.0):
    """(low, high) of correlations `r` by Fisher's transform with n − 3 − k = `n_eff`."""
    if n_eff <= 0:
        return r.copy(), r.copy()
    a = np.arctanh(np.clip(r, -1 + 1e-15, 1 - 1e-15))
    h = z * np.sqrt(v / n_eff)
    return np.tanh(a - h), np.tanh(a + h)


def _fit(x, y, z, spearman_v: float):
    """(correlation, its low, high, SRC, low, high, PCC, low, high, R², constant) of `y` (n, M) on
    `x` (n, T) (values or ranks)."""
    n, T = x.shape
    xc = x - x.mean(axis=0)
    yc = y - y.mean(axis=0)
    sx = np.sqrt((xc * xc).sum(axis=0) / (n - 1))
    syy = (yc * yc).sum(axis=0)
    sy = np.sqrt(syy / (n - 1))
    scale = np.abs(y).max(axis=0) if n else np.zeros(y.shape[1])
    constant = sy <= 1e-12 * scale + 1e-300
    sy_safe = np.where(constant, 1.0, sy)
    r = (xc.T @ yc).T / ((n - 1) * sx[None] * sy_safe[:, None])  # (M, T)
    c = np.linalg.inv(xc.T @ xc)
    b = c @ (xc.T @ yc)  # (T, M)
    resid = yc - xc @ b
    rss = (resid * resid).sum(axis=0)  # (M,)
    src = (b * sx[:, None]).T / sy_safe[:, None]
    dof = n - T - 1
    se = np.sqrt(np.maximum(rss, 0.0)[None] * np.diag(c)[:, None] / max(dof, 1)).T  # (M, T)
    src_h = z * se * sx[None] / sy_safe[:, None]
    den = np.sqrt(b.T ** 2 + rss[:, None] * np.diag(c)[None])
    pcc = np.where(den > 0, b.T / np.where(den > 0, den, 1.0), 0.0)
    r2 = np.where(constant, 0.0, 1.0 - rss / np.where(constant, 1.0, syy))
    r_lo, r_hi = _fisher(r, n - 3, z, spearman_v)
    p_lo, p_hi = _fisher(pcc, n - 3 - (T - 1), z)
    out = [r, r_lo, r_hi, src, src - src_h, src + src_h, pcc, p_lo, p_hi]
    out = [np.where(constant[:, None], 0.0, v) for v in out]
    return out, r2, constant


def regression_indices(x, y, *, weight=None, confidence: float = 0.95) -> RegressionIndices:
    """The coefficients (see the module doc) of every output column of `y` (n, M) or (n,) on the
    inputs `x` (n, T), over the rows of `weight` 1 (default all); needs at least T + 3 rows."""
    from scipy.stats import norm, rankdata

    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if y.ndim == 1:
        y = y[:, None]
    if weight is not None:
        keep = np.asarray(weight, bool)
        x, y = x[keep], y[keep]
    n, T = x.shape
    if n < T + 3:
        raise ValueError(f"the regression coefficients need at least T + 3 = {T + 3} designs, got {n}")
    z = float(norm.ppf(0.5 + confidence / 2))
    vals, r2, constant = _fit(x, y, z, 1.0)
    ranks, rank_r2, _ = _fit(rankdata(x, axis=0), rankdata(y, axis=0), z, 1.06)
    values, low, high = {}, {}, {}
    for name, k, src in (("pearson", 0, vals), ("spearman", 0, ranks), ("src", 3, vals), ("srrc", 3, ranks),
                         ("pcc", 6, vals), ("prcc", 6, ranks)):
        values[name], low[name], high[name] = src[k], src[k + 1], src[k + 2]
    rank_r2 = np.where(constant, 0.0, rank_r2)
    return RegressionIndices(values, low, high, r2, rank_r2, n, constant, confidence)


class RegressionReport(NamedTuple):
    """The result of `regression` (file units): `inputs`; `factors` (T,) the inputs' names (a
    zone's two coordinates); `labels` (M,) `(output, unit, position index or None)`;
    `input_values`; `nominal` (M,); `indices` (`RegressionIndices` of the responses over the
    feasible designs; None with fewer than T + 3); `feasibility` (of the indicator over all the
    designs; all 0 and `constant` when every design, or none, is feasible); `samples`,
    `feasible_fraction`; `values` (n, T) the designs; `certificate`, `warnings`, `timings`."""

    inputs: StudyInputs
    factors: tuple
    labels: tuple
    input_values: np.ndarray
    nominal: np.ndarray
    indices: RegressionIndices | None
    feasibility: RegressionIndices
    samples: int
    feasible_fraction: float
    values: np.ndarray
    certificate: str
    warnings: list
    timings: dict


def regression(mech, inputs: StudyInputs | None = None, *, samples: int | None = None, chunk=None, options=None,
               progress=None, study=None, checkpoint=None) -> RegressionReport:
    """Correlation and regression coefficients of every response along the cycle (and of the
    feasibility) on the parameters, from `samples` designs drawn as `sample` draws them (the
    sampler, the correlation of `[study.correlation]`). Every response of every design is kept
    (n × M numbers: the ranks need them all).

    **Arguments:** as `sample` (`checkpoint`: a `checkpoint.Checkpoint`, every batch's designs,
    responses and flags written as they come, a saved study resumed: the batches done read back,
    the same result bit for bit). **Returns:** a `RegressionReport` (see the module doc).
    """
    from .sampling import _Evaluator, _study

    t0 = time.perf_counter()
    study = _study(mech, inputs, study, chunk, options)
    inputs = study.inputs
    ev = _Evaluator(study)
    T = len(inputs.parameters)
    n = inputs.samples if samples is None else int(samples)
    if n < T + 3:
        raise MechanismError(f"a regression study of {T} inputs needs at least {T + 3} designs, got {n}",
                             file=mech.file, key="study.samples")
    _resources.check(study, "regression", n, checkpoint=checkpoint)
    xs, ys, oks = [], [], []
    done = 0
    saved = None if checkpoint is None else checkpoint.load()
    if saved is not None:
        done, state = saved
        ev.nominal = state["nominal"]
    for i, u in enumerate(unit_blocks(inputs.sampler, T, n, inputs.seed, study.chunk)):
        if i < done:
            assert checkpoint is not None
            z = checkpoint.load_chunk(i)
            x, y, ok = z["x"], z["responses"], z["feasible"]
        else:
            x = to_values(inputs, study.x0, correlate(inputs, u, [inputs.seed, 2, i]))  # as `sample`
            y, ok = ev(x)
            if checkpoint is not None:
                checkpoint.save_chunk(i, x=x, feasible=ok, responses=y)
                checkpoint.save(i + 1, {"nominal": ev.nominal})
        xs.append(x)
        ys.append(y)
        oks.append(ok)
        if progress is not None:
            progress(len(x))
    assert ev.nominal is not None
    x = np.concatenate(xs)
    y = np.concatenate(ys)
    ok = np.concatenate(oks)
    t1 = time.perf_counter()
    warnings = []
    feas = regression_indices(x, ok.astype(float), confidence=inputs.confidence)
    indices = None
    good = int(ok.sum())
    if good >= T + 3:
        indices = regression_indices(x, y, weight=ok, confidence=inputs.confidence)
        if good < n:
            warnings.append(f"{n - good} of {n} designs do not assemble over the whole cycle: the responses' "
                            f"coefficients are over the {good} others (conditional on feasibility); the feasibility's "
                            "own coefficients say which inputs drive it")
    else:
        warnings.append(f"only {good} of {n} designs are feasible (at least {T + 3} needed): the responses' "
                        "coefficients are not computed (only the feasibility's)")
    outside = study.responses.outside(x)
    if outside:
        warnings.append(outside_warning(outside, n))
    if inputs.correlation:
        warnings.append("the inputs are correlated ([study.correlation]): a coefficient mixes an input's own effect "
                        "with those of the inputs correlated with it (PCC/PRCC remove the others' linear effect)")
    timings = {"evaluate": ev.seconds, "estimate": time.perf_counter() - t1, "total": time.perf_counter() - t0}
    r = study.responses
    return RegressionReport(inputs, tuple(inputs.parameters), ev.labels, r.input_values, ev.nominal, indices, feas, n,
                            good / n, x, r.certificate, warnings, timings)
