"""The responses of a study: one design p ↦ the studied points' x and y over the cycle and a few
scalar cycle metrics, with its feasibility — one traced function, `vmap`ped over designs and
differentiated (`jax.jacfwd`) with respect to the parameters.

**The cycle** is a full turn of the angle input: `positions` φ_k = φ₀ + 2πk/N from the
file's `[input] start` φ₀.

**One design** (`Responses.single`):

1. its configuration at φ₀ on the *nominal's branch*: the dyads' closed form with the nominal's
   branch signs σ (`jaxlink.optimize.start.closed_form_start`), or, for a mechanism not made of
   dyads, continuation in the parameters from the nominal (`continuation_start`), as the design
   search does;
2. the path solve over the cycle (`jaxlink.solvers.assemble.solve_path`: closed-form dyads or
   Newton continuation), whose derivative with respect to p is the implicit one,
   dq = −Φ_q⁻¹ Φ_p dp at every position (exact, no finite differences);
3. the responses (file units): x, y of each studied point at each position; per metric
   - `stroke`: each slider's stroke and each rocker's swing (the outputs of
     `jaxlink.analysis.stroke`: length unknowns, and angle unknowns of links pivoted to the frame
     that come back after the turn), max − min over the cycle, each extreme refined by the parabola
     through the largest (least) sample and its two neighbours — its derivative is that of the
     output at the refined extreme (the extreme's move does not count to first order);
   - `speed`, `acceleration`: max over the cycle of |dP/dφ| and |d²P/dφ²| of each point
     (`jaxlink.analysis.transfer`), times ω and ω² when `rpm` is given (a constant input speed),
     refined the same way;
   - `deviation` is computed from the curves by the caller (max over the cycle of |P − P_nominal|);
   - the response expressions (`expressions.py`): `travel(P, axis)`, a quantity at a named input
     angle, `max(…)`, `min(…)`: extremes located between the samples by Newton on the exact
     derivative (`jaxlink.analysis.taylor`), values at an angle solved there;
4. **feasibility**: every parameter within its domain (`jaxlink.model.domains`, what the file
   reader and `--set` accept: a link length ≥ 0, …; a design outside it is infeasible, counted
   by the studies: `outside`), the start and every position converged (assembled, not singular) and, for a
   mechanism of dyads, the reach margin's minimum over the whole turn, refined between the
   samples (`jaxlink.analysis.feasibility.certify`), is ≥ 0 on the nominal's branches: the
   design assembles over the whole cycle and stays on its branch, not only at the samples. A
   mechanism not made of dyads has no certificate: its feasibility is sampled only (say so).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from ..analysis import feasibility as _feasibility
from ..analysis import stroke as _stroke
from ..analysis.transfer import transfer_one
from ..errors import MechanismError
from ..model import domains as _domains
from ..solvers import dyads as _dyads
from ..solvers.assemble import solve, solve_path
from ..solvers.options import NewtonOptions, default_rtol
from . import expressions as _expr
from .inputs import StudyInputs

_UNIT_NAMES = {1.0: "m", 1e-3: "mm", 1e-2: "cm"}


def unit_names(mech) -> tuple[str, str]:
    """(length unit, angle unit) names of the file."""
    lu = _UNIT_NAMES.get(mech.units.length, "m")
    au = "deg" if abs(mech.units.angle - math.pi / 180) < 1e-15 else "rad"
    return lu, au


class Responses:
    """The response function of one study (see the module doc).

    **Arguments:** `mech`, `inputs` (`StudyInputs`), `options` (`NewtonOptions`).

    **Attributes:** `phis` (N,) the cycle's inputs (SI); `labels` (the M responses: `(output,
    unit, position index or None)`); `n_curve` (the first `n_curve` responses are the curves,
    point by point: P.x at every position, then P.y); `index` (the toleranced parameters' indices in
    `mech.parameters`); `factor` (file unit → SI of each); `certificate` ("reach margin" or
    "sampled only"); `scales` (SI → file unit of each response).
    """

    def __init__(self, mech, inputs: StudyInputs, options: NewtonOptions = NewtonOptions()):
        from ..optimize.start import circuit_signs, file_configuration

        if mech.input_kind != "angle":
            raise MechanismError("a study's cycle is a full turn of an angle input; a length input is not yet "
                                 "supported", file=mech.file, key="input")
        self.mech = mech
        self.inputs = inputs
        self.options = options
        n = inputs.positions
        self.phi0 = float(mech.input_start)
        self.phis = self.phi0 + 2.0 * np.pi * np.arange(n) / n
        self.q_file = file_configuration(mech, self.phi0)
        self.dyads = _dyads.classify(mech)
        if self.dyads is not None:
            self.sigma = np.asarray(circuit_signs(mech, self.q_file, self.phi0, all_circuits=False)[0])
        else:
            self.sigma = np.zeros(0)
        self.certificate = "reach margin" if self.dyads is not None else "sampled only"
        self.index = np.asarray([mech.parameter_index(p) for p in inputs.parameters], int)
        self.factor = np.asarray([mech.kind_factor(mech.kinds[p]) for p in inputs.parameters])
        self.point_index = tuple(mech.point_names.index(p) for p in inputs.points)
        self.omega = None if inputs.rpm is None else inputs.rpm * 2.0 * np.pi / 60.0
        lu, au = unit_names(mech)
        lf, af = mech.units.length, mech.units.angle
        deg = mech.from_si(mech.input_name, self.phis)
        labels: list = []
        scales: list = []
        for p in inputs.points:
            for c in ("x", "y"):
                labels += [(f"{p}.{c}", lu, k) for k in range(n)]
                scales += [1.0 / lf] * n
        self.n_curve = len(labels)
        self.input_values = np.asarray(deg)  # the cycle's inputs in the file's unit
        # stroke outputs: sliders and rockers that come back after the turn, at the nominal
        self.outputs: tuple = ()
        if "stroke" in inputs.metrics:
            rock = _stroke.rockers(mech)
            cand = [i for i, (nm, k) in enumerate(zip(mech.unknown_names, mech.unknown_kinds))
                    if k != "angle" or nm in rock]
            sol = solve(mech, jnp.asarray(self.phis), jnp.asarray(mech.parameters), jnp.asarray(self.q_file),
                        options=options, points=False)
            q = np.asarray(sol.q)
            keep = []
            for i in cand:
                if mech.unknown_kinds[i] == "angle":
                    u = np.unwrap(np.append(q[:, i], q[0, i]))
                    if abs(u[-1] - u[0]) > np.pi:  # turns fully: a crank, no swing
                        continue
                keep.append(i)
            self.outputs = tuple(keep)
            for i in keep:
                angle = mech.unknown_kinds[i] == "angle"
                labels.append((f"{'swing' if angle else 'stroke'}({mech.unknown_names[i]})", au if angle else lu, None))
                scales.append(1.0 / (af if angle else lf))
        for metric, power in (("speed", 1), ("acceleration", 2)):
            if metric in inputs.metrics:
                unit = f"{lu}/s" + ("^2" if power == 2 else "") if self.omega else f"{lu}/rad" + (
                    "^2" if power == 2 else "")
                for p in inputs.points:
                    labels.append((f"max_{metric}({p})", unit, None))
                    scales.append((self.omega ** power if self.omega else 1.0) / lf)
        # the response expressions (travel, values at named angles, extremes: `expressions.py`)
        self.expressions: tuple = tuple(e for m in inputs.metrics if _expr.is_expression(m)
                                        for e in _expr.parse(mech, m))
        for e in self.expressions:
            labels.append((e.text, _expr.unit(e, lu, au, self.omega is not None), None))
            scales.append(_expr.scale(e, mech, self.omega))
        self.labels = tuple(labels)
        self.scales = np.asarray(scales)
        self.order = 2 if "acceleration" in inputs.metrics else 1 if "speed" in inputs.metrics else 0

    # ------------------------------------------------------------------ one design (traced)
    def certified(self, x):
        """Whether the design `x` (file units) assembles over the whole cycle on the nominal's
        branches (`feasibility.certify`; a mechanism of dyads)."""
        from ..optimize.start import closed_form_start

        p = self.params(x)
        tol = default_rtol(p.dtype) * self.mech.length_scale(p)
        sig = jnp.asarray(self.sigma, p.dtype)
        q0, _ = closed_form_start(self.mech, self.dyads, self.q_file, self.phi0, p, sig, tol)
        cert = _feasibility.certify(self.mech, self.dyads, sig, q0, jnp.asarray(self.phis, p.dtype), p).certified
        return cert & _domains.inside(self.mech, p)

    def outside(self, x, base=None) -> int:
        """How many of the designs `x` (n, T) (file units) have a value outside its domain
        (`jaxlink.model.domains`: a negative link length, …): counted infeasible by `single`."""
        x = np.asarray(x, dtype=float).reshape(-1, len(self.index))
        p = np.broadcast_to(np.asarray(self.mech.parameters if base is None else base, float),
                            (len(x), len(self.mech.parameters))).copy()
        p[:, self.index] = x * self.factor
        return int(np.count_nonzero(~_domains.inside(self.mech, p)))

    def params(self, x, base=None):
        """The full parameter vector (SI) with the toleranced ones set to `x` (file units); the
        others those of `base` (SI, default the file's)."""
        p = jnp.asarray(self.mech.parameters if base is None else base, x.dtype)
        return p.at[jnp.asarray(self.index)].set(x * jnp.asarray(self.factor, x.dtype))

    def single(self, x, check: str = "certify", base=None):
        """(responses (M,) in file units, feasible, margin) of one design whose toleranced
        parameters are `x` (T,) (file units). Where infeasible, the responses are finite (the
        solver's last finite iterate, masked to 0 where not finite): counted, never used.

        `check` (static): "certify" (the reach margin refined between the samples:
        `feasibility.certify`), or "screen" (its conservative estimate from the samples alone,
        `feasibility.screen`, cheaper: `margin` is then that estimate and `feasible` says only that
        every position converged — the caller certifies the designs whose estimate is below zero).
        A mechanism not made of dyads has no margin (+inf). `base`: the other parameters (SI,
        default the file's; the robust-design map's designs)."""
        from ..optimize.start import closed_form_start, continuation_start

        mech = self.mech
        p = self.params(x, base)
        dtype = p.dtype
        tol = default_rtol(dtype) * mech.length_scale(jax.lax.stop_gradient(p))
        phis = jnp.asarray(self.phis, dtype)
        if self.dyads is not None:
            sigma = jnp.asarray(self.sigma, dtype)
            q0, ok = closed_form_start(mech, self.dyads, self.q_file, self.phi0, p, sigma, tol)
        else:
            q0, ok = continuation_start(mech, self.q_file, mech.parameters, self.phi0, p, tol)
        q0 = jax.lax.stop_gradient(q0)
        sol = solve_path(mech, phis, p, q0, options=self.options, points=True)
        feasible = ok & jnp.all(sol.converged) & _domains.inside(mech, p)  # a value the file could hold
        margin = jnp.asarray(jnp.inf, dtype)
        if self.dyads is not None:
            sig, ps = jnp.asarray(self.sigma, dtype), jax.lax.stop_gradient(p)
            if check == "certify":
                cert = _feasibility.certify(mech, self.dyads, sig, q0, phis, ps)
                feasible = feasible & cert.certified
                margin = jnp.asarray(cert.margin)
            else:
                margin = _feasibility.least(_feasibility.screen(mech, self.dyads, sig, q0, phis, ps))
        parts = []
        assert sol.points is not None
        pts = sol.points[:, jnp.asarray(self.point_index, int)]  # (N, K, 2)
        parts.append(jnp.transpose(pts, (1, 2, 0)).reshape(-1))  # P.x over the cycle, P.y, next point
        for i in self.outputs:
            qi = sol.q[:, i]
            if mech.unknown_kinds[i] == "angle":
                qi = jnp.unwrap(qi)
            parts.append((_peak(qi) + _peak(-qi))[None])
        if self.order:
            t = jax.vmap(lambda q, ph: transfer_one(mech, q, ph, p, self.order))(sol.q, phis)
            if "speed" in self.inputs.metrics:
                assert t.dpoints is not None
                d = t.dpoints[:, jnp.asarray(self.point_index, int)]
                parts.append(jnp.sqrt(jax.vmap(_peak, in_axes=1)(jnp.sum(d * d, axis=-1))))
            if "acceleration" in self.inputs.metrics:
                assert t.ddpoints is not None
                d = t.ddpoints[:, jnp.asarray(self.point_index, int)]
                parts.append(jnp.sqrt(jax.vmap(_peak, in_axes=1)(jnp.sum(d * d, axis=-1))))
        if self.expressions:
            parts.append(_expr.evaluate(mech, self.expressions, sol.q, phis, p, self.phi0))
        values = jnp.concatenate(parts) * jnp.asarray(self.scales, dtype)
        good = jnp.isfinite(values)
        feasible = feasible & jnp.all(good)
        return jnp.where(good, values, 0.0), feasible, margin


def outside_warning(outside: int, n: int, what: str = "designs") -> str:
    """The studies' line for the `outside` of `n` designs with a value outside its domain."""
    return (f"{outside} of {n} {what} have a value outside its domain (a negative link length, …: what the file and "
            "--set refuse; jaxlink/model/domains.py): counted infeasible, not evaluated as designs")


def _peak(y):
    """The largest value of the periodic samples `y` (N,), refined by the parabola through the
    largest sample and its neighbours: b − (a − c)² / (8 (a − 2b + c)), the vertex's value."""
    n = y.shape[0]
    k = jnp.argmax(y)
    a, b, c = y[(k - 1) % n], y[k], y[(k + 1) % n]
    den = a - 2.0 * b + c
    concave = den < 0
    t = jnp.clip(jnp.where(concave, 0.5 * (a - c) / jnp.where(concave, den, -1.0), 0.0), -1.0, 1.0)
    return b - 0.25 * (a - c) * t
