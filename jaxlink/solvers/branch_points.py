"""Branch points between the samples of a solved path: change points and toggles of the dyads.

A dyad (`_dyads`) of links L_a, L_b over its known vector w has two assembly branches σ = ±1
that meet where the two links are collinear. How its margin

    S(φ) = sin² of the angle between the two links, signed (`jaxlink.solvers.dyads.reach_margins`):
    RRR: ((L_a + L_b)² − |w|²)(|w|² − (L_a − L_b)²) / (4 L_a² L_b²);
    RRP: 1 − (w × e_b)² / L_a² (the link against the slider's normal); RPR: 1 − e² / |w|² (the
    slot against the line from its pivot, e the slot's offset); PP: (e_a × e_b)²,

a smooth (polynomial) function of the input along a path, meets zero tells what lies there:

- a **change point** (bifurcation): S touches zero and stays ≥ 0 on both sides, S ≈ c (φ − φ*)².
  Two smooth branches cross there (the Peaucellier cell's flat rhombus: D = C and D on its line;
  a Grashof four-bar with s + l = p + q folding flat: parallelogram and antiparallelogram). The
  closed form on a kept side σ goes on along the *other* smooth branch (its velocity jumps); the
  smooth continuation flips σ there;
- a **toggle** (limit position): S crosses zero, S ≈ c (φ − φ*); past it the dyad cannot be
  assembled and the input cannot go on;
- a **gap**: two toggles between two samples that both assemble, S dipping below zero between
  them (a window narrower than the samples' spacing: a four-bar just off s + l = p + q). Its
  minimum looks like a change point's from the samples; only its value tells them apart.

Between two consecutive samples k, k+1 (φ along the path, both assembled, σ of sample k for the
dyads solved before) a change point is looked for where S′ goes from < 0 to ≥ 0 (a minimum of S
inside) and located as the root of S′ by Newton's method on S′ (S″ by forward-mode AD),
safeguarded by bisection in the bracket; it is a gap when S there is below −max(singular_ratio²,
`MARGIN_SLACK`) (negative by more than rounding; the slack is the searches' certificate's, so that
a design it certifies has no gap here), its toggles then located as the roots of S in the two
brackets either side of the minimum; else a change point when the sine there is below
`singular_ratio` (the same threshold as a `singular` position). A toggle is looked for between an
assembled and a not assembled sample where S changes sign, located as the root of S the same way.
The roots are simple, so Newton converges quadratically: the location is exact to a few ulp of
the input (measured within 1e-15 rad of the closed forms, gaps' toggles within 2e-13 rad,
tests/test_branch_points.py).

`locate` is pure and batched over the intervals (`vmap`, one `while_loop` per interval, which
stops at once where there is nothing to locate): no raising, a `kind` code per (interval, dyad).
`smooth_sides` gives, per sample, the sides σ of the smooth continuation through every change
point (the closed form's schedule for `NewtonOptions(change_points="smooth")`).

Only structures whose blocks are all dyads (`_dyads.classify`) are covered; elsewhere (a block of
more than two unknowns) there is nothing to locate (D = 0 columns). A change point of an earlier
dyad in the same interval as one of a later dyad is located for the earlier one only correctly.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..model.mechanism import Mechanism
from . import dyads as _dyads

NONE, CHANGE_POINT, TOGGLE, GAP = 0, 1, 2, 3
KINDS = {NONE: "none", CHANGE_POINT: "change point", TOGGLE: "toggle", GAP: "gap"}
MAX_ITERATIONS = 60  # safeguarded Newton per interval (bisection alone reaches 2^-60 of the interval)
#: a reach margin this much below zero still counts as assembled (rounding at an exact toggle or
#: change point): the searches' certificate (`jaxlink.analysis.feasibility`) and, in float64, the
#: depth below which a minimum of the margin between two samples is a gap rather than a change point
MARGIN_SLACK = 1e-12


class BranchPoints(NamedTuple):
    """Branch points located between consecutive samples: one entry per (interval, dyad), shape
    (…, N − 1, D); interval k lies between `phis[k]` and `phis[k + 1]`, dyads in solve order.

    - `input`: the located input (rad, or m for a length input); NaN where `kind` is `NONE`.
    - `kind`: int8, `NONE` (0), `CHANGE_POINT` (1) or `TOGGLE` (2) (`KINDS` names them).
    - `smooth`: at a change point, whether the solved path crossed it smoothly (the dyad's side σ
      differs between the two samples: the branch whose velocity is continuous); False where it
      kept its side (the closed form's default: the other branch, its velocity jumps).
    - `step`: the last Newton correction of the location, an estimate of its error (same unit).
    - `end`: at a gap, its second toggle (where the dyad assembles again, in the path's order);
      `input` is then the first. NaN elsewhere.

    `kind` `GAP` (3): both samples assemble but the dyad does not between them, from the toggle
    `input` to the toggle `end` (a window narrower than the samples' spacing; not a change point).
    """

    input: jax.Array | np.ndarray
    kind: jax.Array | np.ndarray
    smooth: jax.Array | np.ndarray
    step: jax.Array | np.ndarray
    end: jax.Array | np.ndarray


def margin(mech: Mechanism, dyads, j: int, sigma, q_ref, phi, p):
    """S of dyad j at input φ, the dyads before it in closed form on their sides σ (D,): the reach
    margin of `jaxlink.solvers.dyads.reach_margins` (one formula for the certificate of the
    searches and for the branch points)."""
    return _dyads.reach_margins(mech, dyads[:j + 1], sigma[:j + 1], q_ref, phi, p)[j]


def _interval_ends(phis, q, sigmas, assembled):
    """Per interval k (between samples k and k + 1): its ends `a`, `b`, whether each is assembled,
    and the sides σ and unknowns q of the assembled end (the left one where both are), which the
    closed form continues."""
    ok_a, ok_b = assembled[:-1], assembled[1:]
    use_b = ~ok_a & ok_b
    sig = jnp.where(use_b[:, None], sigmas[1:], sigmas[:-1])
    qr = jnp.where(use_b[:, None], q[1:], q[:-1])
    return phis[:-1], phis[1:], ok_a, ok_b, sig, qr


def _jets(f, x):
    """(S, S′, S″) at x, by nested forward-mode AD."""
    one = jnp.ones_like(x)
    (v, d1), (_, d2) = jax.jvp(lambda y: jax.jvp(f, (y,), (one,)), (x,), (one,))
    return v, d1, d2


def _root(F, lo, hi, Flo, Fhi, x0, active):
    """The root of F in the bracket [lo, hi] (F(lo), F(hi) of opposite signs or one zero) by
    Newton's method from x0, each step kept inside the bracket (else bisection), the bracket shrunk
    at every evaluation. `F(x) -> (F, F′)`. Stops when the step is at the rounding of x or after
    `MAX_ITERATIONS`. Returns `(root, |last step|)`; no iteration where not `active`."""
    dtype = jnp.result_type(lo)
    eps = float(np.finfo(dtype).eps)
    s = jnp.where(Flo <= 0, 1.0, -1.0)  # s F(lo) ≤ 0 ≤ s F(hi)
    del Fhi

    def cond(st):
        return ~st[5] & (st[0] < MAX_ITERATIONS)

    def body(st):
        k, x, lo, hi, _, _ = st
        v, dv = F(x)
        neg = s * v < 0
        lo, hi = jnp.where(neg, x, lo), jnp.where(neg, hi, x)
        newton = x - v / jnp.where(dv != 0, dv, 1.0)
        inside = (dv != 0) & jnp.isfinite(newton) & (newton > lo) & (newton < hi)
        x_new = jnp.where(v == 0, x, jnp.where(inside, newton, 0.5 * (lo + hi)))
        step = jnp.abs(x_new - x)
        tiny = 4 * eps * jnp.maximum(jnp.abs(x), 1.0)
        done = (step <= tiny) | (hi - lo <= tiny) | ~jnp.isfinite(v)
        return k + 1, x_new, lo, hi, step, done

    init = (jnp.zeros((), jnp.int32), x0, lo, hi, jnp.asarray(jnp.inf, dtype), ~active)
    _, x, _, _, step, _ = jax.lax.while_loop(cond, body, init)
    return x, step


def _secant(lo, hi, Flo, Fhi):
    """The secant root of a bracket, the midpoint where it is not defined or outside."""
    den = Fhi - Flo
    x0 = jnp.where(den != 0, lo - Flo * (hi - lo) / jnp.where(den != 0, den, 1.0), 0.5 * (lo + hi))
    return jnp.where((x0 > lo) & (x0 < hi), x0, 0.5 * (lo + hi))


def sides(mech: Mechanism, dyads, q, phis, p):
    """(N, D) the side σ of every dyad at each solved sample `q` (N, n) (`_dyads.solve_nearest`)."""
    return jax.vmap(lambda qq, ph: _dyads.solve_nearest(mech, dyads, qq, ph, p)[3])(q, phis)


def locate(mech: Mechanism, dyads, sigmas, q, phis, p, assembled, singular_ratio: float,
           only: int | None = None) -> BranchPoints:
    """Branch points between consecutive samples of one design's path (see the module docstring).

    **Arguments:** `sigmas` (N, D) the side of every dyad at each sample; `q` (N, n) the solved
    unknowns (a reference for the angles only); `phis` (N,) the inputs; `p` (P,); `assembled` (N,)
    bool (converged or singular); `singular_ratio`: the sine below which a minimum of S is a change
    point (static); `only`: locate for this dyad only (the others `NONE`).

    **Returns:** `BranchPoints`, (N − 1, D) each."""
    dtype = jnp.result_type(phis)
    D = len(dyads)
    a, b, ok_a, ok_b, sig, qr = _interval_ends(phis, q, sigmas, assembled)
    thr2 = float(singular_ratio) ** 2
    slack = max(thr2, MARGIN_SLACK)  # a minimum of S below −slack is a gap (two toggles)

    def one_dyad(j):
        def interval(sg, qq, x0, x1, oa, ob):
            f = lambda x: margin(mech, dyads, j, sg, qq, x, p)  # noqa: E731
            lo, hi = jnp.minimum(x0, x1), jnp.maximum(x0, x1)
            # (S, S′) at both ends: a minimum of S inside (S′ from < 0 to ≥ 0), or S changing sign
            S_lo, d_lo = jax.jvp(f, (lo,), (jnp.ones_like(lo),))
            S_hi, d_hi = jax.jvp(f, (hi,), (jnp.ones_like(hi),))
            change = oa & ob & (d_lo < 0) & (d_hi >= 0)
            toggle = (oa != ob) & ((S_lo > 0) != (S_hi > 0))
            if j:  # a toggle of this dyad only where the dyads before it assemble at both ends
                before = jnp.stack([margin(mech, dyads, i, sg, qq, x, p) for i in range(j) for x in (lo, hi)])
                toggle = toggle & jnp.all(before > 0)
            toggle = toggle & ~change
            # the root sought: of S′ (a change point, a minimum of S) or of S (a toggle); one loop
            F_lo, F_hi = jnp.where(change, d_lo, S_lo), jnp.where(change, d_hi, S_hi)

            def F(x):
                v, d1, d2 = _jets(f, x)
                return jnp.where(change, d1, v), jnp.where(change, d2, d1)

            x, step = _root(F, lo, hi, F_lo, F_hi, _secant(lo, hi, F_lo, F_hi), change | toggle)
            S_x = f(x)
            # a minimum below zero by more than rounding is a window that cannot be assembled: a gap
            is_gap = change & (S_x < -slack)
            is_change = change & (S_x <= thr2) & ~is_gap

            def G(y):  # (S, S′): the gap's two toggles are roots of S on either side of its minimum
                return jax.jvp(f, (y,), (jnp.ones_like(y),))

            g_lo, st_lo = _root(G, lo, x, S_lo, S_x, _secant(lo, x, S_lo, S_x), is_gap)
            g_hi, st_hi = _root(G, x, hi, S_x, S_hi, _secant(x, hi, S_x, S_hi), is_gap)
            forward = x1 >= x0  # the gap's toggles in the path's order: `input` reached first
            first, second = jnp.where(forward, g_lo, g_hi), jnp.where(forward, g_hi, g_lo)
            kind = jnp.where(is_gap, GAP, jnp.where(is_change, CHANGE_POINT, jnp.where(toggle, TOGGLE, NONE)))
            kind = kind.astype(jnp.int8)
            found = kind != NONE
            x = jnp.where(is_gap, first, x)
            step = jnp.where(is_gap, jnp.maximum(st_lo, st_hi), step)
            return (jnp.where(found, x, jnp.nan), kind, jnp.where(found, step, jnp.nan),
                    jnp.where(is_gap, second, jnp.nan))

        return jax.vmap(interval)(sig, qr, a, b, ok_a, ok_b)

    cols = []
    for j in range(D):
        if only is not None and j != only:
            n = a.shape[0]
            nan = jnp.full((n,), jnp.nan, dtype)
            cols.append((nan, jnp.zeros((n,), jnp.int8), nan, nan))
        else:
            cols.append(one_dyad(j))
    if D == 0:
        n = a.shape[0]
        empty = jnp.zeros((n, 0), dtype)
        return BranchPoints(empty, jnp.zeros((n, 0), jnp.int8), jnp.zeros((n, 0), bool), empty, empty)
    x, kind, step, end = (jnp.stack([c[i] for c in cols], axis=1) for i in range(4))
    smooth = (kind == CHANGE_POINT) & (sigmas[:-1] != sigmas[1:])
    return BranchPoints(x, kind, smooth, step, end)


def smooth_sides(mech: Mechanism, dyads, sigma0, q_ref, phis, phi_ref, p, tol, singular_ratio: float):
    """(N, D) the sides σ of the smooth continuation through the inputs `phis` from the sides
    `sigma0` at `phi_ref` (where the guess selected them). Dyad by dyad in solve order (a later
    dyad's margin depends on the earlier dyads' sides), σ_j flips at every change point of dyad j
    located between consecutive inputs, counted from the input nearest to `phi_ref` (and between
    `phi_ref` and it: at most one there, exact when `phi_ref` lies within a step of it). `tol`: an
    input is assembled where the closed form's loops close to it."""
    N, D = phis.shape[0], len(dyads)
    k0 = jnp.argmin(jnp.abs(phis - phi_ref))
    anchor = jnp.stack([jnp.asarray(phi_ref, phis.dtype), phis[k0]])

    def assembled(inputs):
        return jax.vmap(lambda ph: _dyads.solve(mech, dyads, sigma0, q_ref, ph, p)[2] <= tol)(inputs)

    # the intervals of `phis`, then (junk) phis[-1] → phi_ref, then the anchor phi_ref → phis[k0]:
    # one `locate` per dyad
    inputs = jnp.concatenate([phis, anchor])
    ok = assembled(inputs)
    sig = jnp.broadcast_to(sigma0, (N + 2, D))
    qs = jnp.broadcast_to(q_ref, (N + 2,) + q_ref.shape)
    for j in range(D):
        change = locate(mech, dyads, sig, qs, inputs, p, ok, singular_ratio, only=j).kind[:, j] == CHANGE_POINT
        count = jnp.concatenate([jnp.zeros((1,), jnp.int32), jnp.cumsum(change[:N - 1].astype(jnp.int32))])
        parity = (count - count[k0] + change[N].astype(jnp.int32)) % 2
        col = sigma0[j] * jnp.where(parity == 1, -1.0, 1.0).astype(sig.dtype)
        sig = sig.at[:, j].set(jnp.concatenate([col, jnp.stack([sigma0[j], col[k0]])]))
    return sig[:N]


def _candidates(mech, dyads, sigmas, phis, q, p, assembled):
    """(N − 1, D) bool: the intervals where `locate` may find something, from S and S′ at the
    samples only (one forward derivative, no iteration). A minimum of S inside (S′ from < 0 to ≥ 0)
    is kept only where S could reach zero there: a change point has S ≈ c (φ − φ*)², so that
    φ − 2 S / S′ from either end predicts φ*; a minimum well above zero (a crank-rocker's least
    transmission angle) predicts a point far outside the interval and is left out. A toggle is
    kept where S changes sign between an assembled and a not assembled sample."""
    a, b, ok_a, ok_b, sig, qr = _interval_ends(phis, q, sigmas, assembled)

    def one(j):
        def interval(sg, qq, x0, x1, oa, ob):
            f = lambda x: margin(mech, dyads, j, sg, qq, x, p)  # noqa: E731
            lo, hi = jnp.minimum(x0, x1), jnp.maximum(x0, x1)
            S_lo, d_lo = jax.jvp(f, (lo,), (jnp.ones_like(lo),))
            S_hi, d_hi = jax.jvp(f, (hi,), (jnp.ones_like(hi),))
            h = hi - lo
            near = []
            for x, S, d in ((lo, S_lo, d_lo), (hi, S_hi, d_hi)):
                guess = x - 2.0 * S / jnp.where(d != 0, d, 1.0)
                near.append((d == 0) | ((guess >= lo - 2 * h) & (guess <= hi + 2 * h)))
            change = oa & ob & (d_lo < 0) & (d_hi >= 0) & (near[0] | near[1])
            toggle = (oa != ob) & ((S_lo > 0) != (S_hi > 0))
            return change | toggle
        return jax.vmap(interval)(sig, qr, a, b, ok_a, ok_b)

    if not dyads:
        return jnp.zeros((a.shape[0], 0), bool)
    return jnp.stack([one(j) for j in range(len(dyads))], axis=1)


def candidates(mech: Mechanism, phis, q, p, result):
    """The first stage of `branch_points`, pure (for use inside the caller's traced function):
    `(candidates (N − 1, D) bool, sides (N, D))` from a solved path's `q` (N, n) and result codes
    (N,): the intervals where a branch point may lie and the dyads' side at each sample. D = 0
    where not every block is a dyad."""
    dyads = _dyads.classify(mech)
    n = phis.shape[0]
    if dyads is None or n < 2:
        d = 0 if dyads is None else len(dyads)
        return jnp.zeros((max(n - 1, 0), d), bool), jnp.zeros((n, d), jnp.result_type(phis))
    assembled = (result == 0) | (result == 2)
    sg = sides(mech, dyads, q, phis, p)
    return _candidates(mech, dyads, sg, phis, q, p, assembled), sg


@functools.partial(jax.jit, static_argnums=(0,))
def _stage_candidates(structure, phis, q, p, assembled):
    dyads = _dyads.classify(structure)
    sg = sides(structure, dyads, q, phis, p)
    return _candidates(structure, dyads, sg, phis, q, p, assembled), sg


@functools.partial(jax.jit, static_argnums=(0, 6))
def _stage_locate(structure, phis, q, p, assembled, sg, thr):
    return locate(structure, _dyads.classify(structure), sg, q, phis, p, assembled, thr)


def singular_ratio_default(dtype) -> float:
    """10 √eps of the dtype: the default `NewtonOptions.singular_ratio`."""
    return float(10 * np.sqrt(np.finfo(dtype).eps))


def branch_points(mech: Mechanism, phis, solution, p=None, *, singular_ratio: float | None = None,
                  candidates=None) -> BranchPoints:
    """The branch points (change points, toggles) between consecutive samples of a solved path.

    **Arguments:**

    - `mech`: the mechanism; every block of its structure a dyad (else nothing is located: D = 0).
    - `phis`: (N,) the inputs of the solve, in its order (SI).
    - `solution`: the `Solution` of `jaxlink.solve(mech, phis, p)` (one design).
    - `p`: (P,) the parameters of that solve (default `mech.parameters`).
    - `singular_ratio`: the sine between a dyad's links below which a located minimum is a change
      point (default 10 √eps, as `NewtonOptions`).
    - `candidates`: the first stage's `(candidates, sides)` if already computed for this solution
      (`jaxlink.solvers.branch_points.candidates` inside one's own traced function).

    **Returns:** `BranchPoints` (numpy, (N − 1, D) each; `kind` 0 none, 1 change point, 2 toggle),
    located to a few ulp of the input by safeguarded Newton on the smooth margin S (the squared
    sine between the dyad's links): on S′ at a change point, on S at a toggle. Two compiled
    stages: S and S′ at the samples pick the intervals (a cheap test), and only if there are any is
    the location compiled and run. Not for use inside `jit` (it decides on the host); the pure
    function is `jaxlink.solvers.branch_points.locate`.
    """
    p = np.asarray(mech.parameters if p is None else p)
    dtype = p.dtype if np.issubdtype(p.dtype, np.floating) else np.result_type(float)
    phis = jnp.asarray(phis, dtype=dtype)
    q = jnp.asarray(solution.q, dtype=dtype)
    res = np.asarray(solution.result)
    N = phis.shape[0]
    dyads = _dyads.classify(mech)
    D = 0 if dyads is None else len(dyads)
    nan = np.full((max(N - 1, 0), D), np.nan, dtype)
    empty = BranchPoints(nan, np.zeros((max(N - 1, 0), D), np.int8), np.zeros((max(N - 1, 0), D), bool), nan, nan)
    if D == 0 or N < 2:
        return empty
    assembled = jnp.asarray((res == 0) | (res == 2))
    pj = jnp.asarray(p, dtype=dtype)
    if candidates is None:
        cand, sg = _stage_candidates(mech.structure, phis, q, pj, assembled)
    else:
        cand, sg = (jnp.asarray(x) for x in candidates)
    if not bool(np.any(np.asarray(cand))):
        return empty
    thr = singular_ratio_default(dtype) if singular_ratio is None else float(singular_ratio)
    out = _stage_locate(mech.structure, phis, q, pj, assembled, sg, thr)
    return BranchPoints(*(np.asarray(x) for x in out))
