"""The public solve: one jitted entry point that gives the same answer eagerly, under an outer
`jit` (the mechanism passed as a pytree) and under `vmap`, continuing from `[input] start` to the
first input; its points equal the transfer module's."""

import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxlink as jl

FOURBAR = (pathlib.Path(jl.__file__).parent / "scenes" / "four-bar.toml").read_text()


def _started_at_90():
    """The four-bar scene with its guesses given at φ = 90° (`[input] start = 90`)."""
    m0 = jl.load("four-bar")
    q90 = np.rad2deg(np.asarray(jl.solve(m0, np.deg2rad([0.0, 45.0, 90.0])).q[-1]))
    text = FOURBAR.replace('name = "phi2"', 'name = "phi2"\nstart = 90.0')
    text = text.replace("phi3 = 30.0", f"phi3 = {float(q90[0])!r}").replace("phi4 = 80.0", f"phi4 = {float(q90[1])!r}")
    assert text != FOURBAR and "start = 90.0" in text
    return m0, jl.loads(text)


@pytest.mark.parametrize("method", ["auto", "continuation"])
def test_same_answer_eager_jit_and_from_another_start(method):
    m0, m = _started_at_90()
    assert m.input_start == pytest.approx(np.pi / 2)
    opts = jl.NewtonOptions(method=method)
    phis = np.deg2rad(np.arange(0.0, 360.0, 10.0))  # the lead-in runs backwards from 90° to 0°
    eager = jl.solve(m, phis, options=opts)
    jitted = jax.jit(lambda mm, ph: jl.solve(mm, ph, options=opts))(m, jnp.asarray(phis))
    assert bool(np.all(np.asarray(eager.converged)))
    np.testing.assert_array_equal(np.asarray(eager.q), np.asarray(jitted.q))
    np.testing.assert_array_equal(np.asarray(eager.result), np.asarray(jitted.result))
    # the same assembly branch as the scene whose guesses hold at 0°
    ref = jl.solve(m0, phis, options=opts)
    np.testing.assert_allclose(np.asarray(eager.q), np.asarray(ref.q), rtol=0, atol=1e-12)
    # the points: the transfer module's
    tr = jl.transfer(m, phis, eager.q, order=0)
    np.testing.assert_allclose(np.asarray(eager.points), np.asarray(tr.points), rtol=0, atol=1e-15)


def test_batch_equals_vmap_of_solve_path_and_numbers_are_leaves():
    m = jl.load("four-bar")
    phis = jnp.asarray(np.deg2rad(np.arange(0.0, 360.0, 15.0)))
    P = jnp.asarray(m.parameters) * jnp.asarray([[1.0], [1.01], [0.99]])
    batch = jl.solve(m, phis, P)
    mapped = jax.vmap(lambda p: jl.solve_path(m, phis, p, points=True))(P)
    np.testing.assert_allclose(np.asarray(batch.q), np.asarray(mapped.q), rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(batch.points), np.asarray(mapped.points), rtol=0, atol=1e-15)
    # a mechanism with other numbers (replace) is solved by the same compiled function
    m2 = m.replace(parameters=np.asarray(P[1]))
    assert m2.structure is m.structure
    np.testing.assert_allclose(np.asarray(jl.solve(m2, phis).q), np.asarray(batch.q[1]), rtol=0, atol=1e-15)
    assert len(jax.tree_util.tree_leaves(m)) == 2


def test_points_nan_where_not_assembled():
    m = jl.load("four-bar", overrides={"b": 40.0, "c": 30.0})  # cannot reach part of the revolution
    phis = np.deg2rad(np.arange(0.0, 360.0, 5.0))
    sol = jl.solve(m, phis)
    bad = ~np.isin(np.asarray(sol.result), [jl.RESULTS.converged, jl.RESULTS.singular])
    assert bad.any() and (~bad).any()
    assert np.all(np.isnan(np.asarray(sol.points)[bad])) and np.all(np.isfinite(np.asarray(sol.points)[~bad]))


def test_non_finite_points_are_not_converged():
    """A point whose expression has no real value at some positions (the square root of a
    negative sine: finite at the guess, where the file is checked) makes them `nonfinite`."""
    old = 'P = ["a @ phi2", "cx @ phi3", "cy @ phi3 + 90"]'
    assert old in FOURBAR
    m = jl.loads(FOURBAR.replace(old, 'P = ["a @ phi2", "sqrt(sin(phi2)) * cx @ phi3"]'))
    phis = np.deg2rad(np.arange(0.0, 360.0, 30.0))
    sol = jl.solve(m, phis)
    negative = np.sin(phis) < 0
    assert negative.sum() == 5
    assert np.all(np.asarray(sol.result)[negative] == jl.RESULTS.nonfinite)
    assert not np.any(np.asarray(sol.converged)[negative])
    assert np.all(np.asarray(sol.converged)[~negative])
    assert np.all(np.isnan(np.asarray(sol.points)[negative])) and np.all(np.isfinite(np.asarray(sol.points)[~negative]))
    # the loops themselves closed: q is the closed form's
    ref = jl.solve(jl.load("four-bar"), np.deg2rad(np.arange(0.0, 360.0, 30.0)))
    np.testing.assert_allclose(np.asarray(sol.q), np.asarray(ref.q), rtol=0, atol=1e-14)


