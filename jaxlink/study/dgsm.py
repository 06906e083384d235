"""Derivative-based global sensitivity measures (DGSM; Sobol' & Kucherenko 2009) of many outputs
at once from the *exact* gradients (`jax.jacfwd` of the response function, the path solve
differentiated implicitly: no finite differences), with bootstrap intervals and the upper bound
of Sobol's total index they give. docs/methods/sensitivity.md gives the formulas.

**The measures.** For a response y(x) of independent factors drawn from their distributions
(n designs drawn by the study's sampler, as `sample` draws them), per factor f of columns c:

    ν_f = E[Σ_c∈f (∂y/∂x_c)²]                          (in (output unit / parameter unit)²)
    ST_f ≤ C_f ν_f / V(y)                              (the Poincaré inequality)

with C_f the factor's Poincaré constant: a range or a uniform tolerance of width w = high − low
(= 2t): w² / π²; a normal tolerance: σ²; a uniform circular zone of radius r: r² / j'₁,₁²
(j'₁,₁ = 1.8412, the first zero of J₁', the disc's first Neumann eigenvalue); a normal zone: σ²;
a triangular tolerance ±t: (2t)² / π² (a log-concave density on an interval of length 2t:
Payne–Weinberger's bound, an upper bound of C_f, so the index bound stays an upper bound); a
truncated normal (σ_n cut at ±t): min(σ_n², (2t)² / π²) (Bakry–Émery and the same bound).
V(y) is the variance of the n responses (population form). The bound is an upper bound of the
total index (reported as `ST_bound`): a factor whose bound is small is unimportant (screening);
a large bound says little — it is reached for a linear response of a uniform factor only within
π²/12 ≈ 0.82 (ν w² / π² = a² w² / π², ST = a² w² / 12 / V).

**The derivative of `deviation(P)`** (max over the cycle of |P − P_nominal|) is that at the
position of the maximum: (d · ∂P/∂x) / |d| with d = P − P_nominal there (the maximum's move does
not count to first order); the stroke's and speed's are those of their refined extremes
(`responses`).

**Bootstrap.** The n designs resampled with replacement R times (`bootstrap`; counts as in
`sobol.bootstrap_counts`): one (R + 1) × n by n × (M (T + 2)) product per batch; each interval
the estimate ± z σ_boot.

**Feasibility.** An infeasible design weighs 0 (the measures are conditional on feasibility, a
warning); the feasibility indicator has no derivative (its Sobol' or Morris indices say which
factors drive it). An output that does not vary gets 0 (never a NaN), `constant` True.
"""

from __future__ import annotations

import math
import time
import weakref
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import MechanismError
from . import resources as _resources
from .design import to_values, unit_blocks
from .inputs import Range, StudyInputs
from .responses import outside_warning
from .sobol import bootstrap_counts
from .streamed import Streamed

#: j'₁,₁: the first zero of J₁' (the uniform disc's Poincaré constant r² / j'₁,₁²)
J11 = 1.8411837813406593
_JACOBIANS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


class DGSMIndices(NamedTuple):
    """DGSM of M outputs and D factors: `nu`, `nu_low`, `nu_high` ((output / parameter unit)²) and
    `bound`, `bound_low`, `bound_high` (C_f ν_f / V, the upper bound of ST) (M, D); `samples`;
    `constant` (M,); `confidence`."""

    nu: np.ndarray
    nu_low: np.ndarray
    nu_high: np.ndarray
    bound: np.ndarray
    bound_low: np.ndarray
    bound_high: np.ndarray
    samples: int
    constant: np.ndarray
    confidence: float


