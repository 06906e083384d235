"""The records every objective shares: the traced path it is given (`PathData`), what an
objective is (`Objective`), and helpers to read `[optimize]` options and report values."""

from __future__ import annotations

import math
from typing import Any, Callable, NamedTuple

import jax
import numpy as np


class PathData(NamedTuple):
    """The traced path of the point, file length units, and the solved configuration.

    - `xy`: (N, 2) positions at the sampled inputs (a full revolution, equally spaced).
    - `dxy`, `ddxy`: (N, 2) first and second derivatives w.r.t. the input (per rad), or None.
    - `q`: (N, n) the solved unknowns at the same inputs (SI: rad, m), or None.
    - `p`: (P,) the design's parameters (SI), or None.
    """

    xy: jax.Array
    dxy: jax.Array | None = None
    ddxy: jax.Array | None = None
    q: jax.Array | None = None
    p: jax.Array | None = None


class Objective(NamedTuple):
    name: str
    order: int
    value: Callable
    smooth: Callable
    metrics: Callable
    report_order: int = 0
    constraints: Callable | None = None
    equalities: int = 0
    rank: Callable | None = None
    residuals: Callable | None = None  # path → r with value = Σ r² (least-squares polish)


def number(problem, key: str, default: float | None = None, *, positive: bool = False) -> float:
    """The `[optimize]` option `key` as a finite (`positive`: > 0) float; `default` when the
    file does not set it (None: the key is required). Raises the problem's `MechanismError`
    naming the key."""
    v = problem.option(key, default)
    if v is None:
        raise problem.error(f"the objective '{problem.objective}' needs '{key}' "
                            f"(a {'positive ' if positive else ''}number)", key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (positive and v <= 0):
        raise problem.error(f"'{key}' must be a {'positive ' if positive else ''}finite number, got {v!r}", key)
    return float(v)


def to_python(tree) -> Any:
    """Arrays → floats (JSON-ready); non-finite → None."""
    def conv(v):
        v = float(np.asarray(v))
        return v if math.isfinite(v) else None

    return {k: conv(v) for k, v in tree.items()}
