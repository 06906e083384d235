"""Dwell metrics of a needle stroke (seed 003, spec/needle-six-bar.md §3) and the `dwell` design
objective.

Everything is computed from the solved stroke s(φ) at N equally spaced crank angles together with
its exact input derivatives s'(φ), s''(φ) (`jaxlink.transfer`: forward-mode AD of the loop
closure, no finite differences), and from the solved joint angles for the linkage quality
figures. With Δφ = 2π/N:

- **stroke** h = max s − min s.
- **dwell_ε**: width (crank degrees) of the contiguous arc around the top dead centre
  (TDC, k₀ = argmax s) on which s ≥ s_max − ε. Starting at k₀, the arc runs over the consecutive
  samples above the band; its two ends are refined inside the first interval that leaves the band
  by solving H(t) = s_max − ε on the cubic Hermite interpolant H of (s_k, s'_k Δφ), (s_{k+1},
  s'_{k+1} Δφ) (Newton from the chord's root, clipped to [0, 1]). The interpolant is C¹ across
  samples, so the width is a continuous, almost everywhere differentiable function of the design
  (used as is by the gradient search).
- **acc_sign_changes**: sign changes of s'' around the cycle (cyclic), ignoring samples with
  |s''| < 10⁻³ max|s''| (a quartic touching zero does not count).
- **sag**: s_max minus the lowest s between the outermost local maxima of s (s' from + to −)
  that lie in the top 25 % of the stroke, within the arc around the TDC above that level; 0 for
  one hump.
- **amax_rel**, **vmax_rel**: max|s''|/l₂, max|s'|/l₂ (peak acceleration / (l₂ω²)).
- **mu_min_deg**: min over the cycle of the four-bar transmission angle μ (between coupler and
  rocker), folded to min(μ, 180° − μ).
- **rod_angle_max_deg**: max angle between the rod D→B and the slider axis (pressure angle).
- **toggle_clear_deg**: min angle between the arm C₀→D and the rod D→B; 0 when the signed angle
  changes sign over the cycle (the linkage passes through its stretched position).

Lengths: `length_to_mm` converts the solved s (SI) to mm. For a dimensionless design (crank = 1,
`needle-arachne-unit`) pass `stroke_mm = 20.0` instead: s is scaled so that h = 20 mm, i.e. the
absolute 0.05 mm tolerance is 0.25 % of the stroke and the sag is in mm at a 20 mm stroke (the
spec's convention). amax_rel/vmax_rel are per crank length and never rescaled.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

# relative tolerances (fractions of the stroke) reported as dwell_<x>pct_deg
REL_TOLERANCES = (("025", 0.0025), ("05", 0.005), ("1", 0.01), ("2", 0.02))
ABS_TOLERANCE_MM = 0.05
SIGN_IGNORE = 1e-3


# ----------------------------------------------------------------------------- stroke metrics (jax)


def _hermite_root(s_a, s_b, d_a, d_b, level):
    """t ∈ [0, 1] with H(t) = level on the cubic Hermite H(0) = s_a, H(1) = s_b, H'(0) = d_a,
    H'(1) = d_b (derivatives per unit t), assuming s_a ≥ level > s_b (else the clipped chord)."""
    den = s_a - s_b
    t = jnp.clip((s_a - level) / jnp.where(den > 0, den, 1.0), 0.0, 1.0)

    def h(t):
        t2, t3 = t * t, t * t * t
        return ((2 * t3 - 3 * t2 + 1) * s_a + (t3 - 2 * t2 + t) * d_a + (-2 * t3 + 3 * t2) * s_b
                + (t3 - t2) * d_b)

    def dh(t):
        t2 = t * t
        return (6 * t2 - 6 * t) * s_a + (3 * t2 - 4 * t + 1) * d_a + (-6 * t2 + 6 * t) * s_b + (3 * t2 - 2 * t) * d_b

    for _ in range(6):
        g = dh(t)
        step = (h(t) - level) / jnp.where(jnp.abs(g) > 0, g, 1.0)
        t = jnp.clip(t - jnp.where(jnp.abs(g) > 0, step, 0.0), 0.0, 1.0)
    return t


