"""A time-limited synthesis never overruns its limit by more than 10 % (issue 46, item 6): a
batch is abandoned before a turn of blocks that would not end by the limit, a compile that would
not fit is not started (and the search says so), the limit counts from the command's start, and
the command line's process does not wait for XLA's compile threads it stopped waiting for.

Deterministic: a clock that the blocks advance, a compile estimate given, a compile thread that
never ends — no timed assertion (the wall times are in docs/numbers.md)."""

import subprocess
import sys
import textwrap
import time
import types

import numpy as np
import pytest

_IMPORTED = time.perf_counter()  # this module's import: after the process's start


class _Clock:
    """`time.perf_counter` of a machine where each block takes `step` seconds."""

    def __init__(self, step: float):
        self.t, self.step = 1000.0, step

    def perf_counter(self) -> float:
        return self.t


def test_a_batch_stops_before_a_block_that_would_end_past_its_deadline(monkeypatch):
    """Ten blocks of 1 s each and a deadline 4.5 s after the start: the batch is abandoned before
    its clock passes the deadline (the former rule started the fifth block at 4 s and stopped at
    5 s, past it); the blocks it computed are the free run's, and the next call of the same batch,
    whose turn is known by then, is abandoned before its first block when the whole batch cannot fit."""
    import jax.numpy as jnp

    from jaxlink.synthesis import spread
    from jaxlink.synthesis.spread import Blocked, OutOfTime, layout

    clock = _Clock(1.0)
    monkeypatch.setattr(spread, "time", types.SimpleNamespace(perf_counter=clock.perf_counter))
    calls: list[float] = []

    def block(x):
        calls.append(clock.t)
        clock.t += clock.step  # the block's time
        return (jnp.sin(x),)

    x = np.linspace(0.0, 1.0, 20).reshape(10, 2)
    free = Blocked([block], (0,), None, layout(), 10, 1)(x)[0]
    assert len(calls) == 10
    calls.clear()
    late = Blocked([block], (0,), None, layout(), 10, 1)
    start = clock.t
    late.deadline = start + 4.5
    with pytest.raises(OutOfTime):
        late(x)
    assert clock.t <= late.deadline  # stopped before its deadline, not a block after it
    assert len(calls) >= 1 and late.turn_s == pytest.approx(1.0)
    calls.clear()
    late.deadline = clock.t + 9.5  # ten blocks of 1 s do not fit: not one is started
    with pytest.raises(OutOfTime):
        late(x)
    assert calls == []
    late.deadline = clock.t + 10.5  # they fit: all computed, the free run's bits
    assert late(x)[0].tobytes() == free.tobytes() and len(calls) == 10


def test_a_compile_that_would_not_fit_is_not_started(monkeypatch):
    """A search whose programs' compile is expected to take longer than its limit leaves (an
    estimate measured here before: `compiling.estimate`) compiles nothing and says so; one whose
    limit's clock started long enough ago (`started`: the command's start) neither."""
    from jaxlink.synthesis import compiling
    from jaxlink.synthesis import programs as P
    from jaxlink.synthesis.api import synthesize

    def never(*args, **kw):
        raise AssertionError("a program was compiled")

    monkeypatch.setattr(P, "_compiled", never)
    monkeypatch.setattr(compiling, "estimate", lambda key: 100.0)
    k = np.arange(60) * 2 * np.pi / 60
    target = np.stack([np.cos(k), 0.5 * np.sin(k)], axis=1)
    lines: list[str] = []
    r = synthesize(target, topologies=["four-bar"], time_limit=20.0, log=lines.append)
    assert (r.designs, r.rounds, r.stopped_by) == ([], 0, "time_limit")
    assert any("would take about 100.0 s" in x and "time limit (20 s" in x for x in lines), lines
    monkeypatch.setattr(compiling, "estimate", lambda key: None)  # nothing known, but no time left
    lines.clear()
    r = synthesize(target, topologies=["four-bar"], time_limit=20.0, log=lines.append,
                   started=time.perf_counter() - 25.0)
    assert (r.designs, r.stopped_by) == ([], "time_limit") and r.wall_s >= 25.0
    assert any("no time was left" in x for x in lines), lines


