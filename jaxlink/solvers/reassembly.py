"""Re-assembly on the circuit kept: the branch rule of the Newton path.

- **re-assembly (the branch rule)**: at the first position, after a failed position (e.g. past the
  reach of a non-Grashof linkage) and where a continuation step fails, the position is assembled
  afresh *on the circuit kept* (that of the guess until a position converges, then of the last
  converged one): from the closed form of the dyads where every block is one, else by
  step-limited Newton from the last converged q and from the file's guess, with deflation of a
  solution found on another circuit (`_reassemble`). So every window of inputs where the linkage
  can be assembled is found, on the branch the closed form keeps;
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..model.mechanism import Mechanism
from ..results import RESULTS
from . import dyads as _dyads
from .fusion import batched_like
from .linalg import solve_small
from .newton import _linear_solve, _units, newton


class _Track(NamedTuple):
    """The continuation state of one design: the last (up to three) converged positions, newest
    first (`hq`, `hph`, `ng` of them valid), the circuit to keep (`sign_ref`: sign of det of each
    diagonal block of Φ_q; 0 = not known yet, any circuit), the code of the last position, and the
    guess of the file (`q_file`, a candidate of every re-assembly)."""

    hq: tuple
    hph: tuple
    ng: jax.Array
    sign_ref: jax.Array
    last: jax.Array
    q_file: jax.Array


def _circuit(mech: Mechanism, q, phi, p):
    """Sign of det of each diagonal block of Φ_q at (q, φ): the circuit (assembly branch) of q."""
    jac = jax.jacfwd(mech.residual)(q, phi, p)
    return _linear_solve(mech, signs=True)(jac, jnp.zeros_like(q))[2]


def _track_start(mech: Mechanism, q0, phi, p) -> _Track:
    """The state before the first position: nothing converged, the guess `q0` (holding at `phi`)
    selects the circuit: the sign of det of each block of Φ_q at the guess, or, when every block is
    a dyad, at the closed form on the branches nearest to the guess (`_dyads.solve_nearest`, as the
    closed-form path chooses them); 0 (any circuit) where that is singular."""
    dyads = _dyads.classify(mech)
    q_sel = q0 if dyads is None else _dyads.solve_nearest(mech, dyads, q0, phi, p)[0]
    sg = _circuit(mech, q_sel, phi, p)
    sg = jnp.where(jnp.isfinite(sg), sg, 0.0)
    return _Track((q0, q0, q0), (phi, phi, phi), jnp.zeros((), jnp.int32), sg,
                  jnp.asarray(RESULTS.cannot_assemble, jnp.int8), q0)


def _same_circuit(sg, sign_ref):
    return jnp.all((sg == sign_ref) | (sign_ref == 0))


def _deflated_newton(mech: Mechanism, q, phi, p, roots, active, unit, scale, max_steps):
    """Newton on the deflated residual M(q) = Φ(q) Π_i (1 / |(q − r_i) / unit|² + 1) over the
    `active` roots r_i (Farrell, Birkisson & Funke's deflation: M has the zeros of Φ except the
    r_i, so Newton from a guess near a known root finds another one), step-limited (0.5 rad, 0.5 ×
    the length scale). Zero iterations when no root is active. Returns q (not polished)."""
    dtype = jnp.result_type(q)
    n_active = jnp.sum(active.astype(jnp.int32))

    def m(x):
        d2 = jnp.sum(((x[None, :] - roots) / unit) ** 2, axis=1)
        fac = jnp.prod(jnp.where(active, 1.0 / jnp.maximum(d2, 1e-300) + 1.0, 1.0))
        return mech.residual(x, phi, p) * fac

    def body(st):
        k, x, _ = st
        val = m(x)
        jac = jax.jacfwd(m)(x)
        dx, _ = solve_small(jac, val)
        dqa = jnp.max(jnp.abs(dx) / unit)
        ok = jnp.all(jnp.isfinite(dx))
        dx = jnp.where(ok, dx * jnp.minimum(1.0, 0.5 / jnp.maximum(dqa, 1e-30)), 0.0)
        rn = jnp.max(jnp.abs(mech.residual(x - dx, phi, p)))
        return k + 1, x - dx, ~ok | (rn <= 1e-6 * scale)

    init = batched_like((jnp.zeros((), jnp.int32), q, n_active == 0), q, phi, p, roots, active, max_steps)
    out = jax.lax.while_loop(lambda st: (~st[2]) & (st[0] < max_steps), body, init)
    return out[1].astype(dtype)


def _reassemble(mech, opts, p, phi, st: _Track, tol, kw, active):
    """A position after one that did not assemble: a fresh assembly instead of an extrapolation
    across the gap, on the circuit `st.sign_ref` (each block's sign of det Φ_q: for a dyad, the
    side of its known vector that its first link lies on, the branch σ of `_dyads`).

    For a structure that is not all dyads (a dyadic one re-assembles from the closed form inside
    the continuation step, `continuation._advance`): the candidates are the last converged q and the
    file's guess, each by step-limited Newton; a candidate that converges on another circuit is
    deflated (`_deflated_newton`) and the search goes on from the candidates with the roots found
    so far removed, up to twice the number of candidates in all. Returns `(q, rnorm, result,
    steps, signs)`; `max_steps` where only another circuit was found (the branch is kept, never
    switched). No iteration where not `active`."""
    assert _dyads.classify(mech) is None, "a dyadic linkage re-assembles inside the continuation step (_advance)"
    dtype = jnp.result_type(st.hq[0])
    scale = mech.length_scale(p)
    unit = _units(mech, scale, dtype)
    cands = [st.hq[0], st.q_file]
    C = jnp.stack(cands)
    nc = len(cands)
    T = 2 * nc
    n = C.shape[1]

    def cond(s):
        t, done, nroots = s[0], s[1], s[4]
        return (~done) & ((t < nc) | ((nroots > 0) & (t < T)))

    def body(s):
        t, _, out, roots, nroots, ksum = s
        live = jnp.arange(T) < nroots
        i = t % nc
        guess = C[i]
        plain = nroots == 0
        # a plain try from the same guess as the first one would only repeat it
        skip = plain & (i > 0) & jnp.all(guess == C[0])
        qd = _deflated_newton(mech, guess, phi, p, roots, live, unit, scale, opts.max_steps_first)
        q, rn, code, k, sg = newton(mech, qd, phi, p, tol=jnp.where(skip, jnp.nan, tol), limit_step=plain,
                                    max_steps=jnp.where(plain, opts.max_steps_first, opts.max_steps), **kw)
        ksum = ksum + k
        conv = code == RESULTS.converged
        ok = (code == RESULTS.singular) | (conv & _same_circuit(sg, st.sign_ref))
        other = conv & ~ok
        # what to report if nothing better is found: a position on another circuit (`max_steps`)
        # over a failure
        better = ~skip & (ok | (other & (out[2] != RESULTS.max_steps)) | (t == 0))
        rep = (q, rn, jnp.where(other, jnp.asarray(RESULTS.max_steps, jnp.int8), code), ksum, sg)
        out = jax.tree_util.tree_map(lambda a, b: jnp.where(better, a, b), rep, out)
        out = out[:3] + (ksum,) + out[4:]
        roots = jnp.where((jnp.arange(T)[:, None] == nroots) & other, q[None, :], roots)
        nroots = nroots + other.astype(jnp.int32)
        return t + 1, ok, out, roots, nroots, ksum

    zero = jnp.zeros((), jnp.int32)
    out0 = (st.hq[0], jnp.asarray(jnp.inf, dtype), jnp.asarray(RESULTS.cannot_assemble, jnp.int8), zero,
            st.sign_ref)
    init = batched_like((zero, ~jnp.asarray(active), out0, jnp.zeros((T, n), dtype), zero, zero), st, phi, p, tol,
                        active)
    return jax.lax.while_loop(cond, body, init)[2]
