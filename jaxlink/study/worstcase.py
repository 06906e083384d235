"""The true worst case over the tolerance box: the largest deviation from the nominal of each
objective over every design x̄ + δ with |δ_j| ≤ t_j (a zone: ‖δ_(x, y)‖ ≤ r), the responses
computed exactly (not linearized). docs/methods/tolerance.md gives the method.

**Objectives** (Q of them, file units), each a deviation ≥ 0 from the nominal:

- each scalar metric m (stroke, swing, max speed, …): |m(x) − m(x̄)|;
- per studied point P: `deviation(P.x)` = max_k |P.x(φ_k; x) − P.x(φ_k; x̄)| (likewise P.y) and
  `deviation(P)` = max_k |P(φ_k; x) − P(φ_k; x̄)| (the path's largest distance from nominal).

**Candidates.** With no zone and at most `MAX_CORNERS` (2^10) corners, every corner of the box
(δ_j = ±t_j); else the linear worst-case corner of every response (δ_j = t_j sign J_ij, a zone
r g/‖g‖ with g its gradient in (x, y)) and its opposite, deduplicated (a zone in an enumeration:
`ZONE_POINTS` points on its circle). They are solved in batches (the Monte Carlo's compiled
batch), feasibility screened and certified as there.

**Ascent.** From the `RESTARTS` best feasible candidates of each objective, projected gradient
ascent in the scaled box s = δ / t ∈ [−1, 1]^T (a zone: the unit disc): s ← Π(s + α g_s / ‖g_s‖∞)
with g_s = t ⊙ ∂f/∂δ, the gradient exact (the study's compiled Jacobian: implicit differentiation
through the solve; a maximum over the cycle differentiates at its active position); a step is kept
only where it increases f and the design is feasible (certified), else α is halved; it stops where
the projection leaves s unchanged (a KKT point of the box), α < `MIN_STEP` or after `MAX_STEPS`.

**Status.** "enumerated": every corner was evaluated, no zone, and the ascent did not improve on
the best corner — the box's maximum for any objective monotone in each parameter over the box
(the usual case at tolerance size; not a proof for a response with an interior extreme); else
"found": the largest deviation found, a lower bound of the true worst case, never claimed optimal.
Infeasible designs are not candidates (counted: `infeasible`).
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

#: the largest number of corners enumerated
MAX_CORNERS = 1 << 10
#: points on a zone's circle in a corner enumeration
ZONE_POINTS = 8
#: ascents per objective (from its best candidates)
RESTARTS = 3
#: the ascent's step limits (scaled units: 1 = the whole half-width)
MAX_STEPS = 40
MIN_STEP = 1e-4


class WorstCase(NamedTuple):
    """The worst case over the tolerance box (file units; see the module doc).

    `names` (Q,) objective names, `units` (Q,), `value` (Q,) the largest deviation found,
    `linear` (Q,) its linear counterpart (the linear worst case), `design` (Q, T) the deviations δ
    of the toleranced parameters that give it, `status` (Q,) "enumerated" | "found" | "none
    feasible" (no candidate assembles: `value` NaN, `design` 0);
    `candidates` (designs evaluated in the batch), `infeasible` (of them, not assembling),
    `corners` (True: every corner of the box was evaluated), `evaluations` (ascent steps)."""

    names: tuple
    units: tuple
    value: np.ndarray
    linear: np.ndarray
    design: np.ndarray
    status: tuple
    candidates: int
    infeasible: int
    corners: bool
    evaluations: int


def objective_labels(labels, points, n_curve: int, length_unit: str):
    """(names, units, index) of the objectives: the scalar metrics, then per point P.x, P.y, P."""
    names, units = [], []
    for i in range(n_curve, len(labels)):
        names.append(labels[i][0])
        units.append(labels[i][1])
    for p in points:
        for c in (f"{p}.x", f"{p}.y", p):
            names.append(f"deviation({c})")
            units.append(length_unit)
    return tuple(names), tuple(units)


def objectives(v, y0, K: int, N: int, n_curve: int):
    """(B, Q) the objectives of the responses `v` (B, M) (see the module doc), with the active
    position (B, Q) of each (−1 for a metric)."""
    v = np.atleast_2d(v)
    d = v - y0
    B = d.shape[0]
    vals = [np.abs(d[:, n_curve:])]
    act = [np.full((B, d.shape[1] - n_curve), -1)]
    if K:
        c = d[:, :n_curve].reshape(B, K, 2, N)
        dist = np.sqrt(c[:, :, 0] ** 2 + c[:, :, 1] ** 2)  # (B, K, N)
        per = np.concatenate([np.abs(c), dist[:, :, None]], axis=2)  # (B, K, 3, N)
        vals.append(per.max(axis=3).reshape(B, 3 * K))
        act.append(per.argmax(axis=3).reshape(B, 3 * K))
    return np.concatenate(vals, axis=1), np.concatenate(act, axis=1)


def gradient(q: int, v, J, y0, active: int, K: int, N: int, n_curve: int):
    """(T,) the gradient of objective `q` at a design with responses `v` (M,) and Jacobian `J`
    (M, T), its maximum over the cycle at position `active`."""
    d = v - y0
    nm = len(v) - n_curve
    if q < nm:
        i = n_curve + q
        return np.sign(d[i]) * J[i]
    j, c = divmod(q - nm, 3)
    ix, iy = 2 * N * j + active, 2 * N * j + N + active
    if c < 2:
        i = ix if c == 0 else iy
        return np.sign(d[i]) * J[i]
    r = np.hypot(d[ix], d[iy])
    return (d[ix] * J[ix] + d[iy] * J[iy]) / r if r > 0 else np.zeros(J.shape[1])


def linear_objectives(first, bound, K: int, N: int, n_curve: int):
    """(Q,) the linear worst case of each objective: a metric's own; a coordinate's largest over
    the cycle; the path's `deviation_bound`."""
    w = first.worst_case
    out = list(w[n_curve:])
    for j in range(K):
        a = 2 * N * j
        out += [w[a:a + N].max(), w[a + N:a + 2 * N].max(), bound[j]]
    return np.asarray(out)


