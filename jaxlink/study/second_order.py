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

**Correlated inputs** (`[study.correlation]`; Σ the covariance of `copula.covariance`): the joint
distribution is still symmetric about the nominal (a Gaussian copula of symmetric marginals), so

    mean shift = ½ tr(H Σ),   Var₂ = gᵀ Σ g + ¼ (Σ_ijkl H_ij H_kl E[δ_i δ_j δ_k δ_l] − (tr H Σ)²)

with the fourth moments (`fourth_moments`) a product over the independent groups: one input, a
zone's two coordinates (as above), a correlated pair (`copula.moment`, any distributions), a group
of three or more inputs linked by correlations, all normal (Isserlis: E[δ_i δ_j δ_k δ_l] =
Σ_ij Σ_kl + Σ_ik Σ_jl + Σ_il Σ_jk). Three or more linked inputs, one of them not normal, need 3- and
4-dimensional integrals of the copula: refused (`unsupported`).

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
    (M, T, T) of the responses; with a `[study.correlation]` the correlated form (module doc).
    Raises `ValueError` (`unsupported`'s reason) where its fourth moments are not computable."""
    J = np.asarray(J, float)
    H = np.asarray(H, float)
    if inputs.correlation:
        return _correlated_stats(J, H, inputs)
    s2, cov, cross = input_moments(inputs)
    d = np.diagonal(H, axis1=1, axis2=2)  # (M, T)
    off = cross * (1.0 - np.eye(len(s2)))
    var = (J ** 2) @ s2 + 0.25 * np.einsum("mi,ij,mj->m", d, cov, d) + 0.5 * np.einsum("mij,ij->m", H ** 2, off)
    return SecondOrder(0.5 * d @ s2, np.sqrt(np.maximum(var, 0.0)), H)


def _correlated_stats(J, H, inputs) -> SecondOrder:
    """The correlated form: shift ½ tr(H Σ), Var₂ = gᵀ Σ g + ¼ (Σ H_ij H_kl E[δ_i δ_j δ_k δ_l] − (tr H Σ)²)."""
    from .copula import covariance

    sigma = covariance(inputs)
    m4 = fourth_moments(inputs)
    T = sigma.shape[0]
    M = H.shape[0]
    Hf = H.reshape(M, T * T)
    tr = Hf @ sigma.reshape(T * T)
    quad = np.einsum("mi,mi->m", Hf @ m4.reshape(T * T, T * T), Hf)
    var = np.einsum("mi,ij,mj->m", J, sigma, J) + 0.25 * (quad - tr ** 2)
    return SecondOrder(0.5 * tr, np.sqrt(np.maximum(var, 0.0)), H)


def _structure(inputs):
    """(tolerance per parameter (T,), the normal-scores correlation C (T, T), the zone partner of
    each parameter or −1)."""
    tols = [t for t in inputs.tolerances for _ in t.parameters]
    params = list(inputs.parameters)
    c = np.eye(len(tols))
    for a, b, r in inputs.correlation:
        i, j = params.index(a), params.index(b)
        c[i, j] = c[j, i] = r
    partner = -np.ones(len(tols), int)
    j = 0
    for t in inputs.tolerances:
        if t.zone:
            partner[j], partner[j + 1] = j + 1, j
        j += len(t.parameters)
    return tols, c, partner


def _components(idx, link) -> list[list[int]]:
    """The connected components of the distinct parameters `idx` under `link` (T, T) (truthy: linked)."""
    left = list(idx)
    out = []
    while left:
        comp = [left.pop(0)]
        k = 0
        while k < len(comp):
            near = [j for j in left if link[comp[k], j]]
            comp += near
            left = [j for j in left if j not in near]
            k += 1
        out.append(comp)
    return out


def unsupported(inputs) -> str | None:
    """Why the second-order σ cannot be computed exactly with the inputs' correlation, or None:
    three or more inputs linked by correlations, one of them not normal (their joint fourth moments
    under the Gaussian copula are 3- and 4-dimensional integrals, not computed)."""
    if not inputs.correlation:
        return None
    tols, c, _ = _structure(inputs)
    for comp in _components(list(range(len(tols))), c != 0.0):
        if len(comp) >= 3 and any(tols[i].distribution != "normal" for i in comp):
            names = [inputs.parameters[i] for i in comp]
            return (f"second order with correlated inputs is computed for correlated pairs (any distribution) and "
                    f"for groups of normal inputs; {', '.join(names)} are linked by correlations and not all normal: "
                    "leave second_order out, or correlate them in pairs, or make them normal")
    return None


def fourth_moments(inputs) -> np.ndarray:
    """E[δ_i δ_j δ_k δ_l] (T, T, T, T) of the toleranced parameters: a product over the independent
    groups of the indices (module doc): one input μ₂ or μ₄; a zone's coordinates (the disc's mixed
    moments); a correlated pair by quadrature (`copula.moment`); a correlated group of normal
    inputs by Isserlis' theorem, E[δ_i δ_j δ_k δ_l] = Σ_ij Σ_kl + Σ_ik Σ_jl + Σ_il Σ_jk. Raises
    `ValueError` as `unsupported`."""
    import itertools

    from .copula import covariance, moment

    why = unsupported(inputs)
    if why:
        raise ValueError(why)
    tols, c, partner = _structure(inputs)
    sigma = covariance(inputs)
    T = len(tols)

    def part(idx) -> float:
        counts = {i: idx.count(i) for i in dict.fromkeys(idx)}
        if sum(counts.values()) % 2:
            return 0.0  # the joint distribution is symmetric about the nominal
        keys = list(counts)
        if len(keys) == 1:
            (i, n), = counts.items()
            t = tols[i]
            return t.sigma ** 2 if n == 2 else fourth_moment_ratio(t.distribution, t.k, t.zone) * t.sigma ** 4
        i, j = keys[0], keys[1]
        if len(keys) == 2 and partner[i] == j:  # a zone's two coordinates
            if any(n % 2 for n in counts.values()):
                return 0.0  # the disc is symmetric in each coordinate
            s4 = tols[i].sigma ** 4
            return 2.0 / 3.0 * s4 if tols[i].distribution == "uniform" else s4
        if len(keys) == 2:
            return moment(tols[i], tols[j], c[i, j], counts[i], counts[j])
        a, b, cc, d = idx  # three or four distinct: normal (`unsupported`)
        return sigma[a, b] * sigma[cc, d] + sigma[a, cc] * sigma[b, d] + sigma[a, d] * sigma[b, cc]

    link = (c != 0.0) | (partner[:, None] == np.arange(T)[None, :])
    out = np.zeros((T, T, T, T))
    for q in itertools.combinations_with_replacement(range(T), 4):
        v = 1.0
        for g in _components(list(dict.fromkeys(q)), link):
            v *= part(tuple(i for i in q if i in g))
        for perm in set(itertools.permutations(q)):
            out[perm] = v
    return out