def poincare_constants(inputs: StudyInputs) -> np.ndarray:
    """(D,) the Poincaré constant C_f of each factor's distribution (see the module doc)."""
    out = []
    for f in inputs.factors:
        if isinstance(f, Range):
            out.append((f.high - f.low) ** 2 / math.pi ** 2)
        elif f.distribution == "normal":
            out.append(f.sigma ** 2)
        elif f.distribution == "truncated-normal":
            out.append(min((f.half_width / f.k) ** 2, (2.0 * f.half_width) ** 2 / math.pi ** 2))
        elif f.zone:
            out.append(f.half_width ** 2 / J11 ** 2)
        else:
            out.append((2.0 * f.half_width) ** 2 / math.pi ** 2)
    return np.asarray(out)


class DGSMAccumulator(Streamed):
    """Streamed sums of the DGSM estimators of M outputs, T columns grouped into D factors.

    **Arguments:** `m`, `groups` (a list of column-index arrays), `constants` (D,) the Poincaré
    constants, `counts` (R, n) the bootstrap counts, `shift` (M,) subtracted from the outputs."""

    def __init__(self, m: int, groups, constants, counts, shift=None):
        self.m = int(m)
        self.groups = [np.asarray(g) for g in groups]
        self.d = len(self.groups)
        self.constants = np.asarray(constants, float)
        self.counts = np.asarray(counts)
        self.r = self.counts.shape[0]
        self.shift = np.zeros(self.m) if shift is None else np.asarray(shift, float)
        self.sums = np.zeros((self.r + 1, self.m * (self.d + 2)))
        self.n = np.zeros(self.r + 1)
        self.used = 0

    FIELDS = ("sums", "n", "used", "shift")
    COUNT = "used"

    def update(self, start: int, grad, y, weight=None) -> None:
        """Add designs `start` … `start + n − 1`: `grad` (n, M, T), `y` (n, M), `weight` (n,)."""
        n = y.shape[0]
        if n == 0:
            return
        w = np.ones(n) if weight is None else np.asarray(weight, float)
        g2 = np.asarray(grad, float) ** 2
        per = np.stack([g2[:, :, g].sum(axis=2) for g in self.groups], axis=2)  # (n, M, D)
        yy = np.asarray(y, float) - self.shift
        terms = np.concatenate([per.reshape(n, -1), yy, yy * yy], axis=1)
        c = np.empty((self.r + 1, n))
        c[0] = w
        c[1:] = self.counts[:, start:start + n] * w
        self.sums += c @ terms
        self.n += c.sum(axis=1)
        self.used += int(w.sum())

    def result(self, confidence: float = 0.95) -> DGSMIndices:
        from scipy.stats import norm

        M, D = self.m, self.d
        few = self.n < 2
        n = np.where(few, 1.0, self.n)[:, None]
        nu = (self.sums[:, :M * D] / n).reshape(-1, M, D)
        mean = self.sums[:, M * D:M * (D + 1)] / n
        var = self.sums[:, M * (D + 1):] / n - mean * mean  # (R + 1, M)
        scale = np.abs(mean[0] + self.shift) + np.sqrt(np.maximum(var[0], 0.0))
        flat = (var <= 1e-24 * scale * scale + 1e-300) | few[:, None]
        nu = np.where(few[:, None, None], 0.0, nu)
        bound = np.where(flat[:, :, None], 0.0, nu * self.constants / np.where(flat, 1.0, var)[:, :, None])
        z = float(norm.ppf(0.5 + confidence / 2))
        out = []
        for est in (nu, bound):
            v = est[0]
            half = z * est[1:].std(axis=0, ddof=1) if self.r > 1 else np.zeros_like(v)
            out += [v, v - half, v + half]
        return DGSMIndices(out[0], out[1], out[2], out[3], out[4], out[5], self.used, flat[0], confidence)


