"""The exact derivative of the batched path solve: the implicit rule.

**Exact gradients.** The whole path solve is a `jax.custom_jvp`: by the implicit function
theorem, dq_k = −Φ_q⁻¹ (Φ_p dp + Φ_φ dφ_k) at the converged solution — one linear solve per
position, independent of the Newton iterations (and zero at non-converged positions, `singular`
ones included). Reverse mode (`jax.grad`) follows by transposition of that linear map. The rule
(`_implicit_tangents`) costs no trigonometry: the forward solve also returns, stored, the sines
and cosines of the input, of the angle parameters and of the solved angles (`_Trig`; the closed
form has those of the solved angles without evaluating any), Φ_q, Φ_p, Φ_φ and the points'
derivatives are products and sums of them, and Φ_q is solved by forward substitution over its
diagonal blocks (Cramer on each dyad's 2×2 block). Per position it works on scalars only, so that
its transpose is as elementwise as the rule itself, and the forward's outputs are stored
(`materialize`), one (B, N) array per value, so that XLA does not recompute the closed form inside
the derivative's kernels and each of them reads only the values it uses: a gradient of a path
objective in all parameters costs about one forward solve (benchmarks/gradient_cost.py).

"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero

from ..model import structure as _structure
from ..model.mechanism import Mechanism
from ..results import RESULTS
from .linalg import solve_block_lower_scalars
from .newton import _env_known, _residual_known, _sum_terms


def _implicit_tangents(mech: Mechanism, points: bool, primals, tangents, out):
    """Implicit differentiation at every converged position (zero elsewhere):

        Φ_q dq = −(Φ_p dp + Φ_φ dφ),      d(point) = P_q dq + P_p dp + P_φ dφ,

    with Φ_q, the right-hand side and the points' derivatives evaluated from the (cos, sin) the
    forward solve stored (`_Trig`: no trigonometry here, only products and sums), and Φ_q solved
    by forward substitution over its diagonal blocks (Cramer on the 2×2 block of each dyad,
    `_linalg.solve_block_lower_scalars`). Per position everything is a scalar (the unknowns, the
    parameters, the columns of Φ_q): no array is assembled or indexed there, so that the transpose
    (reverse mode) is as elementwise as the tangent. The guesses and the reference input select a
    branch and carry no derivative."""
    P, phis, _, _ = primals
    dP, dphis = (None if isinstance(t, SymbolicZero) else t for t in tangents[:2])
    q, _, code, _, _, tr = out
    ax = None if phis.ndim == 1 else 0
    B, N, n = q.shape
    dtype = q.dtype
    order = _structure.blocks(mech)
    blocks = tuple((tuple(r for li in loops for r in (2 * li, 2 * li + 1)), cols) for loops, cols in order)
    if len(blocks) == 1 and len(blocks[0][1]) > 2:
        blocks = ((tuple(range(2 * len(mech.loops))), tuple(range(n))),)
    # the parameters as separate scalars, each tangent broadcast to the positions on its own: the
    # transpose is then one reduction over the positions per parameter, fused with the kernel that
    # computes it (a (B, N, P) broadcast would make it write a stack of every position's
    # cotangents and sum that: 0.5 -> 0.23 s of a gradient at 1e5 designs)
    Ps = tuple(P[:, i] for i in range(P.shape[1]))
    dPN = None if dP is None else tuple(jnp.broadcast_to(dP[:, i, None], (B, N)) for i in range(P.shape[1]))
    dphiN = None if dphis is None else jnp.broadcast_to(dphis, (B, N))
    Qs = tuple(jnp.unstack(q, axis=-1))

    def one(p, dp, qk, phik, dphik, ok, t_in, t_p, t_q):

        def res(qq, pp, ph):
            return _residual_known(mech, *_env_known(mech, qq, ph, pp, t_in, t_p, t_q), dtype)

        # the columns of Φ_q, one forward derivative per unknown (only the entries that depend on it)
        one_ = jnp.ones((), dtype)
        cols = [jax.jvp(lambda x, j=j: res(qk[:j] + (x,) + qk[j + 1:], p, phik), (qk[j],), (one_,))[1]
                for j in range(n)]
        if dp is None and dphik is None:
            rhs = tuple(jnp.zeros((), dtype) for _ in range(2 * len(mech.loops)))
        elif dphik is None:
            rhs = jax.jvp(lambda pp: res(qk, pp, phik), (p,), (dp,))[1]
        elif dp is None:
            rhs = jax.jvp(lambda ph: res(qk, p, ph), (phik,), (dphik,))[1]
        else:
            rhs = jax.jvp(lambda pp, ph: res(qk, pp, ph), (p, phik), (dp, dphik))[1]
        # where not converged the sensitivity is undefined: the result is zeroed, and the diagonal
        # blocks are made regular there (`ok`), so that neither the JVP nor its transpose (grad)
        # produces NaN
        dq = solve_block_lower_scalars(lambda r, c: cols[c][r], rhs, blocks, ok)
        dq = tuple(jnp.where(ok, -v, 0.0) for v in dq)
        if not points:
            return jnp.stack(dq), None

        def pts(qq, pp, ph):
            env, trig = _env_known(mech, qq, ph, pp, t_in, t_p, t_q)
            return tuple(_sum_terms(mech, terms, env, trig, dtype) for _, terms in mech.points)
        prim = (qk, p) + (() if dphik is None else (phik,))
        dpp = dp if dp is not None else tuple(jnp.zeros((), dtype) for _ in p)
        tang = (dq, dpp) + (() if dphik is None else (dphik,))
        dxy = jax.jvp(lambda qq, pp, *ph: pts(qq, pp, ph[0] if ph else phik), prim, tang)[1]
        dpts = jnp.stack([jnp.stack(v) for v in dxy]) if dxy else jnp.zeros((0, 2), dtype)
        return jnp.stack(dq), dpts

    per_pos = jax.vmap(one, in_axes=(None, 0, 0, 0, 0, 0, 0, None, 0))
    return jax.vmap(per_pos, in_axes=(0, 0, 0, ax, 0, 0, ax, 0, 0))(
        Ps, dPN, Qs, phis, dphiN, code == RESULTS.converged, tr.inputs, tr.params, tr.unknowns)


def _float0(x):
    return np.zeros(np.shape(x), dtype=jax.dtypes.float0)
