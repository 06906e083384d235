"""JAX's persistent compilation cache for jaxlink's commands: compile once per machine, not once
per command.

Every `jaxlink` command compiles its solver for the shapes it needs (about 3–10 s on a 2-core
CPU); with the cache the compiled executables are written to disk and a repeated command loads
them instead (`docs/numbers.md`, "Latency": cold against warm).

The directory is `JAXLINK_CACHE_DIR` if set, else the user's cache directory
(`$XDG_CACHE_HOME/jaxlink/xla`, default `~/.cache/jaxlink/xla`); an empty `JAXLINK_CACHE_DIR`
turns the cache off. The command line turns it on by itself; a Python program calls
`jaxlink.enable_compilation_cache()` (JAX's own `jax_compilation_cache_dir`, set before, wins).
"""

from __future__ import annotations

import os
import warnings

ENV = "JAXLINK_CACHE_DIR"


def cache_dir() -> str | None:
    """The directory the cache would use (None: turned off by an empty `JAXLINK_CACHE_DIR`)."""
    value = os.environ.get(ENV)
    if value is not None:
        return os.path.expanduser(value) if value.strip() else None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "jaxlink", "xla")


def enable_compilation_cache(path: str | None = None) -> str | None:
    """Turn on JAX's persistent compilation cache in `path` (default `cache_dir()`).

    Caches every compiled function however short its compilation (JAX's default skips those under
    one second, which are most of a small command's). Returns the directory in use, or None when
    the cache is off (`JAXLINK_CACHE_DIR=""`), already set by the caller to another directory, or
    the directory cannot be created (a warning says why; the command still runs, uncached).
    """
    import jax

    current = getattr(jax.config, "jax_compilation_cache_dir", None)
    if current:
        return current
    path = cache_dir() if path is None else path
    if not path:
        return None
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        warnings.warn(f"jaxlink: compilation cache off: cannot create {path}: {exc.strerror or exc} "
                      f"(set {ENV} to a writable directory, or to an empty value to silence this)", stacklevel=2)
        return None
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path


# ---------------------------------------------------------------------------- stored traces
# The compilation cache skips XLA's compilation, not the tracing of jaxlink's Python code into a
# program (about 2 s of a small command). A command's whole computation, traced once, is stored
# beside the compiled code as a serialized `jax.export.Exported` (StableHLO) and called from there
# the next time: nothing is traced again, and its compilation comes from the compilation cache.

TRACE_SUFFIX = ".jaxlink-trace"


_SOURCE_DIGEST: list = []


def source_digest() -> str:
    """A digest of jaxlink's own source files: a stored trace is used only by the code that made it."""
    if not _SOURCE_DIGEST:
        import hashlib

        h = hashlib.sha256()
        root = os.path.dirname(os.path.abspath(__file__))
        for folder, dirs, files in sorted(os.walk(root)):
            dirs.sort()
            for name in sorted(files):
                if name.endswith((".py", ".toml")):
                    path = os.path.join(folder, name)
                    h.update(os.path.relpath(path, root).encode())
                    with open(path, "rb") as fh:
                        h.update(fh.read())
        _SOURCE_DIGEST.append(h.hexdigest())
    return _SOURCE_DIGEST[0]


_LOADED: dict = {}  # in this process: (name, key, argument spec) -> a jitted callable
_LOADED_MAX = 256


def _spec(args) -> tuple:
    import numpy as np

    return tuple((tuple(np.shape(a)), str(getattr(a, "dtype", None) or np.asarray(a).dtype)) for a in args)


def _trace_path(name: str, key: str, spec: tuple) -> str | None:
    import hashlib

    import jax

    folder = getattr(jax.config, "jax_compilation_cache_dir", None)
    if not folder:
        return None
    text = repr((name, key, spec, source_digest(), jax.__version__, jax.default_backend(),
                 bool(jax.config.read("jax_enable_x64"))))
    return os.path.join(folder, "trace-" + hashlib.sha256(text.encode()).hexdigest()[:40] + TRACE_SUFFIX)


def traced(name: str, fun, args: tuple, key: str):
    """`fun(*args)` (arrays in, a tuple of arrays out) under `jax.jit`, through a stored trace when
    the compilation cache is on (`enable_compilation_cache`): the first call traces `fun`, stores
    the program in the cache directory and runs it; a later process calling with the same `name`,
    `key` (what `fun` closes over: a structure's `key`, static options), argument shapes and
    dtypes, jaxlink source (`source_digest`), JAX version and backend loads it instead of tracing.
    In one process the callable is kept: a second call traces nothing either way. When the
    stored trace cannot be written or read, it is `jax.jit(fun)(*args)`."""
    import jax

    spec = _spec(args)
    memo = (name, key, spec, bool(jax.config.read("jax_enable_x64")))
    call = _LOADED.get(memo)
    if call is None:
        call = _load_or_store(fun, args, _trace_path(name, key, spec))
        if len(_LOADED) >= _LOADED_MAX:
            _LOADED.pop(next(iter(_LOADED)))
        _LOADED[memo] = call
    return call(*args)


def _load_or_store(fun, args, path):
    import jax

    if path is None:
        return jax.jit(fun)
    from jax import export

    if os.path.exists(path):
        try:
            with open(path, "rb") as fh:
                return jax.jit(export.deserialize(bytearray(fh.read())).call)
        except Exception:  # noqa: BLE001 (a stale or damaged file: trace again and replace it)
            pass
    try:
        exp = export.export(jax.jit(fun))(*args)
        data = exp.serialize()
    except Exception:  # noqa: BLE001 (cannot be exported or serialized here: no stored trace)
        return jax.jit(fun)
    tmp = f"{path}.{os.getpid()}.tmp"
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except OSError:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return jax.jit(exp.call)
