"""JAX's persistent compilation cache for jaxlink's commands: compile once per machine, not once
per command.

Every `jaxlink` command compiles its solver for the shapes it needs (about 3–10 s on a 2-core
CPU); with the cache the compiled executables are written to disk and a repeated command loads
them instead (`docs/numbers.md`, "`kinematics` latency": cold against warm).

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
#
# A stored program is a pure function of its inputs. What it is called with — every array leaf of
# its arguments, a mechanism's parameters and guesses included — is an *argument* of the program,
# never a constant inside it; everything that is baked in (the function's code, the arguments'
# tree structure with a mechanism's `Structure.key`, the static options, shapes, dtypes) is part
# of the key, together with jaxlink's source, the JAX and jaxlib versions, the backend and the x64
# mode. A function with a closure is refused (it could hide numbers the key does not see). A file
# that does not hold exactly the program of its key (damaged, truncated, another key) is traced
# again and replaced, never loaded.

TRACE_SUFFIX = ".jaxlink-trace"
_MAGIC = b"jaxlink-trace 2\n"


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


# in this process: the key text, and (name, fun, tree structure, static, shapes and dtypes, x64 mode)
# of a call made before -> a jitted callable of the flat leaves
_LOADED: dict = {}
_LOADED_MAX = 256


def _tree_key(treedef) -> str:
    """A text of a tree structure that is the same in every process: node types by name, a
    mechanism's `Structure` by its `key`, other node data by `repr`, `*` for a leaf."""
    from .model.mechanism import Structure

    data = treedef.node_data()
    if data is None:
        return "*"
    kind, aux = data
    aux_text = aux.key if isinstance(aux, Structure) else repr(aux)
    children = ",".join(_tree_key(c) for c in treedef.children())
    return f"{kind.__module__}.{kind.__qualname__}[{aux_text}]({children})"


def _spec(leaves) -> tuple:
    """Shapes and dtypes (as JAX will hold them: float64 is float32 when x64 is off)."""
    import jax
    import numpy as np

    return tuple((tuple(np.shape(a)), str(jax.dtypes.canonicalize_dtype(np.result_type(a)))) for a in leaves)


def key_text(name: str, fun, treedef, static: tuple, leaves) -> str:
    """Everything a stored program depends on besides the values of its arguments."""
    import jax
    import jaxlib

    return repr((name, f"{fun.__module__}.{fun.__qualname__}", _tree_key(treedef), static, _spec(leaves),
                 source_digest(), jax.__version__, jaxlib.__version__, jax.default_backend(),
                 bool(jax.config.read("jax_enable_x64"))))


def _trace_path(key: str) -> str | None:
    import hashlib

    import jax

    folder = getattr(jax.config, "jax_compilation_cache_dir", None)
    if not folder:
        return None
    return os.path.join(folder, "trace-" + hashlib.sha256(key.encode()).hexdigest()[:40] + TRACE_SUFFIX)


def stored_traces() -> bool:
    """Whether `traced` stores and loads programs here (the compilation cache is on)."""
    import jax

    return bool(getattr(jax.config, "jax_compilation_cache_dir", None))


_ONE_COMMAND: list = []


@__import__("contextlib").contextmanager
def one_command():
    """While a command of the command line runs (`jaxlink.cli.main`): small steps that a library
    session evaluates as it goes — each operation compiled once per process and kept, cheap for a
    long session, a fresh compilation for every new mechanism when traced — become stored programs
    too (`in_one_command`), since a short process pays for every operation it dispatches."""
    _ONE_COMMAND.append(True)
    try:
        yield
    finally:
        _ONE_COMMAND.pop()


def in_one_command() -> bool:
    """Inside `one_command` with the stored traces on."""
    return bool(_ONE_COMMAND) and stored_traces()


