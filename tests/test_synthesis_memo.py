"""The synthesis search's memo of compiled programs (`search._compiled`, an `lru_cache` keyed by every
static input) never changes an answer: a program it returns gives the bits of a program compiled
afresh for the same key, and a second request of a key returns that same program. The comparison
is written once (`_same_as_fresh`) and run on the real memo and on one keyed without `closed` (a
deliberately wrong key): the screen's program is the one whose inputs have the same shapes for an
open and a closed target, so a key blind to `closed` would hand an open target the closed one's
descriptors — and the check must say so. The same for `sliders`: a slider-crank's arrays through
a program keyed without it get the revolute program, which reads the slider's encoded parent as
a joint."""

from __future__ import annotations

import functools

import jax
import numpy as np
import pytest

from jaxlink.synthesis import search
from jaxlink.synthesis.topology import as_arrays, topologies

B = 32  # a four-bar's screen on 32 random poses: small programs
#: the bounds (a size some of those poses exceed, `size`; a margin floor, `transmission`): read by the
#: bounded programs only
LIM = np.array([4.0, 0.1], np.float32)
N_DYADS = 2  # the four-bar with its coupler point: two dyads (`topology`)


def _inputs(slider: bool = False):
    arr = as_arrays(topologies(4, sliders=True)[1:] if slider else topologies(4))  # the slider-crank, the four-bar
    assert arr.parents.shape[1] == N_DYADS and arr.parents.shape[0] == 1
    rep = [np.repeat(a[:1], B, 0) for a in (arr.parents, arr.active, arr.traced)]
    return (jax.random.PRNGKey(3), *rep, np.linspace(0.5, 1.5, search.DESC_N).astype(np.float32), LIM)


def _same_as_fresh(memo, slider: bool = False, bounded: bool = False) -> bool:
    """Request the closed target's screen, then the open one's through `memo`; compare the open
    one's output with a program compiled afresh for it (`_compiled` without its cache). `slider`:
    the revolute open screen first, then the slider-crank's; `bounded`: the unbounded open screen
    first, then the bounded one (`size`)."""
    x64 = bool(jax.config.read("jax_enable_x64"))
    args = _inputs(slider)
    closed = not (slider or bounded)
    memo("screen", B, N_DYADS, closed, 0, True, False, False, x64)
    got = memo("screen", B, N_DYADS, False, 0, True, slider, bounded, x64)(*args)
    again = memo("screen", B, N_DYADS, False, 0, True, slider, bounded, x64)(*args)
    fresh = search._compiled.__wrapped__("screen", B, N_DYADS, False, 0, True, slider, bounded, x64)(*args)
    same = [np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True) and np.shape(a) == np.shape(b)
            for a, b in zip(got + again, fresh + fresh)]
    return all(same)


def test_memoized_program_equals_a_fresh_compile_and_a_wrong_key_is_caught():
    search._compiled.cache_clear()
    assert _same_as_fresh(search._compiled)
    info = search._compiled.cache_info()
    assert info.hits >= 1 and info.currsize == 2  # the repeated request came from the memo
    assert _same_as_fresh(search._compiled, slider=True)
    assert _same_as_fresh(search._compiled, bounded=True)

    @functools.lru_cache(maxsize=16)
    def blind(which, b, n_dyads, closed, steps, quick, sliders, bounded, x64):
        return search._compiled.__wrapped__(which, b, n_dyads, True if closed is None else closed, steps, quick,
                                            False if sliders is None else sliders,
                                            False if bounded is None else bounded, x64)

    def blind_memo(which, b, n_dyads, closed, steps, quick, sliders, bounded, x64):  # the key without `closed`
        return blind(which, b, n_dyads, None, steps, quick, sliders, bounded, x64)

    def blind_sliders(which, b, n_dyads, closed, steps, quick, sliders, bounded, x64):  # the key without `sliders`
        return blind(which, b, n_dyads, closed, steps, quick, None, bounded, x64)

    def blind_bounded(which, b, n_dyads, closed, steps, quick, sliders, bounded, x64):  # the key without `bounded`
        return blind(which, b, n_dyads, closed, steps, quick, sliders, None, x64)

    assert not _same_as_fresh(blind_memo)
    assert not _same_as_fresh(blind_sliders, slider=True)
    assert not _same_as_fresh(blind_bounded, bounded=True)


