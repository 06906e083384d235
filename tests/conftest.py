"""Test configuration: float64 on (the library itself follows the dtype of its inputs), and one
persistent compilation cache for the whole run.

Many tests load the same scenes afresh (a new `Mechanism` structure compiles anew in memory) and
many run the command line in subprocesses: with JAX's persistent compilation cache
(jaxlink/cache.py) in a directory made for this run — shared by the pytest-xdist workers and their
subprocesses through `JAXLINK_CACHE_DIR`, removed at the end — identical programs compile once.
A run that sets `JAXLINK_CACHE_DIR` itself keeps it (an empty value: no cache)."""

import atexit
import os
import shutil
import tempfile

# Most of the suite's time is XLA compiling (the tests are small). LLVM's optimization level 0
# compiles the machine code about 20 % faster (tests/test_windows.py + test_gradients.py: 171 ->
# 138 s); XLA's own HLO passes (fusion, loop removal: what tests/test_fusion.py checks) run as
# shipped, and every numerical check has a tolerance above what it changes. Set in the
# environment, so that the command-line subprocesses inherit it; `JAXLINK_TEST_XLA_OPT=1` keeps
# the shipped level (and so does an XLA_FLAGS that sets one).
if os.environ.get("JAXLINK_TEST_XLA_OPT") != "1" and "xla_backend_optimization_level" not in os.environ.get(
        "XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_backend_optimization_level=0").strip()

import jax  # noqa: E402

if "JAXLINK_CACHE_DIR" not in os.environ:
    _run_cache = tempfile.mkdtemp(prefix="jaxlink-test-xla-")
    os.environ["JAXLINK_CACHE_DIR"] = _run_cache
    _owner = os.getpid()
    atexit.register(lambda: shutil.rmtree(_run_cache, ignore_errors=True) if os.getpid() == _owner else None)

jax.config.update("jax_enable_x64", True)

from jaxlink.cache import enable_compilation_cache  # noqa: E402

enable_compilation_cache()

import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _figures_read_cleanly():
    """Every figure a test saves in its own process is checked as it is written (tests/layout.py:
    no text outside the figure, no overlapping tick labels); the test fails if one is not."""
    from layout import Watch

    with Watch() as w:
        yield
    assert not w.found, "figures with cut-off or overlapping text:\n" + "\n".join(w.found)
