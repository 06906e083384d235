"""The persistent compilation cache of the command line (jaxlink/cache.py): a second identical
command loads its compiled code from `JAXLINK_CACHE_DIR` instead of compiling it again, and its
stored trace instead of tracing the table's computation again; an empty value turns the cache off.
Subprocesses: JAX's cache settings are global to a process."""

import os
import subprocess
import sys

import pytest

ARGS = [sys.executable, "-m", "jaxlink.cli", "kinematics", "four-bar", "--count", "12"]

# the command, in a process that counts JAX's persistent-cache hits and misses (its monitoring events)
COUNTED = """
import collections, sys
import jax.monitoring
from jaxlink.cli import main
import jaxlink.report.kinematics as k
seen = collections.Counter()
jax.monitoring.register_event_listener(lambda name, **kw: seen.update([name]))
arrays = k._arrays
def counted(*a):
    seen["traced"] += 1
    return arrays(*a)
k._arrays = counted
status = main(sys.argv[1:])
print("HITS", seen["/jax/compilation_cache/cache_hits"], "MISSES", seen["/jax/compilation_cache/cache_misses"],
      "TRACED", seen["traced"])
sys.exit(status)
"""


def _run(cache, tmp_path, name):
    env = dict(os.environ, JAXLINK_CACHE_DIR=str(cache))
    out = tmp_path / name
    r = subprocess.run([sys.executable, "-c", COUNTED, *ARGS[3:], "--csv", str(out)], env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    words = r.stdout.split()
    counts = int(words[words.index("HITS") + 1]), int(words[words.index("MISSES") + 1])
    return out.read_text(), counts, int(words[words.index("TRACED") + 1])


def test_second_command_loads_compiled_code_from_the_cache(tmp_path):
    cache = tmp_path / "xla"
    first, (hits1, misses1), traced1 = _run(cache, tmp_path, "a.csv")
    assert any(cache.iterdir()), "the first command wrote nothing to the cache"
    assert misses1 > 0  # (a hit or two: the same computation compiled twice in one process)
    # two stored programs: the table's, and the load's check of the file at its guesses
    assert traced1 == 1 and len(list(cache.glob("trace-*"))) == 2
    second, (hits2, misses2), traced2 = _run(cache, tmp_path, "b.csv")
    assert second == first  # same table, bit for bit, from the cached executables
    assert misses2 == 0 and hits2 > 0  # every executable loaded, none compiled again
    assert traced2 == 0  # the table's computation came from the stored trace
    # a damaged stored trace is traced again and replaced, with the same table
    for path in cache.glob("trace-*"):
        path.write_bytes(b"damaged")
    third, _, traced3 = _run(cache, tmp_path, "c.csv")
    assert third == first and traced3 == 1
    assert all(p.read_bytes() != b"damaged" for p in cache.glob("trace-*"))


def test_empty_value_turns_the_cache_off(tmp_path):
    env = dict(os.environ, JAXLINK_CACHE_DIR="")
    code = "import jaxlink, jax; print(jaxlink.enable_compilation_cache(), jax.config.jax_compilation_cache_dir)"
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["None", "None"]


def test_unwritable_directory_warns_and_runs_uncached(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    env = dict(os.environ, JAXLINK_CACHE_DIR=str(blocker / "xla"))
    r = subprocess.run(ARGS, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "compilation cache off" in r.stderr


@pytest.mark.parametrize("value", ["~/jl-cache-test-unused"])
def test_user_directory_is_expanded(value, monkeypatch):
    from jaxlink.cache import cache_dir

    monkeypatch.setenv("JAXLINK_CACHE_DIR", value)
    assert cache_dir() == os.path.expanduser(value)
    monkeypatch.delenv("JAXLINK_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", "/x/y")
    assert cache_dir() == "/x/y/jaxlink/xla"
