"""Differential test of the study's one program for all its response expressions
(jaxlink/study/expressions.py `evaluate`: one traced Newton and one series of the highest order
for all, one extreme search with the orders as indices): expressions of different kinds and orders
evaluated together give what each gives in a program of its own (a value at an angle of order 1,
together from a series of order 2; an extreme of order 1, together searched beside legs of orders
0 and 2)."""

import math

import jax
import numpy as np

import jaxlink as jl
from jaxlink.solvers.assemble import solve_path
from jaxlink.study import expressions


def test_expressions_together_equal_each_alone():
    mech = jl.load("four-bar")
    p = np.asarray(mech.parameters, float)
    n = 24
    phis = jax.numpy.asarray(2 * math.pi * np.arange(n) / n)
    q = np.asarray(solve_path(mech, phis, p=p).q)
    texts = ["vx(P) @ 40", "max(vy(P))", "travel(P, x)", "min(a(P))", "min(phi4)"]  # orders 1, 1, 0, 2, 0
    exprs = tuple(e for t in texts for e in expressions.parse(mech, t))

    def run(es):
        return np.asarray(jax.jit(lambda q, p: expressions.evaluate(mech, es, q, phis, p, 0.0))(q, p))

    together = run(exprs)
    alone = np.concatenate([run((e,)) for e in exprs[:2]])  # a value at an angle; an extreme of order 1
    assert np.all(np.isfinite(together))
    np.testing.assert_allclose(together[:2], alone, rtol=1e-12, atol=1e-12)
