"""Compilation time apart from search time.

JAX reports the duration of every tracing, lowering and XLA compilation through
`jax.monitoring` (events `/jax/core/compile/*_duration`). One listener, registered when this
module is imported, adds them to the clock of the thread that compiled, if that thread is inside
a `compile_clock()` block; a search's runner holds one around every chunk, so the chunk's wall
time splits into compilation and search. A compilation started in a background thread
(`searches.base.compile_ahead`) overlaps the search; only the time the search then waits for it
(`waited`) counts as compilation.
"""

from __future__ import annotations

import contextlib
import threading

import jax.monitoring

_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration",
           "/jax/core/compile/backend_compile_duration")
_clocks: dict[int, list] = {}


def _listener(event: str, duration_secs: float, **_kw: str | int) -> None:
    if event in _EVENTS:
        clock = _clocks.get(threading.get_ident())
        if clock is not None:
            clock[0] += float(duration_secs)


jax.monitoring.register_event_duration_secs_listener(_listener)


def waited(seconds: float) -> None:
    """Count `seconds` spent waiting for a background compilation on this thread's clock."""
    clock = _clocks.get(threading.get_ident())
    if clock is not None:
        clock[0] += float(seconds)


@contextlib.contextmanager
def compile_clock():
    """`with compile_clock() as c:` … `c[0]`: seconds of compilation on this thread inside."""
    tid = threading.get_ident()
    outer = _clocks.get(tid)
    clock = [0.0]
    _clocks[tid] = clock
    try:
        yield clock
    finally:
        if outer is not None:
            outer[0] += clock[0]
            _clocks[tid] = outer
        else:
            _clocks.pop(tid, None)
