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
