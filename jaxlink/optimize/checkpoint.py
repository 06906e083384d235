"""Append-as-you-go results and resume.

A search runs in deterministic *chunks* (a batch of designs, or a few gradient iterations);
after every chunk:

1. the whole search state (chunk index, counters, best design, the optimizer's arrays) is
   written to `OUT.state.npz` (atomically: temporary file + rename);
2. one line describing the chunk is appended to `OUT.log.jsonl` (evaluations, best so far);
3. `OUT` (the JSON summary) is rewritten atomically with the best so far and `"complete": false`
   (true at the end).

`--resume` loads `OUT.state.npz`, checks that it belongs to the same file, method, seed and
budget, and continues with the next chunk: no chunk is lost or repeated, and since every chunk's
designs depend only on (seed, chunk index) and the saved state, a resumed search ends with
exactly the result of an uninterrupted one.
"""

from __future__ import annotations

import hashlib
import json
import os
import pathlib

import numpy as np


def paths(out: str | os.PathLike) -> tuple[pathlib.Path, pathlib.Path, pathlib.Path]:
    out = pathlib.Path(out)
    stem = out.with_suffix("") if out.suffix == ".json" else out
    return out, pathlib.Path(str(stem) + ".state.npz"), pathlib.Path(str(stem) + ".log.jsonl")


def fingerprint(problem, method: str, seed: int, budget: int, extra: str = "") -> str:
    """What a checkpoint must match to be resumed."""
    h = hashlib.sha256()
    h.update(json.dumps(problem.options, sort_keys=True, default=str).encode())
    h.update(np.asarray(problem.mech.parameters, dtype=np.float64).tobytes())
    h.update(f"{problem.mech.file}|{method}|{seed}|{budget}|{extra}".encode())
    return h.hexdigest()[:16]


def write_json_atomic(path: pathlib.Path, data) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(data, fh, indent=2, allow_nan=False)
        fh.write("\n")
    os.replace(tmp, path)


def save_state(path: pathlib.Path, state: dict) -> None:
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, **{k: np.asarray(v) for k, v in state.items()})
    os.replace(tmp, path)


def load_state(path: pathlib.Path) -> dict | None:
    if not path.exists():
        return None
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def append_log(path: pathlib.Path, record: dict) -> None:
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(json.dumps(record, allow_nan=False) + "\n")
        fh.flush()
        os.fsync(fh.fileno())
