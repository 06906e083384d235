"""Starting configurations for candidate designs far from the file's design.

The path solve continues along the revolution from a configuration at the first input φ₀; a
candidate design needs its own one, on the file's assembly branch (circuit). Two finders:

- **closed form** (every block of the mechanism is a dyad, `jaxlink.solvers.dyads`): the file's
  configuration at φ₀ fixes the branch sign σ of every dyad; the candidate's configuration is the
  dyads' closed form with the same σ (or any σ for `circuits = "all"`). Exact, no iteration: a
  design is declared unassemblable at φ₀ only when a circle–circle intersection is empty.
- **continuation in the parameters** (any mechanism): from the file's design p_f and its solved
  configuration q_f at φ₀, K = 16 homotopy steps p(t) = p_f + t (p − p_f), each corrected by a
  few Newton iterations (the step limited to 0.3 rad / 0.3 × length scale), then a final polish;
  the result must close the loops to the solver's tolerance. It stays on the branch connected to
  the file's configuration; it can fail (wrongly infeasible) when the straight homotopy path
  crosses a region where the mechanism cannot be assembled at φ₀ although both ends can — the
  rate is measured in `tests/test_optimize.py` and docs/methods/optimize.md.
"""

from __future__ import annotations

import itertools

import jax
import jax.numpy as jnp
import numpy as np

from ..results import RESULTS
from ..solvers import dyads as _dyads
from ..solvers.assemble import solve
from ..solvers.linalg import solve_small


def _nearest_closed_form(mech, phi0):
    """The file's design in closed form at φ₀ on the branches nearest to its guesses — what the
    path solve's closed form computes at its first input — with its loop residual and the least
    sine of its dyads (a stored trace: `jaxlink.cache.traced`)."""
    dyads = _dyads.classify(mech)
    p = mech.parameters
    sigma = _dyads.solve_nearest(mech, dyads, mech.guess, phi0, p)[3]
    q, _, rn, sine = _dyads.solve(mech, dyads, sigma, mech.guess, phi0, p)
    return q, rn, sine


def file_configuration(mech, phi0) -> np.ndarray:
    """The file's design solved at φ₀ (continued from the file's `[input] start`).

    A mechanism of dyads at its own start takes its closed form nearest to the guesses there (the
    branches the path solve takes; one small program, 0.05 s to compile against 0.55 s for the path
    solve on 2 CPU cores: a cold study's set-up) where that is clearly assembled — the residual
    within half the solver's tolerance, every dyad's sine at least twice the singular threshold;
    anything else (a guess far from the turn, a design near a toggle or that does not assemble)
    goes to the path solve, which decides and names the result. The configuration is the
    reference of the designs' branches and angles; the two routes differ by rounding only."""
    q = _closed_form_configuration(mech, phi0)
    if q is not None:
        return q
    # the points are not computed (a smaller program: 0.3 s less to compile on 2 CPU cores)
    sol = solve(mech, np.asarray([phi0]), points=False)
    # indexed as numpy arrays: an indexed JAX array compiles a one-operation program per call site
    # in a new process (≈ 20 ms each on the CPU)
    result, q = np.asarray(sol.result), np.asarray(sol.q)
    if int(result[0]) != RESULTS.converged:
        from ..errors import MechanismError

        raise MechanismError(
            f"the file's own design cannot be assembled at the first input of the search "
            f"({RESULTS.messages[int(result[0])]}); the search needs an assemblable design in the "
            "file to define the assembly branch", file=mech.file, key="parameters")
    return q[0]


