"""The synthesis search's memo of compiled programs (`search._compiled`, an `lru_cache` keyed by every
static input) never changes an answer: a program it returns gives the bits of a program compiled
afresh for the same key, and a second request of a key returns that same program. The comparison
is written once (`_same_as_fresh`) and run on the real memo and on one keyed without `closed` (a
deliberately wrong key): the screen's program is the one whose inputs have the same shapes for an
open and a closed target, so a key blind to `closed` would hand an open target the closed one's
descriptors — and the check must say so."""

from __future__ import annotations

import functools

import jax
import numpy as np

from jaxlink.synthesis import search
from jaxlink.synthesis.topology import as_arrays, topologies

B = 32  # a four-bar's screen on 32 random poses: small programs
N_DYADS = 2  # the four-bar with its coupler point: two dyads (`topology`)


def _inputs():
    arr = as_arrays(topologies(4))  # the four-bar
    assert arr.parents.shape[1] == N_DYADS
    rep = [np.repeat(a[:1], B, 0) for a in (arr.parents, arr.active, arr.traced)]
    return (jax.random.PRNGKey(3), *rep, np.linspace(0.5, 1.5, search.DESC_N).astype(np.float32))


def _same_as_fresh(memo) -> bool:
    """Request the closed target's screen, then the open one's through `memo`; compare the open
    one's output with a program compiled afresh for it (`_compiled` without its cache)."""
    x64 = bool(jax.config.read("jax_enable_x64"))
    args = _inputs()
    memo("screen", B, N_DYADS, True, 0, True, x64)
    got = memo("screen", B, N_DYADS, False, 0, True, x64)(*args)
    again = memo("screen", B, N_DYADS, False, 0, True, x64)(*args)
    fresh = search._compiled.__wrapped__("screen", B, N_DYADS, False, 0, True, x64)(*args)
    same = [np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True) and np.shape(a) == np.shape(b)
            for a, b in zip(got + again, fresh + fresh)]
    return all(same)


def test_memoized_program_equals_a_fresh_compile_and_a_wrong_key_is_caught():
    search._compiled.cache_clear()
    assert _same_as_fresh(search._compiled)
    info = search._compiled.cache_info()
    assert info.hits >= 1 and info.currsize == 2  # the repeated request came from the memo

    @functools.lru_cache(maxsize=16)
    def blind(which, b, n_dyads, closed, steps, quick, x64):
        return search._compiled.__wrapped__(which, b, n_dyads, True, steps, quick, x64)

    def blind_memo(which, b, n_dyads, closed, steps, quick, x64):  # the key without `closed`
        return blind(which, b, n_dyads, None, steps, quick, x64)

    assert not _same_as_fresh(blind_memo)
