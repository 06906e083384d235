"""Sobol' indices of many outputs at once, streamed over batches of base samples, with bootstrap
intervals — the estimators of SALib's `sobol.analyze` (Saltelli et al. 2010 for S1, Jansen 1999
for ST), vectorized over the outputs and the bootstrap replicates. docs/methods/sensitivity.md
gives the design and the formulas.

**The design.** Two independent N × d matrices A and B of input draws; for each factor j the
matrix AB_j: A with factor j's columns taken from B. The model is evaluated on A, B and every
AB_j (N (D + 2) evaluations, D factors); y_A, y_B, y_ABj (N, M) are the M outputs.

**The estimators** (per output; m the mean of every evaluation, V the variance of the 2N values
of y_A and y_B, population form as SALib):

    S1_j = (1/N) Σ_i (y_B,i − m) (y_ABj,i − y_A,i) / V          (Saltelli et al. 2010)
    ST_j = (1/2N) Σ_i (y_A,i − y_ABj,i)² / V                    (Jansen 1999)

**Second order** (`second_order`, Saltelli 2002 as SALib's `calc_second_order=True`): the
matrices BA_j (B with factor j's columns from A) too, N (2D + 2) evaluations, m their mean, and

    S2_jk = (1/N) Σ_i [(y_BAj,i − m)(y_ABk,i − m) − (y_A,i − m)(y_B,i − m)] / V − S1_j − S1_k   (j < k)

from the sums of y_BAj − y_B and of y_BAj y_ABk − y_A y_B (the m² terms cancel).

S1 is not invariant to a shift of y in a finite sample: centring with m is SALib's (it normalizes
y by its mean and standard deviation before estimating).

**Streaming.** Every estimator is a ratio of sums over the base samples i, so a batch adds to
sums and nothing per sample is kept. Sums are of y − s, s a fixed shift per output (the nominal
design's responses): no cancellation of large equal numbers; m is applied at the end through
Σ (y_B − m)(y_AB − y_A) = Σ (y_B − s)(y_AB − y_A) − (m − s) Σ (y_AB − y_A).

**Bootstrap.** Resample i.e. of the N base samples with replacement, R times; replicate b counts
base sample i c_bi times (multinomial counts, from `numpy.random.default_rng(seed).integers(N,
size=(N, R))`, SALib's draw). Each replicate's sums are c_b · (per-sample terms): one matrix
product (R + 1) × n by n × (M (3D + 2)) per batch, row 0 the estimate itself (all counts 1). The
interval is SALib's: the estimate ± z σ_boot (σ_boot the replicates' standard deviation, z the
normal quantile of the confidence level).

**Weights.** A base sample of weight 0 is left out of every sum (the study's infeasible designs:
`w_i = 0` where any of its D + 2 evaluations is infeasible); the normalizations count only the
rest. An output whose V is zero (constant; relative to its scale, below 1e−24 (|m| + …)²) gets
indices 0 and `constant` True, never a NaN; so does a replicate with fewer than two samples.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class SobolIndices(NamedTuple):
    """Sobol' indices of M outputs and D factors: `S1`, `S1_low`, `S1_high`, `ST`, `ST_low`,
    `ST_high` (M, D); `samples` (the base samples used, those of weight 1), `constant` (M,) True
    where the output did not vary (its indices 0), `confidence` (the intervals' level); with the
    second order, `S2`, `S2_low`, `S2_high` (M, D (D − 1) / 2): the pairs (j, k), j < k, in the
    order of `pairs(D)` (else None)."""

    S1: np.ndarray
    S1_low: np.ndarray
    S1_high: np.ndarray
    ST: np.ndarray
    ST_low: np.ndarray
    ST_high: np.ndarray
    samples: int
    constant: np.ndarray
    confidence: float
    S2: np.ndarray | None = None
    S2_low: np.ndarray | None = None
    S2_high: np.ndarray | None = None


def pairs(d: int) -> list:
    """The factor pairs (j, k), j < k, in the order of the second-order indices' columns."""
    return [(j, k) for j in range(d) for k in range(j + 1, d)]


def bootstrap_counts(n: int, resamples: int, seed) -> np.ndarray:
    """(R, N) uint16: how often replicate b draws base sample i — SALib's draw
    `default_rng(seed).integers(N, size=(N, R))` counted per column."""
    if resamples == 0 or n == 0:
        return np.zeros((resamples, n), np.uint16)
    r = np.random.default_rng(seed).integers(n, size=(n, resamples))
    counts = np.zeros((resamples, n), np.uint16)
    for b in range(resamples):
        counts[b] = np.bincount(r[:, b], minlength=n)
    return counts


class SobolAccumulator:
    """Streamed sums of the Sobol' estimators of M outputs and D factors (see the module doc).

    **Arguments:** `m` (outputs), `d` (factors), `counts` (R, N) the bootstrap counts
    (`bootstrap_counts`), `shift` (M,) subtracted from every output (default 0), `second_order`
    (the sums of S2 too: `update` then takes the evaluations on BA_j)."""

    def __init__(self, m: int, d: int, counts, shift=None, second_order: bool = False):
        self.m, self.d = int(m), int(d)
        self.counts = np.asarray(counts)
        self.r = self.counts.shape[0]
        self.shift = np.zeros(self.m) if shift is None else np.asarray(shift, float)
        self.second_order = bool(second_order)
        self.pairs = pairs(self.d) if self.second_order else []
        k = self.m * self._blocks()
        self.sums = np.zeros((self.r + 1, k))
        self.n = np.zeros(self.r + 1)
        self.sum_a = np.zeros(self.m)  # unweighted by the bootstrap: the mean m of every evaluation
        self.sum_b = np.zeros(self.m)
        self.used = 0
        self._buffer: np.ndarray | None = None

    def _blocks(self) -> int:
        """Per-sample terms per output: 2 + 3D, and D + D (D − 1) / 2 more with the second order."""
        return 2 + 3 * self.d + ((self.d + len(self.pairs)) if self.second_order else 0)

    FIELDS = ("sums", "n", "sum_a", "sum_b", "used", "shift")

    def state(self) -> dict:
        """The sums so far (for a checkpoint; `restore` puts them back exactly)."""
        return {k: getattr(self, k) for k in self.FIELDS}

    def restore(self, state) -> None:
        for k in self.FIELDS:
            setattr(self, k, int(state[k]) if k == "used" else np.array(state[k]))

    def update(self, start: int, ya, yb, yab, weight=None, yba=None) -> None:
        """Add base samples `start` … `start + n − 1`: `ya`, `yb` (n, M), `yab` (D, n, M), `weight`
        (n,) of 0 and 1 (default 1); with the second order `yba` (D, n, M), the evaluations on BA_j."""
        n = ya.shape[0]
        if n == 0:
            return
        w = np.ones(n) if weight is None else np.asarray(weight, float)
        s = self.shift
        M, D = self.m, self.d
        ya = np.asarray(ya, float) - s
        yb = np.asarray(yb, float) - s
        # the per-sample terms, written in place: (n, 3D + 2, M) = [y_A + y_B, y_A² + y_B²,
        # y_B (y_AB_j − y_A) for each j, y_AB_j − y_A, (y_AB_j − y_A)²], flattened (n, M (3D + 2))
        if self._buffer is None or self._buffer.shape[0] != n:  # kept: a fresh 10–100 MB array costs its page faults
            self._buffer = np.empty((n, self._blocks(), M))
        t3 = self._buffer
        np.add(ya, yb, out=t3[:, 0])
        np.multiply(ya, ya, out=t3[:, 1])
        t3[:, 1] += yb * yb
        diff = t3[:, 2 + D:2 + 2 * D]
        yab = np.asarray(yab, float)
        for j in range(D):  # factor by factor: contiguous reads (the same numbers as one strided pass)
            np.subtract(yab[j], s, out=diff[:, j])
            diff[:, j] -= ya
        np.multiply(yb[:, None], diff, out=t3[:, 2:2 + D])
        np.multiply(diff, diff, out=t3[:, 2 + 2 * D:2 + 3 * D])
        if self.second_order:
            # [y_BA_j − y_B for each j, y_BA_j y_AB_k − y_A y_B for each pair j < k] (Saltelli 2002)
            if yba is None:
                raise ValueError("a second-order accumulator needs the evaluations on BA_j (yba)")
            ba = t3[:, 2 + 3 * D:2 + 4 * D]
            yba = np.asarray(yba, float)
            for j in range(D):
                np.subtract(yba[j], s, out=ba[:, j])
            ab = diff + ya[:, None]  # y_AB_j − s
            prod = ya * yb
            for i, (j, k) in enumerate(self.pairs):
                out = t3[:, 2 + 4 * D + i]
                np.multiply(ba[:, j], ab[:, k], out=out)
                out -= prod
            ba -= yb[:, None]
        terms = t3.reshape(n, -1)
        c = np.empty((self.r + 1, n))
        c[0] = w
        c[1:] = self.counts[:, start:start + n] * w
        self.sums += c @ terms
        self.n += c.sum(axis=1)
        self.sum_a += w @ ya
        self.sum_b += w @ yb
        self.used += int(w.sum())

    def result(self, confidence: float = 0.95) -> SobolIndices:
        """The indices and their bootstrap intervals (see the module doc)."""
        from scipy.stats import norm

        M, D = self.m, self.d
        n = np.maximum(self.n, 1.0)[:, None]
        s = self.sums
        sum_ab = s[:, 0:M]
        sq = s[:, M:2 * M]
        p = s[:, 2 * M:(2 + D) * M].reshape(-1, D, M)
        q = s[:, (2 + D) * M:(2 + 2 * D) * M].reshape(-1, D, M)
        t = s[:, (2 + 2 * D) * M:(2 + 3 * D) * M].reshape(-1, D, M)
        # m − s: the mean of every evaluation (A, B, every AB_j and BA_j) of the estimate's samples
        total = (D + 1) * self.sum_a + self.sum_b + q[0].sum(axis=0)
        E = D + 2
        if self.second_order:
            e = s[:, (2 + 3 * D) * M:(2 + 4 * D) * M].reshape(-1, D, M)  # Σ (y_BA_j − y_B)
            g = s[:, (2 + 4 * D) * M:].reshape(-1, len(self.pairs), M)  # Σ (y_BA_j y_AB_k − y_A y_B)
            total = total + D * self.sum_b + e[0].sum(axis=0)
            E = 2 * D + 2
        mean = total / max(self.used * E, 1)
        mu = sum_ab / (2 * n)
        var = sq / (2 * n) - mu * mu  # (R + 1, M)
        scale = np.abs(mean + self.shift) + np.sqrt(np.maximum(var[0], 0.0))
        few = (self.n < 2)[:, None]
        flat = (var <= 1e-24 * scale * scale + 1e-300) | few
        den = np.where(flat, 1.0, var)[:, None, :]
        s1 = np.where(flat[:, None, :], 0.0, (p - mean * q) / n[:, :, None] / den)
        st = np.where(flat[:, None, :], 0.0, 0.5 * t / n[:, :, None] / den)
        ests = [s1, st]
        if self.second_order:
            # S2_jk = (1/N) Σ [(y_BA_j − m)(y_AB_k − m) − (y_A − m)(y_B − m)] / V − S1_j − S1_k
            # (Saltelli 2002, as SALib): the m² terms cancel, the m terms are m's multiples of
            # Σ (y_AB_k − y_A) and Σ (y_BA_j − y_B)
            if self.pairs:
                j, k = (np.asarray(v) for v in zip(*self.pairs))
                v2 = (g - mean * (q[:, k] + e[:, j])) / n[:, :, None] / den - s1[:, j] - s1[:, k]
                ests.append(np.where(flat[:, None, :], 0.0, v2))
            else:
                ests.append(np.zeros((self.r + 1, 0, M)))
        z = float(norm.ppf(0.5 + confidence / 2))
        out = []
        for est in ests:
            v = est[0].T  # (M, D) or (M, pairs)
            half = z * est[1:].std(axis=0, ddof=1).T if self.r > 1 else np.zeros_like(v)
            out += [v, v - half, v + half]
        return SobolIndices(out[0], out[1], out[2], out[3], out[4], out[5], self.used, flat[0], confidence,
                            *out[6:9])


def sobol_indices(ya, yb, yab, *, resamples: int = 100, confidence: float = 0.95, seed=None,
                  weight=None, yba=None) -> SobolIndices:
    """Sobol' S1 and ST of every output column from the evaluations on A, B and AB_j: `ya`, `yb`
    (N, M) or (N,), `yab` (D, N, M) or (D, N); bootstrap with `resamples` replicates drawn with
    `seed` (SALib's draw for the same seed); `weight` (N,) of 0 and 1 leaves base samples out;
    `yba` (D, N, M) or (D, N), the evaluations on BA_j (B with factor j's columns from A): S2 too."""
    ya = np.asarray(ya, float)
    yb = np.asarray(yb, float)
    yab = np.asarray(yab, float)
    if yba is not None:
        yba = np.asarray(yba, float)
    if ya.ndim == 1:
        ya, yb, yab = ya[:, None], yb[:, None], yab[..., None]
        yba = None if yba is None else yba[..., None]
    n, m = ya.shape
    acc = SobolAccumulator(m, yab.shape[0], bootstrap_counts(n, resamples, seed), second_order=yba is not None)
    acc.update(0, ya, yb, yab, weight, yba=yba)
    return acc.result(confidence)