def monte_carlo_objectives(mc, K: int, N: int, n_curve: int):
    """(Q,) Monte Carlo's largest deviation of each objective over its feasible samples (not a
    worst case: a sample's largest)."""
    out = list(mc.max_abs[n_curve:])
    for j in range(K):
        a = 2 * N * j
        out += [mc.max_abs[a:a + N].max(), mc.max_abs[a + N:a + 2 * N].max(), mc.deviation_max[j]]
    return np.asarray(out)


def _groups(inputs):
    """(scale (T,), zone pairs [(j, j + 1)], scalar indices)."""
    scale, zones, scalars, j = [], [], [], 0
    for t in inputs.tolerances:
        scale += [t.half_width] * len(t.parameters)
        if t.zone:
            zones.append((j, j + 1))
        else:
            scalars.append(j)
        j += len(t.parameters)
    return np.asarray(scale), zones, scalars


def _project(s, zones):
    """s projected onto the scaled box (each scalar in [−1, 1], each zone in the unit disc)."""
    s = np.clip(s, -1.0, 1.0)
    for a, b in zones:
        r = np.hypot(s[..., a], s[..., b])
        f = np.where(r > 1.0, 1.0 / np.maximum(r, 1.0), 1.0)
        s[..., a] *= f
        s[..., b] *= f
    return s


def _linear_corners(J, scale, zones, scalars):
    """(2M, T) scaled linear worst-case corners of every response and their opposites."""
    s = np.zeros(J.shape)
    g = J * scale
    s[:, scalars] = np.sign(g[:, scalars])
    for a, b in zones:
        r = np.hypot(g[:, a], g[:, b])
        ok = r > 0
        s[:, a] = np.where(ok, g[:, a] / np.where(ok, r, 1.0), 1.0)
        s[:, b] = np.where(ok, g[:, b] / np.where(ok, r, 1.0), 0.0)
    return np.concatenate([s, -s])


