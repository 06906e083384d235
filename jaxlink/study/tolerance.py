"""Tolerance analysis around one design: exact first order from the Jacobian of the responses,
and Monte Carlo with the tolerances' distributions. The formulas and when first order can be
trusted: docs/methods/tolerance.md.

**First order.** J = ∂y/∂x (M responses × T toleranced parameters, file units) by `jax.jacfwd`
of `Responses.single`, the path solve differentiated implicitly. With σ_j the standard deviation
of parameter j (independent inputs) and t_j its half-width:

    σ_y,RSS = √(Σ_j (J_j σ_j)²)                  (root sum of squares)
    w_y = Σ_j |J_j| t_j                           (linear worst case over the box)
    I_j = (J_j σ_j)² / σ_y,RSS²                   (importance factors, Σ_j I_j = 1)

A circular zone (x, y) of radius r counts r √(J_x² + J_y²) to the worst case (the largest change
over the disc), and σ_x = σ_y per coordinate to the RSS (uncorrelated). With a
`[study.correlation]`, Σ the covariance of the inputs that the Monte Carlo draws have
(`copula.covariance`: Σ_ab = σ_a σ_b ρ_ab, ρ the Pearson correlation of the Gaussian copula):

    σ_y,RSS² = J Σ Jᵀ,   I_j = J_j (Σ J)_j / σ_y,RSS²   (Σ_j I_j = 1; an I_j can be negative)

and the linear worst case is unchanged (the box is the box).

**Monte Carlo.** `samples` designs drawn from the distributions (`draw`: numpy's Generator,
one stream per block of `BLOCK` samples seeded with (seed, block), so the samples do not depend
on the batch size), solved in batches (`vmap`, `chunk` designs per compiled call, bounded memory),
the statistics streamed (`moments.Moments`). A design that does not assemble over the whole cycle
on the nominal's branch is *counted* (`infeasible`) and left out of the statistics, which are
those of the feasible designs; never dropped silently, never a NaN.

**Agreement** (`agreement`). Where Monte Carlo ran, every response whose Monte Carlo σ differs
from σ_RSS by more than z standard errors of the sample σ, or whose mean differs from the nominal
(plus the second-order mean shift where second order ran) by more than z standard errors of the
mean, is flagged (z for a family-wise 1 % false-alarm rate over the
responses: Bonferroni), with the nonlinearity it reveals.
"""

from __future__ import annotations

import functools
import math
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..analysis.feasibility import MARGIN_SLACK
from ..solvers.options import NewtonOptions
from . import reuse
from .distributions import deviations
from .inputs import StudyInputs
from .moments import Moments
from .responses import Responses, outside_warning
from .second_order import SecondOrder, second_order_stats
from .worstcase import WorstCase, worst_case

#: samples per random stream (the chunk is a multiple of it)
BLOCK = 1024
#: the lower and upper quantiles reported (the ±3σ coverage of a normal distribution)
QUANTILES = (0.00135, 0.99865)
#: designs per batch of the certificate (those whose screened margin is below zero)
CERTIFY_BATCH = 256
#: Monte Carlo samples needed before first order is compared with it
MIN_COMPARE = 100


class FirstOrder(NamedTuple):
    """First-order results (file units). `jacobian` (M, T); `sigma_rss`, `worst_case` (M,);
    `importance` (M, T); `sigma`, `half_width` (T,) of each toleranced parameter."""

    jacobian: np.ndarray
    sigma_rss: np.ndarray
    worst_case: np.ndarray
    importance: np.ndarray
    sigma: np.ndarray
    half_width: np.ndarray


