"""Streamed statistics of many outputs over batches of samples, in memory independent of the
number of samples: moments up to the fourth (Welford/Chan, with Pébay's pairwise update of the
third and fourth), the least and largest value, and quantiles from a fixed histogram per output.

Pairwise update of two sets a, b (sizes n_a, n_b; n = n_a + n_b; δ = mean_b − mean_a; M_p the
sums of p-th powers of the deviations from each set's mean):

    mean = mean_a + δ n_b / n
    M2 = M2_a + M2_b + δ² n_a n_b / n
    M3 = M3_a + M3_b + δ³ n_a n_b (n_a − n_b) / n² + 3 δ (n_a M2_b − n_b M2_a) / n
    M4 = M4_a + M4_b + δ⁴ n_a n_b (n_a² − n_a n_b + n_b²) / n³ + 6 δ² (n_a² M2_b + n_b² M2_a) / n²
         + 4 δ (n_a M3_b − n_b M3_a) / n

(Chan, Golub & LeVeque 1979; Pébay 2008, SAND2008-6212). Each batch's own moments are computed
in two passes (its mean first), so no sum of squares of large numbers is ever formed.

**Sampling errors** (`std_error`, `mean_error`): SE(mean) = s / √n; SE(s²) = √((m₄ − s⁴ (n − 3) /
(n − 1)) / n) with m₄ = M4 / n (the variance of the sample variance, any distribution) and
SE(s) ≈ SE(s²) / (2 s).

**Quantiles**: each output's values are binned into `bins` equal bins over [−w, w] (w given per
output), with the counts below and above kept; a quantile is interpolated linearly within its bin
(between the least value and −w, or w and the largest, where it falls outside): its error is at
most one bin, 2w / bins.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np


class Moments:
    """Streamed moments, extremes and histogram quantiles of M outputs.

    **Arguments:** `width` (M,) the half-width w of each output's histogram (> 0), `bins`."""

    def __init__(self, width, bins: int = 1024):
        width = np.asarray(width, float)
        self.m = width.shape[0]
        self.width = np.where(width > 0, width, 1.0)
        self.bins = int(bins)
        self.n = 0
        self.mean = np.zeros(self.m)
        self.m2 = np.zeros(self.m)
        self.m3 = np.zeros(self.m)
        self.m4 = np.zeros(self.m)
        self.low = np.full(self.m, np.inf)
        self.high = np.full(self.m, -np.inf)
        self.hist = np.zeros((self.m, self.bins + 2), np.int64)  # [below, bins..., above]

    def update(self, x, weight=None) -> None:
        """Add a batch `x` (B, M) (numpy or JAX; its rows with `weight` 0 left out, `weight` (B,) of
        0 and 1, default all 1). The batch's own moments are computed by `batch_moments` (jitted:
        where `x` lies on a device, only (M,) arrays and the histogram come back)."""
        w = np.ones(x.shape[0]) if weight is None else np.asarray(weight, float)
        if x.shape[0] == 0 or not w.any():
            return
        stats = batch_moments(x, w, self.width, self.bins)
        self.merge(*(np.asarray(a) for a in stats))

    def merge(self, nb, mb, m2b, m3b, m4b, low, high, hist) -> None:
        """Combine the moments of another set (see the module doc for the formulas)."""
        nb = int(nb)
        if nb == 0:
            return
        na, n = self.n, self.n + nb
        delta = mb - self.mean
        m2a, m3a = self.m2, self.m3
        self.m4 = (self.m4 + m4b + delta**4 * na * nb * (na * na - na * nb + nb * nb) / n**3
                   + 6 * delta**2 * (na * na * m2b + nb * nb * m2a) / n**2 + 4 * delta * (na * m3b - nb * m3a) / n)
        self.m3 = m3a + m3b + delta**3 * na * nb * (na - nb) / n**2 + 3 * delta * (na * m2b - nb * m2a) / n
        self.m2 = m2a + m2b + delta**2 * na * nb / n
        self.mean = self.mean + delta * nb / n
        self.n = n
        self.low = np.minimum(self.low, low)
        self.high = np.maximum(self.high, high)
        self.hist += hist.astype(np.int64)

    FIELDS = ("n", "mean", "m2", "m3", "m4", "low", "high", "hist")

    def state(self) -> dict:
        """Everything streamed so far (for a checkpoint; `restore` puts it back exactly)."""
        return {k: getattr(self, k) for k in self.FIELDS}

    def restore(self, state) -> None:
        for k in self.FIELDS:
            v = state[k]
            setattr(self, k, int(v) if k == "n" else np.array(v))

    @property
    def variance(self):
        """Sample variance (n − 1 in the denominator); 0 below two samples."""
        return self.m2 / max(self.n - 1, 1)

    @property
    def std(self):
        return np.sqrt(self.variance)

    @property
    def mean_error(self):
        """Standard error of the mean, s / √n."""
        return self.std / np.sqrt(max(self.n, 1))

    @property
    def std_error(self):
        """Standard error of the sample standard deviation (see the module doc); 0 where s = 0."""
        n = max(self.n, 4)
        s2 = self.variance
        m4 = self.m4 / n
        var_s2 = np.maximum(m4 - s2 * s2 * (n - 3) / (n - 1), 0.0) / n
        s = np.sqrt(s2)
        return np.where(s > 0, np.sqrt(var_s2) / (2 * np.where(s > 0, s, 1.0)), 0.0)

    def quantile(self, q: float):
        """The `q` quantile of every output (from the histogram; see the module doc)."""
        if self.n == 0:
            return np.zeros(self.m)
        target = q * self.n
        c = np.cumsum(self.hist, axis=1)
        k = np.argmax(c >= target, axis=1)  # first bin whose cumulative count reaches the target
        before = np.where(k > 0, np.take_along_axis(c, np.maximum(k - 1, 0)[:, None], 1)[:, 0], 0)
        inbin = self.hist[np.arange(self.m), k]
        frac = np.where(inbin > 0, (target - before) / np.where(inbin > 0, inbin, 1), 0.0)
        step = 2.0 * self.width / self.bins
        lo_edge = -self.width + (k - 1) * step
        hi_edge = lo_edge + step
        # the outer bins run from the least value to −w and from w to the largest
        lo_edge = np.where(k == 0, self.low, lo_edge)
        hi_edge = np.where(k == 0, -self.width, np.where(k == self.bins + 1, self.high, hi_edge))
        lo_edge = np.where(k == self.bins + 1, self.width, lo_edge)
        v = lo_edge + np.clip(frac, 0.0, 1.0) * (hi_edge - lo_edge)
        return np.clip(v, self.low, self.high)


