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
