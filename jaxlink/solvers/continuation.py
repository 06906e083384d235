"""Newton with continuation along the inputs of one design (`"continuation"`, `"independent"`, and
`"auto"` for structures that are not all dyads).

- **first position**: Newton from the guess q0, with a step limit (0.5 rad for angles, 0.5 × the
  length scale for lengths) so that a rough guess does not jump to another branch;
- **lead-in**: with the file's guesses, from `[input] start` to the first input, by the same
  continuation; for a 2π-periodic input (`periodic_input`: a crank) reduced to at most half a
  revolution, else at most `MAX_LEAD_IN` steps (`_lead_in_inputs`): bounded, never a hang;
- **continuation**: position k starts from a Lagrange extrapolation of the last (up to three)
  converged solutions, which keeps the assembly branch of the guess through the revolution and
  typically needs two or three Newton steps. The sign of det of each diagonal block of Φ_q (each
  dyad's circuit; for a dyad, the side σ of `_dyads`) is tracked: a step that lands on another
  circuit without a singular or failed position in between is redone in sub-steps, and reported
  `max_steps` if that does not help — never as a converged position on another circuit;
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..files import expr as _expr
from ..model.mechanism import Mechanism
from ..results import RESULTS
from . import dyads as _dyads
from .closed_form import _closed_form_reference, _smooth_sides
from .fusion import batched_like
from .newton import newton
from .options import MAX_LEAD_IN, REFINE_TRIES, NewtonOptions
from .reassembly import _reassemble, _same_circuit, _Track, _track_start


def _extrapolate(hist_q, hist_phi, n_good, phi, order: int):
    """Lagrange extrapolation through the last `min(n_good, order+1)` converged solutions."""
    q1, q2, q3 = hist_q
    f1, f2, f3 = hist_phi
    if order == 0:
        return q1
    eps = 1e-12
    # linear
    d12 = f1 - f2
    ok12 = jnp.abs(d12) > eps
    lin = q1 + (q1 - q2) * jnp.where(ok12, (phi - f1) / jnp.where(ok12, d12, 1.0), 0.0)
    if order == 1:
        return jnp.where(n_good >= 2, lin, q1)
    d13, d23 = f1 - f3, f2 - f3
    ok = ok12 & (jnp.abs(d13) > eps) & (jnp.abs(d23) > eps)
    s13 = jnp.where(ok, d13, 1.0)
    s23 = jnp.where(ok, d23, 1.0)
    s12 = jnp.where(ok, d12, 1.0)
    w1 = (phi - f2) * (phi - f3) / (s12 * s13)
    w2 = (phi - f1) * (phi - f3) / (-s12 * s23)
    w3 = (phi - f1) * (phi - f2) / (s13 * s23)
    quad = w1 * q1 + w2 * q2 + w3 * q3
    return jnp.where((n_good >= 3) & ok, quad, jnp.where(n_good >= 2, lin, q1))


def _push(hist, value, cond):
    """History (newest first) with `value` pushed in where `cond`."""
    return tuple(jnp.where(cond, a, b) for a, b in zip((value,) + hist[:-1], hist))


def _coefficient(node, name):
    """The integer k when `node` is k·name + (terms free of name), else None."""
    if not any(n.name == name for n in _expr.names_in(node)):
        return 0
    if isinstance(node, _expr.Name):
        return 1
    if isinstance(node, _expr.Neg):
        k = _coefficient(node.arg, name)
        return None if k is None else -k
    if isinstance(node, _expr.Bin) and node.op in "+-":
        a, b = _coefficient(node.left, name), _coefficient(node.right, name)
        if a is None or b is None:
            return None
        return a + b if node.op == "+" else a - b
    if isinstance(node, _expr.Bin) and node.op == "*":
        for num, other in ((node.left, node.right), (node.right, node.left)):
            if isinstance(num, _expr.Num) and float(num.value).is_integer():
                k = _coefficient(other, name)
                return None if k is None else int(num.value) * k
    return None


def _periodic_node(node, name) -> bool:
    """Whether `node` is a 2π-periodic function of `name` (free of it, or built from sin/cos/tan of
    integer multiples of it)."""
    if not any(n.name == name for n in _expr.names_in(node)):
        return True
    if isinstance(node, _expr.Call):
        if node.func in ("sin", "cos", "tan"):
            return _coefficient(node.args[0], name) is not None or _periodic_node(node.args[0], name)
        return all(_periodic_node(a, name) for a in node.args)
    if isinstance(node, _expr.Neg):
        return _periodic_node(node.arg, name)
    if isinstance(node, _expr.Bin):
        return _periodic_node(node.left, name) and _periodic_node(node.right, name)
    return False


def periodic_input(mech: Mechanism) -> bool:
    """Whether the loop equations are 2π-periodic in the input: an angle input that appears only as
    k·input + c (k an integer) in the angle of a polar vector, or inside sin/cos/tan of such (a
    revolute crank). A length input (a slider) never is."""
    if mech.input_kind != "angle":
        return False
    name = mech.input_name
    for _, terms in mech.loops:
        for t in terms:
            for node in t.nodes():
                if t.polar and node is t.angle and _coefficient(node, name) is not None:
                    continue
                if not _periodic_node(node, name):
                    return False
    return True


def reduce_angles(mech: Mechanism, q, bound: float):
    """`q` with every angle unknown larger than `bound` in magnitude reduced to (−π, π] (exactly:
    `remainder` is exact in floating point). Adding whole turns to an angle of magnitude A costs
    ≈ eps·A of accuracy, so a guess far beyond `bound` could not be reproduced to the tolerance."""
    two_pi = 2 * np.pi
    ang = np.array([k == "angle" for k in mech.unknown_kinds])
    if not ang.any():
        return q
    r = jnp.remainder(q, two_pi)
    r = jnp.where(r > np.pi, r - two_pi, r)
    return jnp.where(jnp.asarray(ang) & (jnp.abs(q) > bound), r, q)


def _advance(mech, opts, p, tol, kw, st: _Track, phi):
    """One position of the continuation: `(state, (q, rnorm, result, steps))`.

    After a converged or singular position: Newton from the Lagrange extrapolation of the last
    converged positions. The sign of det of each diagonal block of Φ_q (each dyad's circuit) is
    compared with the last converged position: a change without a singular or failed position in
    between means the step jumped to another circuit, and the position is re-solved in sub-steps
    from the last converged position (half the step, halved again after every failure, each
    sub-step required to converge on the same circuit; at most `REFINE_TRIES` Newton solves, else
    the position is reported `max_steps`: refine the input step). The attempts are one
    `while_loop` around the single Newton solve, whose trip count is 1 where nothing flipped: under
    `vmap` the sub-steps cost nothing unless some lane needs them (`lax.cond` would evaluate both
    branches).

    After a position that did not assemble (and at the first position), or where this
    continuation step failed (next to a toggle the predictor may be far off): a re-assembly on the
    circuit kept, so that every assemblable window of the input is found on the branch of the
    guess, as the closed form finds it. The history restarts there. When every block is a dyad the
    re-assembly is one Newton solve from the closed form on the branches of the last converged
    position, made as one more trip of the attempts' loop (the same Newton call: one copy of it in
    the program, a quarter less to compile); otherwise `_reassemble`'s search with deflation."""
    hist_q, hist_phi, n_good, sign_ref, last = st.hq, st.hph, st.ng, st.sign_ref, st.last
    restart = (last != RESULTS.converged) & (last != RESULTS.singular)
    check = last == RESULTS.converged
    zero = jnp.zeros((), jnp.int32)
    dtype = jnp.result_type(phi)
    dyads = _dyads.classify(mech)
    # every block a dyad: the re-assembly is one more Newton solve from the closed form (on the
    # branches of the last converged position), made by the same call as the attempts' (an extra
    # trip of their loop where one is needed) — one Newton in the program instead of two
    merged = dyads is not None
    if merged:
        _, _, _, sigma = _dyads.solve_nearest(mech, dyads, hist_q[0], hist_phi[0], p)
        q_cf = _dyads.solve(mech, dyads, sigma, hist_q[0], phi, p)[0]

    def failing(code):
        return (code != RESULTS.converged) & (code != RESULTS.singular)

    def over(s):  # the attempts are over (for a lane that restarts: from the start)
        return s[6] | (s[5] > REFINE_TRIES)

    def cond(s):
        if not merged:
            return (~s[6]) & (s[5] <= REFINE_TRIES)
        need = restart | (~restart & failing(s[7][2]))
        return (~over(s)) | (need & ~s[10])

    def body(s):
        hq, hph, ng, phi_cur, h, tries, done, out, ksum = s[:9]
        first_try = tries == 0
        last_sub = jnp.abs(phi - phi_cur) <= 1.000001 * jnp.abs(h)
        phi_try = jnp.where(first_try | last_sub, phi, phi_cur + h)
        guess = _extrapolate(hq, hph, ng, phi_try, opts.predictor_order)
        if merged:
            re_phase = over(s)
            q, rn, code, k, sg = newton(mech, jnp.where(re_phase, q_cf, guess), jnp.where(re_phase, phi, phi_try), p,
                                        tol=tol, limit_step=re_phase,
                                        max_steps=jnp.where(re_phase, opts.max_steps_first, opts.max_steps), **kw)
        else:
            q, rn, code, k, sg = newton(mech, guess, phi_try, p, tol=tol, limit_step=False,
                                        max_steps=opts.max_steps, **kw)
        ksum_new = ksum + k
        conv = code == RESULTS.converged
        same = _same_circuit(sg, sign_ref)
        # first try: done unless it converged on another circuit; sub-steps: accepted when
        # converged on the circuit, done when the last one is
        flipped = first_try & conv & check & ~same
        ok = ~first_try & conv & same
        fin = (first_try & ~flipped) | (ok & last_sub)
        # (where the sub-steps fail: the first try's position, on the other circuit, `max_steps`)
        code_c = jnp.where(flipped, jnp.asarray(RESULTS.max_steps, code.dtype), code)
        out_n = jax.tree_util.tree_map(lambda a, b: jnp.where(fin | flipped, a, b), (q, rn, code_c, ksum_new, sg), out)
        out_n = out_n[:3] + (ksum_new,) + out_n[4:]
        h = jnp.where(first_try, 0.5 * (phi - hph[0]), jnp.where(ok, h, 0.5 * h))
        new = (_push(hq, q, ok), _push(hph, phi_try, ok), ng + ok.astype(jnp.int32),
               jnp.where(first_try, hph[0], jnp.where(ok, phi_try, phi_cur)), h, tries + 1, fin, out_n, ksum_new)
        if not merged:
            return new
        # the re-assembly's trip: its result on the circuit kept (another circuit: `max_steps`)
        other = conv & ~_same_circuit(sg, st.sign_ref)
        re = (q, rn, jnp.where(other, jnp.asarray(RESULTS.max_steps, jnp.int8), code), k, sg)
        kept = jax.tree_util.tree_map(lambda a, b: jnp.where(re_phase, b, a), new, s[:9])
        return kept + (jax.tree_util.tree_map(lambda a, b: jnp.where(re_phase, a, b), re, s[9]), s[10] | re_phase)

    out0 = (hist_q[0], jnp.asarray(jnp.inf, dtype), jnp.asarray(RESULTS.max_steps, jnp.int8), zero, sign_ref)
    state: tuple = (hist_q, hist_phi, n_good, hist_phi[0], jnp.zeros((), dtype), zero, restart, out0, zero)
    if merged:
        re0 = (hist_q[0], jnp.asarray(jnp.inf, dtype), jnp.asarray(RESULTS.nonfinite, jnp.int8), zero, sign_ref)
        state = state + (re0, jnp.zeros((), bool))
    final = jax.lax.while_loop(cond, body, batched_like(state, st, phi, p, tol))
    cont = final[7]
    # where the continuation failed (next to a toggle the predictor can be far off) or after a
    # failed position: re-assemble
    failed = ~restart & failing(cont[2])
    re = final[9] if merged else _reassemble(mech, opts, p, phi, st, tol, kw, restart | failed)
    use = restart | (failed & ((re[2] == RESULTS.converged) | (re[2] == RESULTS.singular)))
    q, rn, code, k, sg = jax.tree_util.tree_map(lambda a, b: jnp.where(use, a, b), re, cont)
    k = jnp.where(failed, re[3] + cont[3], k)
    good = code == RESULTS.converged
    # a re-assembled position starts a new history (no extrapolation across the gap)
    hq = tuple(jnp.where(use & good, q, h) for h in hist_q)
    hph = tuple(jnp.where(use & good, phi, h) for h in hist_phi)
    ng = jnp.where(use & good, 0, n_good)
    new = _Track(_push(hq, q, good), _push(hph, phi, good), ng + good.astype(jnp.int32),
                 jnp.where(good, sg, sign_ref), code, st.q_file)
    return new, (q, rn, code, k)