@functools.partial(jax.jit, static_argnames=("bins",))
def batch_moments(x, w, width, bins: int):
    """(n, mean, M2, M3, M4, least, largest, histogram (M, bins + 2)) of the rows of `x` (B, M)
    with weight `w` (B,) 1 (0: left out), the histogram over [−width, width] (see the module doc).
    Two passes (the mean first); the rows left out may hold any finite values."""
    x = jnp.asarray(x)
    w = jnp.asarray(w, x.dtype)
    n = jnp.sum(w)
    mean = jnp.sum(w[:, None] * x, axis=0) / jnp.maximum(n, 1.0)
    d = (x - mean) * w[:, None]
    d2 = d * d
    m2, m3, m4 = jnp.sum(d2, axis=0), jnp.sum(d2 * d, axis=0), jnp.sum(d2 * d2, axis=0)
    keep = w[:, None] > 0
    low = jnp.min(jnp.where(keep, x, jnp.inf), axis=0)
    high = jnp.max(jnp.where(keep, x, -jnp.inf), axis=0)
    m = x.shape[1]
    idx = jnp.clip(jnp.floor((x / width + 1.0) * 0.5 * bins).astype(jnp.int32) + 1, 0, bins + 1)
    flat = (idx + jnp.arange(m, dtype=jnp.int32) * (bins + 2)).ravel()
    hist = jnp.zeros(m * (bins + 2), jnp.int32).at[flat].add(jnp.broadcast_to(keep, x.shape).astype(jnp.int32).ravel())
    return n, mean, m2, m3, m4, low, high, hist.reshape(m, bins + 2)