def traced(name: str, fun, args: tuple, static: tuple = ()):
    """`fun(*args, *static)` under `jax.jit`, through a stored trace when the compilation cache is
    on (`enable_compilation_cache`): the first call traces `fun`, stores the program in the cache
    directory and runs it; a later process calling with the same key (`key_text`: `name`, `fun`,
    the tree structure of `args`, `static`, shapes and dtypes, jaxlink's source, JAX and jaxlib
    versions, backend, x64 mode) loads it instead of tracing. In one process the callable is kept.

    `fun` must be a module-level function (no closure): every number it uses comes in through
    `args` (a tuple of pytrees of arrays; a `Mechanism` is one, its parameters and guesses are
    leaves), every static option through `static` (hashable values whose `repr` identifies them).
    When the stored trace cannot be written or read, it is `jax.jit` of the same function."""
    import jax

    if getattr(fun, "__closure__", None) or not hasattr(fun, "__qualname__") or "<locals>" in fun.__qualname__:
        raise TypeError(f"traced({name!r}): {fun!r} must be a module-level function without a closure "
                        "(pass every number as an argument, every option in `static`)")
    leaves, treedef = jax.tree_util.tree_flatten(args)
    static = tuple(static)
    # a call like one made before in this process (a search's many small calls) skips the key text
    fast = _fast_key(name, fun, treedef, static, leaves)
    call = _LOADED.get(fast)
    if call is None and fast in _PENDING:  # being compiled ahead (`prepare`): wait for it
        try:
            _PENDING.pop(fast).result()
        except Exception:  # noqa: BLE001 (it failed there: here it is traced again, and fails or not as it will)
            pass
        call = _LOADED.get(fast)
    if call is None:
        key = key_text(name, fun, treedef, static, leaves)
        call = _LOADED.get(key)
        if call is None:
            def flat(*xs):
                return fun(*jax.tree_util.tree_unflatten(treedef, xs), *static)

            call, lapack = _load_or_store(flat, leaves, key, _trace_path(key))
            _remember(key, call)
            _remember(fast, call)
            if not lapack:  # its first call lowers it: without JAX's LAPACK set-up, which it does not use
                with _without_lapack_setup():
                    return call(*leaves)
        _remember(fast, call)
    return call(*leaves)


# compilations started ahead (`prepare`), by the in-process key of the call they are for
_PENDING: dict = {}
#: held while a program of `prepare` is traced and lowered: Python runs one thread at a time
#: anyway, and interleaved tracings all finish late; one after the other, in the order asked, the
#: first program starts compiling (which XLA does without Python's lock) while the next is traced
#: (`check four-bar` cold, 3 pairs A B: 2.46-2.55 s interleaved, 2.33-2.39 s one at a time)
_TRACING = __import__("threading").Lock()
_POOL: list = []


def prepare(name: str, fun, args: tuple, static: tuple = ()):
    """Start compiling, in a background thread, the program that `traced(name, fun, args, static)`
    will run, and return its `concurrent.futures.Future` (None where it is compiled already).

    Only the shapes, dtypes and tree structure of `args` matter (the program is the same for any
    values: every number is an argument), so a caller that knows them before it has the values
    passes placeholders of the same shapes and dtypes. A later `traced` call of the same key waits
    for this compilation and runs what it made: the same program as without `prepare`, traced,
    stored and compiled the same way (tests/test_check_start.py). The programs are traced one at a
    time in the order asked, and while one compiles (XLA, without Python's lock, on two threads of
    its own) the next is traced and the command goes on: on a cold start the tracing, the
    compiling and the command's own work overlap. An error in the background is not raised here:
    the `traced` call traces again and raises it (or not) as it would have. `cancel_prepared` (at
    the end of a command) drops those that have not started."""
    import jax

    if getattr(fun, "__closure__", None) or not hasattr(fun, "__qualname__") or "<locals>" in fun.__qualname__:
        raise TypeError(f"prepare({name!r}): {fun!r} must be a module-level function without a closure")
    leaves, treedef = jax.tree_util.tree_flatten(args)
    static = tuple(static)
    fast = _fast_key(name, fun, treedef, static, leaves)
    if fast in _LOADED or (fast in _PENDING and not _PENDING[fast].done()):
        return None
    if not _POOL:
        from concurrent.futures import ThreadPoolExecutor

        _POOL.append(ThreadPoolExecutor(max_workers=4, thread_name_prefix="jaxlink-prepare"))
    future = _POOL[0].submit(_prepare_one, name, fun, treedef, static, leaves, fast, _GENERATION[0])
    _PENDING[fast] = future
    return future


def cancel_prepared() -> None:
    """Cancel the compilations `prepare` queued that have not started (at the end of a command:
    one that stops early does not wait for programs it will not run; those under way finish)."""
    _GENERATION[0] += 1  # those waiting for their turn to trace give up
    for fast, future in list(_PENDING.items()):
        if future.cancel():
            _PENDING.pop(fast, None)


_GENERATION = [0]

# compilations started in threads of their own that a command may stop waiting for (`background`)
_BACKGROUND: list = []


def background(future) -> None:
    """Note a compilation running in a thread of its own (a `concurrent.futures.Future`) that its
    caller may stop waiting for (`jaxlink.synthesis.programs.programs` at a time limit): the command
    line then ends its process without waiting for it (`unfinished`, `jaxlink.cli.run`)."""
    _BACKGROUND[:] = [f for f in _BACKGROUND if not f.done()]
    _BACKGROUND.append(future)


