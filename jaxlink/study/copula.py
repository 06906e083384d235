"""The joint moments of correlated tolerances: the Pearson correlation, and the mixed moments
E[δ_a^p δ_b^q], of two inputs whose Monte Carlo draws are correlated by Iman–Conover
(`correlation.py`) with the rank (normal-scores) correlation r of `[study.correlation]`.

Iman–Conover pairs the draws so that their van der Waerden scores have the Pearson correlation r:
the draws follow, up to sampling error, a **Gaussian copula** — δ_a = F_a⁻¹(Φ(Z_a)),
δ_b = F_b⁻¹(Φ(Z_b)) with (Z_a, Z_b) bivariate normal of correlation r, F⁻¹ the inverse CDFs of
`distributions.py`. The Pearson correlation of the inputs themselves is then

    ρ(r) = E[δ_a δ_b] / (σ_a σ_b),    E[δ_a δ_b] = ∬ F_a⁻¹(Φ(x)) F_b⁻¹(Φ(r x + √(1 − r²) w)) φ(x) φ(w) dx dw

(closed forms: two normals ρ = r; two uniforms (6/π) arcsin(r/2); a normal and a uniform
r √(3/π); in general |ρ| ≤ |r|). The first-order covariance Σ_ab = σ_a σ_b ρ_ab uses it.

**Quadrature.** The double integral by Gauss–Legendre on [−L, L]² (L = 9: the normal mass
beyond is 2e−19), split where the integrand has a kink — the triangular inverse CDF's second
derivative jumps at its median, x = 0 outside and r x + √(1 − r²) w = 0 inside — `NODES` nodes on
each piece: 1e−15 against the closed forms and against 200-node references for the triangular and
truncated normal. (Gauss–Hermite, exact for the normals and fast for the smooth uniform, converges
only algebraically on the triangular's kink: 6e−7 with 160² nodes.) Every F⁻¹ is odd about the
median, evaluated as −F⁻¹(Φ(−|z|)) sign z for its accuracy in the tails.
"""

from __future__ import annotations

import functools
import math

import numpy as np

#: Gauss–Legendre nodes per piece of each coordinate (module doc)
NODES = 64
#: the half-width of the integration square in normal scores
SPAN = 9.0


def inverse_cdf(distribution: str, z, half_width: float, sigma: float, k: float) -> np.ndarray:
    """δ = F⁻¹(Φ(z)) of a tolerance (`distributions.deviations` of Φ(z); a normal: σ z exactly)."""
    from scipy.stats import norm

    from .distributions import deviations

    z = np.asarray(z, float)
    if distribution == "normal":
        return sigma * z
    lower = deviations(distribution, norm.cdf(-np.abs(z)), half_width, sigma, k)  # ≤ 0: the lower tail
    return -np.sign(z) * lower


def _tolerance_key(t) -> tuple:
    return (t.distribution, float(t.half_width), float(t.sigma), float(t.k))


def moment(ta, tb, r: float, p: int = 1, q: int = 1) -> float:
    """E[δ_a^p δ_b^q] of two tolerances `ta`, `tb` (`inputs.Tolerance`, scalar) under the Gaussian
    copula with normal-scores correlation `r` (module doc), by quadrature."""
    return _moment(_tolerance_key(ta), _tolerance_key(tb), float(r), int(p), int(q))


@functools.lru_cache(maxsize=256)
def _moment(a: tuple, b: tuple, r: float, p: int, q: int) -> float:
    from numpy.polynomial.legendre import leggauss

    u, v = leggauss(NODES)
    s = math.sqrt(max(1.0 - r * r, 0.0))
    L = SPAN
    x = np.concatenate([L / 2 * (u - 1.0), L / 2 * (u + 1.0)])  # [−L, 0] and [0, L]
    wx = np.concatenate([L / 2 * v, L / 2 * v]) * np.exp(-0.5 * x * x) / math.sqrt(2 * math.pi)
    w0 = np.clip(-r * x / s, -L, L) if s > 0 else np.zeros_like(x)  # the inner kink: r x + s w = 0
    lo, hi = (w0 + L) / 2, (L - w0) / 2  # the half-lengths of [−L, w0] and [w0, L]
    w = np.concatenate([lo[:, None] * (u[None] + 1.0) - L, w0[:, None] + hi[:, None] * (u[None] + 1.0)], axis=1)
    ww = np.concatenate([lo[:, None] * v[None], hi[:, None] * v[None]], axis=1)
    ww = ww * np.exp(-0.5 * w * w) / math.sqrt(2 * math.pi)
    fa = inverse_cdf(a[0], x, *a[1:]) ** p
    fb = inverse_cdf(b[0], r * x[:, None] + s * w, *b[1:]) ** q
    return float(np.sum(wx[:, None] * fa[:, None] * fb * ww))


def pearson(ta, tb, r: float) -> float:
    """The Pearson correlation ρ of two tolerances whose normal scores have correlation `r`
    (module doc; two normals: r exactly)."""
    if ta.distribution == "normal" and tb.distribution == "normal":
        return float(r)
    return moment(ta, tb, r) / (ta.sigma * tb.sigma)


def covariance(inputs) -> np.ndarray:
    """Σ (T, T) of the toleranced parameters of `inputs` (file units): σ_j² on the diagonal (a
    zone's coordinates uncorrelated), σ_a σ_b ρ_ab for each pair of `[study.correlation]`."""
    tols = [t for t in inputs.tolerances for _ in t.parameters]
    sigma = np.asarray([t.sigma for t in tols])
    cov = np.diag(sigma ** 2)
    params = list(inputs.parameters)
    for a, b, r in inputs.correlation:
        i, j = params.index(a), params.index(b)
        cov[i, j] = cov[j, i] = sigma[i] * sigma[j] * pearson(tols[i], tols[j], r)
    return cov