def band_width(s, ds, eps):
    """Width (radians) of the contiguous arc around argmax s on which s ≥ max s − eps.

    `s`, `ds`: (N,) samples at φ_k = φ₀ + 2πk/N and dS/dφ there; `eps` ≥ 0 (same units as s).
    """
    n = s.shape[0]
    dphi = 2 * jnp.pi / n
    k0 = jnp.argmax(s)
    level = s[k0] - eps
    steps = jnp.arange(n)

    def side(direction):
        idx = (k0 + direction * steps) % n
        inside = jnp.cumprod((s[idx] >= level).astype(jnp.int32))
        m = jnp.sum(inside)  # consecutive samples in the band from k0 (k0 included)
        a = idx[jnp.clip(m - 1, 0, n - 1)]
        b = idx[m % n]
        t = _hermite_root(s[a], s[b], direction * ds[a] * dphi, direction * ds[b] * dphi, level)
        return (m - 1 + t) * dphi, m

    fwd, m = side(1)
    bwd, _ = side(-1)
    return jnp.where(m >= n, 2 * jnp.pi, jnp.minimum(fwd + bwd, 2 * jnp.pi))


def sign_changes(a, ignore=SIGN_IGNORE):
    """Sign changes of the samples `a` (N,) around the cycle, ignoring |a| < ignore·max|a|."""
    n = a.shape[0]
    keep = jnp.abs(a) >= ignore * jnp.max(jnp.abs(a))
    k = jnp.arange(n)
    last = jax.lax.cummax(jnp.where(keep, k, -1))
    wrap = jnp.max(jnp.where(keep, k, -1))  # the last kept sample carries over the wrap
    last = jnp.where(last < 0, wrap, last)
    sg = jnp.sign(a)[jnp.maximum(last, 0)]
    return jnp.sum(sg != jnp.roll(sg, 1))


class StrokeScale(NamedTuple):
    """How s (SI) maps to mm for the absolute tolerance and the sag: `to_mm(h)` factor."""

    length_to_mm: float | None = 1000.0
    stroke_mm: float | None = None

    def factor(self, h):
        if self.stroke_mm is not None:
            return self.stroke_mm / h
        return self.length_to_mm


def stroke_metrics(s, ds, dds, crank, *, scale: StrokeScale = StrokeScale()):
    """Stroke, dwell widths, sign changes and peaks of one stroke curve (jax; vmappable).

    **Arguments:** `s`, `ds`, `dds`: (N,) s, s', s'' (SI, per radian), `crank`: l₂ (SI).

    **Returns:** dict of scalars (`stroke_mm`, `dwell_<…>_deg`, `acc_sign_changes`, `amax_rel`,
    `vmax_rel`, `stroke_rel` = h/l₂).
    """
    h = jnp.max(s) - jnp.min(s)
    f = scale.factor(h)
    out = {"stroke_mm": h * f, "stroke_rel": h / crank}
    deg = 180.0 / math.pi
    eps = jnp.stack([ABS_TOLERANCE_MM / f] + [r * h for _, r in REL_TOLERANCES])
    widths = jax.vmap(band_width, in_axes=(None, None, 0))(s, ds, eps) * deg
    out["dwell_005mm_deg"] = widths[0]
    for i, (name, _) in enumerate(REL_TOLERANCES):
        out[f"dwell_{name}pct_deg"] = widths[i + 1]
    out["acc_sign_changes"] = sign_changes(dds)
    out["amax_rel"] = jnp.max(jnp.abs(dds)) / crank
    out["vmax_rel"] = jnp.max(jnp.abs(ds)) / crank
    return out


def sag(s, ds):
    """Sag (units of s; numpy): see the module doc."""
    s, ds = np.asarray(s), np.asarray(ds)
    n = len(s)
    h = s.max() - s.min()
    k0 = int(np.argmax(s))
    top = s >= s.min() + 0.75 * h
    # the arc around the TDC above the 75 % level, as indices in cyclic order
    arc = [k0]
    k = (k0 + 1) % n
    while top[k] and k != k0:
        arc.append(k)
        k = (k + 1) % n
    k = (k0 - 1) % n
    while top[k] and len(arc) < n:
        arc.insert(0, k)
        k = (k - 1) % n
    arc = np.asarray(arc)
    d = ds[arc]
    maxima = [i for i in range(len(arc) - 1) if d[i] > 0 >= d[i + 1]]
    maxima = [i if s[arc[i]] >= s[arc[i + 1]] else i + 1 for i in maxima]
    if len(maxima) < 2:
        return 0.0
    lo = s[arc[maxima[0]:maxima[-1] + 1]].min()
    return float(s[k0] - lo)