def test_the_compile_record(monkeypatch, tmp_path):
    """`compiling.record` and `estimate`: in this process a compiled set costs nothing; in another,
    the same source's warm time once known (unknown after the first, cold, compile), another
    source's (a changed jaxlink: the stored traces are traced again) the cold time."""
    from jaxlink.synthesis import compiling

    monkeypatch.setattr(compiling, "_path", lambda: str(tmp_path / compiling.FILE))
    monkeypatch.setattr(compiling, "_DONE", set())
    source = ["a"]
    monkeypatch.setattr(compiling, "_source", lambda: source[0])
    assert compiling.estimate("k") is None
    compiling.record("k", 7.0)
    assert compiling.estimate("k") == 0.0  # compiled in this process
    compiling._DONE.clear()  # another process
    assert compiling.estimate("k") is None  # a first compile by this source: the next one's time unknown
    compiling.record("k", 2.0)
    compiling._DONE.clear()
    assert compiling.estimate("k") == 2.0 and compiling.estimate("other") is None
    source[0] = "b"
    assert compiling.estimate("k") == 7.0
    compiling.record("k", 9.0)
    compiling._DONE.clear()
    assert compiling.estimate("k") is None
    source[0] = "c"
    assert compiling.estimate("k") == 9.0
    (tmp_path / compiling.FILE).write_text("{not json")
    assert compiling.estimate("k") is None


def test_the_command_does_not_wait_for_a_compile_it_stopped_waiting_for(tmp_path):
    """A compile thread noted as abandoned (`cache.background`, what `programs` does at its
    deadline) that never ends: `jaxlink.cli.run` returns the command's status at once (the output
    flushed) where Python's exit would join the thread forever."""
    code = textwrap.dedent("""
        import sys, threading
        from concurrent.futures import ThreadPoolExecutor
        import jaxlink.cli as cli
        from jaxlink import cache

        forever = threading.Event()
        cache.background(ThreadPoolExecutor(1).submit(forever.wait))

        def main():
            print("written")
            return 1

        cli.main = main
        sys.exit(cli.run())
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert (out.returncode, out.stdout) == (1, "written\n"), out.stderr


def test_the_command_line_counts_from_the_process_start():
    """The time a command's limit counts from (`args.started`) is the process's start: before
    importing JAX and this test module, not when `main` was called."""
    from jaxlink.cli import process_started

    start = process_started()
    assert start <= _IMPORTED <= time.perf_counter()
    assert time.perf_counter() - start < 24 * 3600


def test_the_compile_key_holds_every_option_of_the_programs():
    """The record's key (`programs.compile_key`) changes with each argument that changes the
    programs compiled — a key without one would estimate a set from another set's compile (a wrong
    key: the same estimate for the bounded and the unbounded programs); the same arguments give the
    same key. The programs are compiled for their blocks' shapes, so a count that leaves every block
    as it is (16 topologies instead of 15) is the same key, one that shrinks a block is another."""
    from jaxlink.synthesis.programs import compile_key

    base = dict(n_topos=16, n_dyads=3, closed=True, samples=8192, screen_keep=64, refine=16, steps=200,
                quick=False, polish_points=200, sliders=False, timed=False, bounded=False)
    k0 = compile_key(**base)
    assert compile_key(**base) == k0
    assert compile_key(**{**base, "n_topos": 15}) == k0  # more blocks of the same shapes
    changed = dict(n_dyads=4, closed=False, samples=256, steps=100, quick=True, polish_points=100, sliders=True,
                   timed=True, bounded=True)
    for name, value in changed.items():
        assert compile_key(**{**base, name: value}) != k0, name