def _programs(static_closed: bool, screens_only: bool = False, only: str | None = None,
              options: dict | None = None) -> dict:
    """The four-bar's screen (open and closed target), rank and refinement (a few steps) for small
    blocks, and the float64 polish's value and gradient, through `cache.compiled`, each called on
    fixed inputs: {name: outputs as numpy} (`screens_only`: the two screens; `only`: that one).
    XLA's lowest level unless `options`."""
    from jaxlink.cache import compiled

    f32 = np.float32
    b, nj = 8, search.CRANK + 1 + N_DYADS
    rng = np.random.default_rng(5)
    arr = as_arrays(topologies(4))
    topo = tuple(np.repeat(a[:1], b, 0) for a in (arr.parents, arr.active, arr.traced))
    poses = rng.uniform(-1, 1, (b, nj, 2)).astype(f32)
    arcs = np.stack([rng.uniform(0, 6, b), rng.uniform(1, 6, b)], 1).astype(f32)

    def aval(x):
        return jax.ShapeDtypeStruct(np.shape(x), np.asarray(x).dtype)

    desc = np.linspace(0.5, 1.5, search.DESC_N).astype(f32)
    lim = LIM
    calls = {f"screen-{'closed' if c else 'open'}": (search._screen_of, (jax.random.PRNGKey(3), *topo, desc, lim),
                                                     (c, False, False)) for c in (static_closed, False)}
    calls["rank"] = (search._rank_of, (*topo, poses, arcs, rng.uniform(-1, 1, (search.RANK_T, 2)).astype(f32), f32(1),
                                       rng.uniform(0, 1, search.RANK_T).astype(f32), lim), (False, False))
    calls["refine"] = (search._refine_of, (*topo, poses, arcs, rng.uniform(-1, 1, (search.TARGET_N, 2)).astype(f32),
                                           f32(0.01), f32(1), rng.uniform(0, 1, search.REFINE_T).astype(f32), lim),
                       (5, False, False))
    from jaxlink.synthesis import polish

    x = np.concatenate([poses[0].ravel(), arcs[0]]).astype(np.float64)
    calls["polish"] = (polish._value_and_grad, (x, topo[0][0], topo[1][0], topo[2][0],
                                                rng.uniform(-1, 1, (polish.POLISH_T, 2)), np.float64(1),
                                                np.linspace(0, 1, polish.POLISH_T), np.float64(0.003),
                                                LIM.astype(np.float64)), ())
    # a timed target's programs (`search._screen_timed`, `_refine_timed`, `polish.program_timed`)
    nt = search.TIMED_SCREEN_T
    w = np.full(nt, 1.0 / nt, f32)
    rt = search.REFINE_T
    calls["screen_timed"] = (search._screen_timed_of,
                             (jax.random.PRNGKey(4), *topo, rng.uniform(-1, 1, (nt, 2)).astype(f32), w,
                              np.linspace(0, 1, nt).astype(f32), f32(2.0), lim), (False, False))
    calls["refine_timed"] = (search._refine_timed_of,
                             (*topo, poses, arcs, rng.uniform(-1, 1, (rt, 2)).astype(f32), np.full(rt, 1 / rt, f32),
                              f32(0.01), np.linspace(0, 1, rt).astype(f32), lim), (5, False, False))
    calls["polish_timed"] = (polish._value_and_grad_timed, (x, topo[0][0], topo[1][0], topo[2][0],
                                                            rng.uniform(-1, 1, (9, 2)), np.full(9, 1 / 9),
                                                            np.linspace(0, 1, 9), np.float64(0.003),
                                                            LIM.astype(np.float64)), (False, False))
    out = {}
    for name, (fun, args, static) in calls.items():
        if (screens_only and not name.startswith("screen")) or (only and name != only):
            continue
        prog = compiled(f"test-{name.split('-')[0]}", fun, tuple(aval(a) for a in args), static,
                        {"xla_backend_optimization_level": 0} if options is None else options)
        out[name] = [np.asarray(x) for x in jax.tree_util.tree_leaves(prog(*args))]
    return out


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(
        len(a[k]) == len(b[k]) and all(x.shape == y.shape and np.array_equal(x, y, equal_nan=True)
                                       for x, y in zip(a[k], b[k])) for k in a)


