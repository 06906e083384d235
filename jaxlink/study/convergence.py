"""A precision stopping rule for Sobol' indices and Monte Carlo: double the sample size until the
estimates' intervals are narrow enough, up to a cap (`[study] precision`, `max_samples`).

- `sensitivity`: from N = `samples` base samples, N is doubled until the largest bootstrap
  half-width of S1 and ST — over every response, every factor and the feasibility — is at most
  `precision` (an index's absolute scale: 0.05 ranks factors, 0.02 measures them), or N would
  exceed `max_samples`;
- `tolerance` (Monte Carlo): from n = `samples`, n is doubled until, for every response whose
  Monte Carlo σ is not zero, the half-widths z·(standard error) of its mean and of its σ are both
  at most `precision` × σ (relative to the response's own spread), or n would exceed
  `max_samples`.

Each round is a complete study at its size (the earlier rounds' evaluations are not reused: at
most twice the final round's work), so the result is exactly that of `sensitivity` or
`tolerance` at the size reached — `--samples N` reproduces it. `Convergence` says the size
reached, whether the rule was met, and each round's largest half-width.

**Resume.** With a `checkpoint.Checkpoint`, the round under way is checkpointed batch by batch as
`sensitivity`'s or the Monte Carlo's own (`Rounds`: the saved state is the round's size, the
half-widths of the rounds completed before it and the round's own streamed state). A killed study
resumed starts again in the round it was killed in, from its last batch, the rounds before it not
evaluated again (their half-widths were saved exactly, JSON keeping a float's every bit): the
rounds are deterministic (their sizes N₀ 2ᵏ, their samples from the seed), so the resumed study
ends with the uninterrupted one's result, history and convergence.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np


class Convergence(NamedTuple):
    """`samples` (N reached), `converged` (the rule met), `precision`, `max_samples`, `history`
    (per round: (samples, largest half-width; relative for Monte Carlo))."""

    samples: int
    converged: bool
    precision: float
    max_samples: int
    history: tuple


def sobol_half_width(rep) -> float:
    """The largest bootstrap half-width of S1 and ST of a `SensitivityReport` (its responses and
    its feasibility)."""
    out = 0.0
    for ind in (rep.indices, rep.feasibility):
        if ind is None:
            continue
        for m in ("S1", "ST"):
            h = 0.5 * (getattr(ind, m + "_high") - getattr(ind, m + "_low"))
            if h.size:
                out = max(out, float(np.max(h)))
    return out


def monte_carlo_half_width(mc, confidence: float) -> float:
    """The largest of z·(standard error of the mean) / σ and z·(standard error of σ) / σ over the
    responses of a `MonteCarlo` whose σ is not zero (inf when none is feasible)."""
    from scipy.stats import norm

    if mc is None or mc.feasible < 2:
        return float("inf")
    z = float(norm.ppf(0.5 + confidence / 2))
    scale = np.max(np.abs(mc.std)) if mc.std.size else 0.0
    vary = mc.std > 1e-12 * scale + 1e-300
    if not vary.any():
        return 0.0
    rel = np.maximum(mc.mean_error[vary], mc.std_error[vary]) / mc.std[vary]
    return float(z * rel.max())


class Rounds:
    """The checkpoint of one round of the stopping rule, over the study's `checkpoint.Checkpoint`
    `base`: what `sensitivity` and `Study.monte_carlo` load and save (the round's streamed state)
    wrapped with the round's size `samples` and the completed rounds' `history`. `load()` gives
    the round's state only when the saved round is this one (else None: the round starts afresh);
    `saved_round()` the saved (samples, history), or None."""

    def __init__(self, base, samples: int, history: list):
        self.base = base
        self.samples = int(samples)
        self.history = history

    @property
    def dir(self):
        """The folder of the study's checkpoint (`resources.check` estimates its free space)."""
        return self.base.dir

    @staticmethod
    def saved_round(base):
        saved = None if base is None else base.load()
        if saved is None:
            return None
        state = saved[1]
        return int(state["samples"]), [(int(n), float(h)) for n, h in state["history"]]

    def load(self):
        saved = self.base.load()
        if saved is None or int(saved[1]["samples"]) != self.samples:
            return None
        return saved[0], saved[1]["round"]

    def save(self, done: int, state) -> None:
        self.base.save(done, {"samples": self.samples, "history": [list(r) for r in self.history], "round": state})


def _resumed(checkpoint, n0: int, cap: int) -> tuple[list, list]:
    """(the rounds' sizes still to run, the history of the rounds completed) of a resumed study."""
    sizes = list(_rounds(n0, cap))
    saved = Rounds.saved_round(checkpoint)
    if saved is None:
        return sizes, []
    n, history = saved
    if n not in sizes or [h[0] for h in history] != sizes[:sizes.index(n)]:
        from ..errors import MechanismError

        raise MechanismError(f"{checkpoint.dir}: the checkpoint's round of {n} samples is not a round of this study; "
                             "run without --resume to start afresh")
    return sizes[sizes.index(n):], history


def _rounds(n0: int, cap: int):
    n = max(int(n0), 2)
    while True:
        yield n
        if 2 * n > cap:
            return
        n *= 2


def converged_sensitivity(mech, inputs=None, *, precision: float | None = None, max_samples: int | None = None,
                          chunk=None, options=None, progress=None, study=None, checkpoint=None):
    """`sensitivity` with the stopping rule (see the module doc): (`SensitivityReport` at the N
    reached, `Convergence`). `precision` and `max_samples` default to the inputs'; `checkpoint`
    (a `checkpoint.Checkpoint`): every round checkpointed batch by batch, a killed study resumed
    in its round (see the module doc). Its resume key sees `inputs`: give `precision` and
    `max_samples` there (`read_study(..., precision=...)`), not as arguments, when resuming."""
    from .sampling import _study, sensitivity

    study = _study(mech, inputs, study, chunk, options)
    inputs = study.inputs
    eps = inputs.precision if precision is None else float(precision)
    cap = inputs.max_samples if max_samples is None else int(max_samples)
    if eps is None:
        raise ValueError("converged_sensitivity needs a precision ([study] precision)")
    t0 = time.perf_counter()
    sizes, history = _resumed(checkpoint, inputs.samples, cap) if checkpoint is not None else (
        list(_rounds(inputs.samples, cap)), [])
    rep = None
    for n in sizes:
        rep = sensitivity(mech, study=study, samples=n, progress=progress,
                          checkpoint=None if checkpoint is None else Rounds(checkpoint, n, list(history)))
        h = sobol_half_width(rep)
        history.append((n, h))
        if h <= eps:
            break
    assert rep is not None
    conv = Convergence(history[-1][0], history[-1][1] <= eps, eps, cap, tuple(history))
    rep.timings["rounds_total"] = time.perf_counter() - t0
    if not conv.converged:
        rep.warnings.append(f"the precision {eps:g} was not reached: the largest half-width of S1/ST is "
                            f"{history[-1][1]:.3g} at N = {conv.samples} base samples (max_samples {cap})")
    return rep, conv


def converged_tolerance(mech, inputs=None, *, precision: float | None = None, max_samples: int | None = None,
                        chunk=None, options=None, progress=None, study=None, worst: bool = True, checkpoint=None):
    """`tolerance` with the stopping rule on its Monte Carlo (see the module doc):
    (`ToleranceReport` at the n reached, `Convergence`); `checkpoint` as `converged_sensitivity`'s."""
    from .sampling import _study
    from .tolerance import tolerance
    from .worstcase import worst_case

    study = _study(mech, inputs, study, chunk, options)
    inputs = study.inputs
    eps = inputs.precision if precision is None else float(precision)
    cap = inputs.max_samples if max_samples is None else int(max_samples)
    if eps is None:
        raise ValueError("converged_tolerance needs a precision ([study] precision)")
    t0 = time.perf_counter()
    sizes, history = _resumed(checkpoint, inputs.samples, cap) if checkpoint is not None else (
        list(_rounds(inputs.samples, cap)), [])
    rep = None
    for n in sizes:
        rep = tolerance(mech, study=study, samples=n, progress=progress, worst=False,
                        checkpoint=None if checkpoint is None else Rounds(checkpoint, n, list(history)))
        h = monte_carlo_half_width(rep.monte_carlo, inputs.confidence)
        history.append((n, h))
        if h <= eps:
            break
    assert rep is not None
    conv = Convergence(history[-1][0], history[-1][1] <= eps, eps, cap, tuple(history))
    if worst:  # as `tolerance` does
        t3 = time.perf_counter()
        wc = worst_case(study, rep.first_order, rep.deviation_bound)
        rep.timings["worst_case"] = time.perf_counter() - t3
        if wc.infeasible:
            rep.warnings.append(
                f"{wc.infeasible} of the {wc.candidates} corners searched for the worst case do not assemble over the "
                "whole cycle: the tolerance box holds designs that do not assemble (the worst case is that of the "
                "feasible designs found)")
        rep = rep._replace(worst=wc)
    rep.timings["rounds_total"] = time.perf_counter() - t0
    if not conv.converged:
        rep.warnings.append(f"the precision {eps:g} was not reached: the largest relative half-width of the Monte "
                            f"Carlo mean and σ is {history[-1][1]:.3g} at {conv.samples} samples (max_samples {cap})")
    return rep, conv