def unfinished() -> bool:
    """Whether a compilation noted by `background` is still running (XLA's compiling cannot be
    stopped: a process that exits normally waits for it). Those of `prepare` are not counted: the
    command waits for them (they are the next command's cached programs)."""
    return any(not f.done() for f in _BACKGROUND)


def _prepare_one(name: str, fun, treedef, static: tuple, leaves, fast, generation: int = 0) -> None:
    """`prepare`'s work in its thread: what `traced` does before its first call, then the
    program lowered and compiled for `leaves`' shapes (the jitted callable keeps the executable,
    so the call runs it without compiling again)."""
    import contextlib

    import jax

    key = key_text(name, fun, treedef, static, leaves)
    call = _LOADED.get(key)
    if call is None:
        def flat(*xs):
            return fun(*jax.tree_util.tree_unflatten(treedef, xs), *static)

        with _TRACING:
            if generation != _GENERATION[0]:  # cancelled while it waited
                return
            call, lapack = _load_or_store(flat, leaves, key, _trace_path(key))
            with contextlib.nullcontext() if lapack else _without_lapack_setup():
                lowered = call.lower(*leaves)
        lowered.compile()
        _remember(key, call)
    _remember(fast, call)


def compiled(name: str, fun, avals: tuple, static: tuple = (), options: dict | None = None):
    """`fun(*args, *static)` compiled ahead of time for the arguments `avals` (a tuple of
    `jax.ShapeDtypeStruct`, each possibly placed on a device by its `sharding`) with the XLA
    compile `options`, through a stored trace like `traced`: the first process traces `fun` and
    stores the program; a later one with the same key (`name`, `fun`, the shapes and dtypes, the
    static values, jaxlink's source, JAX and jaxlib, the backend, x64) loads it instead of tracing,
    and its compilation (keyed by the program and the `options`) comes from the compilation cache.
    The same program either way: the stored one is compiled from the trace it stores
    (tests/test_synthesis_memo.py). Neither the arguments' placement nor the options are part of
    the trace's key: a program is traced for no device, then compiled for the device its arguments
    name with the options. Without the cache: plain `jax.jit(...).lower(...)`."""
    import jax

    if getattr(fun, "__closure__", None) or "<locals>" in getattr(fun, "__qualname__", "<locals>"):
        raise TypeError(f"compiled({name!r}): {fun!r} must be a module-level function without a closure")
    static = tuple(static)
    spec = tuple((tuple(a.shape), str(jax.dtypes.canonicalize_dtype(a.dtype))) for a in avals)

    def flat(*xs):
        return fun(*xs, *static)

    target = jax.jit(flat)
    if stored_traces():
        key = _compiled_key(name, fun, static, spec)
        path = _trace_path(key)
        stored = _read_stored(key, path, spec)
        if stored is not None:
            target = jax.jit(stored[0].call)
        else:
            from jax import export

            try:
                exp = export.export(jax.jit(flat))(*(jax.ShapeDtypeStruct(a.shape, a.dtype) for a in avals))
                _store(key, path, exp.serialize())
                target = jax.jit(exp.call)
            except Exception:  # noqa: BLE001 (cannot be exported or serialized here: no stored trace)
                pass
    return target.lower(*avals).compile(options)


def _compiled_key(name: str, fun, static: tuple, spec: tuple) -> str:
    """Everything a program of `compiled` depends on besides its arguments' values and placement."""
    import jax
    import jaxlib

    return repr(("compiled", name, f"{fun.__module__}.{fun.__qualname__}", static, spec, source_digest(),
                 jax.__version__, jaxlib.__version__, jax.default_backend(), bool(jax.config.read("jax_enable_x64"))))


def _read_stored(key: str, path: str | None, spec: tuple):
    """`(Exported, serialized bytes)` of the program stored under `key` at `path` whose arguments
    are `spec` (shapes, dtypes), or None: no file, or one that is damaged, truncated, of another
    key or of other arguments (then traced again and replaced)."""
    if path is None or not os.path.exists(path):
        return None
    from jax import export

    try:
        with open(path, "rb") as fh:
            stored = _unpack(key, fh.read())
        if stored is None:
            return None
        exp = export.deserialize(bytearray(stored))
        if spec != tuple((tuple(a.shape), str(a.dtype)) for a in exp.in_avals):
            return None
        return exp, stored
    except Exception:  # noqa: BLE001 (a stale or damaged file: trace again and replace it)
        return None