def test_stored_programs_cold_warm_and_off_give_the_same_bits_and_a_wrong_key_is_caught(tmp_path, monkeypatch):
    """`cache.compiled` (the search's programs, stored as traces beside the compilation cache): the
    programs traced and stored (cold), loaded from the store (warm) and compiled without a store
    (off) give the same outputs bit for bit; with the key blind to the static options, the open
    target's screen is the stored closed one's, and the comparison fails."""
    import jaxlink.cache as cache

    before = jax.config.jax_compilation_cache_dir
    try:
        jax.config.update("jax_compilation_cache_dir", None)
        assert not cache.stored_traces()
        off = _programs(True)
        (tmp_path / "good").mkdir()
        (tmp_path / "blind").mkdir()
        jax.config.update("jax_compilation_cache_dir", str(tmp_path / "good"))
        cold = _programs(True)
        stored = sorted(p.name for p in (tmp_path / "good").glob("*" + cache.TRACE_SUFFIX))
        assert len(stored) == 8  # the screen twice (open, closed), the rank, the refinement, the polish; timed: 3
        stores = []
        monkeypatch.setattr(cache, "_store", lambda *a: stores.append(a))
        warm = _programs(True)
        assert stores == []  # every program came from the store: none traced again
        monkeypatch.undo()
        assert _same(cold, off) and _same(warm, off)
        # the XLA options are not in the trace's key: the rank stored above (for level 0), compiled at
        # another level, is the uncached rank at that level
        other = {"xla_backend_optimization_level": 2}
        stored_rank = _programs(True, only="rank", options=other)
        jax.config.update("jax_compilation_cache_dir", None)
        assert _same(stored_rank, _programs(True, only="rank", options=other))
        jax.config.update("jax_compilation_cache_dir", str(tmp_path / "good"))
        # the closed and the open target's screens differ (else a key blind to it could not be caught)
        assert not all(np.array_equal(x, y, equal_nan=True) for x, y in zip(off["screen-closed"], off["screen-open"]))
        real = cache._compiled_key
        monkeypatch.setattr(cache, "_compiled_key", lambda name, fun, static, spec: real(name, fun, (), spec))
        jax.config.update("jax_compilation_cache_dir", str(tmp_path / "blind"))
        _programs(True, True)  # stores the closed screen under the key the open one then asks for
        assert not _same(_programs(True, True), {k: off[k] for k in off if k.startswith("screen")})
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


def _twice(x):
    """A stored program's function for the key test below (module level: `cache.compiled` needs it)."""
    return 2 * x + 1


