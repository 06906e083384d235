"""The robust-design map: the first-order tolerance report — σ_RSS, the linear worst case, Cpk
against specification limits — of every design of a grid or sample, a nested design × tolerance
study (`[study] robust = true` with `method = "sample"` or `"grid"`, `[study.ranges]` the designs
and `[study.tolerances]` the tolerances at each). docs/methods/tolerance.md gives the formulas.

At each design d (its ranged parameters set, the others the file's) the Jacobian J_d = ∂y/∂x of
every response with respect to the toleranced parameters is computed exactly (`jax.jacfwd` of
`Responses.single` with the design as its base parameters: the implicit derivative of the path
solve), `vmap`ped over a batch of designs, and reduced on the device to a few numbers per design
(nothing of size M × T comes back):

- per scalar metric m: σ_RSS,m = √(Σ_j (J_mj σ_j)²) and w_m = Σ_groups t_g ‖J_m,g‖ (the linear
  worst case; a zone counts r √(J_x² + J_y²)), and with limits [L, U] on m
  Cpk = min(U − m_d, m_d − L) / (3 σ_RSS,m) (m_d the design's own value: first order centres the
  distribution on it; a one-sided limit gives the one side);
- per studied point P: the largest over the cycle of σ_RSS of P.x and of P.y, of their linear worst
  cases, and the linear bound of the path's deviation max_φ Σ_g t_g ‖∂P/∂x_g‖₂ (a zone: the largest
  singular value of its 2 × 2 block) — the tolerance method's `deviation_bound`.

A toleranced parameter that is also ranged is toleranced around the design's value. A design that
does not assemble over the whole cycle (the sample's certified flag) gets no report (its cells
empty, zeros in the arrays).
"""

from __future__ import annotations

import math
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import MechanismError


class RobustMap(NamedTuple):
    """The robust-design map of a `SampleReport` (file units): `labels` ((column, unit) per
    column: `sigma_rss(m)`, `worst_case_linear(m)`, `cpk(m)` per scalar metric m (Cpk where it has
    limits), then per point `sigma_rss(P.x)`, `sigma_rss(P.y)`, `worst_case_linear(P.x)`,
    `worst_case_linear(P.y)` (the largest over the cycle), `worst_case_linear(P)` (the path's
    deviation bound)); `values` (n, C), 0 where the design is infeasible; `tolerances` (the
    toleranced parameters); `limits` ((output, low, high) used)."""

    labels: tuple
    values: np.ndarray
    tolerances: tuple
    limits: tuple


#: positions × toleranced parameters × designs per robust batch (bounded memory of the Jacobians)
BATCH_BUDGET = 1 << 21


