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
