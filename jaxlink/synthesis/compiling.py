"""How long a search's programs take to compile on this machine, known before they are compiled:
each compile of `programs.programs` is measured and recorded in the compilation cache's directory
(`jaxlink.cache.cache_dir`, file `synthesis-compile.json`), and read back before the next one, so
that a time-limited search whose compiling would not fit in its limit says so and does not start it.

The record holds, per set of programs (their shapes and options, the backend, JAX's version), the
seconds of their last compile by another jaxlink source (`cold`: compiled by XLA, since the stored
traces are keyed by the source) and of the last one by this source after a first (`warm`: loaded
from the cache). `estimate` is 0 for programs compiled in this process already, the `warm` time for
programs this source compiled before here, the `cold` time for programs it did not, and None when
nothing is known (the first compile of these shapes here, or the cache off): the search then starts
compiling and stops waiting at its limit (`programs`' deadline).
"""

from __future__ import annotations

import json
import os
import threading

FILE = "synthesis-compile.json"

_DONE: set[str] = set()  # the programs compiled in this process (their `key`)
_LOCK = threading.Lock()


def key(**shapes) -> str:
    """The record's key of a set of programs (`programs`' shapes and options: keyword values with a
    `repr`), with the backend and JAX's version."""
    import jax

    return repr((sorted(shapes.items()), jax.default_backend(), jax.__version__,
                 bool(jax.config.read("jax_enable_x64"))))


def _path() -> str | None:
    """The record's file: in the compilation cache's directory when the cache is on, else None."""
    import jax

    folder = getattr(jax.config, "jax_compilation_cache_dir", None)
    return os.path.join(folder, FILE) if folder else None


def _read(path: str) -> dict:
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):  # none yet, or being replaced, or damaged: nothing known
        return {}


def _source() -> str:
    from ..cache import source_digest

    return source_digest()


def estimate(k: str) -> float | None:
    """The seconds compiling the programs of key `k` is expected to take here (see the module), or
    None when unknown."""
    if k in _DONE:
        return 0.0
    path = _path()
    entry = _read(path).get(k) if path is not None else None
    if not isinstance(entry, dict):
        return None
    seconds = entry.get("warm") if entry.get("source") == _source() else entry.get("cold")
    return float(seconds) if isinstance(seconds, (int, float)) and seconds >= 0 else None


def record(k: str, seconds: float) -> None:
    """Record that the programs of key `k` took `seconds` to compile (a first compile by this source:
    its `cold` time; a later one: its `warm` time). Nothing when the cache is off or the record
    cannot be written."""
    _DONE.add(k)
    path = _path()
    if path is None:
        return
    with _LOCK:
        data = _read(path)
        old = data.get(k)
        entry: dict = old if isinstance(old, dict) else {}
        source = _source()
        if entry.get("source") == source:
            entry["warm"] = float(seconds)
        else:
            entry = {"source": source, "cold": float(seconds)}
        data[k] = entry
        tmp = f"{path}.{os.getpid()}.{threading.get_ident()}.tmp"
        try:
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(data, fh)
            os.replace(tmp, path)
        except OSError:
            if os.path.exists(tmp):
                os.unlink(tmp)
