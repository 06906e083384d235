"""pylinkage's Strider walking linkage (both legs: four RRR dyads, the ankles as points of plates)
written as a sketch, as `benchmarks/strider_vs_pylinkage.py` solves it: its positions against
numpy circle intersections, and the closed form's stored result codes (`MATERIALIZE_CODES`) and
its batch in chunks of designs (`CHUNK_POSITIONS`) against the same solve without either, bit
for bit."""

import importlib.util
import pathlib

import jax
import numpy as np

import jaxlink as jl
from jaxlink.solvers import assemble, chunks, closed_form

BENCH = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "strider_vs_pylinkage.py"


def _bench():
    spec = importlib.util.spec_from_file_location("strider_vs_pylinkage", BENCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_strider_positions_and_stored_codes(monkeypatch):
    S = _bench()
    mech = S.strider_sketch().mechanism()
    assert closed_form.method_for(mech, jl.NewtonOptions()) == "closed_form"
    D = S.designs(4, seed=1)
    bad = D[1].copy()
    bad[6] = bad[7] + 1.8  # |tibia − f| > |DF| over part of the turn: the foot H cannot be assembled there
    D = np.vstack([D[:3], bad, D[3:]])
    P = S.jaxlink_parameters(mech, D)
    assert np.max(np.abs(P[0] - mech.parameters)) < 1e-12  # the sketch's parameters are the design
    thetas = S.crank_angles()
    sol = jl.solve(mech, thetas, P, mech.guess)
    code = np.asarray(sol.result)
    assert np.all(code[[0, 1, 2, 4]] == jl.RESULTS.converged)
    assert np.any(code[3] == jl.RESULTS.cannot_assemble) and np.any(code[3] == jl.RESULTS.converged)
    _, sides = S.sketch_pose()
    ref = S.reference(D, thetas, sides)
    ref7 = np.stack([ref[n] for n in S.MOVING], -2)
    xy = S.jaxlink_positions(mech, sol.points)
    good = [0, 1, 2, 4]
    assert np.max(np.abs(xy[good] - ref7[good])) < 1e-12
    ok = code[3] == jl.RESULTS.converged
    assert np.max(np.abs(xy[3][ok] - ref7[3][ok])) < 1e-12
    assert np.all(np.isnan(xy[3][~ok]))  # not assembled: NaN points

    # in chunks of 2 designs (3 chunks, the last padded): the same answers, bit for bit (on the CPU)
    assert chunks._design_chunk(1000, 360, 4) == 20 or jax.default_backend() != "cpu"
    assert chunks._design_chunk(1000, 360, 1) == 0  # one dyad: one piece
    monkeypatch.setattr(chunks, "CHUNK_POSITIONS", 2 * len(thetas))
    assert chunks._design_chunk(len(P), len(thetas), 4) == (2 if jax.default_backend() == "cpu" else 0)
    batch = jax.jit(lambda ph, p, q0: assemble._batch(mech, ph, p, q0, jl.NewtonOptions(), True))
    chunked = batch(thetas, P, mech.guess)
    # the same solve in one piece, with the codes fused into every consumer (not stored): the
    # same answers
    monkeypatch.setattr(chunks, "CHUNK_POSITIONS", 0)
    monkeypatch.setattr(closed_form, "MATERIALIZE_CODES", False)
    fused = jax.jit(lambda ph, p, q0: assemble._batch(mech, ph, p, q0, jl.NewtonOptions(), True))
    off = fused(thetas, P, mech.guess)
    for a, b, c in zip(*(jax.tree_util.tree_leaves(x) for x in (sol, off, chunked))):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        np.testing.assert_array_equal(np.asarray(c), np.asarray(b))


def test_feed_batch_in_chunks_is_bit_identical(monkeypatch):
    """The sewing feed (two dyads) in chunks of 2 designs, against one piece: the same answers bit
    for bit (the chunk's inputs are copied first; read through the loop's slice, XLA fused the
    four-bar's kernels otherwise and its points changed in the last bit)."""
    mech = jl.load("sewing-feed")
    rng = np.random.default_rng(3)
    P = mech.parameters[None] * (1 + 0.01 * rng.uniform(-1, 1, (6, len(mech.parameters))))
    phis = np.linspace(0, 2 * np.pi, 36, endpoint=False)
    run = jax.jit(lambda ph, p: assemble._batch(mech, ph, p, None, jl.NewtonOptions(), True))
    monkeypatch.setattr(chunks, "CHUNK_POSITIONS", 2 * len(phis))
    assert chunks._design_chunk(6, len(phis), 2) == (2 if jax.default_backend() == "cpu" else 0)
    chunked = run(phis, P)
    monkeypatch.setattr(chunks, "CHUNK_POSITIONS", 0)
    whole = jax.jit(lambda ph, p: assemble._batch(mech, ph, p, None, jl.NewtonOptions(), True))(phis, P)
    assert np.all(np.asarray(whole.result) == jl.RESULTS.converged)
    # (the rounding depends on the kernels at the shipped optimization level: there, without the
    # copy, 24 of 432 values differ; the suite's level 0 (conftest.py) contracts no
    # multiply-adds, `JAXLINK_TEST_XLA_OPT=1` checks the shipped one)
    for a, b in zip(jax.tree_util.tree_leaves(chunked), jax.tree_util.tree_leaves(whole)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_strider_positions_without_unknowns_bit_for_bit():
    """The positions alone (`unknowns=False`: no angle's atan2 computed) are the full solve's, bit
    for bit, for one design over a revolution (the benchmark's call against `step_fast`; a batch:
    `tests/test_solve_api.py`), and for a design that cannot be assembled over part of it."""
    S = _bench()
    mech = S.strider_sketch().mechanism()
    D = S.designs(4, seed=2)
    D[2, 6] = D[2, 7] + 1.8  # the foot H cannot be assembled over part of the turn
    P = S.jaxlink_parameters(mech, D)
    thetas = S.crank_angles()
    for p in (P[1], P[2]):
        full, pos = jl.solve(mech, thetas, p, mech.guess), jl.solve(mech, thetas, p, mech.guess, unknowns=False)
        assert pos.q is None
        for x, y in ((full.points, pos.points), (full.result, pos.result), (full.stats.residual, pos.stats.residual)):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    assert np.any(np.asarray(full.result) == jl.RESULTS.cannot_assemble)