@pytest.mark.parametrize("part", ["versions", "backend", "x64"])
def test_a_stored_program_is_traced_again_under_another_jax_backend_or_x64_and_a_blind_key_is_caught(
        part, tmp_path, monkeypatch):
    """The key of `cache.compiled` holds the JAX and jaxlib versions, the backend and the x64 mode:
    a program stored under one is not handed out under another (it is traced and stored again),
    while a second request under the same ones loads it (nothing stored). The same check with a
    key blind to that part (its value replaced by a constant) finds no new trace: it fails."""
    import jaxlink.cache as cache

    real = cache._compiled_key
    x64 = bool(jax.config.read("jax_enable_x64"))

    def other():  # the part changed (x64: really off; the argument's dtype stays float32)
        if part == "versions":
            monkeypatch.setattr(jax, "__version__", "0.0.0-another")
        elif part == "backend":
            monkeypatch.setattr(jax, "default_backend", lambda: "another-backend")
        else:
            jax.config.update("jax_enable_x64", False)

    def blind(name, fun, static, spec):
        import jaxlib

        key = real(name, fun, static, spec)
        if part == "versions":
            return key.replace(repr(jax.__version__), "'V'").replace(repr(jaxlib.__version__), "'V'")
        if part == "backend":
            return key.replace(repr(jax.default_backend()), "'B'")
        return key.rsplit(",", 1)[0] + ", 'X')"

    def stores_after_change(key_fn) -> int:
        folder = tmp_path / key_fn.__name__ / part
        folder.mkdir(parents=True)
        monkeypatch.setattr(cache, "_compiled_key", key_fn)
        aval = (jax.ShapeDtypeStruct((4,), np.float32),)
        x = np.arange(4, dtype=np.float32)
        before = jax.config.jax_compilation_cache_dir
        stores: list = []
        real_store = cache._store
        try:
            jax.config.update("jax_compilation_cache_dir", str(folder))
            cache.compiled("test-key", _twice, aval)(x)  # stored
            monkeypatch.setattr(cache, "_store", lambda *a: (stores.append(a), real_store(*a)))
            cache.compiled("test-key", _twice, aval)(x)  # the same key: loaded
            assert stores == []
            other()
            got = cache.compiled("test-key", _twice, aval)(x)
            np.testing.assert_array_equal(np.asarray(got), 2 * x + 1)
            return len(stores)
        finally:
            jax.config.update("jax_enable_x64", x64)
            jax.config.update("jax_compilation_cache_dir", before)
            monkeypatch.undo()

    assert stores_after_change(real) == 1  # traced and stored again under the changed part
    assert stores_after_change(blind) == 0  # a key blind to it hands out the old program: caught


def test_the_bounded_polish_is_another_program_and_a_blind_key_is_caught():
    """`polish.program` is kept per (dyads, points, sliders, bounded): the bounded polish (`size`,
    `transmission`: the bounds a (2,) argument) is another program, whose value at a binding bound
    differs from the unbounded one's and equals it where no bound binds. A memo keyed without
    `bounded` hands out the first program: its value at the binding bound is wrong, and caught."""
    import functools

    from jaxlink.synthesis import polish

    rng = np.random.default_rng(7)
    arr = as_arrays(topologies(4))
    nj = search.CRANK + 1 + N_DYADS
    x = np.concatenate([rng.uniform(-1, 1, 2 * nj), [0.0, 2 * np.pi]])
    args = (x, arr.parents[0], arr.active[0], arr.traced[0], rng.uniform(-1, 1, (9, 2)), np.float64(1.0),
            np.linspace(0, 1, polish.POLISH_T), np.float64(0.003))
    tight, loose = np.array([0.5, 0.0]), np.array([np.inf, 0.0])  # a size bound every pose exceeds; none
    polish.program.cache_clear()
    free, bound = polish.program(N_DYADS, 9, False, False), polish.program(N_DYADS, 9, False, True)
    assert polish.program.cache_info().currsize == 2
    v_free, v_tight, v_loose = (float(p(*args, b)[0]) for p, b in ((free, tight), (bound, tight), (bound, loose)))
    assert v_tight > v_free and v_loose == pytest.approx(v_free, rel=1e-12)

    @functools.lru_cache(maxsize=4)
    def blind(n_dyads, n_points, sliders):
        return polish.program(n_dyads, n_points, sliders, False)

    assert float(blind(N_DYADS, 9, False)(*args, tight)[0]) != v_tight  # the bound ignored: caught
