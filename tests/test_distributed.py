"""A search spread over two processes (`jax.distributed`, two local CPU processes exchanging
values through Gloo) ends with exactly the result of one process (jaxlink/optimize/distributed.py)."""

import json
import os
import socket
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cmd(out, method, budget, extra=()):
    return [sys.executable, "-m", "jaxlink.cli", "optimize", "sewing-feed-opt", "--method", method,
            "--budget", str(budget), "--seed", "4", "--chunk", "512", "--progress", "off", "--out", str(out), *extra]


# the gradient search (presample spread, iterations replicated) gave the same result too with
# budget 600; kept out of CI for time (~2 min on 2 cores): JAXLINK_TEST_DISTRIBUTED_GRADIENT=1
METHODS = [("montecarlo", 2000)] + ([("gradient", 600)] if os.environ.get("JAXLINK_TEST_DISTRIBUTED_GRADIENT") else [])


@pytest.mark.parametrize("method,budget", METHODS)
def test_two_processes_give_the_result_of_one(tmp_path, method, budget):
    # a compilation cache of this test's own: the two processes load what the one compiled (the
    # cache changes no answer: tests/test_cache_differential.py)
    env = dict(os.environ, JAXLINK_CACHE_DIR=str(tmp_path / "xla"))
    one = subprocess.run(_cmd(tmp_path / "one.json", method, budget), env=env, cwd=ROOT,
                         capture_output=True, text=True, timeout=600)
    assert one.returncode == 0, one.stderr
    port = _free_port()
    procs = [subprocess.Popen(_cmd(tmp_path / "two.json", method, budget,
                                   ["--coordinator", f"127.0.0.1:{port}", "--num-processes", "2",
                                    "--process-id", str(i)]),
                              env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i in range(2)]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1][-2000:] for o in outs]
    printed = [[x for x in o[0].splitlines() if not x.startswith("[Gloo]")] for o in outs]  # Gloo's own line
    assert "method" in printed[0][0] and printed[1] == []  # process 0 prints, process 1 is quiet
    a = json.loads((tmp_path / "one.json").read_text())
    b = json.loads((tmp_path / "two.json").read_text())
    for key in ("evaluations", "designs", "infeasible_fraction", "best", "complete"):
        assert a[key] == b[key], key


def test_options_go_together():
    from jaxlink.cli import main

    assert main(["optimize", "sewing-feed-opt", "--method", "montecarlo", "--num-processes", "2"]) == 2
    assert main(["optimize", "sewing-feed-opt", "--method", "montecarlo", "--coordinator", "x",
                 "--num-processes", "2", "--process-id", "0"]) == 2
    assert main(["optimize", "sewing-feed-opt", "--method", "montecarlo", "--coordinator", "h:1",
                 "--num-processes", "2", "--process-id", "2"]) == 2
