"""The synthesis search spread over devices and processes (jaxlink/synthesis/spread.py) and its
deterministic run length (`rounds`).

- the blocks: a batch cut into the fewest blocks of at most `cap` rows, one size (closed forms);
  processes take contiguous runs of whole blocks;
- `rounds`: exactly N rounds whatever the time limit, full and polishing alternating;
- with JAXLINK_TEST_DISTRIBUTED_SYNTHESIS=1 (each compiles every program again, per device or
  process: ~20 s on 2 cores): one device (this process) and two devices
  (`XLA_FLAGS=--xla_force_host_platform_device_count=2`, a subprocess; 2048 poses = two screen
  blocks, 128 = two rank blocks, 16 slots = two refinement blocks, so that each device computes
  blocks) give the same designs bit for bit (distance, interval, traced curve). A variant whose
  block depends on the device count (the batch / devices per device, as a `shard_map` of shares did)
  ends at another design: XLA's CPU code for a reduction depends on the block's shape
  (docs/methods/synthesis.md, "Spread"); two processes (`jax.distributed`, Gloo; a contiguous run
  of blocks each): every process ends with the designs of one process bit for bit.
"""

import os
import socket
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# one worker: the searches share the short four-bar search's compiled programs
pytestmark = pytest.mark.xdist_group("synthesis_spread")


def _arc():
    """A four-bar's coupler curve: a closed one (the four-bar screen's, rank's and refinement's
    blocks of tests/test_synthesis.py's closed run, compiled once)."""
    from jaxlink.synthesis import topology as T
    from jaxlink.synthesis.tracer import trace_exact

    four = T.topologies()[0]
    pose = np.array([[0, 0], [1.0, 0], [0, 0], [0.3, 0.0], [1.1, 0.8], [0.5, 0.9]])
    return trace_exact(four, pose, np.linspace(0.0, 2 * np.pi, 300, endpoint=False))[0][:, four.traced] * 2.0