# ----------------------------------------------------------------------------- linkage angles


def _wrap(a):
    return (a + jnp.pi) % (2 * jnp.pi) - jnp.pi


def needle_angles(mech, q, p):
    """(coupler, rocker, rod, arm) angles (…, N) of a needle six-bar solution q (…, N, n).

    The unknowns must be named `phi3` (coupler), `psi` (rocker), `phi5` (rod); the arm C₀→D is
    the rocker turned by −`beta` if the mechanism has that parameter (bell crank), else the rocker
    itself (the original design, D = C). `p` (…, P) SI parameters.
    """
    names = mech.unknown_names
    phi3, psi, phi5 = (q[..., names.index(n)] for n in ("phi3", "psi", "phi5"))
    if "beta" in mech.parameter_names:
        beta = p[..., mech.parameter_index("beta")]
        arm = psi - jnp.asarray(beta)[..., None]
    else:
        arm = psi
    return phi3, psi, phi5, arm


def angle_metrics(phi3, psi, phi5, arm, *, axis=0.5 * math.pi):
    """mu_min_deg, rod_angle_max_deg, toggle_clear_deg (jax; (N,) angles in rad)."""
    deg = 180.0 / math.pi
    mu = jnp.abs(_wrap(phi3 - psi))
    mu = jnp.minimum(mu, jnp.pi - mu)
    rod = jnp.abs(_wrap(phi5 - axis))
    rod = jnp.minimum(rod, jnp.pi - rod)
    tog = _wrap(phi5 - arm)
    crosses = (jnp.max(tog) > 0) & (jnp.min(tog) < 0)
    return {
        "mu_min_deg": jnp.min(mu) * deg,
        "rod_angle_max_deg": jnp.max(rod) * deg,
        "toggle_clear_deg": jnp.where(crosses, 0.0, jnp.min(jnp.abs(tog))) * deg,
        "toggle_signed_min_deg": jnp.min(jnp.abs(tog)) * deg * jnp.sign(tog[jnp.argmin(jnp.abs(tog))]),
    }


# ----------------------------------------------------------------------------- whole mechanism


def solve_stroke(mech, p=None, samples: int = 7200, *, phi0: float = 0.0, s_name: str = "s"):
    """Solve the needle over a revolution (closed-form dyads, batched if p is (B, P)).

    **Returns:** (phis (N,), q (…, N, n), s, ds, dds (…, N), converged (…,)).
    """
    p = mech.parameters if p is None else p
    phis = phi0 + 2 * np.pi * np.arange(samples) / samples
    sol = _solve(mech, phis, p)
    import jaxlink

    t = jaxlink.transfer(mech, sol.q, phis, p, order=2)
    j = mech.unknown_names.index(s_name)
    conv = jnp.all(sol.converged, axis=-1)
    return phis, sol.q, sol.q[..., j], t.mu[..., j], t.nu[..., j], conv


def _solve(mech, phis, p):
    import jaxlink

    return jaxlink.solve(mech, phis, p)


def needle_metrics(mech, p=None, *, samples: int = 7200, scale: StrokeScale = StrokeScale(),
                   crank_name: str = "l2"):
    """All exact metrics of a design (python numbers) — the report of a design.

    `p`: SI parameters (P,) (default: the file's) → one dict; or a batch (B, P) → a list of B
    dicts, solved and measured in one vectorized pass. See the module doc for the definitions;
    an unassemblable design gives `{"converged": False}`.
    """
    p = np.asarray(mech.parameters if p is None else p, dtype=float)
    batch = p.ndim == 2
    pb = p if batch else p[None]
    phis, q, s, ds, dds, conv = solve_stroke(mech, pb, samples)
    crank = pb[:, mech.parameter_index(crank_name)]
    vals = _jitted_metrics(mech, scale)(q, s, ds, dds, jnp.asarray(pb), jnp.asarray(crank))
    vals = {k: np.asarray(v) for k, v in vals.items()}
    s, ds, conv = np.asarray(s), np.asarray(ds), np.asarray(conv)
    out = []
    for b in range(len(pb)):
        if not conv[b]:
            out.append({"converged": False})
            continue
        row = {k: float(v[b]) for k, v in vals.items()}
        row["acc_sign_changes"] = int(row["acc_sign_changes"])
        h = float(np.max(s[b]) - np.min(s[b]))
        row["sag_mm"] = sag(s[b], ds[b]) * float(scale.factor(h))
        row["converged"] = True
        out.append(row)
    return out if batch else out[0]


