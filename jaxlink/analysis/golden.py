"""Golden-section search on the host, many brackets at once: the refinement step of the
designer's numbers (the extremes of cos μ, `motion`; of the outputs' velocity ratio, `stroke`) and
of the certificate between samples (`feasibility.certify_host`). Each step evaluates one new point
per bracket, all brackets in one call (one compiled program in blocks: `blocks.in_blocks`).
"""

from __future__ import annotations

import numpy as np

#: golden ratio conjugate (√5 − 1) / 2
GOLD = 0.6180339887498949


def golden(ev, a, b, iterations: int):
    """Minimize `ev` ((k,) inputs → (k,) values, one per bracket) in the brackets [a[i], b[i]] by
    `iterations` golden-section reductions. Returns `(x1, x2, f1, f2)`, the last two interior
    points of every bracket and their values (the caller picks the least of them and of its own
    candidates)."""
    x1, x2 = b - GOLD * (b - a), a + GOLD * (b - a)
    f1, f2 = ev(x1), ev(x2)
    for _ in range(int(iterations)):
        left = f1 <= f2  # the minimum is in [a, x2]
        b = np.where(left, x2, b)
        a = np.where(left, a, x1)
        nx1 = np.where(left, b - GOLD * (b - a), x2)
        nx2 = np.where(left, x1, a + GOLD * (b - a))
        fn = ev(np.where(left, nx1, nx2))
        f1, f2 = np.where(left, fn, f2), np.where(left, f1, fn)
        x1, x2 = nx1, nx2
    return x1, x2, f1, f2