def _closed_form_configuration(mech, phi0):
    """`_nearest_closed_form` where it applies and is clearly assembled (see `file_configuration`),
    else None."""
    from ..cache import traced
    from ..solvers.options import NewtonOptions, default_rtol, singular_threshold

    p = np.asarray(mech.parameters)
    g = np.asarray(mech.guess, p.dtype)
    if (_dyads.classify(mech) is None or float(phi0) != float(mech.input_start) or not np.isfinite(g).all()
            or np.abs(g).max(initial=0.0) > 1e3 or not np.isfinite(p).all()):
        return None
    q, rn, sine = (np.asarray(x) for x in traced("file_configuration", _nearest_closed_form,
                                                   (mech.replace(guess=g), np.asarray(phi0, p.dtype))))
    tol = default_rtol(p.dtype) * float(mech.length_scale(p))
    thr = singular_threshold(NewtonOptions(), p.dtype)
    if np.isfinite(q).all() and float(rn) <= 0.5 * tol and float(sine) >= 2 * thr:
        return q
    return None


def _nearest_signs(mech, q_file, phi0):
    """The dyads' branch signs σ of the configuration nearest to `q_file` at φ₀ (a stored trace:
    `jaxlink.cache.traced`, the mechanism an argument)."""
    return _dyads.solve_nearest(mech, _dyads.classify(mech), q_file, phi0, mech.parameters)[3]


def circuit_signs(mech, q_file, phi0, *, all_circuits: bool) -> np.ndarray:
    """(C, n_dyads) branch signs: the file's (C = 1) or every combination (C = 2^n_dyads, the
    file's first).

    The file's σ is one compiled program (`traced`, stored with the compilation cache): evaluated
    operation by operation it compiled ≈ 28 one-operation programs in a new process (0.5 s of a
    cold study's or search's set-up on 2 CPU cores). The same operations on the same numbers: σ
    is a sign, the same either way."""
    from ..cache import traced

    p = np.asarray(mech.parameters)
    own = np.asarray(traced("circuit_signs", _nearest_signs,
                            (mech.replace(guess=np.asarray(mech.guess, p.dtype)), np.asarray(q_file, p.dtype),
                             np.asarray(phi0, p.dtype))))
    if not all_circuits:
        return own[None]
    combos = [own]
    for signs in itertools.product((1.0, -1.0), repeat=len(own)):
        s = np.asarray(signs) * own
        if not any(np.array_equal(s, c) for c in combos):
            combos.append(s)
    return np.stack(combos)


def closed_form_start(mech, dyads, q_file, phi0, p, sigma, tol):
    """(q0, ok): the dyads' closed form at φ₀ on branches σ; ok where its loops close to `tol`
    (as in the path solve: an exact toggle, h² negative by rounding, is assembled)."""
    q, _, rn, _ = _dyads.solve(mech, dyads, sigma, jnp.asarray(q_file, p.dtype), jnp.asarray(phi0, p.dtype), p)
    return q, rn <= tol


def continuation_start(mech, q_file, p_file, phi0, p, tol, *, steps: int = 16, newton: int = 3, polish: int = 6):
    """(q0, ok) by continuation in the parameters from the file's design (see module doc)."""
    dtype = p.dtype
    phi0 = jnp.asarray(phi0, dtype)
    p_file = jnp.asarray(p_file, dtype)
    scale = mech.length_scale(p)
    lim = jnp.asarray([0.3 if k == "angle" else 0.3 * scale for k in mech.unknown_kinds], dtype)

    def newton_step(q, pt):
        r = mech.residual(q, phi0, pt)
        jac = jax.jacfwd(mech.residual)(q, phi0, pt)
        dq, _ = solve_small(jac, r)
        ratio = jnp.max(jnp.abs(dq) / lim)
        dq = dq * jnp.minimum(1.0, 1.0 / jnp.maximum(ratio, 1e-30))
        q_new = q - dq
        return jnp.where(jnp.all(jnp.isfinite(q_new)), q_new, q)

    def body(k, q):
        t = (k + 1.0) / steps
        pt = p_file + t * (p - p_file)
        return jax.lax.fori_loop(0, newton, lambda _, qq: newton_step(qq, pt), q)

    q = jax.lax.fori_loop(0, steps, body, jnp.asarray(q_file, dtype))
    q = jax.lax.fori_loop(0, polish, lambda _, qq: newton_step(qq, p), q)
    rn = jnp.max(jnp.abs(mech.residual(q, phi0, p)))
    return q, rn <= tol
