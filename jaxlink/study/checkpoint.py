"""Write-as-you-go and resume of a long study (Monte Carlo, `sample`, `grid`, `sensitivity`,
`morris`, `regression`, `dgsm`), as `optimize` does (jaxlink/optimize/checkpoint.py): the work runs
in deterministic chunks (each chunk's designs depend only on the seed and the chunk's index), and
after every chunk

1. the chunk's own rows, where the study keeps rows (`sample`, `grid`: each design's parameters,
   flag and scalar responses; `regression`: its designs, flags and every response), go to
   `DIR/chunk-NNNNNN.npz`;
2. the streamed state (moments, histograms, Sobol', Morris or DGSM sums, counters —
   `archive.pack`ed) goes to `DIR/state-NNNNNN.npz`, then `DIR/state.json` names it with the
   number of chunks done,

each written to a temporary file and renamed (atomic: a study killed at any instant leaves the
last complete chunk). `resume` loads them, checks the **resume key** — the mechanism file's SHA-256,
the parameters (after `--set`), the dtype, every input of the study (method, seed, samples,
positions, points, metrics, tolerances, ranges, levels, sampler, bootstrap, …), the chunk size and
what is computed — and refuses a checkpoint whose key differs, naming what differs; a resumed study
skips the chunks done and ends with exactly the result of an uninterrupted one (the same chunks,
the same floating-point operations in the same order).
"""

from __future__ import annotations

import hashlib
import json
import os
import pathlib

import numpy as np

from ..errors import MechanismError
from . import archive

STATE_VERSION = 1


def resume_key(mech, inputs, *, chunk: int, what: str, **extra) -> dict:
    """The key a checkpoint must match (see the module doc), JSON values."""
    src = pathlib.Path(str(mech.file))
    digest = hashlib.sha256(src.read_bytes()).hexdigest() if src.is_file() else None
    key = {"what": what, "state_version": STATE_VERSION, "file": str(mech.file), "file_sha256": digest,
           "parameters": [float(v) for v in np.asarray(mech.parameters, np.float64)],
           "dtype": str(np.asarray(mech.parameters).dtype), "chunk": int(chunk),
           "inputs": json.loads(json.dumps(archive.pack(inputs)[0]))}
    key.update({k: json.loads(json.dumps(v)) for k, v in extra.items()})
    return key


def _write_json(path: pathlib.Path, data) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def _differences(saved: dict, key: dict) -> list:
    out = []
    for k in sorted(set(saved) | set(key)):
        if k == "inputs" and isinstance(saved.get(k), dict) and isinstance(key.get(k), dict):
            a, b = saved[k].get("fields", {}), key[k].get("fields", {})
            out += [f"[study] {f}" for f in sorted(set(a) | set(b)) if a.get(f) != b.get(f)]
        elif saved.get(k) != key.get(k):
            out.append({"file_sha256": "the mechanism file's contents", "parameters": "the parameters (--set)",
                        "what": "the study's method"}.get(k, k))
    return out


class Checkpoint:
    """The checkpoint folder `directory` of one study with resume key `key` (`resume_key`).

    With `resume` False, any checkpoint there is discarded (the study starts afresh); with
    `resume` True, `load()` returns what was saved (after checking the key) or None."""

    def __init__(self, directory, key: dict, *, resume: bool = False):
        self.dir = pathlib.Path(directory)
        self.key = key
        self.resume = resume
        self.dir.mkdir(parents=True, exist_ok=True)
        if not resume:
            self.clear()

    def clear(self) -> None:
        for p in list(self.dir.glob("chunk-*.npz")) + list(self.dir.glob("state-*.npz")) + [self.dir / "state.json"]:
            if p.exists():
                p.unlink()

    def load(self):
        """(chunks done, state) saved, or None when there is none. Raises `MechanismError` when the
        checkpoint belongs to another study (its resume key differs)."""
        meta = self.dir / "state.json"
        if not self.resume or not meta.exists():
            return None
        saved = json.loads(meta.read_text(encoding="utf-8"))
        diff = _differences(saved.get("key", {}), self.key)
        if diff:
            raise MechanismError(
                f"{self.dir}: this checkpoint belongs to another study (different {', '.join(diff)}); run without "
                "--resume to start afresh, or give another --out")
        state = archive.unpack(saved["state"], archive.load_npz(self.dir / saved["arrays"]))
        return int(saved["done"]), state

    def save(self, done: int, state) -> None:
        """Record `done` chunks and the streamed `state` (atomically: the arrays to a file of their
        own, then the JSON that names it, then the older arrays removed)."""
        tree, arrays = archive.pack(state)
        name = f"state-{done:06d}.npz"
        archive.save_npz(self.dir / name, arrays)
        _write_json(self.dir / "state.json", {"key": self.key, "done": int(done), "arrays": name, "state": tree})
        for p in self.dir.glob("state-*.npz"):
            if p.name != name:
                p.unlink()

    def save_chunk(self, index: int, **arrays) -> None:
        archive.save_npz(self.dir / f"chunk-{index:06d}.npz", {k: np.asarray(v) for k, v in arrays.items()})

    def load_chunk(self, index: int) -> dict:
        path = self.dir / f"chunk-{index:06d}.npz"
        if not path.exists():
            raise MechanismError(f"{path}: a chunk of the checkpoint is missing; run without --resume to start afresh")
        return archive.load_npz(path)