def dgsm_indices(grad, y, constants, *, groups=None, weight=None, resamples: int = 100, confidence: float = 0.95,
                 seed=None) -> DGSMIndices:
    """ν and the ST bound of every output from the gradients `grad` (n, M, T) (or (n, T) for one
    output) and values `y` (n, M) (or (n,)) at n designs drawn from the factors' distributions;
    `constants` (D,) the Poincaré constants, `groups` the factors' columns (default one per
    column), `weight` (n,) of 0 and 1, bootstrap with `resamples` replicates drawn with `seed`."""
    grad = np.asarray(grad, float)
    y = np.asarray(y, float)
    if y.ndim == 1:
        y, grad = y[:, None], grad[:, None, :]
    groups = [np.asarray([j]) for j in range(grad.shape[2])] if groups is None else groups
    acc = DGSMAccumulator(y.shape[1], groups, constants, bootstrap_counts(len(y), resamples, seed))
    acc.update(0, grad, y, weight)
    return acc.result(confidence)


def batch_jacobian(study):
    """The compiled x (B, T) ↦ (∂y/∂x (B, M, T), (y, feasible, screened margin)) of a study's
    responses (`Responses.single` with the screen), `vmap`ped: one per `Responses` (a moved
    study reuses it)."""
    r = study.responses
    fn = _JACOBIANS.get(r)
    if fn is None:
        def one(x):
            v, ok, m = r.single(x, "screen")
            return v, (v, ok, m)
        fn = jax.jit(jax.vmap(jax.jacfwd(one, has_aux=True)))
        _JACOBIANS[r] = fn
    return fn


class DGSMReport(NamedTuple):
    """The result of `dgsm` (file units): `inputs`; `factors` (D,); `labels` (M,) `(output, unit,
    position index or None)`; `input_values`; `nominal` (M,); `indices` (`DGSMIndices`,
    conditional on feasibility; None with fewer than two feasible designs); `constants` (D,) the
    Poincaré constants; `samples`, `feasible_fraction`; `certificate`, `warnings`, `timings`."""

    inputs: StudyInputs
    factors: tuple
    labels: tuple
    input_values: np.ndarray
    nominal: np.ndarray
    indices: DGSMIndices | None
    constants: np.ndarray
    samples: int
    feasible_fraction: float
    certificate: str
    warnings: list
    timings: dict


def _with_deviation(v, J, nominal, K: int, N: int):
    """(values, gradients) with each point's deviation(P) = max_φ |P − P_nominal| and its
    derivative at the maximum appended (v (B, M), J (B, M, T))."""
    B = v.shape[0]
    d = (v[:, :2 * K * N] - nominal[:2 * K * N]).reshape(B, K, 2, N)
    dist = np.hypot(d[:, :, 0], d[:, :, 1])  # (B, K, N)
    k = dist.argmax(axis=2)  # (B, K)
    b = np.arange(B)[:, None]
    pk = np.arange(K)[None]
    dx, dy = d[b, pk, 0, k], d[b, pk, 1, k]
    top = dist[b, pk, k]
    jx = J[b, pk * 2 * N + k]  # (B, K, T)
    jy = J[b, pk * 2 * N + N + k]
    safe = np.where(top > 0, top, 1.0)[..., None]
    g = np.where(top[..., None] > 0, (dx[..., None] * jx + dy[..., None] * jy) / safe, 0.0)
    return np.concatenate([v, top], axis=1), np.concatenate([J, g], axis=1)


