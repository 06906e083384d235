"""The second-order moment method: the mean shift and the standard deviation of every response
from its exact gradient g and Hessian H with respect to the toleranced parameters (file units),
the second-order Taylor expansion y(x̄ + δ) ≈ y(x̄) + g·δ + ½ δᵀ H δ taken over the inputs'
distributions (the "second-order mean / variance" of Dakota's reliability methods and OpenTURNS'
Taylor expansion moments). docs/methods/tolerance.md gives the formulas and when to trust them.

With the inputs δ_i of zero mean, uncorrelated, symmetric (every third moment zero, and E[δ_i δ_j
δ_k] = 0 for every triple: all of `distributions.DISTRIBUTIONS` and the zones), σ_i² = E[δ_i²],
μ₄,i = E[δ_i⁴]:

    mean shift  E[y] − y(x̄) = ½ Σ_i H_ii σ_i²
    Var₂ = Σ_i g_i² σ_i²
         + ¼ Σ_i Σ_j H_ii H_jj Cov(δ_i², δ_j²)
         + ½ Σ_{i≠j} H_ij² E[δ_i² δ_j²]

(the terms in g_i H_jk E[δ_i δ_j δ_k] vanish by symmetry). For independent inputs Cov(δ_i², δ_j²)
is μ₄,i − σ_i⁴ on the diagonal and 0 elsewhere, and E[δ_i² δ_j²] = σ_i² σ_j²: the textbook
Var₂ = Σ g_i² σ_i² + ¼ Σ H_ii² (μ₄,i − σ_i⁴) + ½ Σ_{i≠j} H_ij² σ_i² σ_j². The two coordinates of a
uniform circular zone (radius r, σ = r/2) are uncorrelated but not independent:
E[δ_x² δ_y²] = r⁴/24 = (2/3) σ⁴ and Cov(δ_x², δ_y²) = −σ⁴/3 (μ₄ = 2σ⁴).

The standard deviation is std₂ = √Var₂. The Hessian is `jax.jacfwd` of the study's Jacobian
(`jax.jacfwd` of the response function, the path solve differentiated implicitly): both orders
exact, no finite differences.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .distributions import fourth_moment_ratio


class SecondOrder(NamedTuple):
    """Second-order results (file units; M responses): `mean_shift` (M,) E[y] − y(x̄); `std` (M,)
    √Var₂; `hessian` (M, T, T)."""

    mean_shift: np.ndarray
    std: np.ndarray
    hessian: np.ndarray


def input_moments(inputs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(σ² (T,), Cov(δ_i², δ_j²) (T, T), E[δ_i² δ_j²] (T, T; its diagonal unused)) of the
    toleranced parameters (module doc)."""
    var: list[float] = []
    mu4: list[float] = []
    pairs: list[tuple[int, int, float]] = []
    for t in inputs.tolerances:
        r4 = fourth_moment_ratio(t.distribution, t.k, t.zone)
        j = len(var)
        for _ in t.parameters:
            var.append(t.sigma ** 2)
            mu4.append(r4 * t.sigma ** 4)
        if t.zone and t.distribution == "uniform":
            pairs.append((j, j + 1, t.sigma ** 4))
    s2 = np.asarray(var)
    cov = np.diag(np.asarray(mu4) - s2 ** 2)
    cross = np.outer(s2, s2)
    for a, b, s4 in pairs:
        cross[a, b] = cross[b, a] = 2.0 / 3.0 * s4
        cov[a, b] = cov[b, a] = -s4 / 3.0
    return s2, cov, cross


def second_order_stats(J, H, inputs) -> SecondOrder:
    """The mean shift and std₂ (module doc) from the Jacobian `J` (M, T) and Hessians `H`
    (M, T, T) of the responses."""
    J = np.asarray(J, float)
    H = np.asarray(H, float)
    s2, cov, cross = input_moments(inputs)
    d = np.diagonal(H, axis1=1, axis2=2)  # (M, T)
    off = cross * (1.0 - np.eye(len(s2)))
    var = (J ** 2) @ s2 + 0.25 * np.einsum("mi,ij,mj->m", d, cov, d) + 0.5 * np.einsum("mij,ij->m", H ** 2, off)
    return SecondOrder(0.5 * d @ s2, np.sqrt(np.maximum(var, 0.0)), H)
