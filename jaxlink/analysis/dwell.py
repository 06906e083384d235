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


def _hermite(t, s_a, s_b, d_a, d_b):
    t2, t3 = t * t, t * t * t
    return (2 * t3 - 3 * t2 + 1) * s_a + (t3 - 2 * t2 + t) * d_a + (-2 * t3 + 3 * t2) * s_b + (t3 - t2) * d_b


def _hermite_slope(t, s_a, s_b, d_a, d_b):
    t2 = t * t
    return (6 * t2 - 6 * t) * s_a + (3 * t2 - 4 * t + 1) * d_a + (-6 * t2 + 6 * t) * s_b + (3 * t2 - 2 * t) * d_b


def _newton_step(t, s_a, s_b, d_a, d_b, level):
    g = _hermite_slope(t, s_a, s_b, d_a, d_b)
    ok = jnp.abs(g) > 0
    step = (_hermite(t, s_a, s_b, d_a, d_b) - level) / jnp.where(ok, g, 1.0)
    return jnp.clip(t - jnp.where(ok, step, 0.0), 0.0, 1.0)


def _hermite_root(s_a, s_b, d_a, d_b, level):
    """t ∈ [0, 1] with H(t) = level on the cubic Hermite H(0) = s_a, H(1) = s_b, H'(0) = d_a,
    H'(1) = d_b (derivatives per unit t), assuming s_a ≥ level > s_b (else the clipped chord).

    Newton from the chord's root (6 iterations, no derivatives traced), then one more Newton step
    with derivatives: at the root it carries the exact derivative of t (implicit function
    theorem), so reverse mode differentiates one step instead of the iterations."""
    args = (s_a, s_b, d_a, d_b, level)
    c = [jax.lax.stop_gradient(a) for a in args]
    den = c[0] - c[1]
    t = jnp.clip((c[0] - c[4]) / jnp.where(den > 0, den, 1.0), 0.0, 1.0)
    t = jax.lax.fori_loop(0, 6, lambda _, tt: _newton_step(tt, *c), t)
    return _newton_step(jax.lax.stop_gradient(t), *args)


def band_width(s, ds, eps):
    """Width (radians) of the contiguous arc around argmax s on which s ≥ max s − eps.

    `s`, `ds`: (N,) samples at φ_k = φ₀ + 2πk/N and dS/dφ there; `eps` ≥ 0 (same units as s).
    """
    n = s.shape[0]
    dphi = 2 * jnp.pi / n
    k0 = jnp.argmax(s)
    level = s[k0] - eps
    k = jnp.arange(n)
    out = s < level  # the samples outside the band
    # consecutive samples in the band from k0 (k0 included), forward and backward around the cycle
    m_f = jnp.min(jnp.where(out, (k - k0) % n, n))
    m_b = jnp.min(jnp.where(out, (k0 - k) % n, n))

    def side(direction, m):
        a = (k0 + direction * (m - 1)) % n
        b = (k0 + direction * m) % n
        t = _hermite_root(s[a], s[b], direction * ds[a] * dphi, direction * ds[b] * dphi, level)
        return (m - 1 + t) * dphi

    width = side(1, m_f) + side(-1, m_b)
    return jnp.where(m_f >= n, 2 * jnp.pi, jnp.minimum(width, 2 * jnp.pi))


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
    `vmax_rel`, `stroke_rel` = h/l₂, `sag_mm`).
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
    out["sag_mm"] = sag(s, ds) * f
    return out


def sag(s, ds):
    """Sag (units of s; jax, traceable): see the module doc. The arc around the TDC above the
    75 % level (cyclic), its local maxima (s' from + to −), and s_max minus the lowest s between
    the outermost two; 0 for one hump."""
    n = s.shape[0]
    half = n // 2
    lo, hi = jnp.min(s), jnp.max(s)
    level = lo + 0.75 * (hi - lo)
    k0 = jnp.argmax(s)
    idx = (k0 + jnp.arange(-half, n - half)) % n  # cyclic order with the TDC at position `half`
    ss, dd = s[idx], ds[idx]
    top = ss >= level
    fwd = jnp.cumprod(top[half:].astype(jnp.int32))
    bwd = jnp.cumprod(top[:half + 1][::-1].astype(jnp.int32))[::-1]
    arc = jnp.concatenate([bwd[:-1], fwd]).astype(bool)  # contiguous with the TDC
    pair = arc[:-1] & arc[1:] & (dd[:-1] > 0) & (dd[1:] <= 0)
    j = jnp.arange(n - 1)
    m = jnp.where(ss[:-1] >= ss[1:], j, j + 1)
    first = jnp.min(jnp.where(pair, m, n))
    last = jnp.max(jnp.where(pair, m, -1))
    pos = jnp.arange(n)
    low = jnp.min(jnp.where((pos >= first) & (pos <= last), ss, jnp.inf))
    return jnp.where(jnp.sum(pair) >= 2, ss[half] - low, 0.0)


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

    t = jaxlink.transfer(mech, phis, sol.q, p, order=2)
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


