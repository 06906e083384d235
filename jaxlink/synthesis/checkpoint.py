"""The search's state after every round, written as it goes, and its resume.

After every round (and after every final polish) `search.search` writes its whole state — the
round count, the random key and generator, the elites, every candidate found, which of them were
polished, the rounds' durations and the time spent — to one file, atomically (a temporary file,
then a rename: a kill leaves the previous round's state). `resume` continues from it: with
`rounds` the search then ends with exactly the designs of an uninterrupted one (the rounds draw
from the saved key and generator, refine from the saved elites); with a time limit, the time
spent before counts against it.

The file is a Python pickle (candidates hold topologies, matches and certificates): resume only a
search of your own. It carries a fingerprint of everything the result depends on (the target,
the topologies, the seed, the options, jaxlink's source and JAX's version): a state of another search
is refused, never continued.
"""

from __future__ import annotations

import hashlib
import json
import os
import pathlib
import pickle
from typing import Any

import numpy as np

VERSION = 1


def fingerprint(target, topos, **options: Any) -> str:
    """What a saved state must match to be resumed: the target's points (and inputs), closed or
    open, the topologies (their structure, not only their names), `options`, jaxlink's own code
    (`cache.source_digest`: a state is resumed only by the code that wrote it, as a stored trace is
    loaded only by it — the package's version number stays the same across changes) and the JAX
    version."""
    import jax

    from ..cache import source_digest

    h = hashlib.sha256()
    h.update(np.ascontiguousarray(target.points, np.float64).tobytes())
    if target.inputs is not None:
        h.update(np.ascontiguousarray(target.inputs, np.float64).tobytes())
    h.update(repr([(t.name, tuple(t.dyads), t.traced, t.sliders, t.levers) for t in topos]).encode())
    h.update(json.dumps({"closed": bool(target.closed), "jaxlink": source_digest(), "jax": jax.__version__,
                         **options}, sort_keys=True, default=repr).encode())
    return h.hexdigest()[:16]


def save(path: pathlib.Path, fp: str, state: dict) -> None:
    """Write `state` with the fingerprint `fp` to `path` atomically."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        pickle.dump({"version": VERSION, "fingerprint": fp, **state}, fh, protocol=pickle.HIGHEST_PROTOCOL)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def load(path: pathlib.Path, fp: str) -> dict | None:
    """The state saved at `path`, None if there is none; `MechanismError` if it is not a state of
    this search (another fingerprint, another version of the file, or not one at all)."""
    from ..errors import MechanismError

    if not path.exists():
        return None
    try:
        with open(path, "rb") as fh:
            state = pickle.load(fh)
    except Exception as exc:  # a truncated or foreign file
        raise MechanismError(f"{path}: not a saved synthesis state ({type(exc).__name__}); run without --resume "
                             "to start afresh") from None
    if not isinstance(state, dict) or state.get("version") != VERSION:
        raise MechanismError(f"{path}: not a saved synthesis state of this version; run without --resume to "
                             "start afresh")
    if state.get("fingerprint") != fp:
        raise MechanismError(f"{path}: this state belongs to another search (the target, the topologies, the "
                             "seed, --rounds, --samples or another option differ); run without --resume to "
                             "start afresh")
    return state