def candidates(first, inputs):
    """(C, T) scaled candidates and whether they are every corner of the box (module doc)."""
    scale, zones, scalars = _groups(inputs)
    T = len(scale)
    n_corner = 2 ** len(scalars) * ZONE_POINTS ** len(zones)
    if n_corner <= MAX_CORNERS:
        ang = 2.0 * np.pi * np.arange(ZONE_POINTS) / ZONE_POINTS
        rows = []
        for signs in itertools.product((-1.0, 1.0), repeat=len(scalars)):
            for circ in itertools.product(ang, repeat=len(zones)):
                s = np.zeros(T)
                s[scalars] = signs
                for (a, b), t in zip(zones, circ):
                    s[a], s[b] = np.cos(t), np.sin(t)
                rows.append(s)
        s = np.asarray(rows).reshape(-1, T)
        if zones:  # and the linear worst-case points of the zones
            s = np.concatenate([s, _linear_corners(first.jacobian, scale, zones, scalars)])
        return np.unique(np.round(s, 12), axis=0), not zones
    return np.unique(np.round(_linear_corners(first.jacobian, scale, zones, scalars), 12), axis=0), False


def worst_case(study, first, bound) -> WorstCase:
    """The worst case of `study` (a `tolerance.Study`) over its tolerance box, from its first-order
    results `first` and path deviation bound `bound` (see the module doc)."""
    from .responses import unit_names

    r = study.responses
    inputs = study.inputs
    y0 = np.asarray(study.nominal()[0])
    K, N, nc = len(inputs.points), inputs.positions, r.n_curve
    names, units = objective_labels(r.labels, inputs.points, nc, unit_names(study.mech)[0])
    scale, zones, _ = _groups(inputs)
    s_all, exhaustive = candidates(first, inputs)
    C = len(s_all)
    vals = np.full((C, len(names)), -np.inf)
    feas = np.zeros(C, bool)
    for c0 in range(0, C, study.chunk):
        s = s_all[c0:c0 + study.chunk]
        x = np.empty((study.chunk, len(study.x0)))
        x[:] = study.x0
        x[:len(s)] += s * scale
        v, ok, est = study._batch(jnp.asarray(x))
        ok = study._certified(x[:len(s)], np.asarray(ok)[:len(s)], np.asarray(est)[:len(s)])
        feas[c0:c0 + len(s)] = ok
        vals[c0:c0 + len(s)] = np.where(ok[:, None], objectives(np.asarray(v)[:len(s)], y0, K, N, nc)[0], -np.inf)
    Q = len(names)
    best = np.zeros(Q)
    design = np.zeros((Q, len(scale)))
    status = []
    evals = 0
    cache: dict = {}

    def evaluate(s):
        key = s.tobytes()
        if key not in cache:
            J, (v, ok, _m) = study._jac(jnp.asarray(study.x0 + s * scale))
            cache[key] = (np.asarray(v), np.asarray(J), bool(ok))
        return cache[key]

    for q in range(Q):
        order = [int(i) for i in np.argsort(-vals[:, q])[:RESTARTS] if np.isfinite(vals[i, q])]
        corner_best = vals[order[0], q] if order else 0.0
        found, at = (corner_best, s_all[order[0]]) if order else (0.0, np.zeros(len(scale)))
        for i in order:
            s = s_all[i].copy()
            v, J, ok = evaluate(s)
            evals += 1
            if not ok:
                continue
            f, act = objectives(v, y0, K, N, nc)
            f, act = f[0, q], act[0, q]
            alpha = 1.0
            for _ in range(MAX_STEPS):
                g = gradient(q, v, J, y0, act, K, N, nc) * scale
                m = np.abs(g).max()
                if m == 0 or alpha < MIN_STEP:
                    break
                s_new = _project(s + alpha * g / m, zones)
                if np.array_equal(s_new, s):
                    break  # a KKT point of the box
                v2, J2, ok2 = evaluate(s_new)
                evals += 1
                f2, act2 = objectives(v2, y0, K, N, nc)
                if ok2 and f2[0, q] > f:
                    s, v, J, f, act = s_new, v2, J2, f2[0, q], act2[0, q]
                else:
                    alpha *= 0.5
            if f > found:
                found, at = f, s
        if not order:  # no candidate assembles: no worst case was found, not a worst deviation of 0
            best[q] = np.nan
            status.append("none feasible")
            continue
        best[q] = found
        design[q] = at * scale
        status.append("enumerated" if exhaustive and found <= corner_best * (1 + 1e-9) + 1e-300 else "found")
    return WorstCase(names, units, best, linear_objectives(first, bound, K, N, nc), design, tuple(status), C,
                     int(C - feas.sum()), exhaustive, evals)
