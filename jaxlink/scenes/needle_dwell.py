"""Scene module of the needle six-bar with a dwell (`needle-dwell.toml`, `needle-arachne*.toml`):
the design objective `dwell` and its defaults.

The objective maximizes the dwell of the needle at its top dead centre at a required stroke,
under the constraints on the linkage's transmission, rod and toggle angles, its peak
acceleration, its Grashof margin and the number of acceleration sign changes; the metrics and
the roles of the mechanism's unknowns are those of `jaxlink/analysis/dwell.py` (docs/methods/dwell.md).
Registered by `register_objectives`, which the objective registry
(`jaxlink/optimize/objectives/__init__.py`) calls.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from ..analysis.dwell import (
    ROLE_KEYS,
    StrokeScale,
    design_metrics,
    dwell_roles,
    spectral_derivatives,
    stroke_metrics,
)
from ..optimize.objectives.base import Objective


def register_objectives(register) -> None:
    """Register `dwell` with `register(name, factory, keys=...)`: its options and the roles."""
    register("dwell", dwell_objective, keys=tuple(DWELL_OPTIONS) + ROLE_KEYS)


#: `[optimize]` keys of the dwell objective (file units: mm, degrees) and their defaults.
DWELL_OPTIONS = {
    "stroke": 20.0,            # required stroke h (file length units)
    "stroke_tol": 0.01,        # |h − stroke| allowed in the exact check (file length units)
    "dwell_weight": 0.3,       # objective: maximize dwell(abs_tol) + dwell_weight · dwell(1 %)
    "abs_tol": 0.05,           # the absolute band (file length units), 0.05 mm
    "mu_min": 40.0,            # transmission angle ≥ (deg)
    "rod_max": 45.0,           # rod (pressure) angle ≤ (deg)
    "toggle_min": 1.0,         # toggle clearance ≥ (deg)
    "amax_max": 1.95,          # peak |s''| / l2 ≤
    "sign_changes": 2,         # acceleration sign changes per revolution (exactly)
    "penalty": 10.0,           # weight ρ of the squared, normalized constraint violations
}
#: the constraints, in the order of `dwell_constraints` (the stroke is the one equality)
CONSTRAINTS = ("stroke", "mu", "rod", "toggle", "amax", "grashof", "sign")
# normalization of each constraint violation, and the margin the smooth search keeps inside each
# inequality (the exact check has none) so that its optimum meets the exact constraints
_SCALE = {"stroke": 2.0, "mu": 10.0, "rod": 10.0, "toggle": 1.0, "amax": 0.1, "grashof": 0.1, "sign": 1.0}
_MARGIN = {"mu": 0.01, "rod": 0.01, "toggle": 0.002, "amax": 0.0005, "grashof": 0.0}


def _relu(x):
    return jnp.maximum(x, 0.0)


def _sign_surrogate(s, dds):
    """Smooth stand-in for "exactly 2 sign changes of s''": s'' should be ≤ 0 on the upper quarter
    of the stroke and ≥ 0 on the lower quarter (a sag or a wiggle breaks one of them). Returns a
    violation ≥ 0 normalized by max|s''| (0 for a clean stroke), with logistic weights (width 2 %
    of the stroke) so that it is differentiable."""
    h = jnp.max(s) - jnp.min(s)
    z = (s - jnp.min(s)) / h
    a = dds / jnp.max(jnp.abs(dds))
    top = jax.nn.sigmoid((z - 0.75) / 0.02)
    bottom = jax.nn.sigmoid((0.25 - z) / 0.02)
    return jnp.sqrt(jnp.mean(top * _relu(a) ** 2 + bottom * _relu(-a) ** 2) + 1e-30)


def dwell_score(m, opts, *, smooth_sign=None):
    """(objective J to minimize, constraints-met flag) from metrics `m` (exact or smooth).

    J = −(dwell_abs + w · dwell_1%)/100 + ρ Σ_i (violation_i / scale_i)², the violations of
    |h − stroke| ≤ stroke_tol, μ_min ≥ mu_min, rod ≤ rod_max, toggle ≥ toggle_min, amax ≤ amax_max,
    Grashof crank-rocker (crank shortest) and the sign-change count (`smooth_sign`: the surrogate
    violation instead of |count − 2|, the stroke without its tolerance and the margins `_MARGIN`).
    The flag is the exact check of every constraint.
    """
    margin = _MARGIN if smooth_sign is not None else dict.fromkeys(_MARGIN, 0.0)
    v = {
        "stroke": _relu(jnp.abs(m["stroke_file"] - opts["stroke"])
                        - (0.0 if smooth_sign is not None else opts["stroke_tol"])),
        "mu": _relu(opts["mu_min"] + margin["mu"] - m["mu_min_deg"]),
        "rod": _relu(m["rod_angle_max_deg"] - opts["rod_max"] + margin["rod"]),
        "toggle": _relu(opts["toggle_min"] + margin["toggle"] - m["toggle_clear_deg"]),
        "amax": _relu(m["amax_rel"] - opts["amax_max"] + margin["amax"]),
        "grashof": _relu(margin["grashof"] - m["grashof_margin_rel"]),
        "sign": (smooth_sign if smooth_sign is not None
                 else jnp.abs(m["acc_sign_changes"] - opts["sign_changes"]).astype(float)),
    }
    pen = sum((v[k] / _SCALE[k]) ** 2 for k in v)
    dwell = m["dwell_abs_deg"] + opts["dwell_weight"] * m["dwell_1pct_deg"]
    j = -dwell / 100.0 + opts["penalty"] * pen
    exact = dict(v)
    exact["stroke"] = _relu(jnp.abs(m["stroke_file"] - opts["stroke"]) - opts["stroke_tol"])
    ok = (jnp.all(jnp.stack([exact[k] <= 0 for k in exact if k != "sign"]))
          & (m["acc_sign_changes"] == opts["sign_changes"]))
    return j, ok


def dwell_constraints(m, opts, sign_violation):
    """(f, c) for the constrained gradient search: f = −(dwell_abs + w · dwell_1%)/100 and the
    normalized constraints c (7,) in the order of `CONSTRAINTS`: c[0] = (h − stroke)/2 mm = 0, and
    c[1:] ≤ 0 for the transmission angle, rod angle, toggle clearance (signed), peak acceleration
    and Grashof margin, each with its margin `_MARGIN`, and the sign-change surrogate."""
    mg = _MARGIN
    c = jnp.stack([
        (m["stroke_file"] - opts["stroke"]) / _SCALE["stroke"],
        (opts["mu_min"] + mg["mu"] - m["mu_min_deg"]) / _SCALE["mu"],
        (m["rod_angle_max_deg"] - opts["rod_max"] + mg["rod"]) / _SCALE["rod"],
        (opts["toggle_min"] + mg["toggle"] - m["toggle_signed_deg"]) / _SCALE["toggle"],
        (m["amax_rel"] - opts["amax_max"] + mg["amax"]) / _SCALE["amax"],
        (mg["grashof"] - m["grashof_margin_rel"]) / _SCALE["grashof"],
        sign_violation / _SCALE["sign"],
    ])
    f = -(m["dwell_abs_deg"] + opts["dwell_weight"] * m["dwell_1pct_deg"]) / 100.0
    return f, c


def dwell_objective(problem):
    """Factory of the objective `dwell`.

    The design search hands it the path of the `[optimize]` point (the needle B, whose y is the
    slider position s, file units), the solved unknowns q and the parameters p (`PathData`). The
    search solves positions only and takes s', s'' spectrally from the samples
    (`spectral_derivatives`, agreeing with the exact transfer functions to ~1e-10: the gradient
    call is ~10× cheaper than through the second-order transfer functions); the report re-solves
    at `report_samples` with the exact transfer functions. From them:

    - `value`: the exact J of `dwell_score` (+10 when a constraint is missed, so every design
      that meets the constraints ranks first), with parabola-refined extremes (`design_metrics`);
    - `rank` (picks the gradient search's starts): (value, the same J without the +10: a long
      dwell at the wrong stroke is a good start);
    - `smooth`: the quadratic-penalty J with the sign-change surrogate and the margins;
    - `constraints`: (f, c) of `dwell_constraints` for the augmented-Lagrangian gradient search;
    - `metrics` (the report): stroke, all dwell widths, sign changes, peaks and angles exactly as
      `needle_metrics` measures them (extreme samples of the report grid), the Grashof margin,
      the sag and `constraints_met` (1/0), the exact check of every constraint on those numbers.

    The roles of the mechanism's unknowns and parameters (coupler, rocker, rod, arm offset, crank,
    four-bar loop) are the `[optimize]` keys of `jaxlink.analysis.dwell.dwell_roles`; amax is
    max|s''| per crank length.
    """
    mech = problem.mech
    roles = dwell_roles(mech, problem.options)
    opts = {k: problem.option(k, d) for k, d in DWELL_OPTIONS.items()}
    for k, v in opts.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise problem.error(f"'{k}' must be a finite number, got {v!r}", k)
    lf = mech.units.length
    crank_index = mech.parameter_index(roles.crank)

    def measured(path, refined):
        if path.q is None or path.p is None:
            raise ValueError("the dwell objective needs the solved configuration q and the parameters p (PathData)")
        s = path.xy[:, 1]
        if path.dxy is None or path.ddxy is None:  # the search: spectral derivatives of the samples
            ds, dds = spectral_derivatives(s)
        else:  # the report: the exact transfer functions
            ds, dds = path.dxy[:, 1], path.ddxy[:, 1]
        crank = path.p[crank_index] / lf
        m = design_metrics(mech, roles, path.q, s, ds, dds, path.p, crank, opts["abs_tol"], refined=refined)
        return m, s, ds, dds

    def score(path):
        m, _, _, _ = measured(path, True)
        return dwell_score(m, opts)

    def value(path):
        j, ok = score(path)
        return jnp.where(ok, j, j + 10.0)

    def rank(path):
        j, ok = score(path)
        return jnp.where(ok, j, j + 10.0), j

    def smooth(path):
        m, s, _, dds = measured(path, True)
        m = dict(m, toggle_clear_deg=m["toggle_signed_deg"])
        return dwell_score(m, opts, smooth_sign=_sign_surrogate(s, dds))[0]

    def constraints(path):
        m, s, _, dds = measured(path, True)
        f, c = dwell_constraints(m, opts, _sign_surrogate(s, dds))
        j, ok = dwell_score(m, opts)
        return f, c, jnp.where(ok, j, j + 10.0)

    def metrics(path):
        m, s, ds, dds = measured(path, False)
        crank = path.p[crank_index] / lf
        out = stroke_metrics(s, ds, dds, crank, scale=StrokeScale(length_to_mm=lf * 1e3))
        out.pop("stroke_rel")
        out.update({k: m[k] for k in ("mu_min_deg", "rod_angle_max_deg", "toggle_clear_deg", "grashof_margin_rel")})
        out["constraints_met"] = dwell_score(m, opts)[1].astype(float)
        return out

    # the search solves positions only (order 0: s', s'' spectral); the report adds the exact
    # transfer functions (report_order 2)
    return Objective("dwell", 0, value, smooth, metrics, report_order=2, constraints=constraints, equalities=1,
                     rank=rank)
