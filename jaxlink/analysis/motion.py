"""The range of motion of an angle input and the transmission angles of the dyads, on the branch
the file's guesses choose (a mechanism made of dyads: `jaxlink.solvers.dyads`).

**Range of motion.** The positions of one revolution from `[input] start` (`samples` of them)
are solved in closed form on the file's branches; where some are not assembled, the limit
positions on either side of the start are toggles of a dyad: the first sample, going forward and
back from the start, where a dyad's reach margin is not positive, then bisection on that dyad's
margin to the last input where it still assembles, the float next to the root
(`jaxlink.analysis.whole_curve.limit`: the bisection uses only the margin's sign; where it finds
none on a side, or the start is not assembled, the toggles of `jaxlink.branch_points`). Where
every sample is assembled, the reach margins are still minimized between them
(`jaxlink.analysis.feasibility.certify_host`): a window narrower than the samples' spacing is
found, and its two toggles located. The result is the interval of inputs around `start` that the
input can reach, or a full turn (certified between the samples). A full turn's **change points**
(flat positions: a dyad's margin touching zero, two branches crossing) are located by Newton's
method on the margin's derivative (`_change_points`), for the outputs' extremes there
(`jaxlink.analysis.stroke`).

**Transmission angle** (Alt 1932; Balli & Chand, "Transmission angle in mechanisms", Mechanism
and Machine Theory 37 (2002) 175–195): μ = 90° − the pressure angle, the angle between the force
the dyad's driving part passes on (along a two-pin link, normal to a sliding pair without
friction) and the velocity of the point it acts on, relative to the dyad's other end; 90° is
ideal, near 0 the linkage jams. Per dyad kind, from its closed form's known vectors
(`jaxlink.solvers.dyads.geometry`):

- RRR, two links L_a, L_b over their known diagonal w: the angle between the links at their
  joint, cos μ = (L_a² + L_b² − |w|²) / (2 |L_a| |L_b|) (a four-bar: coupler and rocker), 0 … π;
- RRP, a link a to a joint on a guide d (a slider-crank's connecting rod and slider; Whitworth's
  rod and ram): the link against the guide's normal, cos μ = |w × d| / (|a| |d|), 0 … π/2 (the
  force along the rod, the slider's velocity along the guide);
- RPR, a block on a known joint sliding in the slot b of a link turning about the dyad's other
  joint (the slotted lever of a Whitworth or crank-shaper quick return): the block's push, normal
  to the slot, against the velocity of the lever's point there, normal to the pivot–block line
  u: sin μ = |u · b| / (|u| |b|), cos μ = |e| / |u| with e the slot's offset from the pivot, 0 …
  π/2 — 90° throughout for a slot through the pivot.

A PP dyad (two sliders) has none. Its extremes over the reachable inputs
are found on the samples and refined by golden-section search (60 reductions of a bracket of two
sample steps: the input to about 1e-13 rad, the angle — stationary there — to rounding); an end
of the range counts where the extreme lies at a limit position. The designer's *worst*
transmission angle is the one farthest from 90°: min over the motion of min(μ, 180° − μ).
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..cache import traced
from ..model.mechanism import Mechanism
from ..results import RESULTS
from ..solvers import dyads as _dyads
from ..solvers.assemble import solve
from ..solvers.branch_points import GAP, TOGGLE, branch_points
from .blocks import BLOCK, in_blocks
from .golden import golden
from .whole_curve import _arg, margins_blocked


@dataclasses.dataclass(frozen=True)
class Motion:
    """The input's reach on the file's branch (SI).

    - `full_turn`: the input turns fully (every sample assembled, no limit position).
    - `lower`, `upper`: the limit positions around `start` (None with a full turn; `lower` <
      `start` < `upper`, as reached turning back and forward from it).
    - `transmission`: per RRR, RRP and RPR dyad (solve order), a dict `loop`, `kind`,
      `unknowns`, `min`, `min_at`, `max`, `max_at` (μ in rad, where in the input's SI unit) and
      `worst` (rad, the angle farthest from 90°).
    - `outputs`: with a full turn, per slider or rocker the stroke or swing, its dead centres (and
      flat positions), the time ratio and the velocity ratio (`jaxlink.analysis.stroke.outputs`);
      else empty.
    - `change_points`: with a full turn, the inputs (rad, in the turn from `start`) where a dyad's
      links come into line and two assembly branches cross (`_change_points`): the *flat
      positions*, where the linkage can switch branch and an output's rate may jump.
    - `low`, `high`: a length input (an actuator): the range its numbers cover (m) — `lower` and
      `upper` where they are limit positions, else the end of the scan (`_length_motion`) — and
      `outputs` each output's range over it (`jaxlink.analysis.stroke.outputs_over`); None for an
      angle input.
    """

    full_turn: bool
    lower: float | None
    upper: float | None
    transmission: list
    outputs: list = dataclasses.field(default_factory=list)
    change_points: list = dataclasses.field(default_factory=list)
    low: float | None = None
    high: float | None = None


TRANSMITTED = ("RRR", "RRP", "RPR")
"""The dyad kinds with a transmission angle (a PP dyad, two sliders, has no link to push)."""


def _cos_mu(mech, dyads, j, sigma, q_ref, phi, p):
    """cos μ of dyad j at input φ (the dyads before it on their sides σ): RRR the angle between
    its links (0 … π); RRP the link against the guide's normal, RPR the slotted link's push (normal
    to the slot) against the path of its point at the block (about the dyad's other joint), both
    0 … π/2 (the module's docstring)."""
    from ..solvers.dyads.forms import cross, safe_norm

    q, _, _, _, _, trig = _dyads._solve(mech, dyads[:j], sigma[:j], q_ref, phi, p, None, with_trig=True)
    env = mech.env(q, phi, p)
    d = dyads[j]
    (wx, wy), a, b = _dyads.geometry(mech, d, env, trig)
    if d.kind == "RRR":
        La, Lb = a.L, b.L
        return (La * La + Lb * Lb - (wx * wx + wy * wy)) / (2.0 * jnp.abs(La) * jnp.abs(Lb))
    dv = b[0]
    nd = safe_norm(dv[0] * dv[0] + dv[1] * dv[1])
    if d.kind == "RRP":  # a e(θ) + ℓ d = w: |w × d| / (|a| |d|), the rod's share across the guide
        return jnp.abs(cross((wx, wy), dv)) / (jnp.abs(a.L) * nd)
    # RPR, R(θ)(a + ℓ b) = w: |a × b| / (|b| |w|) = the slot's offset from the pivot over |w|
    e = jnp.zeros_like(wx) if a is None else jnp.abs(cross(a, dv))
    nw = safe_norm(wx * wx + wy * wy)
    return e / jnp.where(nw * nd > 0, nw * nd, 1.0)


# ---------------------------------------------------------------- the compiled parts, stored
# Each is a module-level function of arrays (the mechanism, with its parameters and guesses, is an
# argument) run through `jaxlink.cache.traced`: a repeated `check` loads the stored programs
# instead of tracing them again (`docs/numbers.md`, "`check` latency").


def _turn_arrays(mech, phis, p):
    """The turn's closed-form solve (`solve`, from the guesses), the dyads' branches σ at its
    first sample and that sample's residual and Newton steps: `(q, result, sigma, residual,
    steps)`."""
    sol = solve(mech, phis, p, points=False)
    dyads = _dyads.classify(mech)
    sigma = _dyads.solve_nearest(mech, dyads, sol.q[0], phis[0], p)[3]
    return sol.q, sol.result, sigma, sol.residual[0], sol.steps[0]


def _certificate(mech, sigma, q_ref, phis, p):
    """The certificate of the turn between its samples `phis` (a whole turn) on the branches σ:
    `(certified, where)` (`jaxlink.analysis.feasibility.certify_host`: the margins from one small
    program, compiled beside the turn's — `prepare` — where `certify`'s own program, which traces
    five instances of the margins, took 0.5–0.8 s to compile)."""
    from .feasibility import certify_host

    cert = certify_host(lambda x: margins_blocked(mech, sigma, q_ref, x, p), phis)
    return cert.certified, cert.where


def _cos_mus(mech, sigma, q_ref, phis, p, js):
    """cos μ of the dyads `js` (static) at the inputs `phis` (M,): (len(js), M)."""
    dyads = _dyads.classify(mech)
    return jnp.stack([jax.vmap(lambda ph, j=j: _cos_mu(mech, dyads, j, sigma, q_ref, ph, p))(phis) for j in js])


def _cos_mus_blocked(mech, js, sigma, q_ref, x, p):
    """`_cos_mus` at the inputs `x` (M,) through a stored trace, in blocks (`blocks.in_blocks`: one
    program for the samples and the refinement, so that an input's value is the same whichever
    inputs are beside it): numpy (len(js), M)."""
    return in_blocks(np.asarray(x, p.dtype), lambda xs: (traced(
        "motion_cos_mu", _cos_mus, (_arg(mech, p), sigma, q_ref, xs, p), (js,)),), axis=1)[0]


def _margin_root(mech, sigma, q_ref, lo, hi, p, j):
    """The root of dyad j's reach margin in [lo, hi] (the branch points' bracketed Newton)."""
    from ..solvers.branch_points import _root, _secant

    dyads = _dyads.classify(mech)

    def f(x):
        return _dyads.reach_margins(mech, dyads, sigma, q_ref, x, p)[j]

    def F(x):
        return jax.jvp(f, (x,), (jnp.ones_like(x),))

    flo, fhi = f(lo), f(hi)
    return _root(F, lo, hi, flo, fhi, _secant(lo, hi, flo, fhi), jnp.asarray(True))[0]


def _window_between_samples(mech, sigma, q_ref, phis, p, cert):
    """A window where the linkage cannot assemble that lies wholly between two of the equally
    spaced inputs `phis` of a turn (all assembled), or None: the reach margin's minimum refined
    between the samples (`cert = (certified, where)`: `jaxlink.analysis.feasibility.certify_host`);
    where it is negative, the two toggles on either side of it in its interval, the roots of that
    dyad's margin by the bracketed Newton iteration of the branch points (`(first, second)`,
    turning forward)."""
    certified, where = cert
    if bool(certified):
        return None
    where = float(where)
    j = int(np.argmin(margins_blocked(mech, sigma, q_ref, [where], p)[0]))

    def root(lo, hi):
        return float(traced("motion_margin_root", _margin_root,
                            (_arg(mech, p), sigma, q_ref, np.asarray(lo), np.asarray(hi), p), (j,)))

    h = float(phis[1] - phis[0])
    k = int(np.floor((where - float(phis[0])) / h))
    a, b = float(phis[0]) + k * h, float(phis[0]) + (k + 1) * h
    return root(a, where), root(where, b)


def _golden(f, a, b, c0, x0, sign, iterations: int = 60):
    """Golden-section refinement of the extremes of cos μ, every (dyad, extreme) pair at once:
    pair i minimizes `sign[i]` × cos μ, the diagonal of `f(x)` ((pairs,) → (pairs, pairs)), in
    the bracket [a[i], b[i]] around its best sample x0[i] (cos μ there c0[i]). Returns
    `(cos μ, where)` (pairs,): the best of the sample and the two last points."""
    rows = np.arange(a.shape[0])

    def ev(x):
        return sign * np.asarray(f(x))[rows, rows]

    x1, x2, f1, f2 = golden(ev, a, b, iterations)
    best, best_x = [], []
    for i in rows:  # the least of the sample and the two refined points (the first on a tie)
        cands = [(c0[i], x0[i]), (f1[i] * sign[i], x1[i]), (f2[i] * sign[i], x2[i])]
        k = 0
        for n in (1, 2):
            if sign[i] * cands[n][0] < sign[i] * cands[k][0]:
                k = n
        best.append(cands[k][0])
        best_x.append(cands[k][1])
    return np.asarray(best), np.asarray(best_x)


def _turn_inputs(mech, p, samples: int):
    """The turn's inputs (one turn from `start`, the start again at the end) and the design in
    float64 where JAX computes in it (the command line), JAX's float (float32) otherwise."""
    p = np.asarray(mech.parameters if p is None else p, dtype=jax.dtypes.canonicalize_dtype(np.float64))
    h = 2 * np.pi / samples
    return float(mech.input_start) + h * np.arange(samples + 1), p


def prepare(mech: Mechanism, p=None, *, samples: int = 3600) -> None:
    """Start compiling the programs `motion(mech, p, samples=samples)` runs on a linkage whose input
    turns fully (the turn, its certificate, the transmission angles and the outputs' jets) and the
    Jacobian of `start`, in background threads (`jaxlink.cache.prepare`: traced one after the
    other, each compiling while the next is traced and the command goes on). Only the shapes
    matter: the programs serve any design, start and guesses of this structure. Nothing where
    `motion` gives None."""
    from ..cache import prepare as _prepare
    from . import stroke

    dyads = _dyads.classify(mech)
    if dyads is None or mech.input_kind != "angle":
        return
    phis, p = _turn_inputs(mech, p, samples)
    arg = _arg(mech, p)
    # traced one at a time (`jaxlink.cache.prepare`): the turn, needed first, then the outputs' jets,
    # the longest trace of the others, so that its compiling starts early (whitworth cold, 7 runs
    # each: 1.77 s against 1.81 s in the order needed), then the small ones
    _prepare("motion_turn", _turn_arrays, (arg, phis, p))
    sigma = np.zeros(len(dyads), p.dtype)  # placeholders: the shapes and dtypes `motion_turn` gives
    q0 = np.zeros(len(mech.unknown_names), p.dtype)
    stroke.prepare(mech, sigma, q0, p)
    _prepare("motion_jacobian", _jacobian, (arg, q0, phis[0], p))
    from .whole_curve import _margins

    _prepare("reach_margins", _margins, (arg, sigma, q0, np.zeros(BLOCK, p.dtype), p))
    js = tuple(j for j, d in enumerate(dyads) if d.kind in TRANSMITTED)
    if js:
        _prepare("motion_cos_mu", _cos_mus, (arg, sigma, q0, np.zeros(BLOCK, p.dtype), p), (js,))


def _jacobian(mech, q, phi, p):
    """Φ_q at (q, φ)."""
    return jax.jacfwd(mech.residual)(q, phi, p)


def start(mech: Mechanism, p=None, *, samples: int = 3600):
    """What `jaxlink check` reports at `[input] start`, from the programs of `motion` (the first
    input of its turn is the start, solved from the guesses as a solve of the start alone: the
    same closed form, number for number — tests/test_check_start.py): `(q, result, residual,
    steps, jacobian)` as numpy arrays, or None where `motion` gives None."""
    dyads = _dyads.classify(mech)
    if dyads is None or mech.input_kind != "angle":
        return None
    phis, p = _turn_inputs(mech, p, samples)
    arg = _arg(mech, p)
    q, res, _, resid0, steps0 = (np.asarray(x) for x in traced("motion_turn", _turn_arrays, (arg, phis, p)))
    jac = np.asarray(traced("motion_jacobian", _jacobian, (arg, q[0], phis[0], p)))
    return q[0], res[0], resid0, steps0, jac


def motion(mech: Mechanism, p=None, *, samples: int = 3600) -> Motion | None:
    """The range of motion and the dyads' transmission angles of `mech` (design `p`, SI, default
    the file's) on the branch of its guesses; None unless the input is an angle and every block
    is a dyad. Host-side (a few compiled calls, stored traces where the compilation cache is on:
    `jaxlink.cache.traced`)."""
    dyads = _dyads.classify(mech)
    if dyads is None:
        return None
    if mech.input_kind != "angle":
        return _length_motion(mech, dyads, p, samples)
    phis, p = _turn_inputs(mech, p, samples)
    start = float(mech.input_start)
    q_all, res, sigma, _, _ = (np.asarray(x) for x in traced("motion_turn", _turn_arrays, (_arg(mech, p), phis, p)))
    ok = (res == RESULTS.converged) | (res == RESULTS.singular)
    lower = upper = None
    full = bool(ok.all())
    q0 = q_all[0]
    if not full:
        from .whole_curve import limit

        # each limit to adjacent floats by bisection on the toggling dyad's reach margin, found by
        # scanning the samples from the start (`whole_curve.limit`: the margins' program, compiled
        # ahead by `prepare`); the branch points (programs of their own: 1.5–2 s of a cold `check`)
        # only where that finds no toggle on a side or the start is not assembled
        up = down = None
        if ok[0]:
            up, down = (limit(mech, dyads, sigma, q0, p, start, d, samples) for d in (1.0, -1.0))
        if up is not None and down is not None:
            upper, lower = up[0], down[0]
        else:
            bp = branch_points(mech, phis, _Path(q_all, res), p)
            kind = np.asarray(bp.kind)  # a gap between two assembled samples: two toggles
            toggles = np.sort(np.concatenate([bp.input[(kind == TOGGLE) | (kind == GAP)], bp.end[kind == GAP]]))
            ahead, behind = toggles[toggles > start], toggles[toggles < start + 2 * np.pi]
            upper = float(ahead[0]) if ahead.size else None
            lower = float(behind[-1] - 2 * np.pi) if behind.size else None
            if not ok[0] or upper is None or lower is None:
                return Motion(False, lower, upper, [])
            upper = upper if up is None else up[0]
            lower = lower if down is None else down[0]
    if full:  # every sample assembled: certify the whole turn between them too
        cert = _certificate(mech, sigma, q0, phis[:-1], p)
        window = _window_between_samples(mech, sigma, q0, phis[:-1], p, cert)
        if window is not None:
            full, upper, lower = False, window[0], window[1] - 2 * np.pi
    lo_end = start if full or lower is None else lower
    hi_end = start + 2 * np.pi if full or upper is None else upper
    trans = _transmission(mech, dyads, sigma, q0, p, lo_end, hi_end, samples)
    outs: list = []
    flats: list = []
    if full:
        from .stroke import outputs

        flats = _change_points(mech, sigma, q0, phis, p)
        outs = outputs(mech, dyads, sigma, q0, phis, p, flats)
    return Motion(full, lower, upper, trans, outs, flats)


def _length_motion(mech: Mechanism, dyads, p, samples: int) -> Motion:
    """`motion` of a length input (an actuator, a cylinder): its range around `[input] start` —
    the toggles on either side, where a dyad's reach margin reaches zero, scanned in `samples`
    steps of (|start| + the sum of the design's lengths) / `samples` each way (no linkage of links
    reaches further; a positive distance, an actuator's length, down to zero only, a slider's signed
    position — a sketch's `slider` input, or a start ≤ 0 — past zero; past the scan no limit:
    `lower`/`upper` None) and bisected to adjacent floats (`whole_curve.limit`) —, the
    transmission angles over it, and each output's range over it
    (`jaxlink.analysis.stroke.outputs_over`)."""
    from .stroke import outputs_over
    from .whole_curve import limit

    p = np.asarray(mech.parameters if p is None else p, dtype=jax.dtypes.canonicalize_dtype(np.float64))
    start = float(mech.input_start)
    q_s, res, sigma, _, _ = (np.asarray(x) for x in traced(
        "motion_turn", _turn_arrays, (_arg(mech, p), np.asarray([start, start], p.dtype), p)))
    if not (res[0] == RESULTS.converged or res[0] == RESULTS.singular):
        return Motion(False, None, None, [])
    q0 = q_s[0]
    lengths = [abs(float(v)) for v, k in zip(p, mech.parameter_kinds) if k == "length"]
    step = (abs(start) + sum(lengths)) / samples
    # a distance (an actuator's length) stays above zero; a slider's signed position need not
    signed = start <= 0 or (mech.sketch is not None and mech.sketch.input[0] == "slider")
    n_down = samples if signed else max(1, int(np.ceil(start / step)) - 1)
    up = limit(mech, dyads, sigma, q0, p, start, 1.0, samples, step=step)
    down = limit(mech, dyads, sigma, q0, p, start, -1.0, n_down, step=step)
    upper = None if up is None else up[0]
    lower = None if down is None else down[0]
    hi_end = start + samples * step if upper is None else upper
    lo_end = start - n_down * step if lower is None else lower
    trans = _transmission(mech, dyads, sigma, q0, p, lo_end, hi_end, samples)
    outs = outputs_over(mech, sigma, q0, lo_end, hi_end, p, samples)
    return Motion(False, lower, upper, trans, outs, [], lo_end, hi_end)


def _transmission(mech, dyads, sigma, q0, p, lo_end, hi_end, samples) -> list:
    """The transmission angles of the dyads over the inputs [lo_end, hi_end] (`samples` + 1 of
    them, the extremes refined by golden section): `Motion.transmission`."""
    trans = []
    js = tuple(j for j, d in enumerate(dyads) if d.kind in TRANSMITTED)
    if js:
        def f(x):  # (len(js), len(x)), numpy (indexing a JAX array would dispatch an operation)
            return _cos_mus_blocked(mech, js, sigma, q0, x, p)

        grid = np.linspace(lo_end, hi_end, samples + 1)
        c = f(grid)  # (len(js), samples + 1)
        # the pairs (dyad, extreme): μ max where cos μ is least (sign 1), μ min where it is largest
        row = np.repeat(np.arange(len(js)), 2)
        sign = np.tile([1.0, -1.0], len(js))
        k = np.argmin(sign[:, None] * c[row], axis=1)
        a, b = grid[np.maximum(k - 1, 0)], grid[np.minimum(k + 1, samples)]

        def g(x):  # cos μ of pair i's dyad at x[i]: the evaluations at x, rows per pair
            return f(x)[row]

        best, best_x = _golden(g, a, b, c[row, k], grid[k], sign)
        mu = np.arccos(np.clip(best, -1.0, 1.0))
        for i, j in enumerate(js):
            d = dyads[j]
            mu_max, mu_min = float(mu[2 * i]), float(mu[2 * i + 1])
            trans.append({"loop": mech.loops[d.loop][0], "kind": d.kind,
                          "unknowns": tuple(mech.unknown_names[u] for u in d.unknowns),
                          "min": mu_min, "min_at": float(best_x[2 * i + 1]), "max": mu_max,
                          "max_at": float(best_x[2 * i]), "worst": min(mu_min, np.pi - mu_max)})
    return trans


def _margin_minimum(mech, sigma, q_ref, lo, hi, p, j):
    """The minimum of dyad j's reach margin S in [lo, hi] (S′ < 0 at lo, > 0 at hi): the root of S′
    by the branch points' bracketed Newton iteration (S″ by forward-mode AD). `(x, S(x))`."""
    from ..solvers.branch_points import _jets, _root, _secant

    dyads = _dyads.classify(mech)

    def f(x):
        return _dyads.reach_margins(mech, dyads, sigma, q_ref, x, p)[j]

    def F(x):
        return _jets(f, x)[1:]

    dlo, dhi = F(lo)[0], F(hi)[0]
    x = _root(F, lo, hi, dlo, dhi, _secant(lo, hi, dlo, dhi), jnp.asarray(True))[0]
    return x, f(x)


def _change_points(mech, sigma, q_ref, phis, p) -> list:
    """The change points of a full turn sampled by `phis` (N + 1,: the start again at the end) on
    the branches σ: the inputs where a dyad's reach margin S touches zero (its links in line, two
    branches crossing; `jaxlink.solvers.branch_points`), sorted, in [phis[0], phis[-1]).

    Each local minimum of a dyad's margin on the samples (periodic) whose parabola through it and
    its two neighbours reaches below a quarter of the neighbours' mean (S ≈ c (φ − φ*)² predicts
    zero; a minimum well above zero, a crank-rocker's least transmission angle, does not) is
    located by Newton's method on S′ in the bracket of its two neighbours, and kept where S
    there is below the singular threshold (10 √eps)²: to a few ulp of the input, also where it
    falls exactly on a sample (a change point at the start)."""
    from ..solvers.branch_points import singular_ratio_default

    m = np.asarray(margins_blocked(mech, sigma, q_ref, phis[:-1], p), dtype=float)  # (N, D)
    h = float(phis[1] - phis[0])
    thr2 = singular_ratio_default(np.asarray(p).dtype) ** 2
    prev, nxt = np.roll(m, 1, 0), np.roll(m, -1, 0)
    a, b = 0.5 * (prev + nxt) - m, 0.5 * (nxt - prev)
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = np.where(a > 0, m - b * b / (4 * a), m)
    ks, js = np.nonzero((m <= prev) & (m <= nxt) & (vertex <= 0.125 * (prev + nxt)))
    found: list = []
    for k, j in zip(ks, js):
        lo, hi = float(phis[0]) + (k - 1) * h, float(phis[0]) + (k + 1) * h
        x, S = (float(v) for v in traced("motion_margin_minimum", _margin_minimum, (
            _arg(mech, p), sigma, q_ref, np.asarray(lo, p.dtype), np.asarray(hi, p.dtype), p), (int(j),)))
        if abs(S) <= thr2:
            x = float(phis[0]) + float(np.mod(x - float(phis[0]), 2 * np.pi))
            x = float(phis[0]) if x >= float(phis[0]) + 2 * np.pi - 1e-12 else x
            if all(abs(math.remainder(x - y, 2 * np.pi)) > 1e-9 for y in found):
                found.append(x)
    return sorted(found)


class _Path(NamedTuple):
    """A solved path as `branch_points` reads it (q, result)."""

    q: np.ndarray
    result: np.ndarray
