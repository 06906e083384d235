"""The static settings of the loop-closure solve (`NewtonOptions`: changing them recompiles) and
their defaults."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class NewtonOptions(NamedTuple):
    """Static solver settings (changing them recompiles).

    - `method`: `"auto"` (closed-form dyads when every block of the structure is a dyad, else
      Newton with continuation), `"closed_form"`, `"continuation"` or `"independent"` (every
      position by Newton from q0: only safe with a close guess).
    - `rtol`: a position is converged when max|Φ| at the returned q is ≤ rtol × length scale (the
      largest |length parameter|); `None` = 1000 × machine epsilon of the dtype (2.2e-13 in
      float64, 1.2e-4 in float32). Newton stops early: once max|Φ| ≤ max(rtol, √eps) × scale and
      the step is small enough that one more correction leaves an error below rtol / 100 (the
      error after a Newton step is ≈ |dq|² / (2 × pivot ratio)), that correction is applied and
      the residual after it is evaluated (cheaply: the sines and cosines of the corrected angles
      by angle addition) and tested against rtol; the returned q is accurate to rounding (tested
      against closed forms to 1e-15 rad) and `residual` is the residual at it.
    - `max_steps`: Newton iterations per position after the first (up to `EXTRA_STEPS` = 32 more
      while the residual falls by 2–10× per step at a small pivot ratio: linear convergence at a
      double root, e.g. an exact toggle). A position that ran out of steps returns its last
      evaluated iterate.
    - `max_steps_first`: iterations for the first position (from the file's guess), for every
      position of `"independent"`, and for each try of a re-assembly after a position that failed.
    - `continuation`: False is the same as `method="independent"` (kept for compatibility).
    - `predictor_order`: 0 (previous solution), 1 (secant) or 2 (quadratic) extrapolation.
    - `singular_ratio`: below this column-scaled pivot ratio of Φ_q (≈ the sine of the angle
      between its columns; for the closed form the sine of the angle between a dyad's two links)
      an assembled position is reported `singular` (dead centre, toggle, change point: the
      solution is not unique there); `None` = 10 √eps (1.5e-7 in float64, 3.5e-3 in float32).
    - `change_points`: what the path does at a change point of a dyad (two branches crossing, e.g.
      a Peaucellier cell's flat rhombus, a Grashof four-bar with s + l = p + q folding flat)
      located between two samples (`branch_points`): `"keep"` (default) keeps each dyad's side σ
      (the circuit), so the path goes on along the other branch (its velocity jumps there);
      `"smooth"` flips σ at each located change point, the branch whose velocity is continuous.
      Closed form and `"continuation"` (where every block is a dyad); `"independent"` keeps.
    """

    rtol: float | None = None
    max_steps: int = 12
    max_steps_first: int = 60
    continuation: bool = True
    predictor_order: int = 2
    singular_ratio: float | None = None
    method: str = "auto"
    change_points: str = "keep"


METHODS = ("auto", "closed_form", "continuation", "independent")


CHANGE_POINTS = ("keep", "smooth")


EXTRA_STEPS = 32  # more Newton steps allowed while converging linearly (double roots)


REFINE_TRIES = 24  # sub-steps tried when the continuation lands on another circuit


MAX_LEAD_IN = 4096  # lead-in positions at most (a longer way takes longer steps)


def default_rtol(dtype) -> float:
    return float(1000 * np.finfo(dtype).eps)


def singular_threshold(opts: NewtonOptions, dtype) -> float:
    """The pivot ratio (sine) below which a position is `singular`: `opts.singular_ratio` or 10 √eps."""
    if opts.singular_ratio is not None:
        return float(opts.singular_ratio)
    return float(10 * np.sqrt(np.finfo(dtype).eps))
