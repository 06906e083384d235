"""How near a singular position float32 still meets its tolerance (issue 46, item 8).

A dyad whose two links are nearly in line (the sine s between them small: near a change point, a
toggle or a dead centre; `jaxlink.solvers.dyads.reach_margins` is S = s², signed) solves with its
rounding amplified: the closed form's square root of S and the Jacobian, whose condition number
grows as 1/s, make the error of a position about K₀ eps / s, of a velocity K₁ eps / s² and of an
acceleration K₂ eps / s³ (relative to the length scale, a radian, the table's largest magnitude of
that quantity). The float32 tolerance is rtol = 1000 eps (docs/reference/cli.md, "Precision"), so
a float32 row meets it only where

    s ≥ (K_k / 1000)^(1 / (k + 1)),   k the highest order asked for (0 positions, 1 velocities,
                                        2 accelerations or the unknowns' rates),

whatever eps: with the constants `K` measured against float64 (a Peaucellier cell folding flat and
a change-point four-bar 30, 60, 50, 40 mm, rows 0.1°–30° from the change point; the largest ratio
seen, rounded up to a power of two: K₀ ≤ 6.8, K₁ ≤ 8.9, K₂ ≤ 51) s ≥ 0.008 for positions (the
links 0.46° from in line), 0.126 for velocities (7.3°) and 0.40 for accelerations (23.6°). A
float32 row below its bound is `RESULTS.imprecise` in the kinematics table (`report/kinematics.py`):
the position given, the rates NaN. Only mechanisms made of dyads have the sine; float64 rows are
never flagged (their error is eps₆₄ / eps₃₂ ≈ 2e-9 of float32's).
"""

from __future__ import annotations

import numpy as np

K = (8.0, 16.0, 64.0)
"""The error constants of positions, velocities and accelerations (see the module doc)."""


def least_sine(order: int) -> float:
    """The smallest sine between a dyad's links at which a float32 row meets the float32
    tolerance for outputs up to `order` (0, 1 or 2)."""
    return float((K[order] / 1000.0) ** (1.0 / (order + 1)))


def imprecise(margin, order: int, dtype) -> np.ndarray:
    """(N,) bool: the rows whose least reach margin `margin` (N,) (S = s² of the dyad nearest to
    in line; NaN where not known) is below `least_sine(order)`², in float32 only."""
    margin = np.asarray(margin, dtype=float)
    if np.dtype(dtype) != np.float32:
        return np.zeros(margin.shape, bool)
    with np.errstate(invalid="ignore"):
        return np.isfinite(margin) & (margin < least_sine(order) ** 2)
