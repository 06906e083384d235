"""The closed-form path of a dyadic structure: every position solved in closed form on the
branches chosen at the first position.

**Closed form** (`method="auto"` when every block of the structure is a dyad, `"closed_form"`):
no Newton at all. At φ_0 each dyad's assembly branch is the one nearest to the guess q0
(`_dyads.solve_nearest`, dyad by dyad), and every position of every design is then solved in
closed form on those branches (`_closed_form_path`). A position is converged when its loops close
to the tolerance (a dyad at its exact toggle, h² negative by rounding, is assembled at h = 0) and
`singular` when a dyad's two links are collinear to within `singular_ratio` (toggle, dead
centre, change point). On the CPU a batch of two dyads or more is solved in chunks of about
`CHUNK_POSITIONS` positions (`lax.map` over designs), so that its intermediate arrays stay in
the cache; the answers do not depend on it, bit for bit.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..model.mechanism import Mechanism
from ..results import RESULTS
from . import branch_points as _branch_points
from . import dyads as _dyads
from .fusion import materialize
from .options import CHANGE_POINTS, METHODS, NewtonOptions

#: store the closed form's result codes once (`_closed_form_path`); False only for the differential
#: test (the same answers either way, bit for bit)
MATERIALIZE_CODES = True


def method_for(mech: Mechanism, opts: "NewtonOptions") -> str:
    """The path method `opts` resolves to for this mechanism."""
    if opts.method not in METHODS:
        raise ValueError(f"unknown method {opts.method!r}; use one of {METHODS}")
    if opts.change_points not in CHANGE_POINTS:
        raise ValueError(f"unknown change_points {opts.change_points!r}; use one of {CHANGE_POINTS}")
    if not opts.continuation and opts.method in ("auto", "continuation"):
        return "independent"
    if opts.method == "auto":
        return "closed_form" if _dyads.classify(mech) is not None else "continuation"
    if opts.method == "closed_form" and _dyads.classify(mech) is None:
        raise ValueError(f"{mech.name}: not every block is a dyad of known form; no closed form")
    return opts.method


def _closed_form_reference(mech, p, q0, tol, trig_p, phi_ref):
    """What one design's closed-form path needs besides its inputs: the branches σ of its dyads
    nearest to the guess q0 at the input `phi_ref` where it holds (`_dyads.solve_nearest`), the
    guess made finite, and whether anything can be verified (`ok`: False for a guess that selects
    no branch (NaN), or parameters that allow no check (a NaN or infinite tolerance, e.g. from a
    NaN length that no loop uses)). Computed once per design and stored with the trigonometry
    (`_solve_batch_impl`): fused into the per-position kernels, its sines and cosines were
    evaluated at every position."""
    dyads = _dyads.classify(mech)
    t_ref = _dyads.input_trig(mech, phi_ref, arith=False)
    _, _, _, sigma = _dyads.solve_nearest(mech, dyads, q0, phi_ref, p, {**t_ref, **trig_p})
    ok = jnp.all(jnp.isfinite(q0)) & jnp.isfinite(tol)
    return sigma, jnp.where(jnp.isfinite(q0), q0, 0.0), ok


def _closed_form_path(mech, p, phis, tol, trig_in, trig_p, thr, reference, points: bool = False,
                      trig_out: bool = False):
    """Every position of one design in closed form, on the branches `reference` selects
    (`_closed_form_reference`): no Newton, no continuation.

    A position is assembled when its loops close to `tol` (the residual of the closed form,
    exact to rounding: a dyad at its exact toggle, h² negative by rounding, is assembled at
    h = 0); it is `singular` when some dyad's links are collinear to within `thr` (the sine of
    the angle between them: dead centre, toggle, change point). Returns the packed array
    (`_unpack_closed_form`); with `trig_out`, for the derivative, separate values instead:
    `(result, rnorm, q columns, points or None, (cos, sin))`, (N,) each, the (cos, sin) of each
    solved angle as the closed form has them (no new trigonometry; (1, 0) where a position has no
    finite solution)."""
    dyads = _dyads.classify(mech)
    sigma_all, q_ref, ref_ok = reference
    per_position = sigma_all.ndim == 2  # (N, D): the sides of each position (`change_points="smooth"`)

    def one(phi, t_in, sigma):
        q, ok, rn, sine, trig = _dyads.solve_with_trig(mech, dyads, sigma, q_ref, phi, p, {**t_in, **trig_p})
        conv = (rn <= tol) & ref_ok
        code = jnp.where(conv, jnp.where(sine < thr, RESULTS.singular, RESULTS.converged),
                         jnp.where(~ref_ok | ~jnp.isfinite(rn), RESULTS.nonfinite,
                                   jnp.where(ok, RESULTS.max_steps, RESULTS.cannot_assemble)))
        q = jnp.where(jnp.all(jnp.isfinite(q)), q, q_ref)
        if trig_out:
            # for the derivative: one value per leaf, so that each is stored as its own (B, N)
            # array and every kernel of the derivative reads only the values it uses
            pts = mech.point_positions(q, phi, p, trig) if points else None
            cs = tuple(tuple(jnp.where(jnp.isfinite(trig[n][j]), trig[n][j], float(1 - j)) for n in ang)
                       for j in (0, 1))
            return code.astype(jnp.int8), rn, tuple(jnp.unstack(q)), pts, cs
        # every output of a position packed into one array: measured faster than separate outputs
        # for the forward (feed, 1e4 designs: 1.4e7 against 1.1e7 positions/s); the points from
        # the sines and cosines the solve already has (no new trigonometry)
        parts = [q, rn[None], code.astype(q.dtype)[None]]
        if points:
            parts.append(jnp.ravel(mech.point_positions(q, phi, p, trig)))
        return jnp.concatenate(parts)

    ang = [n for n, k in zip(mech.unknown_names, mech.unknown_kinds) if k == "angle"]
    packed = jax.vmap(one, in_axes=(0, 0, 0 if per_position else None))(phis, trig_in, sigma_all)
    if trig_out:
        return packed
    q, rn, code, steps, pts = _unpack_closed_form(mech, packed, points)
    if MATERIALIZE_CODES:
        # the result codes computed once and stored: every element of the points' and the unknowns'
        # outputs (the masks of `_batch`) reads them. Fused, XLA recomputed each position's residual
        # and transmission sines for each of them (the Strider, 4 dyads and 7 points: 1000 designs ×
        # 360 positions 1.2× faster, one design 1.1×; benchmarks/strider_vs_pylinkage.py)
        code = materialize(code)
    return q, rn, code, steps, pts


def _unpack_closed_form(mech, packed, points: bool):
    """The outputs of `_closed_form_path` from its packed array (…, N, m): `(q, rnorm, result,
    steps, points or None)`."""
    n = len(mech.unknown_names)
    lead = packed.shape[:-1]
    pts = packed[..., n + 2:].reshape(lead + (-1, 2)) if points else None
    return (packed[..., :n], packed[..., n], packed[..., n + 1].astype(jnp.int8), jnp.zeros(lead, jnp.int32), pts)


def _smooth_sides(mech: Mechanism, reference, p, phis, phi_ref, tol, thr):
    """(N, D) the sides of one design's dyads at every position of the smooth continuation from
    the closed form's branches `reference` (`_closed_form_reference`) at `phi_ref`, where the guess
    selected them: flipped at each change point located between two inputs
    (`branch_points.smooth_sides`)."""
    dyads = _dyads.classify(mech)
    sigma, q_ref, _ = reference
    return _branch_points.smooth_sides(mech, dyads, sigma, q_ref, phis, phi_ref, p, tol, thr)
