"""Dwell metrics of a slider stroke driven by a crank-rocker four-bar and a rod: how long the
slider stands (almost) still at its top dead centre, and the quality figures of the linkage.

**Roles.** The metrics read the mechanism through the roles that its file's `[optimize]`
section names (`dwell_roles`, `DwellRoles`; the needle six-bars `jaxlink/scenes/needle-*.toml`
set them):

- `slider`: the unknown whose value is the slider's position s along its guide (TDC = max s);
- `guide_angle`: direction of the guide (file angle unit);
- `coupler`, `rocker`, `rod`: the unknown angles of the four-bar's coupler and rocker and of the
  rod D→B that drives the slider;
- `arm_offset` (optional): a parameter β; the arm C₀→D that carries the rod is the rocker turned
  by −β (a bell crank). Without it the arm is the rocker itself (D = C);
- `crank`: the parameter that is the crank length l₂ (peaks per crank length);
- `four_bar`: the loop of the crank-rocker four-bar; its four terms are the bars, the crank being
  the term that the input turns (Grashof margin).

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
- **rod_angle_max_deg**: max angle between the rod D→B and the slider's guide (pressure angle).
- **toggle_clear_deg**: min angle between the arm C₀→D and the rod D→B; 0 when the signed angle
  changes sign over the cycle (the linkage passes through its stretched position).
- **grashof_margin_rel**: min((p + q) − (s + l), shortest other bar − crank) / crank of the
  four-bar (> 0: a crank-rocker whose crank is the shortest bar).

Lengths: `length_to_mm` converts the solved s (SI) to mm. For a dimensionless design (crank = 1,
`needle-arachne-unit`) pass `stroke_mm = 20.0` instead: s is scaled so that h = 20 mm, i.e. the
absolute 0.05 mm tolerance is 0.25 % of the stroke and the sag is in mm at a 20 mm stroke.
amax_rel/vmax_rel are per crank length and never rescaled. docs/methods/dwell.md.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import MechanismError
from ..files import expr as _expr
from ..files.expr import LENGTH
from ..solvers.assemble import solve
from .transfer import transfer

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
        return ((m - 1).astype(t.dtype) + t) * dphi

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


# ----------------------------------------------------------------------------- roles


#: the `[optimize]` keys of the roles (see the module doc); all but `arm_offset` are required
ROLE_KEYS = ("slider", "guide_angle", "coupler", "rocker", "rod", "arm_offset", "crank", "four_bar")


class DwellRoles(NamedTuple):
    """Which unknowns, parameters and loop of a mechanism play the roles of the dwell metrics
    (names, see the module doc; `guide` in rad). Read from a file by `dwell_roles`."""

    slider: str
    guide: float
    coupler: str
    rocker: str
    rod: str
    arm_offset: str | None
    crank: str
    four_bar: str


_ROLE_HELP = {
    "slider": ("unknown", "length", "the slider's position along its guide"),
    "coupler": ("unknown", "angle", "the coupler angle of the four-bar"),
    "rocker": ("unknown", "angle", "the rocker angle of the four-bar"),
    "rod": ("unknown", "angle", "the angle of the rod that drives the slider"),
    "arm_offset": ("parameter", "angle", "the angle by which the arm carrying the rod is turned back from the rocker"),
    "crank": ("parameter", "length", "the crank length"),
}


def dwell_roles(mech, table=None) -> DwellRoles:
    """The roles named by `table` (default: the file's `[optimize]` section), checked against
    the mechanism. Raises `MechanismError` naming the file and the key (`optimize.<key>`) when a
    key is missing or names no unknown, parameter or loop of the right kind."""
    table = (mech.tables.get("optimize") or {}) if table is None else table

    def err(msg, key):
        return MechanismError(msg, file=mech.file, key=f"optimize.{key}")

    def name(key, *, optional=False):
        what, kind, role = _ROLE_HELP[key]
        v = table.get(key)
        if v is None and optional:
            return None
        if v is None:
            raise err(f"the dwell metrics need '{key}': the name of the {what} that is {role} "
                      f"(jaxlink/analysis/dwell.py)", key)
        names = mech.unknown_names if what == "unknown" else mech.parameter_names
        if not isinstance(v, str) or v not in names:
            hint = _expr.suggest(v, names) if isinstance(v, str) else ""
            raise err(f"{v!r} is not {_a(what)} of the mechanism{hint}; {what}s: {', '.join(names)}", key)
        if mech.kinds[v] != kind:
            raise err(f"'{v}' is {_a(mech.kinds[v])}; '{key}' must name {_a(what)} that is {_a(kind)} ({role})",
                      key)
        return v

    roles = {k: name(k, optional=k == "arm_offset") for k in _ROLE_HELP}
    guide = table.get("guide_angle")
    if isinstance(guide, bool) or not isinstance(guide, (int, float)) or not math.isfinite(guide):
        raise err(f"'guide_angle' must be the direction of the slider's guide (a number, file angle unit), "
                  f"got {guide!r}", "guide_angle")
    loop = table.get("four_bar")
    loops = dict(mech.loops)
    if not isinstance(loop, str) or loop not in loops:
        hint = _expr.suggest(loop, loops) if isinstance(loop, str) else ""
        raise err(f"'four_bar' must name the loop of the crank-rocker four-bar{hint}; loops: {', '.join(loops)}",
                  "four_bar")
    _four_bar_terms(mech, loops[loop], lambda msg: err(f"loop '{loop}': {msg}", "four_bar"))
    return DwellRoles(guide=float(guide) * mech.units.angle, four_bar=loop, **roles)


def _a(noun: str) -> str:
    return ("an " if noun[0] in "aeiou" else "a ") + noun


def _four_bar_terms(mech, terms, err):
    """(crank term, the other three terms) of a four-bar loop: the crank is the one term whose
    angle contains the input; the others in the order (the term before the crank, the term after
    it, the opposite term) — around the loop crank, coupler, rocker, frame: (frame, coupler,
    rocker). Every bar length must depend on the parameters only."""
    if len(terms) != 4:
        raise err(f"a four-bar loop has 4 terms, this one {len(terms)}")
    fixed = set(mech.parameter_names)
    for t in terms:
        lengths = (t.length,) if t.polar else (t.x, t.y)
        if any(n.name not in fixed for node in lengths for n in _expr.names_in(node)):
            raise err(f"the length of '{t.text}' must depend on parameters only")
    cranks = [t for t in terms if t.polar and any(n.name == mech.input_name for n in _expr.names_in(t.angle))]
    if len(cranks) != 1:
        raise err(f"exactly one term must be turned by the input '{mech.input_name}' (the crank), "
                  f"found {len(cranks)}")
    i = next(k for k, t in enumerate(terms) if t is cranks[0])
    return cranks[0], [terms[(i - 1) % 4], terms[(i + 1) % 4], terms[(i + 2) % 4]]


def _bar_length(mech, term, env):
    """Length (SI) of a bar of the four-bar: the value of LENGTH of a `LENGTH @ ANGLE` term (a
    bar's length is positive), the norm of an `(X, Y)` term."""
    if term.polar:
        return _expr.evaluate(term.length, env, mech.kinds, mech.units, LENGTH)
    x = _expr.evaluate(term.x, env, mech.kinds, mech.units, LENGTH)
    y = _expr.evaluate(term.y, env, mech.kinds, mech.units, LENGTH)
    return jnp.hypot(x, y)


# ----------------------------------------------------------------------------- linkage angles


def _wrap(a):
    return (a + jnp.pi) % (2 * jnp.pi) - jnp.pi


def linkage_angles(mech, roles: DwellRoles, q, p):
    """(coupler, rocker, rod, arm) angles (…, N) of a solution q (…, N, n) with parameters
    p (…, P) (SI). The arm is the rocker turned by −`arm_offset`, or the rocker itself."""
    names = mech.unknown_names
    coupler, rocker, rod = (q[..., names.index(n)] for n in (roles.coupler, roles.rocker, roles.rod))
    if roles.arm_offset is not None:
        offset = p[..., mech.parameter_index(roles.arm_offset)]
        arm = rocker - jnp.asarray(offset)[..., None]
    else:
        arm = rocker
    return coupler, rocker, rod, arm


def angle_metrics(coupler, rocker, rod, arm, *, axis=0.5 * math.pi):
    """mu_min_deg, rod_angle_max_deg, toggle_clear_deg (jax; (N,) angles in rad; `axis`: the
    direction of the slider's guide)."""
    deg = 180.0 / math.pi
    mu = jnp.abs(_wrap(coupler - rocker))
    mu = jnp.minimum(mu, jnp.pi - mu)
    rod_angle = jnp.abs(_wrap(rod - axis))
    rod_angle = jnp.minimum(rod_angle, jnp.pi - rod_angle)
    tog = _wrap(rod - arm)
    crosses = (jnp.max(tog) > 0) & (jnp.min(tog) < 0)
    return {
        "mu_min_deg": jnp.min(mu) * deg,
        "rod_angle_max_deg": jnp.max(rod_angle) * deg,
        "toggle_clear_deg": jnp.where(crosses, 0.0, jnp.min(jnp.abs(tog))) * deg,
        "toggle_signed_min_deg": jnp.min(jnp.abs(tog)) * deg * jnp.sign(tog[jnp.argmin(jnp.abs(tog))]),
    }


def grashof_margin(mech, roles: DwellRoles, p):
    """(p + q) − (s + l) over the bars of the four-bar loop `roles.four_bar` (their term lengths;
    the crank is the term that the input turns), divided by the crank, with the crank required
    to be the shortest (negative margin otherwise). `p` (…, P) SI."""
    terms = dict(mech.loops)[roles.four_bar]
    crank_term, other_terms = _four_bar_terms(mech, terms, MechanismError)
    env = {n: p[..., i] for i, n in enumerate(mech.parameter_names)}
    crank = _bar_length(mech, crank_term, env)
    others = jnp.stack([_bar_length(mech, t, env) for t in other_terms], axis=-1)
    longest = jnp.max(others, axis=-1)
    shortest_other = jnp.min(others, axis=-1)
    margin = jnp.sum(others, axis=-1) - longest - crank - longest  # (p + q) − (s + l)
    return jnp.minimum(margin, shortest_other - crank) / crank


# ----------------------------------------------------------------------------- whole mechanism


def solve_stroke(mech, p=None, samples: int = 7200, *, phi0: float = 0.0, roles: DwellRoles | None = None):
    """Solve the mechanism over a revolution (batched if p is (B, P)); the stroke is the unknown
    `roles.slider` (default roles: `dwell_roles(mech)`).

    **Returns:** (phis (N,), q (…, N, n), s, ds, dds (…, N), converged (…,)).
    """
    roles = dwell_roles(mech) if roles is None else roles
    p = mech.parameters if p is None else p
    # the inputs in the dtype of the solve (float32 parameters: float32 inputs)
    phis = (phi0 + 2 * np.pi * np.arange(samples) / samples).astype(jnp.result_type(p))
    sol = solve(mech, phis, p, points=False)
    t = transfer(mech, phis, sol.q, p, order=2)
    j = mech.unknown_names.index(roles.slider)
    conv = jnp.all(sol.converged, axis=-1)
    assert t.mu is not None and t.nu is not None
    return phis, sol.q, sol.q[..., j], t.mu[..., j], t.nu[..., j], conv


def needle_metrics(mech, p=None, *, samples: int = 7200, scale: StrokeScale = StrokeScale(),
                   roles: DwellRoles | None = None):
    """All exact metrics of a design (python numbers) — the report of a design.

    `p`: SI parameters (P,) (default: the file's) → one dict; or a batch (B, P) → a list of B
    dicts, solved and measured in one vectorized pass. `roles`: default `dwell_roles(mech)` (the
    file's `[optimize]` keys). See the module doc for the definitions; an unassemblable design
    gives `{"converged": False}`.
    """
    roles = dwell_roles(mech) if roles is None else roles
    p = np.asarray(mech.parameters if p is None else p)
    p = p if np.issubdtype(p.dtype, np.floating) else p.astype(float)  # float32 stays float32
    batch = p.ndim == 2
    pb = p if batch else p[None]
    phis, q, s, ds, dds, conv = solve_stroke(mech, pb, samples, roles=roles)
    crank = pb[:, mech.parameter_index(roles.crank)]
    vals = _metrics(mech, q, s, ds, dds, jnp.asarray(pb), jnp.asarray(crank), scale=scale, roles=roles)
    vals = {k: np.asarray(v) for k, v in vals.items()}
    s, ds, conv = np.asarray(s), np.asarray(ds), np.asarray(conv)
    out: list[dict] = []
    for b in range(len(pb)):
        if not conv[b]:
            out.append({"converged": False})
            continue
        row = {k: float(v[b]) for k, v in vals.items()}
        row["acc_sign_changes"] = int(row["acc_sign_changes"])
        row["converged"] = True
        out.append(row)
    return out if batch else out[0]


dwell_metrics = needle_metrics  # the public name (`jaxlink.dwell_metrics`)


@functools.partial(jax.jit, static_argnames=("scale", "roles"))
def _metrics(mech, q, s, ds, dds, p, crank, *, scale, roles):
    def one(q, s, ds, dds, p, crank):
        out = stroke_metrics(s, ds, dds, crank, scale=scale)
        out.update(angle_metrics(*linkage_angles(mech, roles, q, p), axis=roles.guide))
        out["grashof_margin_rel"] = grashof_margin(mech, roles, p)
        return out

    return jax.vmap(one)(q, s, ds, dds, p, crank)


def spectral_derivatives(s):
    """s'(φ), s''(φ) of a periodic signal sampled at N equally spaced φ over a revolution, by FFT
    (exact for a trigonometric polynomial of degree < N/2; for a linkage's smooth stroke the error
    is that of the truncated Fourier series: ~1e-10 relative at N = 720 for the needle designs,
    `tests/test_dwell.py`)."""
    n = s.shape[0]
    k = jnp.fft.rfftfreq(n, 1.0 / n, dtype=s.dtype)  # in the dtype of s (float32 stays float32)
    if n % 2 == 0:
        k1 = k.at[-1].set(0.0)  # the Nyquist term of an odd derivative is not defined: drop it
    else:
        k1 = k
    c = jnp.fft.rfft(s)
    k1, k2 = k1.astype(c.dtype), (k * k).astype(c.dtype)
    return jnp.fft.irfft(1j * k1 * c, n=n), jnp.fft.irfft(-k2 * c, n=n)


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


def design_metrics(mech, roles: DwellRoles, q, s, ds, dds, p, crank, abs_tol, *, refined: bool):
    """The metrics a dwell objective needs (jax, one design; s, crank and abs_tol in the same
    length unit; q (N, n) and p (P,) SI). `refined`: the peak acceleration and the extreme angles
    are parabola-refined extrema (`peak`) instead of the extreme samples — what a search uses, so
    that a 0.5° search grid sees the extremes that a 0.05° report grid measures, with a smooth
    dependence on the design. `toggle_signed_deg` is the clearance with a sign (negative when
    the linkage passes its stretched position); `toggle_clear_deg` is 0 then (as in
    `angle_metrics`)."""
    deg = 180.0 / math.pi
    h = jnp.max(s) - jnp.min(s)
    eps = jnp.stack([jnp.asarray(abs_tol, s.dtype), 0.01 * h])
    w = jax.vmap(band_width, in_axes=(None, None, 0))(s, ds, eps) * deg
    coupler, rocker, rod, arm = linkage_angles(mech, roles, q, p)
    mu = jnp.abs(_wrap(coupler - rocker))
    mu = jnp.minimum(mu, jnp.pi - mu)
    rod_angle = jnp.abs(_wrap(rod - roles.guide))
    rod_angle = jnp.minimum(rod_angle, jnp.pi - rod_angle)
    tog = _wrap(rod - arm)
    crosses = (jnp.max(tog) > 0) & (jnp.min(tog) < 0)
    side = jnp.where(jnp.mean(tog) >= 0, 1.0, -1.0)
    signed = -peak(-side * tog, refined=refined) * deg
    return {
        "stroke_file": h, "dwell_abs_deg": w[0], "dwell_1pct_deg": w[1],
        "acc_sign_changes": sign_changes(dds),
        "amax_rel": peak(jnp.abs(dds), refined=refined) / crank,
        "mu_min_deg": -peak(-mu, refined=refined) * deg,
        "rod_angle_max_deg": peak(rod_angle, refined=refined) * deg,
        "toggle_signed_deg": signed,
        "toggle_clear_deg": jnp.where(crosses, 0.0, signed),
        "grashof_margin_rel": grashof_margin(mech, roles, p),
    }
