"""Scene module of the sewing-machine bottom-feed six-bar (`sewing-feed.toml`,
`sewing-feed-opt.toml`): its design objective `feed` and that objective's defaults.

The feed dog's point Z moves the cloth while its path is above the needle plate (the upper
half of the path, y ≥ ȳ); the defaults are this machine's: a stroke of 5 mm, a lift of 2 mm and
5490 rpm (575 rad/s). Registered by `register_objectives`, which the objective registry
(`jaxlink/optimize/objectives/__init__.py`) calls.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..optimize.objectives.base import Objective, number
from ..optimize.objectives.path import flatness, input_speed, shape_metrics

#: `[optimize]` keys of the `feed` objective and their defaults (file units: mm; m/s²; rpm)
FEED_OPTIONS = {
    "stroke": 5.0,                # lower bound of the stroke 2a (mm)
    "lift": 2.0,                  # lower bound of the lift 2b (mm)
    "acceleration_weight": 1.0,
    "acceleration_ref": 1000.0,   # m/s²
    "penalty": 1e4,
    "rpm": 5490.0,                # input speed: 575 rad/s
}


def register_objectives(register) -> None:
    """Register `feed` with `register(name, factory, keys=...)`."""
    register("feed", feed_objective, keys=tuple(FEED_OPTIONS))


def feed_objective(problem) -> Objective:
    """A straight working part and a low peak acceleration at a given stroke.

    With the working part W = {k : y_k ≥ ȳ} (ȳ the mean height: the half of the path above the
    needle plate; logistic weights of width 0.025·lift in the smooth version), s_W the RMS of its
    heights about their mean (`flatness`, mm: the deviation from a straight line parallel to the
    plate — a tilted or degenerate back-and-forth path scores badly), the stroke
    2a = max x − min x and lift 2b = max y − min y at the samples, A_k = |d²P/dt²| at `rpm`
    and A_p its peak ((mean_k A_k^8)^{1/8} in the smooth version):

        J = s_W² / (lift/2)² + acceleration_weight · (A_p / acceleration_ref)²
            + penalty · [((stroke − 2a)₊ / stroke)² + ((lift − 2b)₊ / lift)²]

    (defaults `FEED_OPTIONS`): stroke and lift are lower bounds, enforced by quadratic penalties.
    Metrics: `shape_metrics` at `rpm`. docs/methods/optimize.md.
    """
    opt = FEED_OPTIONS
    stroke = number(problem, "stroke", opt["stroke"], positive=True)
    lift = number(problem, "lift", opt["lift"], positive=True)
    wacc = number(problem, "acceleration_weight", opt["acceleration_weight"])
    aref = number(problem, "acceleration_ref", opt["acceleration_ref"], positive=True)
    pen = number(problem, "penalty", opt["penalty"], positive=True)
    omega = input_speed(problem, opt["rpm"])
    assert omega is not None  # the feed options always give an rpm
    lf = problem.mech.units.length

    def j(path, soft: bool):
        x, y = path.xy[:, 0], path.xy[:, 1]
        n = jnp.mean(y)
        w = jax.nn.sigmoid((y - n) / (0.025 * lift)) if soft else (y >= n).astype(x.dtype)
        sag = flatness(y, w)
        assert path.ddxy is not None  # the feed objective asks for order 2
        acc = jnp.sqrt(jnp.sum(path.ddxy**2, axis=-1) + 1e-30) * omega**2 * lf
        peak = jnp.mean(acc**8) ** (1 / 8) if soft else jnp.max(acc)
        two_a, two_b = jnp.max(x) - jnp.min(x), jnp.max(y) - jnp.min(y)
        return ((sag / (0.5 * lift)) ** 2 + wacc * (peak / aref) ** 2
                + pen * (jnp.maximum(stroke - two_a, 0.0) / stroke) ** 2
                + pen * (jnp.maximum(lift - two_b, 0.0) / lift) ** 2)

    def metrics(path):
        return shape_metrics(path, omega=omega, length_factor=lf)

    return Objective("feed", 2, lambda p: j(p, False), lambda p: j(p, True), metrics, report_order=2)
