"""The README's Python example runs as written, and what it computes is right: its points agree
with the transfer functions' points, the batch with the single solve, its gradient with central
finite differences."""

import pathlib
import re

import numpy as np

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_example_runs_and_is_right():
    text = README.read_text(encoding="utf-8")
    code = re.search(r"## In Python\n\n```python\n(.*?)```", text, re.S).group(1)
    ns: dict = {}
    exec(compile(code, str(README), "exec"), ns)
    jl, mech, phis, sol, sols, tr, r = (ns[k] for k in ("jl", "mech", "phis", "sol", "sols", "tr", "r"))
    assert bool(np.all(np.asarray(sol.converged)))
    np.testing.assert_allclose(np.asarray(sol.points), np.asarray(tr.points), rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(sols.q[7]), np.asarray(sol.q), rtol=0, atol=1e-14)
    assert np.asarray(r.force).shape[:1] == (len(phis),)
    assert bool(np.all(np.asarray(r.result) == jl.RESULTS.converged))
    f, p0, g = ns["jax"].jit(ns["path_spread"]), np.asarray(mech.parameters, dtype=float), np.asarray(ns["g"])
    for i in range(len(p0)):
        h = 1e-6 * max(abs(p0[i]), 1e-3)
        fd = (float(f(p0 + h * np.eye(len(p0))[i])) - float(f(p0 - h * np.eye(len(p0))[i]))) / (2 * h)
        assert abs(g[i] - fd) <= 1e-5 * max(1.0, abs(fd)), (mech.parameter_names[i], g[i], fd)