def _lead_in_inputs(mech: Mechanism, p, phi_ref, phi0):
    """The inputs of the lead-in from `phi_ref` (where the guesses hold) to `phi0`: `(start, h, n)`,
    positions start + k h, k = 0 … n−1. For an input the loops are 2π-periodic in
    (`periodic_input`), the way is reduced to at most half a revolution: `start` ≡ `phi_ref` (mod
    2π) lies within π of `phi0`. |h| ≤ 5° for an angle, ≤ 5 % of the length scale for a length, and
    n ≤ `MAX_LEAD_IN` (a longer way takes longer steps, which may fail: never a hang). A
    non-finite way has no steps."""
    dtype = jnp.result_type(phi0)
    gap = phi0 - phi_ref
    if periodic_input(mech):
        two_pi = 2 * np.pi
        r = jnp.remainder(gap, two_pi)  # exact
        gap = jnp.where(r > np.pi, r - two_pi, r)
        max_step = jnp.asarray(np.deg2rad(5.0), dtype)
    elif mech.input_kind == "length":
        max_step = 0.05 * mech.length_scale(p)
    else:
        max_step = jnp.asarray(np.deg2rad(5.0), dtype)
    steps = jnp.ceil(jnp.abs(gap) / max_step)
    n = jnp.where(jnp.isfinite(steps), jnp.minimum(steps, MAX_LEAD_IN), 0).astype(jnp.int32)
    h = jnp.where(n > 0, gap / jnp.maximum(n, 1).astype(dtype), 0.0)
    return phi0 - gap, h, n


