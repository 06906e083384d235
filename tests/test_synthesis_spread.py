"""The synthesis search spread over devices and processes (jaxlink/synthesis/spread.py) and its
deterministic run length (`rounds`).

- `rounds`: exactly N rounds whatever the time limit, full and polishing alternating, and the same
  designs again for the same seed;
- two devices (`XLA_FLAGS=--xla_force_host_platform_device_count=2`, a subprocess): each program of
  a round on whole batches, cut into shares (padded: 1001 poses, 3 slots), gives the one-device
  program's poses bit for bit and its numbers to float32 rounding — not bit for bit: XLA's CPU
  code for a reduction depends on the batch's shape (docs/methods/synthesis.md, "Spread");
- two processes (`jax.distributed`, Gloo; ~15 s, so run with JAXLINK_TEST_DISTRIBUTED_SYNTHESIS=1):
  `jaxlink synthesize --rounds 2` ends with the designs of one process, process 1 quiet.
"""

import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _arc():
    from jaxlink.synthesis import topology as T
    from jaxlink.synthesis.tracer import trace_exact

    four = T.topologies()[0]
    pose = np.array([[0, 0], [1.0, 0], [0, 0], [0.3, 0.0], [1.1, 0.8], [0.5, 0.9]])
    return trace_exact(four, pose, np.linspace(1.0, 3.5, 300))[0][:, four.traced] * 2.0


def test_rounds_are_exact_and_repeat():
    from jaxlink.errors import MechanismError
    from jaxlink.synthesis.api import synthesize

    # the shapes of tests/test_synthesis.py's open run (its programs, compiled once)
    runs = []
    for _ in range(2):
        lines: list[str] = []
        r = synthesize(_arc(), closed=False, topologies=["four-bar"], time_limit=0.1, rounds=2, count=400,
                       samples=1024, log=lines.append)
        runs.append(r)
        assert [x.split(":")[0] for x in lines] == ["round 1", "round 2 (polish)"]  # past 0.1 s
    a, b = runs
    assert [(d.topology, d.distance, d.start_deg) for d in a.designs] == [(d.topology, d.distance, d.start_deg)
                                                                         for d in b.designs]
    assert np.array_equal(a.best.curve, b.best.curve)
    with pytest.raises(MechanismError, match="rounds"):
        synthesize(_arc(), closed=False, topologies=["four-bar"], rounds=0)


_TWO_DEVICES = r"""
import jax, numpy as np
jax.config.update("jax_enable_x64", True)
from jaxlink.synthesis import search as S, spread
from jaxlink.synthesis.topology import as_arrays, topologies
assert len(jax.local_devices()) == 2
arr = as_arrays(topologies(4))
n, keep, slots = 1001, 16, 3
kw = dict(samples=n, screen_keep=keep, refine=slots, steps=5, quick=True)
one = S.programs(1, 2, True, where=spread.Layout(1, 1, 0), **kw)
two = S.programs(1, 2, True, where=spread.Layout(2, 1, 0), **kw)
rows = lambda m: [np.repeat(a[:1], m, 0) for a in (arr.parents, arr.active, arr.traced)]
desc = np.sort(np.linspace(0.4, 1.4, S.DESC_N)).astype(np.float32)
key = jax.random.PRNGKey(7)
(p1, d1), (p2, d2) = one.screen(key, *rows(n), desc), two.screen(key, *rows(n), desc)
t = np.linspace(0, 2 * np.pi, S.RANK_T, endpoint=False)
tr = np.stack([np.cos(t), 0.5 * np.sin(t)], -1).astype(np.float32)
poses = np.asarray(p1)[np.argsort(np.asarray(d1), axis=None)[:keep] // np.asarray(d1).shape[1]]
arcs = np.tile(np.array([[0, 2 * np.pi]], np.float32), (keep, 1))
r1 = one.rank(*rows(keep), poses, arcs, tr, np.float32(1), S._u(S.RANK_T, False))
r2 = two.rank(*rows(keep), poses, arcs, tr, np.float32(1), S._u(S.RANK_T, False))
t = np.linspace(0, 2 * np.pi, S.TARGET_N, endpoint=False)
tt = np.stack([np.cos(t), 0.5 * np.sin(t)], -1).astype(np.float32)
ref = (*rows(slots), poses[:slots], arcs[:slots], tt, np.float32(0.01), np.float32(1), S._u(S.REFINE_T, False))
f1, f2 = one.refine(*ref), two.refine(*ref)
fin = lambda x: np.where(np.isfinite(x), x, 0.0)
print({"poses": bool(np.array_equal(np.asarray(p1), p2)), "shapes": [np.shape(p2), np.shape(d2), np.shape(f2[0])],
       "inf": bool(np.array_equal(np.isfinite(d1), np.isfinite(d2))),
       "screen": float(np.max(np.abs(fin(np.asarray(d1)) - fin(d2)))),
       "rank": float(max(np.max(np.abs(fin(np.asarray(a)) - fin(b))) for a, b in zip(r1, r2))),
       "refine": float(max(np.max(np.abs(np.asarray(a) - b)) for a, b in zip(f1, f2)))})
"""


def test_two_devices_compute_the_one_device_numbers():
    flags = os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    out = subprocess.run([sys.executable, "-c", _TWO_DEVICES], env=dict(os.environ, XLA_FLAGS=flags), cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    got = eval(out.stdout.strip().splitlines()[-1])  # a dict of plain values the script printed
    assert got["poses"] and got["inf"], got
    assert got["shapes"] == [(1001, 6, 2), (1001, 1), (3, 6, 2)], got
    assert got["screen"] < 1e-6 and got["rank"] < 1e-5 and got["refine"] < 1e-4, got


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.skipif(not os.environ.get("JAXLINK_TEST_DISTRIBUTED_SYNTHESIS"),
                    reason="two processes, ~15 s: JAXLINK_TEST_DISTRIBUTED_SYNTHESIS=1")
def test_two_processes_give_the_result_of_one(tmp_path):
    f = tmp_path / "arc.csv"
    f.write_text("x,y\n" + "\n".join(f"{x!r},{y!r}" for x, y in _arc().tolist()))

    def cmd(out, extra=()):
        return [sys.executable, "-m", "jaxlink.cli", "synthesize", str(f), "--open", "--topologies", "four-bar",
                "--rounds", "2", "--time-limit", "1", "--samples", "1024", "--count", "400", "--no-plot",
                "--out", str(out), *extra]

    one = subprocess.run(cmd(tmp_path / "one"), cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert one.returncode == 0, one.stderr[-2000:]
    port = _free_port()
    procs = [subprocess.Popen(cmd(tmp_path / "two", ["--coordinator", f"127.0.0.1:{port}", "--num-processes", "2",
                                                     "--process-id", str(i)]),
                              cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(2)]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1][-2000:] for o in outs]
    assert [x for x in outs[1][0].splitlines() if not x.startswith("[Gloo]")] == []  # process 1 prints nothing
    a = json.loads((tmp_path / "one" / "synthesis.json").read_text())["designs"]
    b = json.loads((tmp_path / "two" / "synthesis.json").read_text())["designs"]
    drop = ("found_s",)
    assert [{k: v for k, v in d.items() if k not in drop} for d in a] == [{k: v for k, v in d.items()
                                                                         if k not in drop} for d in b]
