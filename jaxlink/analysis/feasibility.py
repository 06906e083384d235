"""Feasibility between samples: does a design assemble over its whole revolution, not only at
the checked inputs?

A path solve checks N inputs φ_k = φ₀ + k h (h = 2π/N). A dyad that cannot be assembled over a
window narrower than h, lying between two checked inputs, passes that check. The dyads' *reach
margin* m_j(φ) (`jaxlink.solvers.dyads.reach_margins`: the signed sin² of the angle between a
dyad's two links, negative exactly where it cannot be assembled) is a smooth function of the
input, so its minimum between samples can be found:

1. **screen** (`interval_minima`, cheap: the margins at the samples only): on every interval
   [φ_k, φ_k+1] (the last one closing the revolution, φ_N−1 → φ₀ + 2π) the parabolas through the
   samples k−1, k, k+1 and k, k+1, k+2 of each dyad's margin, minimized over the interval; the
   interval's estimate is the smaller of the two (per dyad, then over the dyads), and a
   conservative one subtracts the estimate's error (the parabolas' disagreement and the fourth
   difference of the samples). The searches require the conservative estimate ≥ 0 at every
   design (`screen`): a search pushes its designs up to that boundary, so it must lie on the
   assemblable side.
2. **certificate** (`certify`, per design, for the designs a search reports): on the `refine`
   intervals with the smallest estimates, the margin at 8 interior points, then a golden-section
   search (`steps` reductions by 0.618) on the bracket around the smallest of them; the
   certified margin is the smallest value found (samples, interior points, refined minima) and
   `where` its input. A design is certified iff that margin is ≥ −`MARGIN_SLACK` (an exact
   toggle, a margin negative by rounding, is assembled, as in the solver).

Everything is pure and jittable (`vmap` over designs); the margins are evaluated by the dyads'
closed form on the design's branches σ, so only mechanisms made of dyads (RRR, RRP, RPR, PP blocks)
have a certificate.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..solvers import dyads as _dyads
from ..solvers.branch_points import MARGIN_SLACK as MARGIN_SLACK  # one number: the certificate, the gaps
from .golden import GOLD as _GOLD
from .golden import golden


class Certificate(NamedTuple):
    """The smallest reach margin of a design over its revolution.

    **Fields** (scalars; leading axes of a batch):

    - `margin`: the smallest margin found (refined between samples), dimensionless;
    - `where`: the input value at which it was found (SI: rad);
    - `sampled`: the smallest margin at the checked inputs alone;
    - `certified`: `margin ≥ −MARGIN_SLACK`: the design assembles over the whole revolution.

    JAX arrays from `certify`, numpy from `certify_host`.
    """

    margin: jax.Array | np.ndarray
    where: jax.Array | np.ndarray
    sampled: jax.Array | np.ndarray
    certified: jax.Array | np.ndarray


def margins_at(mech, dyads, sigma, q_ref, phis, p):
    """(N, n_dyads) reach margins at the inputs `phis` (N,) on the branches σ (the sines and
    cosines of the inputs and the angle parameters computed once, vectorized)."""
    trig_p = _dyads.parameter_trig(mech, p)
    trig_in = _dyads.input_trig(mech, phis)
    return jax.vmap(lambda ph, t: _dyads.reach_margins(mech, dyads, sigma, q_ref, ph, p, {**t, **trig_p}))(
        phis, trig_in)


def _parabola(ma, mb, mc, lo, hi, xp=jnp):
    """The parabola through (−1, ma), (0, mb), (1, mc) as a function `val(t)`, and the three
    candidates of its minimum over t ∈ [lo, hi]: lo, hi and its vertex (lo where it is not convex).
    `xp`: `jax.numpy`, or `numpy` on the host (`certify_host`)."""
    a = 0.5 * (ma + mc) - mb
    b = 0.5 * (mc - ma)
    convex = a > 0
    t_star = xp.clip(-b / xp.where(convex, 2.0 * a, 1.0), lo, hi)

    def val(t):
        return a * t * t + b * t + mb

    lo_, hi_ = xp.broadcast_to(lo, a.shape), xp.broadcast_to(hi, a.shape)
    return val, (lo_, hi_, xp.where(convex, t_star, lo_))


def _parabola_min(ma, mb, mc, lo, hi, xp=jnp):
    """Minimum over t ∈ [lo, hi] of the parabola through (−1, ma), (0, mb), (1, mc), and its t."""
    val, cands = _parabola(ma, mb, mc, lo, hi, xp)
    cands = xp.stack(cands)
    vals = val(cands)
    i = xp.argmin(vals, axis=0)
    return xp.take_along_axis(vals, i[None], 0)[0], xp.take_along_axis(cands, i[None], 0)[0]


def _parabola_low(ma, mb, mc, lo, hi):
    """`_parabola_min`'s value alone, as the least of its three candidates' values (`jnp.minimum`,
    no argmin and gather: the same number, several times cheaper in a batch)."""
    val, (lo_, hi_, vertex) = _parabola(ma, mb, mc, lo, hi)
    return jnp.minimum(jnp.minimum(val(lo_), val(hi_)), val(vertex))


def interval_lower(m):
    """`interval_minima(m)[2]` (the conservative estimate, (N,)) alone, computed without the
    estimate's location: the same numbers (the least of the same candidates), the screen's form."""
    prev, nxt, nxt2, nxt3 = jnp.roll(m, 1, 0), jnp.roll(m, -1, 0), jnp.roll(m, -2, 0), jnp.roll(m, -3, 0)
    v1 = _parabola_low(prev, m, nxt, 0.0, 1.0)
    v2 = _parabola_low(m, nxt, nxt2, -1.0, 0.0)
    d4 = jnp.abs(prev - 4.0 * m + 6.0 * nxt - 4.0 * nxt2 + nxt3)
    low = jnp.minimum(v1, v2) - jnp.abs(v1 - v2) - d4 / 16.0
    return functools.reduce(jnp.minimum, [low[:, j] for j in range(low.shape[1])])  # over the dyads


def least(v):
    """The least element of the 1-D array `v` (as `jnp.min`; NaN where one is NaN), written
    `v[argmin v]`: XLA's CPU backend (jaxlib 0.10) fuses a plain min-reduction with the whole
    elementwise computation that produces its operand into one library kernel, which ran the
    batched screen 10× slower than computing the screen itself (0.35 s against 0.03 s for 4096
    designs × 360 positions); the arg-reduction is not fused that way."""
    return v[jnp.argmin(v)]


def interval_minima(m, xp=jnp):
    """Estimated minimum of the margin on every interval between samples, from the samples.

    **Arguments:** `m` (N, D) margins of D dyads at N equally spaced inputs of a revolution.

    **Returns:** `(estimate (N,), t (N,), lower (N,))`: on interval k (from sample k to sample
    k+1, the last one closing the revolution) the smallest over the dyads of the smaller minimum
    of the two parabolas (through samples k−1, k, k+1 and k, k+1, k+2, periodic), where, as a
    fraction t ∈ [0, 1] of the interval, and a conservative `lower` estimate: per dyad that
    minimum less the two parabolas' disagreement |v₁ − v₂| (≈ h³ m‴, the cubic term: the true
    margin lies between the two parabolas to that order) and |δ⁴m| / 16, the fourth difference
    δ⁴m = m_k−1 − 4 m_k + 6 m_k+1 − 4 m_k+2 + m_k+3 ≈ h⁴ m⁗ (the quartic term, which dominates
    where the margin is symmetric about its minimum: for m = b x⁴ sampled at ±h/2, ±3h/2 the
    parabola's minimum misses by 9/16 |b| h⁴ = |δ⁴m| × 9/384, 2.7 times less than |δ⁴m| / 16).
    `xp`: `jax.numpy`, or `numpy` on the host (`certify_host`)."""
    prev, nxt, nxt2, nxt3 = xp.roll(m, 1, 0), xp.roll(m, -1, 0), xp.roll(m, -2, 0), xp.roll(m, -3, 0)
    v1, t1 = _parabola_min(prev, m, nxt, 0.0, 1.0, xp)  # centred on k: t ∈ [0, 1]
    v2, t2 = _parabola_min(m, nxt, nxt2, -1.0, 0.0, xp)  # centred on k+1: t − 1 ∈ [−1, 0]
    t2 = t2 + 1.0
    v = xp.minimum(v1, v2)
    t = xp.where(v1 <= v2, t1, t2)
    d4 = xp.abs(prev - 4.0 * m + 6.0 * nxt - 4.0 * nxt2 + nxt3)
    lower = xp.min(v - xp.abs(v1 - v2) - d4 / 16.0, axis=1)
    j = xp.argmin(v, axis=1)
    return xp.take_along_axis(v, j[:, None], 1)[:, 0], xp.take_along_axis(t, j[:, None], 1)[:, 0], lower


def screen(mech, dyads, sigma, q_ref, phis, p):
    """(N,) conservative estimate of the smallest margin on each interval between the equally
    spaced inputs `phis` of a revolution (`interval_minima`'s `lower` of `margins_at`): < 0
    where a dyad opens, or is about to open, an unassemblable window between two checked
    inputs. Cheap: N closed-form solves."""
    return interval_lower(margins_at(mech, dyads, sigma, q_ref, phis, p))


def certify(mech, dyads, sigma, q_ref, phis, p, *, refine: int = 8, steps: int = 40) -> Certificate:
    """The certificate of one design (see the module doc) over the revolution sampled by the
    equally spaced inputs `phis` (N,), on the dyads' branches σ (`q_ref`: the angles' reference,
    as in `jaxlink.solvers.dyads.solve`). `refine`, `steps` static. Pure; `vmap` over designs."""
    n = phis.shape[0]
    h = 2.0 * jnp.pi / n

    def margin(phi):
        return jnp.min(_dyads.reach_margins(mech, dyads, sigma, q_ref, phi, p))

    m = margins_at(mech, dyads, sigma, q_ref, phis, p)
    sampled = jnp.min(m)
    est, _, _ = interval_minima(m)
    k = min(int(refine), n)
    _, idx = jax.lax.top_k(-est, k)  # the intervals with the smallest estimates

    def refined(i):
        a = phis[i]
        inner = a + h * jnp.arange(1, 9) / 9.0
        vals = jax.vmap(margin)(inner)
        j = jnp.argmin(vals)
        lo, hi = inner[j] - h / 9.0, inner[j] + h / 9.0

        def body(_, st):
            lo, hi, x1, x2, f1, f2 = st
            left = f1 <= f2  # the minimum is in [lo, x2]
            nlo, nhi = jnp.where(left, lo, x1), jnp.where(left, x2, hi)
            nx1 = jnp.where(left, nhi - _GOLD * (nhi - nlo), x2)
            nx2 = jnp.where(left, x1, nlo + _GOLD * (nhi - nlo))
            fnew = margin(jnp.where(left, nx1, nx2))
            return (nlo, nhi, nx1, nx2, jnp.where(left, fnew, f2), jnp.where(left, f1, fnew))

        x1, x2 = hi - _GOLD * (hi - lo), lo + _GOLD * (hi - lo)
        lo, hi, x1, x2, f1, f2 = jax.lax.fori_loop(0, steps, body, (lo, hi, x1, x2, margin(x1), margin(x2)))
        cand = jnp.stack([vals[j], f1, f2])
        where = jnp.stack([inner[j], x1, x2])
        c = jnp.argmin(cand)
        return cand[c], where[c]

    vals, wheres = jax.vmap(refined)(idx)
    r = jnp.argmin(vals)
    ks = jnp.argmin(jnp.min(m, axis=1))
    better = vals[r] < sampled
    best = jnp.where(better, vals[r], sampled)
    where = jnp.where(better, wheres[r], phis[ks])
    return Certificate(best, where, sampled, best >= -MARGIN_SLACK)


def certify_host(margins, phis, *, refine: int = 8, steps: int = 40) -> Certificate:
    """`certify` on the host: the same steps (the margins at the samples, the `refine` intervals
    with the smallest estimates, 8 interior points each, `steps` golden-section reductions), with
    the margins from `margins(x)` (numpy (M,) inputs → (M, n_dyads) margins, e.g. one small
    compiled program called in fixed blocks: `jaxlink.analysis.motion`), every evaluation of a
    step batched over the intervals. For one design whose program is compiled for this alone (a
    command's `check`) it compiles only `margins`: `certify`'s program traced and compiled five
    instances of the margins. Returns numpy scalars."""
    phis = np.asarray(phis)
    n = phis.shape[0]
    h = 2.0 * np.pi / n

    def margin(x):
        return np.min(np.asarray(margins(x)), axis=1)

    m = np.asarray(margins(phis))
    sampled = np.min(m)
    est = interval_minima(m, np)[0]
    k = min(int(refine), n)
    idx = _smallest(est, k)
    inner = phis[idx][:, None] + h * np.arange(1, 9)[None, :] / 9.0  # (k, 8)
    vals = margin(inner.ravel()).reshape(inner.shape)
    j = np.argmin(vals, axis=1)
    rows = np.arange(k)
    vj, xj = vals[rows, j], inner[rows, j]
    x1, x2, f1, f2 = golden(margin, xj - h / 9.0, xj + h / 9.0, steps)
    cand = np.stack([vj, f1, f2])  # (3, k)
    where = np.stack([xj, x1, x2])
    c = np.argmin(cand, axis=0)
    vals_r, wheres_r = cand[c, rows], where[c, rows]
    r = np.argmin(vals_r)
    ks = np.argmin(np.min(m, axis=1))
    better = vals_r[r] < sampled
    best = vals_r[r] if better else sampled
    at = wheres_r[r] if better else phis[ks]
    return Certificate(np.asarray(best), np.asarray(at), np.asarray(sampled), np.asarray(best >= -MARGIN_SLACK))


def _smallest(est, k: int):
    """The indices of the `k` smallest of `est`, least first (`jax.lax.top_k` of −est: of equal
    values the first)."""
    return np.argsort(est, kind="stable")[:k]
