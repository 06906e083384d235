"""The range of motion of an angle input and the transmission angles of the dyads, on the branch
the file's guesses choose (a mechanism made of dyads: `jaxlink.solvers.dyads`).

**Range of motion.** The positions of one revolution from `[input] start` (`samples` of them)
are solved in closed form on the file's branches; where some are not assembled, the limit
positions between an assembled and a not assembled sample are toggles of a dyad, found by
`jaxlink.branch_points` and located by bisection on that dyad's reach margin to the last input
where it still assembles, the float next to the root (`jaxlink.analysis.whole_curve.limit`: the
bisection uses only the margin's sign). Where every sample is assembled, the reach margins are
still minimized between them (`jaxlink.analysis.feasibility.certify`): a window narrower than
the samples' spacing is found, and its two toggles located. The result is the interval of inputs around
`start` that the input can reach, or a full turn (certified between the samples).

**Transmission angle** of a dyad of two links L_a, L_b (RRR) over its known diagonal w: the
angle μ between the two links at their joint, cos μ = (L_a² + L_b² − |w|²) / (2 |L_a| |L_b|)
(for a four-bar, the angle between coupler and rocker). Its extremes over the reachable inputs
are found on the samples and refined by golden-section search (60 reductions of a bracket of two
sample steps: the input to about 1e-13 rad, the angle — stationary there — to rounding); an end
of the range counts where the extreme lies at a limit position. The designer's *worst*
transmission angle is the one farthest from 90°: min over the motion of min(μ, 180° − μ).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from ..model.mechanism import Mechanism
from ..results import RESULTS
from ..solvers import dyads as _dyads
from ..solvers.assemble import solve
from ..solvers.branch_points import TOGGLE, branch_points

_GOLD = 0.6180339887498949


@dataclasses.dataclass(frozen=True)
class Motion:
    """The input's reach on the file's branch (SI).

    - `full_turn`: the input turns fully (every sample assembled, no limit position).
    - `lower`, `upper`: the limit positions around `start` (None with a full turn; `lower` <
      `start` < `upper`, as reached turning back and forward from it).
    - `transmission`: per RRR dyad (solve order), a dict `loop`, `unknowns`, `min`, `min_at`,
      `max`, `max_at` (μ in rad, where in the input's SI unit) and `worst` (rad, the angle
      farthest from 90°).
    - `outputs`: with a full turn, per slider or rocker the stroke or swing, its dead centres, the
      time ratio and the velocity ratio (`jaxlink.analysis.stroke.outputs`); else empty.
    """

    full_turn: bool
    lower: float | None
    upper: float | None
    transmission: list
    outputs: list = dataclasses.field(default_factory=list)


def _cos_mu(mech, dyads, j, sigma, q_ref, phi, p):
    """cos μ of RRR dyad j at input φ (the dyads before it on their sides σ)."""
    q, _, _, _, _, trig = _dyads._solve(mech, dyads[:j], sigma[:j], q_ref, phi, p, None, with_trig=True)
    env = mech.env(q, phi, p)
    (wx, wy), a, b = _dyads.geometry(mech, dyads[j], env, trig)
    La, Lb = a.L, b.L
    return (La * La + Lb * Lb - (wx * wx + wy * wy)) / (2.0 * jnp.abs(La) * jnp.abs(Lb))


def _window_between_samples(mech, dyads, sigma, q_ref, phis, p):
    """A window where the linkage cannot assemble that lies wholly between two of the equally
    spaced inputs `phis` of a turn (all assembled), or None: the reach margin's minimum refined
    between the samples (`jaxlink.analysis.feasibility.certify`); where it is negative, the two
    toggles on either side of it in its interval, the roots of that dyad's margin by the
    bracketed Newton iteration of the branch points (`(first, second)`, turning forward)."""
    from ..solvers.branch_points import _root, _secant
    from .feasibility import certify

    pj = jnp.asarray(p)
    cert = jax.jit(lambda s, q, ph, pp: certify(mech, dyads, s, q, ph, pp))(sigma, q_ref, jnp.asarray(phis), pj)
    if bool(cert.certified):
        return None
    where = jnp.asarray(float(cert.where))
    j = int(jnp.argmin(_dyads.reach_margins(mech, dyads, sigma, q_ref, where, pj)))

    def f(x):
        return _dyads.reach_margins(mech, dyads, sigma, q_ref, x, pj)[j]

    def F(x):
        return jax.jvp(f, (x,), (jnp.ones_like(x),))

    @jax.jit
    def root(lo, hi):
        flo, fhi = f(lo), f(hi)
        return _root(F, lo, hi, flo, fhi, _secant(lo, hi, flo, fhi), jnp.asarray(True))[0]

    h = float(phis[1] - phis[0])
    k = int(np.floor((float(where) - float(phis[0])) / h))
    a, b = jnp.asarray(float(phis[0]) + k * h), jnp.asarray(float(phis[0]) + (k + 1) * h)
    return float(root(a, where)), float(root(where, b))


def motion(mech: Mechanism, p=None, *, samples: int = 3600) -> Motion | None:
    """The range of motion and the dyads' transmission angles of `mech` (design `p`, SI, default
    the file's) on the branch of its guesses; None unless the input is an angle and every block
    is a dyad. Host-side (a few compiled calls)."""
    dyads = _dyads.classify(mech)
    if dyads is None or mech.input_kind != "angle":
        return None
    # float64 where JAX computes in it (the command line); JAX's float (float32) otherwise
    p = np.asarray(mech.parameters if p is None else p, dtype=jax.dtypes.canonicalize_dtype(np.float64))
    start = float(mech.input_start)
    h = 2 * np.pi / samples
    phis = start + h * np.arange(samples + 1)  # one turn, the start again at the end
    sol = solve(mech, phis, p)
    res = np.asarray(sol.result)
    ok = (res == RESULTS.converged) | (res == RESULTS.singular)
    lower = upper = None
    full = bool(ok.all())
    if not full:
        bp = branch_points(mech, phis, sol, p)
        toggles = np.sort(bp.input[np.asarray(bp.kind) == TOGGLE])
        ahead, behind = toggles[toggles > start], toggles[toggles < start + 2 * np.pi]
        upper = float(ahead[0]) if ahead.size else None
        lower = float(behind[-1] - 2 * np.pi) if behind.size else None
        if not ok[0] or upper is None or lower is None:
            return Motion(False, lower, upper, [])
    q0 = jnp.asarray(np.asarray(sol.q)[0])
    sigma = _dyads.solve_nearest(mech, dyads, q0, jnp.asarray(start), jnp.asarray(p))[3]
    if not full:  # each limit to adjacent floats by bisection on the toggling dyad's margin
        from .whole_curve import limit

        up, down = (limit(mech, dyads, sigma, q0, p, start, d, samples) for d in (1.0, -1.0))
        upper = upper if up is None else up[0]
        lower = lower if down is None else down[0]
    if full:  # every sample assembled: certify the whole turn between them too
        window = _window_between_samples(mech, dyads, sigma, q0, phis[:-1], p)
        if window is not None:
            full, upper, lower = False, window[0], window[1] - 2 * np.pi
    lo_end = start if full or lower is None else lower
    hi_end = start + 2 * np.pi if full or upper is None else upper
    trans = []
    for j, d in enumerate(dyads):
        if d.kind != "RRR":
            continue
        f = jax.jit(jax.vmap(lambda ph, j=j: _cos_mu(mech, dyads, j, sigma, q0, ph, jnp.asarray(p))))
        grid = np.linspace(lo_end, hi_end, samples + 1)
        c = np.asarray(f(jnp.asarray(grid)))
        ext = {}
        for which, sign in (("max", 1.0), ("min", -1.0)):  # μ max where cos μ is least, and back
            k = int(np.argmin(sign * c))
            a, b = grid[max(k - 1, 0)], grid[min(k + 1, samples)]
            x1, x2 = b - _GOLD * (b - a), a + _GOLD * (b - a)
            f1, f2 = (sign * float(v) for v in f(jnp.asarray([x1, x2])))

            def one(x):
                return sign * float(f(jnp.asarray([x, x]))[0])  # the shape already compiled

            for _ in range(60):
                if f1 <= f2:
                    b, x2, f2 = x2, x1, f1
                    x1 = b - _GOLD * (b - a)
                    f1 = one(x1)
                else:
                    a, x1, f1 = x1, x2, f2
                    x2 = a + _GOLD * (b - a)
                    f2 = one(x2)
            cands = [(sign * c[k], grid[k]), (f1 * sign, x1), (f2 * sign, x2)]
            best = min(cands, key=lambda t: sign * t[0])
            ext[which] = (float(np.arccos(np.clip(best[0], -1.0, 1.0))), float(best[1]))
        mu_min, mu_max = ext["min"][0], ext["max"][0]
        trans.append({"loop": mech.loops[d.loop][0], "unknowns": tuple(mech.unknown_names[i] for i in d.unknowns),
                      "min": mu_min, "min_at": ext["min"][1], "max": mu_max, "max_at": ext["max"][1],
                      "worst": min(mu_min, np.pi - mu_max)})
    outs = []
    if full:
        from .stroke import outputs

        outs = outputs(mech, dyads, sigma, q0, phis, p)
    return Motion(full, lower, upper, trans, outs)