def _store(key: str, path: str | None, data) -> None:
    """Write a serialized program under `key` to `path` (atomically; nothing when it cannot)."""
    if path is None:
        return
    tmp = f"{path}.{os.getpid()}.{id(data)}.tmp"
    try:
        with open(tmp, "wb") as fh:
            fh.write(_pack(key, data))
        os.replace(tmp, path)
    except OSError:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _fast_key(name: str, fun, treedef, static: tuple, leaves) -> tuple:
    """The in-process memo's key of a call: everything of `key_text` that can change within a
    process (the function, the arguments' structure — a mechanism's `Structure` included — the
    static options, every leaf's shape and dtype, the x64 mode), without building the text."""
    import jax
    import numpy as np

    return (name, fun, treedef, static, tuple((np.shape(a), np.result_type(a)) for a in leaves),
            bool(jax.config.read("jax_enable_x64")))


_LOADED_LOCK = __import__("threading").Lock()


def _remember(key, call) -> None:
    with _LOADED_LOCK:  # `prepare`'s threads remember too
        if len(_LOADED) >= _LOADED_MAX:
            _LOADED.pop(next(iter(_LOADED)))
        _LOADED[key] = call


# JAX sets up its LAPACK kernels (importing scipy.linalg: 0.2–0.4 s, a third of a warm `check`)
# whenever it lowers a call of an exported program on the CPU, whether or not the program uses
# LAPACK. A stored program that names no LAPACK kernel (no `lapack` in its serialized module,
# where every custom call's target is written out) is lowered without it; one that does, as JAX
# does it. (JAX's own lowering of a LAPACK-using function sets them up itself.)
_LAPACK_NAME = b"lapack"


_SKIP_LAPACK = __import__("threading").local()


@__import__("contextlib").contextmanager
def _without_lapack_setup():
    """In this thread only (programs lower side by side: `prepare`), lower without JAX's LAPACK
    set-up: JAX's own function is wrapped once by one that skips it where this is in force."""
    try:
        from jax._src.export import _export
    except ImportError:  # another JAX: nothing to skip
        yield
        return
    ensure = getattr(_export, "_ensure_backends_initialized", None)
    if ensure is None:
        yield
        return
    if not getattr(ensure, "_jaxlink_wrapper", False):
        def wrapper(*a, _ensure=ensure, **k):
            if getattr(_SKIP_LAPACK, "on", False):
                return None
            return _ensure(*a, **k)

        wrapper._jaxlink_wrapper = True  # type: ignore[attr-defined]
        _export._ensure_backends_initialized = wrapper
    before = getattr(_SKIP_LAPACK, "on", False)
    _SKIP_LAPACK.on = True
    try:
        yield
    finally:
        _SKIP_LAPACK.on = before


def _pack(key: str, data: bytes | bytearray) -> bytes:
    import hashlib

    head = key.encode()
    body = len(head).to_bytes(8, "little") + head + len(data).to_bytes(8, "little") + bytes(data)
    return _MAGIC + hashlib.sha256(body).digest() + body


def _unpack(key: str, blob: bytes) -> bytes | None:
    """The serialized program of a stored file, or None unless the file is whole (its digest
    matches) and was stored under exactly `key`."""
    import hashlib

    n = len(_MAGIC)
    if blob[:n] != _MAGIC or len(blob) < n + 32 + 16:
        return None
    digest, body = blob[n:n + 32], blob[n + 32:]
    if hashlib.sha256(body).digest() != digest:
        return None
    klen = int.from_bytes(body[:8], "little")
    if body[8:8 + klen] != key.encode():
        return None
    rest = body[8 + klen:]
    if len(rest) < 8 or int.from_bytes(rest[:8], "little") != len(rest) - 8:
        return None
    return rest[8:]


def _load_or_store(flat, leaves, key: str, path: str | None):
    """`(callable, uses_lapack)`: the stored program of `key` at `path`, else `flat` traced,
    exported and stored there (a plain `jax.jit` where it cannot be)."""
    import jax

    if path is None:
        return jax.jit(flat), True
    from jax import export

    stored = _read_stored(key, path, _spec(leaves))
    if stored is not None:
        return jax.jit(stored[0].call), _LAPACK_NAME in stored[1]
    try:
        exp = export.export(jax.jit(flat))(*leaves)
        data = exp.serialize()
    except Exception:  # noqa: BLE001 (cannot be exported or serialized here: no stored trace)
        return jax.jit(flat), True
    _store(key, path, data)
    return jax.jit(exp.call), _LAPACK_NAME in data