def _continuation_smooth(mech: Mechanism, opts: NewtonOptions, P, phis, Q0, phi_ref, phi0, tol, thr, ax):
    """With `change_points="smooth"` (every block a dyad): `(flips, q_start)`; else None.
    `flips` (B, N, blocks) ±1 is −1 where the circuit to keep flips between positions k − 1 and k
    (a change point of that dyad lies between them: the sides of the closed form's smooth
    continuation from where the guess holds, `_smooth_sides`, differ); `q_start` (B, n) the closed
    form at the first input on those sides, the continuation's start (instead of a lead-in, which
    would keep the circuit of the guess through a change point before the first input)."""
    if opts.change_points != "smooth" or _dyads.classify(mech) is None:
        return None
    dyads = _dyads.classify(mech)
    ref = phi0 if phi_ref is None else phi_ref
    trig_p = _dyads.parameter_trig(mech, P)
    reference = jax.vmap(lambda p, q0, t, tp, r: _closed_form_reference(mech, p, q0, t, tp, r))(
        P, Q0, tol, trig_p, ref)
    sides = jax.vmap(lambda p, ph, ref_, r, t: _smooth_sides(mech, ref_, p, ph, r, t, thr),
                     in_axes=(0, ax, 0, 0, 0))(P, phis, reference, ref, tol)
    q_start = jax.vmap(lambda p, sg, q0, f: _dyads.solve(mech, dyads, sg, q0, f, p)[0])(P, sides[:, 0], Q0, phi0)
    flips = jnp.concatenate([jnp.ones_like(sides[:, :1]), sides[:, 1:] * sides[:, :-1]], axis=1)
    return flips, jnp.where(jnp.all(jnp.isfinite(q_start), axis=1, keepdims=True), q_start, Q0)