def spectral_derivatives(s):
    """s'(φ), s''(φ) of a periodic signal sampled at N equally spaced φ over a revolution, by FFT
    (exact for a trigonometric polynomial of degree < N/2; for a linkage's smooth stroke the error
    is that of the truncated Fourier series: ~1e-10 relative at N = 720 for the needle designs,
    `tests/test_dwell.py`). The spec's reference model computes its derivatives this way."""
    n = s.shape[0]
    k = jnp.fft.rfftfreq(n, 1.0 / n)
    if n % 2 == 0:
        k1 = k.at[-1].set(0.0)  # the Nyquist term of an odd derivative is not defined: drop it
    else:
        k1 = k
    c = jnp.fft.rfft(s)
    return jnp.fft.irfft(1j * k1 * c, n=n), jnp.fft.irfft(-(k * k) * c, n=n)


def peak(x, *, refined: bool = True):
    """Maximum of a periodic sampled signal x (N,): the largest sample, or (`refined`) the vertex
    of the parabola through it and its two neighbours (error O(Δφ³) for a smooth peak; continuous
    and almost everywhere differentiable in the samples)."""
    if not refined:
        return jnp.max(x)
    n = x.shape[0]
    k = jnp.argmax(x)
    a, b, c = x[(k - 1) % n], x[k], x[(k + 1) % n]
    den = 2.0 * b - a - c
    ok = den > 0
    return b + jnp.where(ok, (c - a) ** 2 / (8.0 * jnp.where(ok, den, 1.0)), 0.0)


def design_metrics(mech, q, s, ds, dds, p, crank, abs_tol, *, refined: bool):
    """The metrics the objective needs (jax, one design; s, crank and abs_tol in the same length
    unit). `refined`: the peak acceleration and the extreme angles are parabola-refined extrema
    (`peak`) instead of the extreme samples — what the search uses, so that a 0.5° search grid
    sees the extremes that the 0.05° report grid measures, with a smooth dependence on the
    design. `toggle_signed_deg` is the clearance with a sign (negative when the linkage passes
    its stretched position); `toggle_clear_deg` is the spec's (0 then)."""
    deg = 180.0 / math.pi
    h = jnp.max(s) - jnp.min(s)
    eps = jnp.stack([jnp.asarray(abs_tol, s.dtype), 0.01 * h])
    w = jax.vmap(band_width, in_axes=(None, None, 0))(s, ds, eps) * deg
    phi3, psi, phi5, arm = needle_angles(mech, q, p)
    mu = jnp.abs(_wrap(phi3 - psi))
    mu = jnp.minimum(mu, jnp.pi - mu)
    rod = jnp.abs(_wrap(phi5 - 0.5 * jnp.pi))
    rod = jnp.minimum(rod, jnp.pi - rod)
    tog = _wrap(phi5 - arm)
    crosses = (jnp.max(tog) > 0) & (jnp.min(tog) < 0)
    side = jnp.where(jnp.mean(tog) >= 0, 1.0, -1.0)
    signed = -peak(-side * tog, refined=refined) * deg
    return {
        "stroke_file": h, "dwell_abs_deg": w[0], "dwell_1pct_deg": w[1],
        "acc_sign_changes": sign_changes(dds),
        "amax_rel": peak(jnp.abs(dds), refined=refined) / crank,
        "mu_min_deg": -peak(-mu, refined=refined) * deg,
        "rod_angle_max_deg": peak(rod, refined=refined) * deg,
        "toggle_signed_deg": signed,
        "toggle_clear_deg": jnp.where(crosses, 0.0, signed),
        "grashof_margin_rel": grashof_margin(mech, p),
    }


def dwell_objective(problem):
    """Factory of the registry objective `dwell` (`jaxlink.optimize` `OBJECTIVES`).

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

    The crank is the parameter `l2`; amax is max|s''|/l2.
    """
    from ..optimize.objectives import Objective

    mech = problem.mech
    for name in ("l2", "beta") if "beta" in mech.parameter_names else ("l2",):
        if name not in mech.parameter_names:
            raise problem.error(f"the dwell objective needs the parameter '{name}' (the crank l2; "
                                "the bell crank's arm angle beta)", "objective")
    for name in ("phi3", "psi", "phi5"):
        if name not in mech.unknown_names:
            raise problem.error(f"the dwell objective needs the unknown '{name}' (coupler phi3, rocker psi, "
                                "rod phi5: spec/needle-six-bar.md)", "objective")
    opts = {k: problem.option(k, d) for k, d in DWELL_OPTIONS.items()}
    for k, v in opts.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise problem.error(f"'{k}' must be a finite number, got {v!r}", k)
    lf = mech.units.length
    crank_index = mech.parameter_index("l2")

    def measured(path, refined):
        if path.q is None or path.p is None:
            raise ValueError("the dwell objective needs the solved configuration q and the parameters p (PathData)")
        s = path.xy[:, 1]
        if path.dxy is None or path.ddxy is None:  # the search: spectral derivatives of the samples
            ds, dds = spectral_derivatives(s)
        else:  # the report: the exact transfer functions
            ds, dds = path.dxy[:, 1], path.ddxy[:, 1]
        crank = path.p[crank_index] / lf
        return design_metrics(mech, path.q, s, ds, dds, path.p, crank, opts["abs_tol"], refined=refined), s, ds, dds

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


def _register():
    from ..optimize.objectives import OBJECTIVES

    if "dwell" not in OBJECTIVES:
        OBJECTIVES.register("dwell", keys=tuple(DWELL_OPTIONS))(dwell_objective)


_register()