def dgsm(mech, inputs: StudyInputs | None = None, *, samples: int | None = None, chunk=None, options=None,
         progress=None, study=None, checkpoint=None) -> DGSMReport:
    """ν and the Sobol' total-index bound of every response along the cycle from the exact
    gradients at `samples` designs drawn by the study's sampler over its ranges (or its
    tolerances' distributions).

    **Arguments:** as `sample` (`checkpoint`: a `checkpoint.Checkpoint`, the streamed sums saved
    after every batch, a saved study resumed: the batches done skipped, the same result bit for
    bit). **Returns:** a `DGSMReport` (see the module doc).
    """
    from .responses import unit_names
    from .sampling import _study

    t0 = time.perf_counter()
    study = _study(mech, inputs, study, chunk, options)
    inputs = study.inputs
    r = study.responses
    groups, j = [], 0
    for f in inputs.factors:
        groups.append(np.arange(j, j + len(f.parameters)))
        j += len(f.parameters)
    T = j
    n = inputs.samples if samples is None else int(samples)
    if n < 2:
        raise MechanismError(f"a DGSM study needs at least 2 designs, got {n}", file=mech.file, key="study.samples")
    jac = batch_jacobian(study)
    K, N = len(inputs.points), inputs.positions
    deviation = "deviation" in inputs.metrics and K > 0
    lu = unit_names(mech)[0]
    labels = tuple(r.labels) + (tuple((f"deviation({p})", lu, None) for p in inputs.points) if deviation else ())
    constants = poincare_constants(inputs)
    _resources.check(study, "dgsm", n, checkpoint=checkpoint)
    counts = bootstrap_counts(n, inputs.bootstrap, [inputs.seed, 1])
    per = max(1, study.chunk // 4)  # the Jacobian holds T tangents per design
    nominal = None
    acc: DGSMAccumulator | None = None
    seconds = 0.0
    good = outside = 0
    start = 0
    first = True
    done = 0
    saved = None if checkpoint is None else checkpoint.load()
    if saved is not None:
        done, state = saved
        nominal = state["nominal"]
        first = False
        acc = DGSMAccumulator(len(labels), groups, constants, counts)
        acc.restore(state["sums"])
        good, start = int(state["good"]), int(state["start"])
        outside = int(state.get("outside", 0))
        if progress is not None:
            progress(start)
    for c, u in enumerate(unit_blocks(inputs.sampler, T, n, inputs.seed, per)):
        if c < done:
            continue
        x = to_values(inputs, study.x0, u)
        if first:
            x = np.concatenate([study.x0[None], x])
        t1 = time.perf_counter()
        xp = np.empty((per + 1, T))
        xp[:] = study.x0
        xp[:len(x)] = x
        J, (v, ok, est) = jac(jnp.asarray(xp))
        k = len(x)
        J, v = np.asarray(J)[:k], np.asarray(v)[:k]
        ok = study._certified(xp[:k], np.asarray(ok)[:k], np.asarray(est)[:k])
        seconds += time.perf_counter() - t1
        if first:
            if not ok[0]:
                raise MechanismError("the file's design does not assemble over its whole cycle: a study needs an "
                                     "assemblable design (its branch is the reference)", file=mech.file, key="study")
            nominal = v[0]
            J, v, ok = J[1:], v[1:], ok[1:]
            first = False
        assert nominal is not None
        if deviation:
            v, J = _with_deviation(v, J, nominal, K, N)
        J = np.where(ok[:, None, None], np.nan_to_num(J), 0.0)
        if acc is None:
            shift = np.concatenate([nominal, np.zeros(K if deviation else 0)])
            acc = DGSMAccumulator(len(labels), groups, constants, counts, shift)
        acc.update(start, J, v, ok)
        good += int(ok.sum())
        start += len(v)
        outside += study.responses.outside(x[1:] if len(x) > len(v) else x)
        if checkpoint is not None:
            checkpoint.save(c + 1, {"nominal": nominal, "sums": acc.state(), "good": good, "start": start,
                                    "outside": outside})
        if progress is not None:
            progress(len(v))
    assert acc is not None and nominal is not None
    warnings = []
    indices = acc.result(inputs.confidence) if good >= 2 else None
    if indices is None:
        warnings.append(f"only {good} of {n} designs are feasible: the DGSM are not computed")
    elif good < n:
        warnings.append(f"{n - good} of {n} designs do not assemble over the whole cycle: the DGSM are over the "
                        f"{good} others (conditional on feasibility)")
    if outside:
        warnings.append(outside_warning(outside, n))
    nominal_all = np.concatenate([nominal, np.zeros(K if deviation else 0)])
    timings = {"evaluate": seconds, "total": time.perf_counter() - t0}
    return DGSMReport(inputs, tuple(f.name for f in inputs.factors), labels, r.input_values, nominal_all, indices,
                      constants, n, good / n, r.certificate, warnings, timings)
