"""Closed-form solutions used as references (independent of jaxlink's solver)."""

import numpy as np


def fourbar_freudenstein(a, b, c, d, phi2, branch):
    """Four-bar A0=(0,0), B0=(d,0), crank a at phi2, coupler b at phi3, rocker c at phi4, loop
    a e2 + b e3 - c e4 - d = 0. Freudenstein: K1 cos phi4 - K2 cos phi2 + K3 = cos(phi2 - phi4)
    solved as A t² + B t + C = 0 in t = tan(phi4/2). `branch` = ±1. Returns (phi3, phi4)."""
    K1, K2, K3 = d / a, d / c, (a * a - b * b + c * c + d * d) / (2 * a * c)
    A = np.cos(phi2) - K1 - K2 * np.cos(phi2) + K3
    B = -2 * np.sin(phi2)
    C = K1 - (K2 + 1) * np.cos(phi2) + K3
    disc = B * B - 4 * A * C
    phi4 = 2 * np.arctan2(-B + branch * np.sqrt(disc), 2 * A)
    bx = d + c * np.cos(phi4) - a * np.cos(phi2)
    by = c * np.sin(phi4) - a * np.sin(phi2)
    return np.arctan2(by, bx), phi4


def slider_crank_offset(h1, alpha1, h2, h3, alpha4, psi12):
    """-h1 e(alpha1) + h2 e(psi12) + h3 e(psi13) - p14 e(alpha4) = 0, the + branch.
    Returns (psi13, p14)."""
    w = np.stack([h2 * np.cos(psi12) - h1 * np.cos(alpha1), h2 * np.sin(psi12) - h1 * np.sin(alpha1)])
    e4 = np.array([np.cos(alpha4), np.sin(alpha4)])
    along = e4 @ w
    across = w[0] * e4[1] - w[1] * e4[0]
    p14 = along + np.sqrt(h3 * h3 - across * across)
    rod = p14 * e4[:, None] - w
    return np.arctan2(rod[1], rod[0]), p14


def fourbar_point_derivatives(a, b, c, d, cx, cy, phi2, branch):
    """(P, P′, P″, P‴) of the coupler point P = a e(φ2) + (cx + i cy) e(φ3) of the four-bar of
    `fourbar_freudenstein` (complex numbers x + i y, derivatives per radian of φ2), from the loop
    Σ s_k r_k e^{iθ_k} = 0 differentiated by hand:

        d/dφ e^{iθ} = iθ′ e^{iθ},  d²: (iθ″ − θ′²) e^{iθ},  d³: (iθ‴ − 3θ′θ″ − iθ′³) e^{iθ},

    each order a 2 × 2 linear system in (θ3⁽ᵏ⁾, θ4⁽ᵏ⁾). Also returns [(θ3, θ4), (θ3′, θ4′), …]."""
    phi3, phi4 = fourbar_freudenstein(a, b, c, d, phi2, branch)
    e2, e3, e4 = np.exp(1j * phi2), np.exp(1j * phi3), np.exp(1j * phi4)

    def d_e(t1, t2, t3, k):  # the k-th derivative factor of e^{iθ}
        return [1.0, 1j * t1, 1j * t2 - t1 ** 2, 1j * t3 - 3 * t1 * t2 - 1j * t1 ** 3][k]

    th3, th4 = [phi3], [phi4]
    crank = [1.0, 0.0, 0.0]
    for k in (1, 2, 3):
        # the k-th derivative of a e2 + b e3 − c e4 with θ3⁽ᵏ⁾ = θ4⁽ᵏ⁾ = 0, then the linear terms
        t3 = (th3[1:] + [0.0, 0.0, 0.0])[:3]
        t4 = (th4[1:] + [0.0, 0.0, 0.0])[:3]
        rest = (a * d_e(*crank, k) * e2 + b * d_e(*t3, k) * e3 - c * d_e(*t4, k) * e4)
        # + i b θ3⁽ᵏ⁾ e3 − i c θ4⁽ᵏ⁾ e4 = −rest
        m = np.array([[(1j * b * e3).real, (-1j * c * e4).real], [(1j * b * e3).imag, (-1j * c * e4).imag]])
        x = np.linalg.solve(m, [-rest.real, -rest.imag])
        th3.append(x[0])
        th4.append(x[1])
    w = cx + 1j * cy
    P = []
    for k in range(4):
        P.append(a * d_e(*crank, k) * e2 + w * d_e(*(th3[1:] + [0.0] * 3)[:3], k) * e3)
    return P, list(zip(th3, th4))