class MonteCarlo(NamedTuple):
    """Monte Carlo statistics of the feasible samples (file units; deviations from the nominal).

    `samples`, `feasible`, `infeasible` (counts); `mean_shift`, `std`, `std_error`, `mean_error`,
    `low`, `high` (the `QUANTILES`), `max_abs` (the largest |deviation|) — (M,) each, zeros when no
    sample is feasible; `deviation_max` (K,) the largest path deviation max_φ |P − P_nominal| of each
    point over the samples, `deviation_mean` (K,) its mean; `agree` (M,) False where first order
    and Monte Carlo disagree beyond the sampling error.

    Against the specification limits of `[study] limits` (scalar responses; see `capability`):
    `limits` ((output, low, high, response index) per limited response), `out_of_spec` (L,) the
    feasible samples outside [low, high] (counted exactly, sample by sample), `percent_out` (L,)
    100 × that / `feasible`, `cp` (L,) (U − L) / (6 s) (NaN for a one-sided limit), `cpk` (L,)
    min(U − μ, μ − L) / (3 s) — μ the samples' mean (nominal + `mean_shift`), s their `std`.

    `histogram` (S, bins + 2) the feasible samples' deviations of the S scalar responses (the
    metrics, in the order of the labels) counted in `bins` equal bins over [−w, w] (w =
    `histogram_width` (S,)), with the counts below and above first and last (`moments.Moments`:
    the streamed histogram the quantiles come from); None when there is no scalar response.

    `outside`: of the `infeasible`, the samples with a value outside its domain
    (`jaxlink.model.domains`: a tolerance wider than the link draws a negative length)."""

    samples: int
    feasible: int
    infeasible: int
    mean_shift: np.ndarray
    std: np.ndarray
    std_error: np.ndarray
    mean_error: np.ndarray
    low: np.ndarray
    high: np.ndarray
    max_abs: np.ndarray
    deviation_max: np.ndarray
    deviation_mean: np.ndarray
    agree: np.ndarray
    limits: tuple = ()
    out_of_spec: np.ndarray = np.zeros(0, np.int64)
    percent_out: np.ndarray = np.zeros(0)
    cp: np.ndarray = np.zeros(0)
    cpk: np.ndarray = np.zeros(0)
    histogram: np.ndarray | None = None
    histogram_width: np.ndarray | None = None
    outside: int = 0


class ToleranceReport(NamedTuple):
    """The result of `tolerance`.

    - `inputs`: the `StudyInputs`; `labels`: (output, unit, position index or None) per response;
      `input_values` (N,) the cycle's inputs (the input's file unit); `parameters` (T,) names;
    - `nominal` (M,) the nominal responses; `first_order` (`FirstOrder`); `monte_carlo`
      (`MonteCarlo` or None);
    - `deviation_bound` (K,): per studied point, the linear bound of the path deviation
      max_φ |P − P_nominal| over the tolerance box (Σ_j t_j |∂P/∂x_j|, a zone r ‖∂P/∂(x, y)‖₂);
    - `certificate` ("reach margin" | "sampled only"), `margin` (the nominal's smallest reach
      margin over the cycle, dimensionless; None without a certificate), `margin_drop` (its linear
      worst-case drop under the tolerances; first order is not to be trusted where it reaches the
      margin: a toggle or change point within the tolerances);
    - `warnings` (list of str); `timings` (dict of seconds);
    - `worst` (`worstcase.WorstCase`, or None when not asked): the true worst case over the box;
    - `second_order` (`second_order.SecondOrder`, or None when not asked): the second-order mean
      shift and σ of every response from its exact Hessian.
    """

    inputs: StudyInputs
    labels: tuple
    input_values: np.ndarray
    parameters: tuple
    nominal: np.ndarray
    first_order: FirstOrder
    monte_carlo: MonteCarlo | None
    deviation_bound: np.ndarray
    certificate: str
    margin: float | None
    margin_drop: float | None
    warnings: list
    timings: dict
    worst: WorstCase | None = None
    second_order: SecondOrder | None = None


def draw(inputs: StudyInputs, block: int, size: int = BLOCK) -> np.ndarray:
    """(size, T) deviations of the toleranced parameters from nominal (file units) of random block
    `block` of the study (its own stream, seeded with (seed, block))."""
    rng = np.random.default_rng([inputs.seed, block])
    cols = []
    for t in inputs.tolerances:
        if t.zone:
            if t.distribution == "uniform":
                r = t.half_width * np.sqrt(rng.uniform(0.0, 1.0, size))
                a = rng.uniform(0.0, 2.0 * np.pi, size)
                cols += [r * np.cos(a), r * np.sin(a)]
            else:
                cols += [t.sigma * rng.standard_normal(size), t.sigma * rng.standard_normal(size)]
        elif t.distribution == "uniform":
            cols.append(rng.uniform(-t.half_width, t.half_width, size))
        elif t.distribution == "normal":
            cols.append(t.sigma * rng.standard_normal(size))
        else:  # triangular, truncated normal: the inverse CDF of uniform draws
            cols.append(deviations(t.distribution, rng.uniform(0.0, 1.0, size), t.half_width, t.sigma, t.k))
    if inputs.correlation:  # Iman–Conover on its own stream: the independent draws are unchanged
        from .correlation import correlate

        return correlate(inputs, np.stack(cols, axis=1), [inputs.seed, block, 1])
    return np.stack(cols, axis=1)