def test_blocks_and_their_owners():
    from jaxlink.synthesis.spread import Layout, blocks

    assert blocks(8192, 1024) == (8, 1024) and blocks(8, 4) == (2, 4) and blocks(3, 4) == (1, 3)
    assert blocks(1001, 1024) == (1, 1001) and blocks(1025, 1024) == (2, 513) and blocks(56, 4) == (14, 4)
    for n in range(1, 60):
        for cap in (1, 3, 4, 7, 64):
            k, size = blocks(n, cap)
            assert size <= cap and k * size >= n > (k - 1) * size and k == -(-n // cap)  # the fewest, padding < k
            for p in (1, 2, 3, 5):
                runs = [Layout(1, p, i).mine(k) for i in range(p)]
                assert [b for r in runs for b in r] == list(range(k))  # each block once, in order
    with pytest.raises(ValueError):
        blocks(0, 4)


def test_programs_given_later_compute_the_same_bits_and_are_asked_for_once():
    """`spread.Blocked` with its programs given as a function (the refinement's and the polish's,
    still compiling while the first round screens: `search.programs`) computes what the same
    programs given at once compute, bit for bit, and asks for them once, at their first use."""
    import jax
    import jax.numpy as jnp

    from jaxlink.synthesis.spread import Blocked, layout

    prog = jax.jit(lambda x, k: (jnp.sin(x) * k, jnp.sum(x, axis=1))).lower(
        jax.ShapeDtypeStruct((4, 3), np.float64), jax.ShapeDtypeStruct((), np.float64)).compile()
    asked: list[int] = []

    def later():
        asked.append(1)
        return [prog]

    x = np.random.default_rng(0).normal(size=(10, 3))
    now, deferred = Blocked([prog], (0,), None, layout(), 10, 4), Blocked(later, (0,), None, layout(), 10, 4)
    assert asked == [] and deferred.count == now.count == 3
    for k in (1.5, -2.0):
        got, want = deferred(x, np.float64(k)), now(x, np.float64(k))
        assert [a.tobytes() for a in got] == [a.tobytes() for a in want] and got[0].shape == (10, 3)
    assert asked == [1]
    assert np.array_equal(now(x, np.float64(1.5))[0], np.sin(x) * 1.5)


# a quick search: its refinement's blocks are of at most REFINE_BLOCK_QUICK = 64 slots, so
# 80 slots make two blocks of 40 (each device gets screen, rank and refinement blocks)
# the designer's bounds off (`synthesis.bounds`): the unbounded programs
_SEARCH = dict(closed=True, topologies=["four-bar"], quick=True, rounds=2, count=400, samples=2048, refine=80,
               min_transmission=None, max_size=None, max_pivot=None)

_TWO_DEVICES = r"""
import sys, jax, numpy as np
jax.config.update("jax_enable_x64", True)
from jaxlink.cache import enable_compilation_cache
enable_compilation_cache()
from jaxlink.synthesis import spread
from jaxlink.synthesis.api import synthesize
assert spread.layout() == spread.Layout(2, 1, 0)
arc, kw = np.asarray(eval(sys.argv[1])), eval(sys.argv[2])
r = synthesize(arc, **kw)
print(repr([(d.topology, d.distance.hex(), d.start_deg.hex(), d.stop_deg.hex(), d.curve.tobytes().hex())
            for d in r.designs]))
"""


def _designs(r):
    return [(d.topology, d.distance.hex(), d.start_deg.hex(), d.stop_deg.hex(), d.curve.tobytes().hex())
            for d in r.designs]


_OPT_IN = pytest.mark.skipif(not os.environ.get("JAXLINK_TEST_DISTRIBUTED_SYNTHESIS"),
                             reason="compiles every program once more per device or process (~20 s on 2 cores): "
                                    "JAXLINK_TEST_DISTRIBUTED_SYNTHESIS=1")


def test_rounds_are_exact():
    from jaxlink.errors import MechanismError
    from jaxlink.synthesis.api import synthesize

    lines: list[str] = []
    # a short search polishes only when asked (`finish`)
    one = synthesize(_arc(), log=lines.append, **dict(_SEARCH, refine=8, finish=2))
    assert [x.split(":")[0] for x in lines if x.startswith("round")] == ["round 1", "round 2 (polish)"]
    assert lines[1].startswith("polished ") and lines[2].startswith("round 2")  # the first polish after round 1
    assert one.designs and np.isfinite(one.best.distance)
    with pytest.raises(MechanismError, match="rounds"):
        synthesize(_arc(), closed=False, topologies=["four-bar"], rounds=0)


@_OPT_IN
def test_two_devices_give_the_one_device_designs():
    from jaxlink.synthesis.api import synthesize

    one = _designs(synthesize(_arc(), **_SEARCH))
    flags = os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    out = subprocess.run([sys.executable, "-c", _TWO_DEVICES, repr(_arc().tolist()), repr(_SEARCH)],
                         env=dict(os.environ, XLA_FLAGS=flags), cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert eval(out.stdout.strip().splitlines()[-1]) == one  # a list of strings the script printed


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


_TWO_PROCESSES = r"""
import sys, jax, numpy as np
from jaxlink.optimize import initialize_distributed
initialize_distributed(sys.argv[3], 2, int(sys.argv[4]))
jax.config.update("jax_enable_x64", True)
from jaxlink.cache import enable_compilation_cache
enable_compilation_cache()
from jaxlink.synthesis import spread
from jaxlink.synthesis.api import synthesize
assert spread.layout() == spread.Layout(1, 2, int(sys.argv[4]))
arc, kw = np.asarray(eval(sys.argv[1])), eval(sys.argv[2])
r = synthesize(arc, **kw)
print(repr([(d.topology, d.distance.hex(), d.start_deg.hex(), d.stop_deg.hex(), d.curve.tobytes().hex())
            for d in r.designs]))
"""


@_OPT_IN
def test_two_processes_give_the_designs_of_one():
    from jaxlink.synthesis.api import synthesize

    one = _designs(synthesize(_arc(), **_SEARCH))
    port = _free_port()
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS" or "device_count" not in v}
    procs = [subprocess.Popen([sys.executable, "-c", _TWO_PROCESSES, repr(_arc().tolist()), repr(_SEARCH),
                               f"127.0.0.1:{port}", str(i)], env=env, cwd=ROOT, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for i in range(2)]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1][-2000:] for o in outs]
    for out, _ in outs:  # every process returns the designs of one process, bit for bit
        assert eval([x for x in out.splitlines() if x.startswith("[")][-1]) == one


@pytest.mark.parametrize("platform, counts, sizes", [("cpu", (8, 86, 43), (1024, 64, 8)),
                                                     ("gpu", (1, 3, 1), (8192, 1835, 344))])
def test_the_blocks_of_a_round_on_each_platform(monkeypatch, platform, counts, sizes):
    """The default search over the 43 topologies up to ten links (8192 screen poses a topology, 128
    ranked, 8 refined): on a CPU small blocks (1024, 64, 8 rows); on a GPU, whose small blocks run at
    their kernels' latency one after another, a batch in as few blocks as `ACCEL_BLOCKS` allows (the
    programs not compiled: only their blocks)."""
    from jaxlink.synthesis import programs as P
    from jaxlink.synthesis import search as S

    assert S.block_caps("cpu", False) == (S.SCREEN_BLOCK, S.RANK_BLOCK, S.REFINE_BLOCK) == (1024, 64, 8)
    assert S.block_caps("cpu", True)[2] == S.REFINE_BLOCK_QUICK
    assert S.block_caps("gpu", False) == S.block_caps("gpu", True) == S.block_caps("cuda", False) == S.ACCEL_BLOCKS
    monkeypatch.setattr(P, "_platform", lambda: platform)
    monkeypatch.setattr(P, "_compiled", lambda *a: a)
    prog = S.programs(43, 9, False, samples=8192, screen_keep=128, refine=8, steps=300)
    assert (prog.screen.count, prog.rank.count, prog.refine.count) == counts
    assert (prog.screen.n, prog.rank.n, prog.refine.n) == (8192, 43 * 128, 43 * 8)
    assert (prog.screen.size, prog.rank.size, prog.refine.size) == sizes
    assert prog.refine.programs[0][1] == prog.refine.size  # the refinement compiled for its block


def test_a_time_limited_search_stops_scoring_at_its_limit(monkeypatch):
    """In one process, once a design is found, no exact score starts past the time limit: a round
    whose scoring reaches the limit (here the clock jumps past it in the second round's first score)
    scores no more candidates, and the search ends with what it found (the first round's designs)."""
    import types

    from jaxlink.synthesis import search as S
    from jaxlink.synthesis.api import synthesize

    real_clock, real_score = S.time.perf_counter, S.score
    jump = [0.0]
    lines: list[str] = []
    calls = {1: 0, 2: 0, 3: 0}

    def score(*args, **kw):
        rnd = sum(x.startswith("round") for x in lines) + 1
        calls[rnd] += 1
        if rnd == 2:
            jump[0] = 1e4  # the limit (1000 s) passes during this score
        return real_score(*args, **kw)

    monkeypatch.setattr(S, "time", types.SimpleNamespace(perf_counter=lambda: real_clock() + jump[0]))
    monkeypatch.setattr(S, "score", score)
    kw = dict(_SEARCH, refine=8, time_limit=1000.0, rounds=None, quick=True)  # test_rounds_are_exact's programs
    r = synthesize(_arc(), log=lines.append, **kw)
    assert [x.split(":")[0] for x in lines if x.startswith("round")] == ["round 1", "round 2 (polish)"]
    assert calls[1] >= 2 and calls[2] == 1 and calls[3] == 0  # round 1 scored its 2 (or more tried)
    assert r.designs and np.isfinite(r.best.distance)


def test_the_blocks_option_is_the_default_path_and_other_blocks_are_other_programs():
    """`blocks` given as the platform's caps is the default search bit for bit; other caps (the
    refinement's 8 slots in two blocks of 4) run their own programs (the compiled programs are keyed
    by the block: a key blind to it would call the block-of-8 program on 4 rows and fail) and still
    end at designs that assemble; a bad value is refused with a message naming it."""
    from jaxlink.errors import MechanismError
    from jaxlink.synthesis import default_blocks
    from jaxlink.synthesis.api import synthesize

    kw = dict(_SEARCH, refine=8, finish=0)  # test_rounds_are_exact's programs (a quick search)
    plain = _designs(synthesize(_arc(), **kw))
    assert _designs(synthesize(_arc(), blocks=default_blocks(True), **kw)) == plain
    other = synthesize(_arc(), blocks=(1024, 64, 4), **kw)
    assert other.designs and all(np.isfinite(d.distance) and d.margin > 0 for d in other.designs)
    for bad in ((0, 64, 8), (1024, 64), "abc", (1.5, 64, 8), (True, 64, 8), 8):
        with pytest.raises(MechanismError, match="blocks = .*three whole numbers"):
            synthesize(_arc(), blocks=bad, **kw)


class _SlowClock:
    """A machine under load, for the search: every reading of the clock `step` seconds after the
    one before (`time.perf_counter` of jaxlink.synthesis.search and .api)."""

    def __init__(self, step: float):
        self.t, self.step = 0.0, step

    def perf_counter(self) -> float:
        self.t += self.step
        return self.t


def test_the_default_search_gives_the_same_designs_under_load(monkeypatch):
    """A search given no rounds and no time limit runs `DEFAULT_ROUNDS` rounds: on a machine whose
    clock runs 30 s a reading it ends at the designs of a quiet run, bit for bit (with the former
    default, a 60 s limit, the loaded run stopped after one round where the quiet one went on)."""
    import types

    from jaxlink.synthesis import api as A
    from jaxlink.synthesis import search as S
    from jaxlink.synthesis.api import synthesize

    kw = dict(_SEARCH, refine=8, finish=0)  # test_rounds_are_exact's programs
    del kw["rounds"]
    quiet = synthesize(_arc(), **kw)
    slow = _SlowClock(30.0)
    monkeypatch.setattr(S, "time", types.SimpleNamespace(perf_counter=slow.perf_counter))
    monkeypatch.setattr(A, "time", types.SimpleNamespace(perf_counter=slow.perf_counter))
    loaded = synthesize(_arc(), **kw)
    assert _designs(loaded) == _designs(quiet) and quiet.designs
    assert (loaded.rounds, loaded.stopped_by) == (quiet.rounds, quiet.stopped_by) == (S.DEFAULT_ROUNDS, "rounds")


def test_the_progress_of_a_search_and_its_best_design_so_far(tmp_path):
    """`synthesize(progress=...)`: a `Progress` from the start (compiling, before any round), each
    round's start and each topology scored, the end; the best so far never worse, and at the end the
    answer's (its distance, topology, joints, transmission angle); `best_file` holds the best
    design so far after every round, at the end the answer's sketch; `report.progress_line` says it."""
    from jaxlink.report.synthesis import progress_line
    from jaxlink.synthesis.api import synthesize

    events: list = []
    best = tmp_path / "best.toml"
    r = synthesize(_arc(), progress=events.append, best_file=best, **dict(_SEARCH, refine=8, finish=0))
    assert events[0].stage == "compiling" and events[0].round == 0 and not events[0].topology
    assert events[-1].stage == "done" and events[-1].round == 2
    assert [(e.round, e.polish) for e in events if e.stage == "round"] == [(1, False), (2, True)]
    assert [(e.scored, e.topologies) for e in events if e.stage == "scored"] == [(1, 1), (1, 1)]
    dist = [e.distance for e in events if e.topology]
    assert dist and dist == sorted(dist, reverse=True)
    last, d = events[-1], r.best
    assert (last.topology, last.joints, last.distance) == (d.topology, d.joints, d.distance)
    assert last.transmission_deg == pytest.approx(d.transmission_deg, abs=1e-9)
    assert all(e.left_s is None for e in events) and all(b.elapsed_s >= a.elapsed_s for a, b in zip(events, events[1:]))
    assert best.read_text() == d.sketch.toml()
    line = progress_line(events[-2], str(best))
    assert line.startswith("round 2 (polish): 1/1 topologies scored | best ") and "four-bar, 5 joints, mu " in line
    assert str(best) in line and progress_line(events[0]).startswith("compiling the programs | no design yet | ")
    assert progress_line(events[0]._replace(left_s=12.4)).endswith(" s, 12 s left")


def test_a_time_limit_caps_the_rounds_and_says_so(monkeypatch, tmp_path):
    """With `rounds` and a time limit, the limit is a cap: the next round starts only if 1.25 times
    the last of its kind fits (here the clock passes the limit in round 1: one round of three), and
    the result says it stopped at the limit, in the JSON too (the former rule ran the three rounds
    whatever the time)."""
    import json
    import types

    from jaxlink.report.synthesis import to_json
    from jaxlink.synthesis import search as S
    from jaxlink.synthesis.api import synthesize

    real = S.time.perf_counter
    jump = [0.0]

    def score(*args, real_score=S.score, **kw):
        jump[0] = 1e4  # the limit (1000 s) passes during round 1's scoring
        return real_score(*args, **kw)

    kw = dict(_SEARCH, refine=8, finish=0, rounds=3, time_limit=1000.0)
    monkeypatch.setattr(S, "time", types.SimpleNamespace(perf_counter=lambda: real() + jump[0]))
    monkeypatch.setattr(S, "score", score)
    lines: list[str] = []
    r = synthesize(_arc(), log=lines.append, **kw)
    assert [x.split(":")[0] for x in lines if x.startswith("round")] == ["round 1"]
    assert r.designs and (r.rounds, r.stopped_by, r.time_limit) == (1, "time_limit", 1000.0)
    doc = json.loads(json.dumps(to_json(r)))
    assert (doc["rounds"], doc["stopped_by"], doc["time_limit_s"]) == (1, "time_limit", 1000.0)


def test_a_batch_past_its_deadline_is_abandoned_between_blocks():
    """`spread.Blocked` with a `deadline`: the blocks before it computed (the same bits as without
    one), then `OutOfTime` between two blocks — the search abandons the round there, keeping the
    rounds done (a run overruns its limit by a block, not by a round)."""
    import time

    import jax
    import jax.numpy as jnp

    from jaxlink.synthesis.spread import Blocked, OutOfTime, layout

    calls: list[int] = []
    prog = jax.jit(lambda x: (jnp.sin(x),)).lower(jax.ShapeDtypeStruct((4, 3), np.float64)).compile()

    def counted(x):
        calls.append(1)
        return prog(x)

    x = np.random.default_rng(0).normal(size=(12, 3))
    free = Blocked([counted], (0,), None, layout(), 12, 4)
    want = free(x)
    assert len(calls) == 3
    late = Blocked([counted], (0,), None, layout(), 12, 4)
    late.deadline = time.perf_counter() + 3600.0
    assert late(x)[0].tobytes() == want[0].tobytes() and len(calls) == 6
    late.deadline = time.perf_counter() - 1.0
    with pytest.raises(OutOfTime):
        late(x)
    assert len(calls) == 6  # nothing computed past it