def _continuation_one(mech, opts, p, phis, q0, phi_ref, tol, kw, flips=None):
    """Newton with continuation along `phis` for one design from its guess `q0` (holding at
    `phi_ref`, or at phis[0] when `phi_ref` is None): the lead-in (`_lead_in_inputs`) and then
    every position, each by `_advance`. Returns `(q, rnorm, result, steps)` of the positions.
    `flips` (N, blocks) ±1: the circuit kept is multiplied by it before position k (the smooth
    continuation through a change point between k − 1 and k, `_continuation_smooth`).

    The lead-in and the positions are one loop over n + N inputs (the first n of the lead-in,
    their results not kept), so that `_advance` — four nested loops — is traced and compiled
    once: two copies doubled the time to compile a continuation solve."""
    def flipped(track, i):
        if flips is None:
            return track
        return track._replace(sign_ref=track.sign_ref * flips[i].astype(track.sign_ref.dtype))

    if phi_ref is None:
        st = batched_like(_track_start(mech, q0, phis[0], p), q0, p, tol, phis)
        idx = jnp.arange(phis.shape[0])
        return jax.lax.scan(lambda s, x: _advance(mech, opts, p, tol, kw, flipped(s, x[1]), x[0]), st, (phis, idx))[1]
    start, h, n = _lead_in_inputs(mech, p, phi_ref, phis[0])
    dtype = jnp.result_type(phis)
    N = phis.shape[0]
    st = _track_start(mech, q0, start, p)
    bufs = (jnp.zeros((N,) + q0.shape, q0.dtype), jnp.zeros((N,), dtype), jnp.zeros((N,), jnp.int8),
            jnp.zeros((N,), jnp.int32))

    def body(s):
        k, track, bufs = s
        lead = k < n
        i = jnp.clip(k - n, 0, N - 1)
        phi = jnp.where(lead, start + k.astype(dtype) * h, phis[i])
        if flips is not None:
            track = track._replace(sign_ref=jnp.where(lead, track.sign_ref, flipped(track, i).sign_ref))
        track, out = _advance(mech, opts, p, tol, kw, track, phi)
        bufs = tuple(b.at[i].set(jnp.where(lead, b[i], o.astype(b.dtype))) for b, o in zip(bufs, out))
        return k + 1, track, bufs

    init = batched_like((jnp.zeros((), jnp.int32), st, bufs), q0, p, tol, h, start, phis)
    return jax.lax.while_loop(lambda s: s[0] < n + N, body, init)[2]


def _lead_in(mech: Mechanism, opts: NewtonOptions, p, phi_a, phi_b, q0, tol, kw):
    """The configuration at `phi_b` of one design from the guess `q0` holding at `phi_a` (for
    `"independent"`): the continuation of the lead-in (`_lead_in_inputs`). Returns the last
    converged q (q0 if none)."""
    start, h, n = _lead_in_inputs(mech, p, phi_a, phi_b)
    dtype = jnp.result_type(q0)

    def lead(s):
        k, track = s
        return k + 1, _advance(mech, opts, p, tol, kw, track, start + k.astype(dtype) * h)[0]

    init = (jnp.zeros((), jnp.int32), _track_start(mech, q0, start, p))
    st = jax.lax.while_loop(lambda s: s[0] < n, lead, batched_like(init, init, p, tol, h, start))[1]
    return st.hq[0]