@functools.lru_cache(maxsize=16)
def _jitted_metrics(mech, scale):
    def one(q, s, ds, dds, p, crank):
        out = stroke_metrics(s, ds, dds, crank, scale=scale)
        out.update(angle_metrics(*needle_angles(mech, q, p)))
        out["grashof_margin_rel"] = grashof_margin(mech, p)
        return out

    return jax.jit(jax.vmap(one))


def grashof_margin(mech, p):
    """(p + q) − (s + l) over the crank-rocker's four bars l1, l2, l3, l4r (or l4), divided by
    the crank, with the crank required to be the shortest (negative margin otherwise)."""
    idx = mech.parameter_index
    rocker = "l4r" if "l4r" in mech.parameter_names else "l4"
    if "l6" in mech.parameter_names:  # the original design: frame C0 at (l1, l6)
        frame = jnp.hypot(p[..., idx("l1")], p[..., idx("l6")])
    else:
        frame = p[..., idx("l1")]
    crank, coupler, rock = p[..., idx("l2")], p[..., idx("l3")], p[..., idx(rocker)]
    others = jnp.stack([frame, coupler, rock], axis=-1)
    longest = jnp.max(others, axis=-1)
    shortest_other = jnp.min(others, axis=-1)
    margin = jnp.sum(others, axis=-1) - longest - crank - longest  # (p + q) − (s + l)
    return jnp.minimum(margin, shortest_other - crank) / crank