class RobustEvaluator:
    """The batched first-order report of a `Study` whose parameters are the ranges' (`sample`,
    `grid`), at designs (n, D) of the ranged parameters (file units)."""

    def __init__(self, study, chunk: int | None = None):
        from .responses import Responses, unit_names

        inputs = study.inputs
        if not inputs.tolerances:
            raise MechanismError("the robust-design map needs [study.tolerances]", file=study.mech.file,
                                 key="study.tolerances")
        self.study = study
        mech = study.mech
        self.responses = r = Responses(mech, inputs._replace(method="tolerance"), study.responses.options)
        self.range_index = np.asarray(study.responses.index)
        self.range_factor = np.asarray(study.responses.factor)
        tol = inputs.tolerances
        self.sigma = np.asarray([t.sigma for t in tol for _ in t.parameters])
        self.half = np.asarray([t.half_width for t in tol])
        groups, j = [], 0
        for t in tol:
            groups.append((j, len(t.parameters)))
            j += len(t.parameters)
        self.groups = tuple(groups)
        T = j
        N, K = inputs.positions, len(inputs.points)
        self.K, self.N, self.n_curve = K, N, r.n_curve
        if chunk is None:
            chunk = 2 ** max(3, int(math.log2(max(1, BATCH_BUDGET // (N * (T + 1))))))
        self.chunk = int(chunk)
        lu = unit_names(mech)[0]
        metrics = [(name, unit) for (name, unit, k) in r.labels if k is None]
        limits = {name: (lo, hi) for name, lo, hi in inputs.limits}
        unknown = [n for n in limits if n not in {m for m, _ in metrics}]
        if unknown:
            raise MechanismError(f"limits: no scalar response {', '.join(map(repr, unknown))}; the scalar responses: "
                                 f"{', '.join(m for m, _ in metrics) or '(none)'}", file=mech.file, key="study.limits")
        labels = []
        self.cpk_rows = []
        for i, (name, unit) in enumerate(metrics):
            labels += [(f"sigma_rss({name})", unit), (f"worst_case_linear({name})", unit)]
            if name in limits:
                labels.append((f"cpk({name})", "1"))
                self.cpk_rows.append((i, *limits[name]))
        for p in inputs.points:
            labels += [(f"sigma_rss({p}.x)", lu), (f"sigma_rss({p}.y)", lu), (f"worst_case_linear({p}.x)", lu),
                       (f"worst_case_linear({p}.y)", lu), (f"worst_case_linear({p})", lu)]
        self.labels = tuple(labels)
        self.limits = tuple((n, lo, hi) for n, lo, hi in inputs.limits)
        self.seconds = 0.0
        self._fn = jax.jit(jax.vmap(self._one, in_axes=(0, None, None)))

    def _one(self, xd, sigma, half):
        """The reduced first-order report of one design `xd` (D,) (see the module doc)."""
        r = self.responses
        dtype = xd.dtype
        p0 = jnp.asarray(self.study.mech.parameters, dtype)
        base = p0.at[jnp.asarray(self.range_index)].set(xd * jnp.asarray(self.range_factor, dtype))
        xt0 = base[jnp.asarray(r.index)] / jnp.asarray(r.factor, dtype)

        def f(xt):
            v, ok, m = r.single(xt, "screen", base=base)
            return v, v

        J, v = jax.jacfwd(f, has_aux=True)(xt0)
        return reduce_first_order(J, v, sigma, half, self.groups, self.K, self.N, self.n_curve)

    def __call__(self, x, feasible) -> np.ndarray:
        """(n, C) the columns of `labels` at the designs `x` (n, D), 0 where not `feasible`."""
        t0 = time.perf_counter()
        n = len(x)
        out = np.zeros((n, len(self.labels)))
        rows = np.flatnonzero(feasible)
        x0 = np.asarray(self.study.x0)
        sig, half = jnp.asarray(self.sigma), jnp.asarray(self.half)
        for a in range(0, rows.size, self.chunk):
            idx = rows[a:a + self.chunk]
            xs = np.empty((self.chunk, x.shape[1]))
            xs[:] = x0
            xs[:len(idx)] = x[idx]
            res = self._fn(jnp.asarray(xs), sig, half)
            metric_s, metric_w, metric_v, pts = (np.asarray(a_)[:len(idx)] for a_ in res)
            out[idx] = self._columns(metric_s, metric_w, metric_v, pts)
        out = np.where(np.isnan(out), 0.0, out)  # Cpk may be ±inf (σ = 0), never NaN
        self.seconds += time.perf_counter() - t0
        return out

    def _columns(self, s, w, v, pts):
        cols = []
        cpk = {i: (lo, hi) for i, lo, hi in self.cpk_rows}
        for i in range(s.shape[1]):
            cols += [s[:, i], w[:, i]]
            if i in cpk:
                cols.append(process_capability(v[:, i], s[:, i], *cpk[i]))
        for k in range(self.K):
            cols += [pts[:, k, c] for c in range(5)]
        return np.stack(cols, axis=1) if cols else np.zeros((len(s), 0))


def process_capability(mean, sigma, low: float, high: float):
    """Cpk = min(U − μ, μ − L) / (3σ) (a one-sided limit: its side only); +inf where σ = 0 and the
    mean lies within the limits, −inf where it lies outside."""
    mean = np.asarray(mean, float)
    sigma = np.asarray(sigma, float)
    gap = np.minimum(high - mean, mean - low)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(sigma > 0, gap / (3.0 * np.where(sigma > 0, sigma, 1.0)), np.where(gap >= 0, np.inf, -np.inf))


def reduce_first_order(J, v, sigma, half, groups: tuple, K: int, N: int, n_curve: int):
    """From one design's Jacobian `J` (M, T) and responses `v` (M,): (σ_RSS (S,), linear worst case
    (S,), value (S,) of the S scalar metrics; (K, 5) per point: the largest over the cycle of σ_RSS
    of P.x, P.y, of their linear worst cases, and the path's deviation bound) — see the module doc."""
    s = jnp.sqrt(jnp.sum((J * sigma) ** 2, axis=1))
    norms = jnp.stack([jnp.sqrt(jnp.sum(J[:, a:a + k] ** 2, axis=1)) for a, k in groups], axis=1)
    w = norms @ half
    if K:
        c = J[:2 * N * K].reshape(K, 2, N, -1)  # (K, xy, N, T)
        total = jnp.zeros((K, N), J.dtype)
        for (a, k), t in zip(groups, [half[g] for g in range(len(groups))]):
            if k == 1:
                size = jnp.sqrt(c[:, 0, :, a] ** 2 + c[:, 1, :, a] ** 2)
            else:  # the largest singular value of [[x_a, x_b], [y_a, y_b]]
                xa, xb, ya, yb = c[:, 0, :, a], c[:, 0, :, a + 1], c[:, 1, :, a], c[:, 1, :, a + 1]
                fro = xa * xa + xb * xb + ya * ya + yb * yb
                det = xa * yb - xb * ya
                size = jnp.sqrt(0.5 * (fro + jnp.sqrt(jnp.maximum(fro * fro - 4.0 * det * det, 0.0))))
            total = total + t * size
        sc = s[:2 * N * K].reshape(K, 2, N).max(axis=2)
        wc = w[:2 * N * K].reshape(K, 2, N).max(axis=2)
        pts = jnp.concatenate([sc, wc, total.max(axis=1)[:, None]], axis=1)
    else:
        pts = jnp.zeros((0, 5), J.dtype)
    return s[n_curve:], w[n_curve:], v[n_curve:], pts


def robust_evaluator(study) -> RobustEvaluator:
    """The study's `RobustEvaluator`, compiled once per study (and its `moved` copies with the same
    tolerance structure)."""
    key = tuple((t.parameters, t.zone) for t in study.inputs.tolerances) + (study.inputs.limits,)
    cache = study._robust_cache
    ev = cache.get(key)
    if ev is None or ev.study.inputs != study.inputs:
        if ev is not None:  # other tolerances' sizes or a moved design: the compiled function is kept
            import copy

            new = copy.copy(ev)
            new.study = study
            new.sigma = np.asarray([t.sigma for t in study.inputs.tolerances for _ in t.parameters])
            new.half = np.asarray([t.half_width for t in study.inputs.tolerances])
            new.seconds = 0.0
            ev = new
        else:
            ev = RobustEvaluator(study)
        cache[key] = ev
    return ev