def draws(inputs: StudyInputs, n: int) -> np.ndarray:
    """(n, T) the first `n` Monte Carlo deviations of the study (blocks 0, 1, … of `draw`): the
    samples `Study.monte_carlo` evaluates, whatever its batch size."""
    blocks = [draw(inputs, b) for b in range(-(-n // BLOCK))]
    return np.concatenate(blocks)[:n] if blocks else np.zeros((0, len(inputs.parameters)))


def default_chunk(inputs: StudyInputs) -> int:
    """The designs per compiled batch when none is given: about 2^21 positions per batch, the
    largest power of two times `BLOCK` below that; for a Monte Carlo (`tolerance` with samples)
    or a `sensitivity` study, the multiple of `BLOCK` up to that size that evaluates the study's
    designs at the least cost, a batch costing its padded size plus about `BLOCK` / 4 designs
    (the call and its copies; the larger chunk on a tie). Monte Carlo: the samples; sensitivity:
    N (D + 2) designs in batches of whole base samples (D + 2 designs each), the first also
    holding the nominal — 4096 base samples of 4 factors over 360 positions are 5 batches of
    5120 designs, not 7 of 4096 (the last one of 24 designs); 2048 Monte Carlo samples one batch
    of 2048, not of 4096."""
    cap = max(1, (1 << 21) // max(inputs.positions, 1))
    pow2 = max(BLOCK, 2 ** int(math.log2(cap)))
    if inputs.method not in ("tolerance", "sensitivity") or not inputs.samples:
        return pow2
    d, nominal = (len(inputs.factors) + 2, 1) if inputs.method == "sensitivity" else (1, 0)

    def cost(c):
        per = c // d
        if per == 0:
            return math.inf
        calls = -(-inputs.samples // per) + (per * d + nominal > c)  # the nominal spills the first batch over
        return calls * (c + BLOCK // 4)

    return min(range(BLOCK, max(BLOCK, cap // BLOCK * BLOCK) + 1, BLOCK), key=lambda c: (cost(c), -c))


class Study:
    """A tolerance study of one mechanism, compiled once: `first_order()` and `monte_carlo(n)`
    may be called again (warm) with nothing recompiled.

    **Arguments:** `mech`, `inputs` (`read_study`), `options` (`NewtonOptions`), `chunk` (designs
    per compiled batch, a multiple of `BLOCK`; default from the number of positions)."""

    def __init__(self, mech, inputs: StudyInputs, *, options: NewtonOptions = NewtonOptions(), chunk=None):
        self.mech = mech
        self.inputs = inputs
        self.responses = r = Responses(mech, inputs, options)
        self.x0 = np.asarray(mech.parameters)[r.index] / r.factor
        sig, half = [], []
        for t in inputs.tolerances:
            sig += [t.sigma] * len(t.parameters)
            half += [t.half_width] * len(t.parameters)
        self.sigma = np.asarray(sig)
        self.half_width = np.asarray(half)
        chunk = chunk or inputs.chunk or default_chunk(inputs)
        self.chunk = -(-int(chunk) // BLOCK) * BLOCK
        self._jac = jax.jit(jax.jacfwd(_with_aux(r.single), has_aux=True))
        self._hess = jax.jit(jax.jacfwd(jax.jacfwd(lambda x: r.single(x, "screen")[0])))  # compiled when first asked
        self._batch = jax.jit(jax.vmap(lambda x: r.single(x, "screen")))
        self._certify = None if r.dyads is None else jax.jit(jax.vmap(r.certified))
        self._margin = None
        if r.dyads is not None:
            self._margin = jax.jit(jax.value_and_grad(self._margin_of))
        self._nominal: tuple | None = None
        self._robust_cache: dict = {}  # the robust-design map's compiled evaluators, shared with `moved` copies

    def moved(self, x0=None, inputs: StudyInputs | None = None) -> "Study":
        """The same study around another design `x0` (T,) (the toleranced parameters, file units)
        and/or with other tolerances `inputs` (the same parameters, positions, points and metrics):
        the compiled functions are reused (nothing is compiled again)."""
        import copy

        new = copy.copy(self)
        if inputs is not None:
            same = ("parameters", "positions", "points", "metrics", "rpm")
            if any(getattr(inputs, k) != getattr(self.inputs, k) for k in same):
                raise ValueError(f"moved: the inputs must keep the {', '.join(same)} of the study")
            new.inputs = inputs
            new.sigma = np.asarray([t.sigma for t in inputs.tolerances for _ in t.parameters])
            new.half_width = np.asarray([t.half_width for t in inputs.tolerances for _ in t.parameters])
        if x0 is not None:
            new.x0 = np.asarray(x0, float)
        new._nominal = None
        return new

    def _margin_of(self, x):
        """The smallest reach margin over the cycle (`feasibility.certify`), as a function of `x`
        for its derivative: the margin at the minimum's input held fixed (the minimum's move does not
        count to first order)."""
        from ..analysis import feasibility as _feasibility
        from ..solvers import dyads as _dyads

        r = self.responses
        p = r.params(x)
        q0 = jnp.asarray(r.q_file, p.dtype)  # the angles' reference (the branches are σ)
        sig = jnp.asarray(r.sigma, p.dtype)
        cert = _feasibility.certify(self.mech, r.dyads, sig, q0, jnp.asarray(r.phis, p.dtype), jax.lax.stop_gradient(p))
        where = jax.lax.stop_gradient(cert.where)
        return jnp.min(_dyads.reach_margins(self.mech, r.dyads, sig, q0, where, p))

    def nominal(self):
        """(responses (M,), feasible, margin) of the nominal design."""
        if self._nominal is None:
            self.first_order()
        return self._nominal

    def first_order(self) -> FirstOrder:
        """The first-order analysis (see the module doc); the nominal responses come with it."""
        J, (v, ok, m) = self._jac(jnp.asarray(self.x0))
        self._nominal = (np.asarray(v), bool(ok), float(m))
        return first_order_stats(np.asarray(J), self.inputs)

    def second_order(self, first: FirstOrder) -> SecondOrder:
        """The second-order mean shift and σ (`second_order.py`) from the exact Hessian of every
        response at the nominal and the first-order Jacobian `first.jacobian`."""
        return second_order_stats(first.jacobian, np.asarray(self._hess(jnp.asarray(self.x0))), self.inputs)

    def margin_drop(self):
        """(margin, its linear worst-case drop) of the nominal (dyad mechanisms), else (None, None)."""
        if self._margin is None:
            return None, None
        m, g = self._margin(jnp.asarray(self.x0))
        g = np.asarray(g)
        if not np.all(np.isfinite(g)):  # a margin not differentiable there (exactly at a toggle)
            return float(m), math.inf
        return float(m), float(_group_norms(g[None], self.inputs)[0] @ _group_half_widths(self.inputs))

    def _certified(self, x, ok, estimate):
        """`ok` and, where the screen's estimate is below zero, the certificate (`Responses.certified`,
        in batches of `CERTIFY_BATCH`): a design whose conservative estimate stays ≥ 0 needs no refinement."""
        doubt = np.flatnonzero(ok & (estimate < -MARGIN_SLACK))
        if doubt.size == 0 or self._certify is None:
            return ok
        ok = ok.copy()
        for s in range(0, doubt.size, CERTIFY_BATCH):
            rows = doubt[s:s + CERTIFY_BATCH]
            xs = np.empty((CERTIFY_BATCH, x.shape[1]))
            xs[:] = self.x0
            xs[:len(rows)] = x[rows]
            ok[rows] = np.asarray(self._certify(jnp.asarray(xs)))[:len(rows)]
        return ok

    def monte_carlo(self, n: int, first: FirstOrder, *, progress=None, checkpoint=None,
                    second: SecondOrder | None = None) -> MonteCarlo:
        """`n` Monte Carlo samples (see the module doc); `progress(k)` is called after each batch
        with the samples done in it. `checkpoint` (a `checkpoint.Checkpoint`): the streamed state
        is saved after every batch, and a saved state resumed (the batches done skipped). `second`
        (`SecondOrder`): the mean is compared with the nominal plus its mean shift (`agreement`)."""
        r = self.responses
        nominal = self.nominal()[0]
        n_curve = r.n_curve
        K = len(self.inputs.points)
        N = self.inputs.positions
        width = np.maximum(1.5 * first.worst_case, 8.0 * first.sigma_rss)
        width = np.where(width > 0, width, 1e-300)
        mom = Moments(width)
        dev_max = np.zeros(K)
        dev_sum = np.zeros(K)
        limits = limited_responses(self.mech, self.inputs, r.labels)
        spec_rows = jnp.asarray([i for (_, _, _, i) in limits], int)
        spec_low = np.asarray([lo for (_, lo, _, _) in limits])
        spec_high = np.asarray([hi for (_, _, hi, _) in limits])
        out_of_spec = np.zeros(len(limits), np.int64)
        feasible = infeasible = outside = 0
        blocks = -(-n // BLOCK)
        per = self.chunk // BLOCK
        done = 0
        saved = None if checkpoint is None else checkpoint.load()
        if saved is not None:
            done, state = saved
            mom.restore(state["moments"])
            dev_max, dev_sum = state["deviation_max"], state["deviation_sum"]
            feasible, infeasible = state["feasible"], state["infeasible"]
            outside = int(state.get("outside", 0))
            out_of_spec = np.asarray(state.get("out_of_spec", out_of_spec), np.int64)
            if progress is not None:
                progress(min(n, done * self.chunk))
        for c, b0 in enumerate(range(0, blocks, per)):
            if c < done:
                continue
            bs = range(b0, min(blocks, b0 + per))
            dx = np.concatenate([draw(self.inputs, b) for b in bs])  # as `draws`
            take = min(n - b0 * BLOCK, len(dx))
            dx = dx[:take]
            x = np.empty((self.chunk, len(self.x0)))
            x[:] = self.x0
            x[:take] += dx
            v, ok, est = self._batch(jnp.asarray(x))
            ok = np.asarray(ok)[:take]
            ok = self._certified(x[:take], ok, np.asarray(est)[:take])
            w = np.zeros(self.chunk)
            w[:take] = ok
            feasible += int(ok.sum())
            infeasible += int(take - ok.sum())
            outside += r.outside(x[:take])
            d = v - jnp.asarray(nominal)
            mom.update(d, w)
            if K and ok.any():
                dist = np.asarray(_path_deviation(d[:, :n_curve], jnp.asarray(w), K, N))
                dev_max = np.maximum(dev_max, dist.max(axis=0))
                dev_sum += dist.sum(axis=0)
            if limits and ok.any():
                vs = np.asarray(v[:, spec_rows])[:take]
                out_of_spec += (((vs < spec_low) | (vs > spec_high)) & ok[:, None]).sum(axis=0)
            if checkpoint is not None:
                checkpoint.save(c + 1, {"moments": mom.state(), "deviation_max": dev_max, "deviation_sum": dev_sum,
                                        "feasible": feasible, "infeasible": infeasible, "out_of_spec": out_of_spec,
                                        "outside": outside})
            if progress is not None:
                progress(take)
        M = len(nominal)
        cap = capability(limits, nominal, mom.mean, mom.std, out_of_spec, mom.n)
        scalar = [i for i, (_nm, _u, k) in enumerate(r.labels) if k is None]
        hist = (mom.hist[scalar].copy(), mom.width[scalar].copy()) if scalar else (None, None)
        if mom.n == 0:
            z = np.zeros(M)
            return MonteCarlo(n, 0, infeasible, z, z, z, z, z, z, z, dev_max, dev_sum, np.ones(M, bool), *cap,
                              *hist)._replace(outside=outside)
        std, se, me = mom.std, mom.std_error, mom.mean_error
        agree = agreement(mom.mean, std, me, se, mom.n, nominal, first, second)
        return MonteCarlo(n, feasible, infeasible, mom.mean, std, se, me, mom.quantile(QUANTILES[0]),
                          mom.quantile(QUANTILES[1]), np.maximum(np.abs(mom.low), np.abs(mom.high)),
                          dev_max, dev_sum / max(feasible, 1), agree, *cap, *hist)._replace(outside=outside)


def agreement(mean_shift, std, mean_error, std_error, n: int, nominal, first: FirstOrder,
              second: SecondOrder | None = None) -> np.ndarray:
    """(M,) False where Monte Carlo disagrees with the moment method beyond its sampling error (the
    module doc): |s − σ_RSS| > z SE(s), or |mean − y(x̄) − shift| > z SE(mean), shift the second-order
    mean shift of `second` (0 without: first order predicts none); z of `_bonferroni` over the M
    responses, plus a floor of 1e-9 relative for the solve's rounding. All True below `MIN_COMPARE`
    samples."""
    M = len(nominal)
    if n < MIN_COMPARE:
        return np.ones(M, bool)
    zcrit = _bonferroni(M)
    floor = 1e-9 * (np.abs(nominal) + first.sigma_rss) + 1e-300  # rounding of the solve
    shift = np.zeros(M) if second is None else np.asarray(second.mean_shift)
    return ((np.abs(np.asarray(std) - first.sigma_rss) <= zcrit * np.asarray(std_error) + floor)
            & (np.abs(np.asarray(mean_shift) - shift) <= zcrit * np.asarray(mean_error) + floor))


def limited_responses(mech, inputs: StudyInputs, labels) -> tuple:
    """((output, low, high, response index), …) of `[study] limits`, each a scalar response of
    `labels` (a metric: stroke(…), swing(…), max_speed(…), …); raises `MechanismError` naming the
    scalar responses where a limit names none of them."""
    from ..errors import MechanismError
    from ..files.keys import suggest

    scalar = {name: i for i, (name, _u, k) in enumerate(labels) if k is None}
    unknown = [name for name, _lo, _hi in inputs.limits if name not in scalar]
    if unknown:
        raise MechanismError(f"limits: no scalar response {', '.join(map(repr, unknown))}"
                             f"{suggest(unknown[0], scalar)}; the scalar responses: {', '.join(scalar) or '(none)'}",
                             file=mech.file, key=f"study.limits.{unknown[0]}")
    return tuple((name, lo, hi, scalar[name]) for name, lo, hi in inputs.limits)


def capability(limits, nominal, mean_shift, std, out_of_spec, feasible: int) -> tuple:
    """(limits, out_of_spec, percent_out, Cp, Cpk) of the limited responses from the streamed
    statistics (`MonteCarlo`'s fields; the formulas in its doc and docs/methods/tolerance.md):
    Cp = (U − L) / (6 s), NaN for a one-sided limit; Cpk = min(U − μ, μ − L) / (3 s) (±inf where
    s = 0, as the robust map's `robust.process_capability`)."""
    rows = np.asarray([i for (*_, i) in limits], int)
    low = np.asarray([lo for (_, lo, _, _) in limits])
    high = np.asarray([hi for (_, _, hi, _) in limits])
    mu = np.asarray(nominal)[rows] + np.asarray(mean_shift)[rows]
    s = np.asarray(std)[rows]
    gap = np.minimum(high - mu, mu - low)
    with np.errstate(divide="ignore", invalid="ignore"):
        cp = np.where(np.isfinite(high - low), (high - low) / (6.0 * s), np.nan)
        cpk = np.where(s > 0, gap / (3.0 * s), np.where(gap >= 0, np.inf, -np.inf))
    out = np.asarray(out_of_spec, np.int64)
    return tuple(limits), out, 100.0 * out / max(feasible, 1), cp, cpk


@functools.partial(jax.jit, static_argnums=(2, 3))
def _path_deviation(d, w, K: int, N: int):
    """(B, K) max over the cycle of |P − P_nominal| of each point, 0 where `w` is 0."""
    c = d.reshape(d.shape[0], K, 2, N)
    return jnp.max(jnp.sqrt(c[:, :, 0] ** 2 + c[:, :, 1] ** 2), axis=2) * w[:, None]


def _with_aux(single):
    """x ↦ (responses, (responses, feasible, margin)): the nominal comes with its Jacobian."""
    def f(x):
        v, ok, m = single(x)
        return v, (v, ok, m)
    return f


def first_order_stats(J, inputs: StudyInputs) -> FirstOrder:
    """σ_RSS, the linear worst case and the importance factors from the Jacobian `J` (M, T); with a
    `[study.correlation]` the covariance Σ of the inputs (`copula.covariance`): σ_RSS² = J Σ Jᵀ and
    I_j = J_j (Σ J)_j / σ_RSS² (module doc)."""
    J = np.asarray(J, float)
    sigma = np.asarray([t.sigma for t in inputs.tolerances for _ in t.parameters])
    half = np.asarray([t.half_width for t in inputs.tolerances for _ in t.parameters])
    if inputs.correlation:
        from .copula import covariance

        contrib = J * (J @ covariance(inputs))  # J_j (Σ J)_j: Σ_j of it is Jᵀ Σ J
    else:
        contrib = (J * sigma) ** 2
    var = np.maximum(contrib.sum(axis=1), 0.0)
    worst = _group_norms(J, inputs) @ _group_half_widths(inputs)
    importance = np.where(var[:, None] > 0, contrib / np.where(var > 0, var, 1.0)[:, None], 0.0)
    return FirstOrder(J, np.sqrt(var), worst, importance, sigma, half)


def _group_norms(J, inputs):
    """(M, G): |J_j| of a scalar tolerance, √(J_x² + J_y²) of a zone."""
    cols, j = [], 0
    for t in inputs.tolerances:
        k = len(t.parameters)
        cols.append(np.sqrt((J[:, j:j + k] ** 2).sum(axis=1)))
        j += k
    return np.stack(cols, axis=1)


def _group_half_widths(inputs):
    return np.asarray([t.half_width for t in inputs.tolerances])


def deviation_bound(J, inputs, n_points: int, n: int):
    """(K,) linear bound of max_φ |P − P_nominal| over the tolerance box, per point: max over the
    positions of Σ_groups t ‖∂P/∂x_group‖₂ (a scalar tolerance: the length of its 2-vector; a zone:
    the largest singular value of its 2 × 2 block)."""
    if n_points == 0:
        return np.zeros(0)
    T = J.shape[1]
    c = J[:2 * n * n_points].reshape(n_points, 2, n, T).transpose(0, 2, 1, 3)  # (K, N, 2, T)
    total = np.zeros((n_points, n))
    j = 0
    for t in inputs.tolerances:
        k = len(t.parameters)
        block = c[..., j:j + k]  # (K, N, 2, k)
        total += t.half_width * (np.linalg.norm(block[..., 0], axis=-1) if k == 1
                                 else np.linalg.svd(block, compute_uv=False)[..., 0])
        j += k
    return total.max(axis=1)


def _bonferroni(m: int) -> float:
    """z of a two-sided test at a family-wise 1 % over `m` tests."""
    from scipy.stats import norm

    return float(norm.isf(0.005 / max(m, 1)))


def study_for(mech, inputs: StudyInputs, *, options: NewtonOptions | None = None, chunk: int | None = None) -> Study:
    """The `Study` of `mech` and `inputs` (`options` default `NewtonOptions()`, `chunk` designs per
    batch as `Study`'s), built at the first call with its key (`reuse.study_key`: the mechanism's
    structure, labels and numbers, every input, the options, the chunk, the devices and x64 mode)
    and reused by the later ones: a second identical call compiles nothing (`reuse.py`)."""
    options = options or NewtonOptions()
    return reuse.kept(mech, inputs, options, chunk,
                      lambda m, i: Study(m, i, options=options, chunk=chunk))


def tolerance(mech, inputs: StudyInputs | None = None, *, samples: int | None = None, chunk=None,
              options: NewtonOptions = NewtonOptions(), progress=None, study: Study | None = None,
              worst: bool = True, checkpoint=None, second_order: bool = False) -> ToleranceReport:
    """The tolerance analysis of `mech` around its design (see the module doc).

    **Arguments:**

    - `mech`: the mechanism; `inputs`: `StudyInputs` (default: its `[study]` table, `read_study`);
    - `samples` (keyword-only): Monte Carlo samples (default the inputs'; 0: first order only);
    - `chunk`: designs per compiled batch; `options`: `NewtonOptions`; `progress`: called with
      the samples done after each Monte Carlo batch; `study`: a `Study` already compiled (warm;
      without it, the `Study` of `mech`, `inputs`, `options` and `chunk` kept from an earlier call
      is reused, `reuse.study_for`);
    - `worst`: search the true worst case over the tolerance box (`worstcase.worst_case`);
    - `checkpoint`: a `checkpoint.Checkpoint` of the Monte Carlo (saved batch by batch, resumed);
    - `second_order`: the second-order mean shift and σ from the exact Hessian (`second_order.py`; off by
      default: its Hessian costs one more compile, about 5 s).

    **Returns:** a `ToleranceReport`. Raises `MechanismError` when the nominal design does not
    assemble over its whole cycle.
    """
    from ..errors import MechanismError
    from .inputs import read_study

    timings = {}
    t0 = time.perf_counter()
    if study is None:  # kept for the next identical call (`study_for`)
        inputs = read_study(mech) if inputs is None else inputs
        study = study_for(mech, inputs, options=options, chunk=chunk)
    inputs = study.inputs
    r = study.responses
    t1 = time.perf_counter()
    first = study.first_order()
    timings["first_order"] = time.perf_counter() - t1
    second = None
    if second_order:
        from .second_order import unsupported

        why = unsupported(inputs)
        if why:
            raise MechanismError(why, file=mech.file, key="study.correlation")
        t1 = time.perf_counter()
        second = study.second_order(first)
        timings["second_order"] = time.perf_counter() - t1
    nominal, ok, margin = study.nominal()
    if not ok:
        raise MechanismError(
            "the nominal design does not assemble over its whole cycle"
            + (f" (its smallest reach margin is {margin:.3g} < 0)" if r.dyads is not None else "")
            + ": a tolerance study needs an assemblable design", file=mech.file, key="study")
    warnings = []
    m, drop = study.margin_drop()
    if m is not None and drop is not None and drop >= m:
        warnings.append(
            f"the tolerances can reach a toggle or change point: the nominal's smallest reach margin {m:.3g} "
            f"falls by up to {drop:.3g} to first order — first order is not to be trusted here (see the Monte Carlo "
            "infeasible count)")
    n_mc = inputs.samples if samples is None else int(samples)
    mc = None
    if n_mc > 0:
        t2 = time.perf_counter()
        mc = study.monte_carlo(n_mc, first, progress=progress, checkpoint=checkpoint, second=second)
        timings["monte_carlo"] = time.perf_counter() - t2
        unassembled = mc.infeasible - mc.outside  # the others are outside the domain: their own warning
        if unassembled:
            warnings.append(
                f"{unassembled} of {mc.samples} Monte Carlo samples ({100 * unassembled / mc.samples:.3g} %) do "
                f"not assemble over the whole cycle on the nominal's branch ({r.certificate}); the statistics are "
                f"those of the {mc.feasible} feasible samples")
        if mc.outside:
            warnings.append(outside_warning(mc.outside, mc.samples, "Monte Carlo samples"))
        if mc.feasible == 0:
            warnings.append("no Monte Carlo sample is feasible: the Monte Carlo statistics are empty (zeros)")
        bad = np.flatnonzero(~mc.agree)
        if bad.size:
            names = sorted({r.labels[i][0] for i in bad})
            rel = np.abs(mc.std[bad] - first.sigma_rss[bad]) / np.maximum(first.sigma_rss[bad], 1e-300)
            warnings.append(
                f"first order and Monte Carlo disagree beyond Monte Carlo's sampling error at {bad.size} of "
                f"{len(nominal)} responses ({', '.join(names[:6])}{', …' if len(names) > 6 else ''}; σ differs by up "
                f"to {100 * float(rel.max()):.3g} %): the response is not linear over the tolerances there"
                + (" (the mean compared with the nominal plus the second-order mean shift)" if second is not None
                   else ""))
    K = len(inputs.points)
    bound = deviation_bound(first.jacobian, inputs, K, inputs.positions)
    wc = None
    if worst:
        t3 = time.perf_counter()
        wc = worst_case(study, first, bound)
        timings["worst_case"] = time.perf_counter() - t3
        if wc.infeasible:
            warnings.append(
                f"{wc.infeasible} of the {wc.candidates} corners searched for the worst case do not assemble over the "
                "whole cycle: the tolerance box holds designs that do not assemble (the worst case is that of the "
                "feasible designs found)")
    timings["total"] = time.perf_counter() - t0
    return ToleranceReport(inputs, r.labels, r.input_values, inputs.parameters, nominal, first, mc, bound,
                           r.certificate, m, drop, warnings, timings, wc, second)