def test_the_same_structure_loaded_twice_compiles_once():
    """Structures are equal by content (not identity): a file loaded again or renamed reuses the
    compiled solve; a changed loop or another `[input] start` (a constant of the lead-in) does not."""
    a = jl.loads(FOURBAR, file="a.toml")
    b = jl.loads(FOURBAR.replace('name = "four-bar"', 'name = "renamed"'), file="b.toml")
    c = jl.loads(FOURBAR.replace('"b @ phi3"', '"b @ phi3 + 0"'))
    d = jl.loads(FOURBAR.replace('name = "phi2"', 'name = "phi2"\nstart = 5.0'))
    assert a.structure is not b.structure and a.structure == b.structure
    assert hash(a.structure) == hash(b.structure)
    assert a.structure != c.structure and a.structure != d.structure
    phis = np.deg2rad(np.arange(0.0, 360.0, 7.0))  # a shape no other test solves
    from jaxlink.solvers.assemble import _solve_jit

    n0 = _solve_jit._cache_size()
    sa = jl.solve(a, phis)
    n1 = _solve_jit._cache_size()
    sb = jl.solve(b, phis)
    assert n1 == n0 + 1 and _solve_jit._cache_size() == n1
    assert np.all(np.asarray(sa.converged)) and np.all(np.asarray(sb.converged))
    np.testing.assert_allclose(np.asarray(sa.q), np.asarray(sb.q), rtol=0, atol=1e-9)
    jl.solve(c, phis)
    assert _solve_jit._cache_size() == n1 + 1


@pytest.mark.parametrize("method, where", [("auto", "device"), ("auto", "host"), ("continuation", "device")])
def test_a_batch_over_the_memory_budget_is_chunked_and_identical(method, where):
    """`max_bytes` smaller than the batch: chunks of designs (the last one padded), bit-identical
    to the one-call solve — per-design inputs and guesses included. The result stays on the
    device where twice its size leaves room for a chunk (4 designs' estimate: the result is
    11 × 24 × 7 values of 8 bytes, 1.375 designs' estimate), else each chunk goes to the host."""
    m = jl.load("four-bar")
    opts = jl.NewtonOptions(method=method)
    phis = np.deg2rad(np.arange(0.0, 360.0, 15.0))
    B = 11
    P = m.parameters * np.ones((B, 1))
    P[:, m.parameter_index("b")] = np.linspace(0.030, 0.080, B)  # some cannot turn a revolution
    one = jl.solve(m, phis, P, options=opts)
    per = (2 + 3 + 2) * len(phis) * 128  # bytes of one design by solve's estimate
    budget = 4 * per if where == "device" else 2 * per  # chunks of 2 designs either way
    from jaxlink.solvers.assemble import _chunk_designs

    assert _chunk_designs(m, phis, P, True, budget) == (2, where == "device")
    chunked = jl.solve(m, phis, P, options=opts, max_bytes=budget)
    assert isinstance(chunked.q, np.ndarray) == (where == "host") and not isinstance(one.q, np.ndarray)
    assert chunked.q.shape == (B, len(phis), 2)
    for x, y in zip(jax.tree_util.tree_leaves(one), jax.tree_util.tree_leaves(chunked)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    assert 0 < np.asarray(one.converged).all(axis=1).sum() < B
    # each design its own inputs and guesses
    PH = phis[None, :] + np.linspace(0.0, 0.3, B)[:, None]
    Q0 = np.asarray(one.q[:, 0])
    a = jl.solve(m, PH, P, Q0, options=opts)
    b = jl.solve(m, PH, P, Q0, options=opts, max_bytes=budget + per)
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    # a wrong chunk (its padding not cut, or the designs shifted) is caught by the same check
    from jaxlink.solvers.assemble import _solve_chunked

    bad = _solve_chunked(m, phis, np.roll(P, 1, axis=0), None, opts, True, 2, where == "device")
    assert not np.array_equal(np.asarray(one.q), np.asarray(bad.q))
    with pytest.raises(ValueError, match="max_bytes"):
        jl.solve(m, phis, P, max_bytes=0)


def test_without_unknowns_the_same_positions_bit_for_bit():
    """`unknowns=False` (q None: the positions without the angles' computation) gives the same
    points, result codes and residuals as the full solve, bit for bit: in closed form one design, a
    batch with designs that cannot turn a revolution, and a chunked batch; by Newton continuation
    the batch; a non-bool is refused."""
    m = jl.load("four-bar")
    phis = np.deg2rad(np.arange(0.0, 360.0, 7.5))
    B = 6
    P = m.parameters * np.ones((B, 1))
    P[:, m.parameter_index("b")] = np.linspace(0.030, 0.080, B)
    chunks = {"max_bytes": 2 * (2 + 3 + 2) * len(phis) * 128}
    cases = [("auto", None, {}), ("auto", P, {}), ("auto", P, chunks), ("continuation", P, {})]
    for method, p, kw in cases:
        opts = jl.NewtonOptions(method=method)
        full = jl.solve(m, phis, p, options=opts, **kw)
        pos = jl.solve(m, phis, p, options=opts, unknowns=False, **kw)
        assert pos.q is None and full.q is not None
        for x, y in ((full.points, pos.points), (full.result, pos.result), (full.stats.residual, pos.stats.residual),
                     (full.stats.steps, pos.stats.steps)):
            x, y = np.asarray(x), np.asarray(y)
            assert x.shape == y.shape
            np.testing.assert_array_equal(x, y)
        if p is not None:
            assert 0 < np.asarray(full.converged).all(axis=1).sum() < B
    # the check would see a wrong answer: the points of another design differ
    other = jl.solve(m, phis, P[::-1], unknowns=False)
    assert not np.array_equal(np.asarray(jl.solve(m, phis, P).points), np.asarray(other.points), equal_nan=True)
    with pytest.raises(TypeError, match="unknowns"):
        jl.solve(m, phis, unknowns=0)
