"""Pin a benchmark to a number of CPU cores, and run a pinned copy of a benchmark in a subprocess.

XLA's CPU backend spreads one large fused kernel over all cores of the machine, while the
baselines here (numpy's batched solve, scipy's fsolve loop, pylinkage's numba loop) run on one.
So every throughput benchmark reports jaxlink twice: on all cores (how a user runs it) and pinned
to one core (`os.sched_setaffinity`, set before JAX starts its threads), the like-for-like
comparison.

Usage in a script, before `import jax`:

    from _cores import pin_from_argv; pin_from_argv()
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile


def pin_from_argv(argv=None) -> int | None:
    """If `--cores N` is among the arguments, restrict this process to N cores; returns N."""
    argv = sys.argv if argv is None else argv
    if "--cores" not in argv:
        return None
    n = int(argv[argv.index("--cores") + 1])
    cpus = sorted(os.sched_getaffinity(0))
    os.sched_setaffinity(0, set(cpus[:n]))
    return n


def cores() -> int:
    return len(os.sched_getaffinity(0))


def run_pinned(script: str, args: list[str], n: int = 1, timeout: float = 1800) -> dict | None:
    """Run `script args --cores n --json TMP` in a subprocess; its JSON, or None on failure."""
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "out.json")
        r = subprocess.run([sys.executable, script, *args, "--cores", str(n), "--json", out],
                           capture_output=True, text=True, timeout=timeout)
        if r.returncode != 0 or not os.path.exists(out):
            print(f"pinned run of {os.path.basename(script)} failed:\n{r.stderr[-2000:]}", file=sys.stderr)
            return None
        with open(out) as fh:
            return json.load(fh)


HERE = os.path.dirname(os.path.abspath(__file__))
RECORDED = os.path.join(HERE, "results")  # the results the docs quote (tracked)
LATEST = os.path.join(HERE, "results", "latest")  # every other run (ignored by git)


def default_output(name: str) -> str:
    """Where a benchmark writes `name` by default: `results/latest/` (untracked), or the recorded
    `results/` when `JAXLINK_BENCH_UPDATE=1` (set by `suite.py --update`)."""
    folder = RECORDED if os.environ.get("JAXLINK_BENCH_UPDATE") == "1" else LATEST
    os.makedirs(folder, exist_ok=True)
    return os.path.join(folder, name)
