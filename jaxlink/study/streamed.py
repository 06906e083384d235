"""The checkpointed state of a streamed accumulator (Morris, DGSM): its sums saved after every
batch (`checkpoint.Checkpoint.save`) and put back exactly on resume."""

from __future__ import annotations

import numpy as np


class Streamed:
    """A streamed accumulator's checkpointed state: its `FIELDS` (arrays, None before the first
    batch where so), `COUNT` the one that is an integer. `state()` for `Checkpoint.save`,
    `restore(state)` puts them back exactly (Morris, DGSM)."""

    FIELDS: tuple = ()
    COUNT: str = ""

    def state(self) -> dict:
        return {k: getattr(self, k) for k in self.FIELDS}

    def restore(self, state) -> None:
        for k in self.FIELDS:
            v = state[k]
            setattr(self, k, int(v) if k == self.COUNT else None if v is None else np.array(v))
