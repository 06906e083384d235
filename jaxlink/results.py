"""One result enumeration for every solver in jaxlink, and the solution record of a position solve.

Solvers never raise inside jitted code: each solved item (a position, a reactions system, an ODE
run) carries an int8 code from `RESULTS`. The loop-closure solve (`jaxlink.solve`), the
kinetostatics (`jaxlink.reactions`) and the cam–follower dynamics (`jaxlink.cam`) share the members
whose meaning is the same (`converged`, `max_steps`, `singular`, `nonfinite`); the others exist
only where their meaning does.
"""

from __future__ import annotations

from typing import NamedTuple

import jax


class RESULTS:
    """Result codes (int8), with a message saying what to do about each.

    | code | name | from | meaning |
    |---|---|---|---|
    | 0 | `converged` | all | solved (loops closed, finite, regular; reactions solved; ODE at its end time) |
    | 1 | `max_steps` | assembly, cam | ran out of iterations / integration steps |
    | 2 | `singular` | assembly, reactions | a singular Jacobian or system (toggle, dead centre) |
    | 3 | `cannot_assemble` | assembly | the loops cannot close at this input |
    | 4 | `nonfinite` | all | non-finite values (NaN/inf parameters, expressions, state) |
    | 5 | `not_assembled` | reactions | the kinematics did not converge at this position |
    | 6 | `step_size_too_small` | cam | the ODE step size underflowed |
    | 7 | `stopped` | cam | a monitor stopped the run early (e.g. jamming): not a failure |
    | 8 | `imprecise` | kinematics table | float32 too near a singular position: outside the float32 tolerance |

    `RESULTS.name(code)` and `RESULTS.message(code)` read them; `names` and `messages` are the
    same as dictionaries.

    Finiteness is part of convergence: a position whose values (unknowns, points, rates,
    velocities, accelerations, reactions) are not finite is never `converged`. A position whose
    loops closed at a singular Jacobian (toggle, change point) is *assembled* but `singular`, not
    `converged`: its positions are given, its rates are not defined.
    """

    converged = 0
    max_steps = 1
    singular = 2
    cannot_assemble = 3
    nonfinite = 4
    not_assembled = 5
    step_size_too_small = 6
    stopped = 7
    imprecise = 8

    names = {0: "converged", 1: "max_steps", 2: "singular", 3: "cannot_assemble", 4: "nonfinite",
             5: "not_assembled", 6: "step_size_too_small", 7: "stopped", 8: "imprecise"}
    messages = {
        0: "converged",
        1: "max steps: the iteration did not reach its tolerance (Newton: or only on another assembly "
           "branch; raise max_steps or refine the input step. ODE: raise max_steps or loosen rtol/atol)",
        2: "singular: a dead-centre/toggle/change-point position (the solution or the reactions are not "
           "unique here; an assembled position is accurate to about √eps near a double root), or joints "
           "that over-constrain the motion",
        3: "cannot assemble: the loops cannot close at this input (a link is too short to reach)",
        4: "non-finite values: check the parameters, masses and expressions (NaN/inf)",
        5: "the kinematics did not converge at this position (see `jaxlink kinematics`)",
        6: "step size underflow or non-finite state: the problem is ill-posed at these parameters "
           "(check the stiffness and mass)",
        7: "stopped early by the monitor (e.g. jamming detected)",
        8: "imprecise: in float32 too near a change point, toggle or dead centre (a dyad's links nearly in "
           "line) for the float32 tolerance: the position is given, its rates are nan; use --dtype float64 "
           "(float32's rounding is amplified by the inverse sine between the links, cubed for accelerations)",
    }

    @classmethod
    def name(cls, code) -> str:
        return cls.names[int(code)]

    @classmethod
    def message(cls, code) -> str:
        return cls.messages[int(code)]


class SolveStats(NamedTuple):
    """Statistics of a position solve (leading axes as the positions).

    - `residual`: max-norm of the loop residual at the returned `q`, metres (after Newton's final
      correction; for the closed form, the miss of the constructed loops, exact to rounding).
    - `steps`: Newton iterations used (0 for the closed form).
    """

    residual: jax.Array
    steps: jax.Array


class Solution(NamedTuple):
    """Positions solved for a sequence of inputs: value, result, stats (leading axes: designs if a
    batch, then positions).

    **Fields:**

    - `q`: (…, N, n) unknowns, SI, in the order of `Mechanism.unknown_names`. Where not converged:
      the last finite iterate (never NaN). None from `solve(..., unknowns=False)`.
    - `points`: (…, N, n_points, 2) the points of interest, metres, in the order of
      `Mechanism.point_names` (NaN where the position did not converge).
    - `result`: (…, N) int8 code, see `RESULTS`.
    - `stats`: `SolveStats` (residual, steps).

    `converged` (result == RESULTS.converged), `residual` and `steps` are shortcuts.
    """

    q: jax.Array
    points: jax.Array | None
    result: jax.Array
    stats: SolveStats

    @property
    def converged(self) -> jax.Array:
        return self.result == RESULTS.converged

    @property
    def residual(self) -> jax.Array:
        return self.stats.residual

    @property
    def steps(self) -> jax.Array:
        return self.stats.steps