# ----------------------------------------------------------------------------- the `dwell` objective

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
# normalization of each constraint violation in the penalty, and the margin the smooth search
# keeps inside each inequality so that the quadratic penalty's optimum is exactly feasible
_SCALE = {"stroke": 2.0, "mu": 10.0, "rod": 10.0, "toggle": 1.0, "amax": 0.1, "grashof": 0.1, "sign": 1.0}
_MARGIN = {"mu": 0.05, "rod": 0.05, "toggle": 0.01, "amax": 0.002, "grashof": 0.0}


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
    violation instead of |count − 2|). The smooth search keeps small margins (`_MARGIN`).
    """
    margin = _MARGIN if smooth_sign is not None else dict.fromkeys(_MARGIN, 0.0)
    v = {
        "stroke": _relu(jnp.abs(m["stroke_file"] - opts["stroke"]) - (0.0 if smooth_sign is not None else opts["stroke_tol"])),
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
    ok = jnp.all(jnp.stack([exact[k] <= 0 for k in exact if k != "sign"])) & (m["acc_sign_changes"] == opts["sign_changes"])
    return j, ok


def _softmax(x, tau):
    """τ log Σ exp(x/τ): a smooth maximum, max ≤ it ≤ max + τ log N (conservative)."""
    return tau * jax.nn.logsumexp(x / tau)


def _design_metrics(mech, q, s, ds, dds, p, crank, abs_tol_si, length_factor, *, soft=False):
    """The metrics the objective needs (jax, one design; file units for the stroke). With `soft`,
    the peak acceleration and the extreme angles are log-sum-exp soft maxima/minima (temperatures
    0.002 l2ω² and 0.02°), so the gradient search sees a smooth function."""
    deg = 180.0 / math.pi
    h = jnp.max(s) - jnp.min(s)
    eps = jnp.stack([abs_tol_si, 0.01 * h])
    w = jax.vmap(band_width, in_axes=(None, None, 0))(s, ds, eps) * deg
    m = {"stroke_file": h / length_factor, "dwell_abs_deg": w[0], "dwell_1pct_deg": w[1],
         "acc_sign_changes": sign_changes(dds), "amax_rel": jnp.max(jnp.abs(dds)) / crank,
         "grashof_margin_rel": grashof_margin(mech, p)}
    phi3, psi, phi5, arm = needle_angles(mech, q, p)
    m.update(angle_metrics(phi3, psi, phi5, arm))
    if soft:
        t = 0.02 / deg
        m["amax_rel"] = _softmax(jnp.abs(dds) / crank, 0.002)
        mu = jnp.abs(_wrap(phi3 - psi))
        m["mu_min_deg"] = -_softmax(-jnp.minimum(mu, jnp.pi - mu), t) * deg
        rod = jnp.abs(_wrap(phi5 - 0.5 * jnp.pi))
        m["rod_angle_max_deg"] = _softmax(jnp.minimum(rod, jnp.pi - rod), t) * deg
        tog = _wrap(phi5 - arm)
        # signed: a linkage that passes the stretched position has a negative clearance
        side = jnp.sign(jnp.mean(tog))
        m["toggle_clear_deg"] = -_softmax(-side * tog, t) * deg
    return m


class DwellEvaluator:
    """Batched evaluation of needle designs for the `dwell` objective, with the interface of
    `jaxlink.optimize.Evaluator` that the searches use (`evaluate`, `smooth_single`, `report`,
    counters), so `jaxlink.optimize._search.run(ev, "uniform" | "montecarlo" | "gradient")` works
    on it. Unlike the generic evaluator it sees the whole solved configuration (the transmission,
    rod and toggle angles need the joint angles, not only the needle's path).

    **Arguments:** `problem` (`jaxlink.optimize.problem_from` of a file whose `[optimize]` has
    `objective = "dwell"`), `chunk` (designs per compiled batch).
    """

    def __init__(self, problem, *, chunk: int = 256):
        from ._sharding import design_sharding

        self.problem = problem
        self.mech = mech = problem.mech
        self.opts = {k: problem.option(k, d) for k, d in DWELL_OPTIONS.items()}
        self.sharding = design_sharding(jax.devices()[:1])
        self.n_devices = 1
        self.n_circuits = 1
        self.chunk = int(chunk)
        self.evaluations = 0
        self.infeasible = 0
        self.lf = mech.units.length
        self.abs_tol_si = self.opts["abs_tol"] * self.lf
        self.crank_index = mech.parameter_index("l2")
        self.report_samples = int(problem.option("report_samples", 7200))
        self.phis = np.asarray(problem.phis)

    # -------------------------------------------------------------- designs
    def params(self, u):
        pr = self.problem
        x = jnp.asarray(pr.lower) + u * jnp.asarray(pr.upper - pr.lower)
        p = jnp.asarray(self.mech.parameters, dtype=u.dtype)
        return p.at[jnp.asarray(pr.index)].set(x * jnp.asarray(pr.factor))

    def _metrics_batch(self, P, phis):
        import jaxlink

        sol = jaxlink.solve(self.mech, phis, P)
        t = jaxlink.transfer(self.mech, sol.q, phis, P, order=2)
        j = self.mech.unknown_names.index("s")
        conv = jnp.all(sol.converged, axis=-1)
        return sol.q, sol.q[..., j], t.mu[..., j], t.nu[..., j], conv

    @functools.cached_property
    def _score_batch(self):
        mech, opts = self.mech, self.opts

        def one(q, s, ds, dds, p):
            m = _design_metrics(mech, q, s, ds, dds, p, p[self.crank_index], self.abs_tol_si, self.lf)
            j, ok = dwell_score(m, opts)
            return j, ok, m

        return jax.jit(jax.vmap(one))

    def exact(self, U, phis=None):
        """Exact penalized objective J (B,), constraints met (B,), assemblable (B,) and metrics."""
        phis = self.phis if phis is None else phis
        U = np.atleast_2d(np.asarray(U, float))
        P = np.asarray(jax.vmap(self.params)(jnp.asarray(U)))
        q, s, ds, dds, conv = self._metrics_batch(P, phis)
        j, ok, m = self._score_batch(q, s, ds, dds, jnp.asarray(P))
        conv = np.asarray(conv)
        j = np.where(conv & np.isfinite(np.asarray(j)), np.asarray(j), np.inf)
        return j, np.asarray(ok) & conv, conv, {k: np.asarray(v) for k, v in m.items()}

    def evaluate(self, U, circuits=None):
        """Searches' ranking value: J, plus 10 when a constraint is not met (so feasible designs
        always rank first while infeasible ones still guide the presample); +inf if unassemblable."""
        del circuits  # unused: the file's circuit
        U = np.asarray(U, float)
        vals, feas = [], []
        for a in range(0, len(U), self.chunk):
            part = U[a:a + self.chunk]
            n = len(part)
            pad = np.concatenate([part, np.repeat(part[:1], self.chunk - n, 0)]) if n < self.chunk else part
            j, ok, conv, _ = self.exact(pad)
            vals.append(np.where(ok, j, j + 10.0)[:n])
            feas.append(conv[:n])
            self.evaluations += n
        out = {"value": np.concatenate(vals), "feasible": np.concatenate(feas),
               "circuit": np.zeros(len(U), int)}
        self.infeasible += int((~out["feasible"]).sum())
        return out

    def smooth_single(self, u, c=0):
        """Smooth objective of one design (traced; +inf if unassemblable): exact dwell widths
        (differentiable crossings), hard max/min over the samples, the sign-change surrogate."""
        del c  # unused
        from ._assemble import solve_path
        from ._kinematics import transfer_one

        p = self.params(u)
        phis = jnp.asarray(self.phis, u.dtype)
        sol = solve_path(self.mech, p, phis)
        t = jax.vmap(lambda q, ph: transfer_one(self.mech, q, ph, p, 2))(sol.q, phis)
        j = self.mech.unknown_names.index("s")
        s, ds, dds = sol.q[:, j], t.mu[:, j], t.nu[:, j]
        m = _design_metrics(self.mech, sol.q, s, ds, dds, p, p[self.crank_index], self.abs_tol_si, self.lf,
                            soft=True)
        val, _ = dwell_score(m, self.opts, smooth_sign=_sign_surrogate(s, dds))
        ok = jnp.all(sol.converged) & jnp.isfinite(val)
        return jnp.where(ok, val, jnp.inf)

    # -------------------------------------------------------------- reports
    def parameters_si(self, u):
        return np.asarray(self.params(jnp.asarray(u, float)))

    def report(self, u, c: int = 0) -> dict:
        """Exact objective and every metric of one design at `report_samples` positions."""
        pr = self.problem
        x = pr.to_file_units(np.asarray(u))
        phis = pr.phis[0] + 2 * np.pi * np.arange(self.report_samples) / self.report_samples
        j, ok, conv, _ = self.exact(np.asarray(u)[None], phis)
        out = {"parameters": {n: float(v) for n, v in zip(pr.names, x)}, "feasible": bool(conv[0]),
               "constraints_met": bool(ok[0]), "circuit": int(c)}
        if not conv[0]:
            return {**out, "objective": None, "metrics": {}}
        scale = StrokeScale(length_to_mm=1e3)
        met = needle_metrics(self.mech, self.parameters_si(u), samples=self.report_samples, scale=scale)
        met.pop("converged", None)
        out["objective"] = float(j[0])
        out["metrics"] = met
        return out


def dwell_objective(problem):
    """Factory of the registry objective `dwell` (`jaxlink.optimize` `OBJECTIVES`).

    The generic evaluator hands an objective only the path of the `[optimize]` point (here the
    needle B, whose y is the slider position s, file units) with exact φ-derivatives. From it this
    objective computes the stroke, the dwell widths, the sign changes and amax = max|s''|/l2
    (l2 = the file's crank, which must not be a variable), and J of `dwell_score` with those
    constraints. The transmission, rod and toggle angles need the joint angles: they are
    included when the path also carries the solved unknowns `q` (N, n) and the SI parameters `p`
    (fields of `PathData`); otherwise use `DwellEvaluator`, which sees the whole configuration.
    """
    from .optimize._objectives import Objective

    mech = problem.mech
    if "l2" in problem.names:
        raise problem.error("the dwell objective normalizes the acceleration by the crank l2: keep l2 fixed",
                            "variables")
    opts = {k: problem.option(k, d) for k, d in DWELL_OPTIONS.items()}
    lf = mech.units.length
    crank = float(mech.parameters[mech.parameter_index("l2")]) / lf  # file units, like the path

    def metrics_of(path):
        s, ds, dds = path.xy[:, 1], path.dxy[:, 1], path.ddxy[:, 1]
        h = jnp.max(s) - jnp.min(s)
        eps = jnp.stack([jnp.asarray(opts["abs_tol"], s.dtype), 0.01 * h])
        w = jax.vmap(band_width, in_axes=(None, None, 0))(s, ds, eps) * (180.0 / math.pi)
        m = {"stroke_file": h, "dwell_abs_deg": w[0], "dwell_1pct_deg": w[1],
             "acc_sign_changes": sign_changes(dds), "amax_rel": jnp.max(jnp.abs(dds)) / crank,
             # unknown without the configuration: neutral values that meet the constraints
             "mu_min_deg": jnp.asarray(90.0), "rod_angle_max_deg": jnp.asarray(0.0),
             "toggle_clear_deg": jnp.asarray(90.0), "grashof_margin_rel": jnp.asarray(1.0)}
        fields = getattr(type(path), "_fields", ())
        if "q" in fields and "p" in fields and path.q is not None and path.p is not None:
            m.update(angle_metrics(*needle_angles(mech, path.q, path.p)))
            m["grashof_margin_rel"] = grashof_margin(mech, path.p)
        return m, s, dds

    def value(path):
        m, _, _ = metrics_of(path)
        j, ok = dwell_score(m, opts)
        return jnp.where(ok, j, j + 10.0)

    def smooth(path):
        m, s, dds = metrics_of(path)
        return dwell_score(m, opts, smooth_sign=_sign_surrogate(s, dds))[0]

    def metrics(path):
        m, s, _ = metrics_of(path)
        out = {"stroke_mm": m["stroke_file"] * lf * 1e3, "dwell_005mm_deg": m["dwell_abs_deg"],
               "dwell_1pct_deg": m["dwell_1pct_deg"], "acc_sign_changes": m["acc_sign_changes"],
               "amax_rel": m["amax_rel"]}
        fields = getattr(type(path), "_fields", ())
        if "q" in fields and getattr(path, "q", None) is not None:
            out.update({k: m[k] for k in ("mu_min_deg", "rod_angle_max_deg", "toggle_clear_deg")})
        out["constraints_met"] = dwell_score(m, opts)[1].astype(float)
        return out

    return Objective("dwell", 2, value, smooth, metrics, report_order=2)


def _register():
    from .optimize._objectives import OBJECTIVES

    if "dwell" not in OBJECTIVES:
        OBJECTIVES.register("dwell", keys=tuple(DWELL_OPTIONS))(dwell_objective)


_register()


# ----------------------------------------------------------------------------- multistart search


def _u_of_v(v):
    return 0.5 - 0.5 * jnp.cos(jnp.pi * v)


def _v_of_u(u):
    return np.arccos(np.clip(1.0 - 2.0 * np.asarray(u), -1.0, 1.0)) / np.pi


def _lbfgs_direction(g, S, Y):
    """Two-loop recursion: −H g from the pairs (s_i, y_i) (oldest first)."""
    q = g.copy()
    alphas = []
    for s, y in reversed(list(zip(S, Y))):
        rho = 1.0 / np.dot(y, s)
        a = rho * np.dot(s, q)
        alphas.append((rho, a, s, y))
        q -= a * y
    if S:
        q *= np.dot(S[-1], Y[-1]) / np.dot(Y[-1], Y[-1])
    for rho, a, s, y in reversed(alphas):
        q += (a - rho * np.dot(y, q)) * s
    return -q


def multistart(ev: DwellEvaluator, *, seed: int = 0, presample: int = 4096, starts: int = 16, iterations: int = 150,
               memory: int = 10, linesearch_steps: int = 8, budget: int | None = None, callback=None) -> dict:
    """Gradient search for the dwell: a Monte Carlo presample ranked by the penalized objective J
    (without the +10 of a missed constraint: a design with a long dwell but the wrong stroke is a
    good start), then L-BFGS (memory 10, Armijo backtracking; bounds by u = (1 − cos πv)/2) from
    the `starts` best in one batch, on the smooth objective with exact implicit gradients. A start
    whose line search fails restarts its memory from the gradient direction instead of stopping.
    The exact objective of every accepted iterate decides the result.

    Counts evaluations as the design search does: one design solved = 1, a value and gradient = 2.
    `callback(evaluations, wall_s, metrics_of_best)` is called after every iteration.
    **Returns:** dict with `best_u`, `best` (report), `evaluations`, `wall_s`, `history`.
    """
    import time

    t0 = time.perf_counter()
    V = ev.problem.n_variables
    rng = np.random.default_rng([seed, 4])
    U = rng.random((presample, V))
    js, oks = [], []
    for a in range(0, presample, ev.chunk):
        part = U[a:a + ev.chunk]
        n = len(part)
        pad = np.concatenate([part, np.repeat(part[:1], ev.chunk - n, 0)]) if n < ev.chunk else part
        j, ok, conv, _ = ev.exact(pad)
        js.append(j[:n])
        oks.append(ok[:n])
    evaluations = presample
    j, ok = np.concatenate(js), np.concatenate(oks)
    best = {"value": np.inf, "u": None}

    def consider(Uc, jc, okc):
        val = np.where(okc, jc, jc + 10.0)
        i = int(np.argmin(val))
        if val[i] < best["value"]:
            best["value"], best["u"] = float(val[i]), np.asarray(Uc[i]).copy()

    consider(U, j, ok)
    order = np.argsort(j, kind="stable")[:starts]
    v = _v_of_u(U[order])
    vg = ev.__dict__.get("_vg_batch")
    if vg is None:
        vg = jax.jit(jax.vmap(jax.value_and_grad(lambda vv: ev.smooth_single(_u_of_v(vv)))))
        ev.__dict__["_vg_batch"] = vg

    def value_grad(vv):
        f, g = vg(jnp.asarray(vv))
        f, g = np.asarray(f), np.asarray(g)
        good = np.isfinite(f) & np.all(np.isfinite(g), axis=1)
        return np.where(good, f, np.inf), np.where(good[:, None], g, 0.0)

    f, g = value_grad(v)
    evaluations += 2 * starts
    mem = [([], []) for _ in range(starts)]
    history = []
    for it in range(iterations):
        if budget is not None and evaluations + 2 * starts * linesearch_steps + starts > budget:
            break
        d = np.stack([_lbfgs_direction(g[i], *mem[i]) for i in range(starts)])
        slope = np.sum(d * g, axis=1)
        bad = ~(slope < 0)
        d[bad] = -g[bad]
        slope[bad] = -np.sum(g[bad] ** 2, axis=1)
        fresh = np.array([len(m[0]) == 0 for m in mem]) | bad
        dn = np.max(np.abs(d), axis=1)
        t = np.where(fresh, np.minimum(1.0, 0.02 / np.maximum(dn, 1e-300)), 1.0)
        searching = np.isfinite(f)
        nv, nf, ng = v.copy(), f.copy(), g.copy()
        for _ in range(linesearch_steps):
            if not searching.any():
                break
            trial = np.where(searching[:, None], v + t[:, None] * d, v)
            tf, tg = value_grad(trial)
            evaluations += 2 * starts
            acc = searching & np.isfinite(tf) & (tf <= f + 1e-4 * t * slope)
            nv[acc], nf[acc], ng[acc] = trial[acc], tf[acc], tg[acc]
            searching &= ~acc
            t = np.where(searching, 0.5 * t, t)
        for i in range(starts):
            if np.any(nv[i] != v[i]):
                s_, y_ = nv[i] - v[i], ng[i] - g[i]
                if np.dot(s_, y_) > 1e-12 * np.linalg.norm(s_) * np.linalg.norm(y_):
                    mem[i][0].append(s_)
                    mem[i][1].append(y_)
                    if len(mem[i][0]) > memory:
                        mem[i][0].pop(0)
                        mem[i][1].pop(0)
            else:  # the line search failed: forget the curvature pairs
                mem[i] = ([], [])
        v, f, g = nv, nf, ng
        Uc = np.asarray(_u_of_v(jnp.asarray(v)))
        jc, okc, _, mc = ev.exact(Uc)
        evaluations += starts
        consider(Uc, jc, okc)
        k = int(np.argmin(np.where(okc, jc, jc + 10.0)))
        row = {"iteration": it, "evaluations": evaluations, "wall_s": time.perf_counter() - t0,
               "best_value": best["value"], "dwell_abs_deg": float(mc["dwell_abs_deg"][k]),
               "dwell_1pct_deg": float(mc["dwell_1pct_deg"][k]), "constraints_met": bool(okc[k])}
        history.append(row)
        if callback is not None:
            callback(row)
    ev.evaluations += evaluations
    wall = time.perf_counter() - t0
    return {"best_u": best["u"], "best_value": best["value"], "evaluations": evaluations, "wall_s": wall,
            "history": history, "best": ev.report(best["u"]) if best["u"] is not None else None}
