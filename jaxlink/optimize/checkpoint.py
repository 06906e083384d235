"""Append-as-you-go results and resume.

A search runs in deterministic *chunks* (a batch of designs, or a few gradient iterations);
after every chunk:

1. the whole search state (a NamedTuple of numpy arrays: chunk index, counters, best design,
   the optimizer's arrays) is written to `OUT.state.npz`, one array per leaf named by its path
   (`progress.best_value`, `lbfgs.count`, …), with the search's fingerprint (atomically:
   temporary file + rename);
2. one line describing the chunk is appended to `OUT.log.jsonl` (evaluations, best so far);
3. `OUT` (the JSON summary) is rewritten atomically with the best so far and `"complete": false`
   (true at the end).

`--resume` loads `OUT.state.npz`, checks that it belongs to the same file, method, seed, budget
and knobs and has the leaves of the search's own state, and continues with the next chunk: no
chunk is lost or repeated, and since every chunk's designs depend only on (seed, chunk index)
and the saved state, a resumed search ends with exactly the result of an uninterrupted one.
"""

from __future__ import annotations

import hashlib
import json
import os
import pathlib
from typing import Any

import jax
import numpy as np


def paths(out: str | os.PathLike) -> tuple[pathlib.Path, pathlib.Path, pathlib.Path]:
    out = pathlib.Path(out)
    stem = out.with_suffix("") if out.suffix == ".json" else out
    return out, pathlib.Path(str(stem) + ".state.npz"), pathlib.Path(str(stem) + ".log.jsonl")


def fingerprint(problem, method: str, seed: int, budget: int | None, extra: str = "") -> str:
    """What a checkpoint must match to be resumed."""
    h = hashlib.sha256()
    h.update(json.dumps(problem.options, sort_keys=True, default=str).encode())
    h.update(np.asarray(problem.mech.parameters, dtype=np.float64).tobytes())
    h.update(f"{problem.mech.file}|{method}|{seed}|{budget}|{extra}".encode())
    return h.hexdigest()[:16]


def write_json_atomic(path: pathlib.Path, data) -> None:
    if path.exists() and not path.is_file():  # a named pipe or a device: written to, not replaced
        with open(path, "w", encoding="utf-8") as fh:
            json.dump(data, fh, indent=2, allow_nan=False)
            fh.write("\n")
        return
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(data, fh, indent=2, allow_nan=False)
        fh.write("\n")
    os.replace(tmp, path)


def _named_leaves(state) -> list[tuple[str, Any]]:
    leaves, _ = jax.tree_util.tree_flatten_with_path(state)
    return [(jax.tree_util.keystr(path, simple=True, separator="."), leaf) for path, leaf in leaves]


def save_state(path: pathlib.Path, state, fingerprint: str) -> None:
    """Write the search state `state` (a pytree of arrays) and its `fingerprint` atomically."""
    tmp = path.with_name(path.name + ".tmp.npz")
    arrays: dict[str, Any] = {k: np.asarray(v) for k, v in _named_leaves(state)}
    np.savez(tmp, fingerprint=np.asarray(fingerprint), **arrays)
    os.replace(tmp, path)


def load_state(path: pathlib.Path, template, fingerprint: str):
    """The state saved at `path`, built on the structure of `template` (the search's `init()`),
    or None if there is no checkpoint. Raises `MechanismError` if it belongs to another search
    (another `fingerprint`) or does not hold exactly the leaves of `template` with their shapes."""
    if not path.exists():
        return None
    from ..errors import MechanismError

    with np.load(path, allow_pickle=False) as z:
        saved = {k: z[k] for k in z.files}
    if str(saved.pop("fingerprint", "")) != fingerprint:
        raise MechanismError(
            f"{path}: this checkpoint belongs to another search (file, [optimize], method, seed, budget or "
            "knobs differ); run without --resume to start afresh")
    named = _named_leaves(template)
    if set(saved) != {k for k, _ in named} or any(np.shape(saved[k]) != np.shape(v) for k, v in named):
        raise MechanismError(f"{path}: not a checkpoint of this search's state (written by another version?); "
                             "run without --resume to start afresh")
    leaves = [saved[k][()] if saved[k].ndim == 0 else saved[k] for k, _ in named]
    return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(template), leaves)


def append_log(path: pathlib.Path, record: dict) -> None:
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(json.dumps(record, allow_nan=False) + "\n")
        fh.flush()
        os.fsync(fh.fileno())
