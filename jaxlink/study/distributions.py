"""The distributions of a scalar tolerance ±t around the nominal x̄ (file units): their standard
deviation, fourth moment and inverse CDF. Every one is symmetric about x̄ (odd central moments
zero); all but the normal are bounded by ±t.

| distribution | support | σ | μ₄ / σ⁴ |
|---|---|---|---|
| `normal` (±t = kσ) | ℝ | t / k | 3 |
| `uniform` | [x̄ − t, x̄ + t] | t / √3 | 9 / 5 |
| `triangular` (symmetric, mode x̄) | [x̄ − t, x̄ + t] | t / √6 | 12 / 5 |
| `truncated-normal` (σ_n = t / k, cut at ±t) | [x̄ − t, x̄ + t] | σ_n c(k) | `scipy.stats.truncnorm(−k, k)` |

with c(k)² = 1 − 2k φ(k) / (2Φ(k) − 1), the variance of a standard normal truncated to [−k, k]
(`scipy.stats.truncnorm(−k, k).var()`), and for the truncated normal μ₄ / σ⁴ = 3 + its excess
kurtosis (`truncnorm.stats(−k, k, moments="k")`). A uniform circular zone (the disc of radius r)
has per coordinate σ = r / 2 and μ₄ = E[r⁴ cos⁴α] = r⁴ / 8, μ₄ / σ⁴ = 2; its two coordinates are
uncorrelated but not independent: E[δ_x² δ_y²] = r⁴ / 24 = (2/3) σ⁴.

**Inverse CDF** (u ∈ (0, 1) → δ): uniform t (2u − 1); triangular −t + t √(2u) for u ≤ ½, else
t − t √(2 (1 − u)); normal σ Φ⁻¹(u); truncated normal σ_n `truncnorm.ppf(u, −k, k)`.
"""

from __future__ import annotations

import math

import numpy as np

#: the distributions of a tolerance
DISTRIBUTIONS = ("normal", "uniform", "triangular", "truncated-normal")
#: those whose support is [x̄ − t, x̄ + t]
BOUNDED = ("uniform", "triangular", "truncated-normal")


def _truncated(k: float) -> tuple[float, float]:
    """(c(k), μ₄/σ⁴) of a standard normal truncated to [−k, k] (module doc)."""
    from scipy.stats import truncnorm

    var, kurt = truncnorm.stats(-k, k, moments="vk")
    return math.sqrt(float(var)), 3.0 + float(kurt)


def sigma_per_half_width(distribution: str, k: float) -> float:
    """σ / t of `distribution` (k: ±t = kσ_n of a normal or truncated normal)."""
    if distribution == "uniform":
        return 1.0 / math.sqrt(3.0)
    if distribution == "triangular":
        return 1.0 / math.sqrt(6.0)
    if distribution == "truncated-normal":
        return _truncated(k)[0] / k
    if distribution == "normal":
        return 1.0 / k
    raise ValueError(f"unknown distribution {distribution!r}")


def fourth_moment_ratio(distribution: str, k: float, zone: bool = False) -> float:
    """μ₄ / σ⁴ of one coordinate (module doc); `zone`: a circular zone's coordinate."""
    if zone:
        return 2.0 if distribution == "uniform" else 3.0
    if distribution == "uniform":
        return 9.0 / 5.0
    if distribution == "triangular":
        return 12.0 / 5.0
    if distribution == "truncated-normal":
        return _truncated(k)[1]
    return 3.0


def deviations(distribution: str, u, half_width: float, sigma: float, k: float) -> np.ndarray:
    """The deviations δ from the nominal at the probabilities `u` (any shape, in (0, 1)) by the
    inverse CDF (module doc)."""
    u = np.asarray(u, float)
    t = half_width
    if distribution == "uniform":
        return t * (2.0 * u - 1.0)
    if distribution == "triangular":
        return np.where(u <= 0.5, -t + t * np.sqrt(2.0 * u), t - t * np.sqrt(2.0 * np.maximum(1.0 - u, 0.0)))
    uc = np.clip(u, 1e-12, 1.0 - 1e-12)
    if distribution == "truncated-normal":
        from scipy.stats import truncnorm

        return (t / k) * truncnorm.ppf(uc, -k, k)
    from scipy.stats import norm

    return sigma * norm.ppf(uc)
