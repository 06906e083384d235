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
        1: "max steps: Newton did not reach the tolerance; raise max_steps or refine the step",
        2: "singular Jacobian: a dead-centre/toggle position; the solution is not unique here",
        3: "cannot assemble: the loops cannot close at this input (a link is too short to reach)",
        4: "non-finite values: check the parameters (NaN/inf) and the expressions",
    }
    names = {0: "converged", 1: "max_steps", 2: "singular", 3: "cannot_assemble", 4: "nonfinite"}


class Solution(NamedTuple):
    """Positions solved for a sequence of inputs (leading axis = position).

    **Fields:**

    - `q`: (N, n) unknowns, SI. Where not converged: the last finite iterate (never NaN).
    - `converged`: (N,) bool.
    - `residual`: (N,) max-norm of the loop residual before the final Newton correction, metres
      (the correction squares it, so the residual at `q` is far smaller when converged).
    - `result`: (N,) int8 code, see `RESULTS`.
    - `steps`: (N,) Newton iterations used.
    """

    q: jax.Array
    converged: jax.Array
    residual: jax.Array
    result: jax.Array
    steps: jax.Array
