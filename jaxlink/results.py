"""Result codes and the solution record of a loop-closure solve."""

from __future__ import annotations

from typing import NamedTuple

import jax


class RESULTS:
    """Result codes (int8) of every solved position, with what to do about each."""

    converged = 0
    max_steps = 1
    singular = 2
    cannot_assemble = 3
    nonfinite = 4

    messages = {
        0: "converged",
        1: "max steps: Newton did not reach the tolerance (or only on another assembly branch); "
           "raise max_steps or refine the input step",
        2: "singular Jacobian: a dead-centre/toggle/change-point position, assembled (to about "
           "√eps near a double root); the solution is not unique here",
        3: "cannot assemble: the loops cannot close at this input (a link is too short to reach)",
        4: "non-finite values: check the parameters (NaN/inf) and the expressions",
    }
    names = {0: "converged", 1: "max_steps", 2: "singular", 3: "cannot_assemble", 4: "nonfinite"}


class Solution(NamedTuple):
    """Positions solved for a sequence of inputs (leading axis = position).

    **Fields:**

    - `q`: (N, n) unknowns, SI. Where not converged: the last finite iterate (never NaN).
    - `converged`: (N,) bool.
    - `residual`: (N,) max-norm of the loop residual at `q`, metres (after Newton's final
      correction; for the closed form, the miss of the constructed loops, exact to rounding).
    - `result`: (N,) int8 code, see `RESULTS`.
    - `steps`: (N,) Newton iterations used.
    """

    q: jax.Array
    converged: jax.Array
    residual: jax.Array
    result: jax.Array
    steps: jax.Array
