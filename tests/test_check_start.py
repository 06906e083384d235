"""`jaxlink check` on a cold start: what it shares and compiles ahead must not change a number.

- The start `check` reports for a linkage of dyads driven by an angle comes from the first input
  of the designer's numbers' turn (`jaxlink.analysis.motion.start`): the same bits as the start
  solved alone (`_start_arrays`, one of two equal inputs), on seven built-in scenes (every dyad kind).
- The jets of the outputs and the transmission angles are evaluated in blocks of `BLOCK` inputs,
  the samples of the turn and the refinement's few inputs alike: an input's numbers are the same
  bits whichever inputs are evaluated beside it.
- `jaxlink.cache.prepare` compiles a program in a background thread for a later `traced` call:
  that call runs what was prepared (no compilation of its own), with the numbers of a plain
  `jax.jit`; a program prepared for other static options is not taken for it."""

import concurrent.futures
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxlink
from jaxlink import cache

# one worker runs the module: its subprocess at XLA's default level (`default_level`, about 20 s)
# runs once, not once per pytest-xdist worker that picks one of its two tests
pytestmark = pytest.mark.xdist_group("check_start")

# At XLA's default optimization level (the tests compile at LLVM's level 0, where the differences
# below do not arise), in one subprocess:
# - START: for seven built-in scenes, the start from the turn against the start solved
#   alone as `check` does (one of two equal inputs), and against a solve of the one input (a
#   program for degenerate shapes, whose last bits differ on some scenes: the padding is needed);
# - BLOCK: the jets and cos μ of inputs picked at random, evaluated in blocks, against the same
#   inputs within the whole turn evaluated in blocks (the same bits: an input's numbers do not
#   depend on the others evaluated with it), and the turn in blocks against one program of all its
#   inputs (whose vectorized code differs in the last bits on some scenes: the reason every
#   evaluation has the one block shape).
SCRIPT = """
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import jaxlink
from jaxlink.analysis import motion, stroke
from jaxlink.analysis.whole_curve import _arg
from jaxlink.cache import traced
from jaxlink.cli.mechanism import _start_arrays
from jaxlink.solvers import dyads
rng = np.random.default_rng(3)
# every dyad kind of the built-in scenes (RRR, RRP, RPR), and the three where a solve of one input
# differs in the last bits (the variants of these scenes: the same structures)
for name in ["four-bar", "whitworth", "slider-crank", "sewing-feed", "needle-dwell", "needle-arachne",
             "sewing-feed-opt"]:
    mech = jaxlink.load(name)
    p = np.asarray(mech.parameters, np.float64)
    phi = np.asarray(mech.input_start)
    alone = [np.asarray(x) for x in jax.jit(_start_arrays)(mech.replace(parameters=p), phi, p)]
    shared = motion.start(mech)
    same = all(a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
               for a, b in zip(alone, shared))
    one = np.asarray(jaxlink.solve(mech, phi[None], p, points=False).q)[0]
    one_same = one.tobytes() == shared[0].tobytes()
    print("START", name, "SAME" if same else "DIFFERENT", "ONE-SAME" if one_same else "ONE-DIFFERENT")
    if name not in ("four-bar", "whitworth", "sewing-feed", "needle-dwell", "slider-crank", "needle-arachne"):
        continue
    phis, p = motion._turn_inputs(mech, None, 3600)
    arg = _arg(mech, p)
    q, _, sigma, _, _ = (np.asarray(x) for x in traced("motion_turn", motion._turn_arrays, (arg, phis, p)))
    pick = rng.choice(phis.size, 37, replace=False)
    idx = stroke.output_columns(mech)[1]
    if idx:
        turn = stroke._jets(mech, idx, sigma, q[0], phis, p)
        few = stroke._jets(mech, idx, sigma, q[0], phis[pick], p)
        whole = jax.jit(stroke._jets_of, static_argnums=5)(arg, sigma, q[0], phis, p, idx)
        print("BLOCK", name, "jets", all(t[pick].tobytes() == f.tobytes() for t, f in zip(turn, few)),
              all(t.tobytes() == np.asarray(w).tobytes() for t, w in zip(turn, whole)))
    js = tuple(j for j, d in enumerate(dyads.classify(mech)) if d.kind == "RRR")
    if js:
        turn = motion._cos_mus_blocked(mech, js, sigma, q[0], phis, p)
        few = motion._cos_mus_blocked(mech, js, sigma, q[0], phis[pick], p)
        whole = np.asarray(jax.jit(motion._cos_mus, static_argnums=5)(arg, sigma, q[0], phis, p, js))
        print("BLOCK", name, "cos", turn[:, pick].tobytes() == few.tobytes(), turn.tobytes() == whole.tobytes())
"""


@pytest.fixture(scope="module")
def default_level():
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    r = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    rows = [line.split() for line in r.stdout.splitlines()]
    return [w[1:] for w in rows if w[0] == "START"], [w[1:] for w in rows if w[0] == "BLOCK"], r.stdout


def test_the_start_from_the_turn_is_the_start_solved_alone(default_level):
    starts, _, out = default_level
    rows = {w[0]: w[1:] for w in starts}
    assert len(rows) == 7, out
    assert all(v[0] == "SAME" for v in rows.values()), out
    # the check has teeth: a start solved as one input alone differs from the turn's somewhere
    assert any(v[1] == "ONE-DIFFERENT" for v in rows.values()), out


def test_jets_and_transmission_angles_of_an_input_do_not_depend_on_the_inputs_beside_it(default_level):
    _, rows, out = default_level
    assert len(rows) >= 8 and {w[1] for w in rows} == {"jets", "cos"}, out
    assert all(w[2] == "True" for w in rows), out
    # the check has teeth: one program of a whole turn gives other last bits than its blocks somewhere
    assert any(w[3] == "False" for w in rows), out


def _power(x, k):
    """A test program with a static option."""
    return jnp.sin(x) ** k


def _compiles(fn):
    seen = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda e, d, **kw: seen.append(e) if e.endswith("backend_compile_duration") else None)
    out = fn()
    return out, len(seen)


def test_a_prepared_program_is_the_one_traced_runs_with_the_same_numbers():
    x = np.linspace(0.1, 2.0, 37) + 1e-3 * np.random.default_rng(7).standard_normal(37)
    k = 3 + np.random.default_rng().integers(1000)  # a key this process has not compiled
    future = cache.prepare("test_prepare_power", _power, (np.zeros(37),), (int(k),))
    assert future is not None
    future.result()
    assert cache.prepare("test_prepare_power", _power, (np.ones(37),), (int(k),)) is None  # compiled already
    out, compiled = _compiles(lambda: np.asarray(cache.traced("test_prepare_power", _power, (x,), (int(k),))))
    assert compiled == 0  # the prepared program ran: nothing compiled for the call
    assert out.tobytes() == np.asarray(jax.jit(_power, static_argnums=1)(x, int(k))).tobytes()


def test_a_program_prepared_for_other_static_options_is_not_taken():
    x = np.linspace(0.1, 2.0, 41)
    k = 3 + np.random.default_rng().integers(1000)
    cache.prepare("test_prepare_other", _power, (np.zeros(41),), (int(k),)).result()
    out, compiled = _compiles(lambda: np.asarray(cache.traced("test_prepare_other", _power, (x,), (int(k) + 1,))))
    assert compiled > 0
    assert out.tobytes() == np.asarray(jax.jit(_power, static_argnums=1)(x, int(k) + 1)).tobytes()
    assert out.tobytes() != np.asarray(jax.jit(_power, static_argnums=1)(x, int(k))).tobytes()


def test_a_call_waits_for_a_compilation_still_under_way():
    x = np.linspace(0.1, 2.0, 43)
    k = 3 + np.random.default_rng().integers(1000)
    future = cache.prepare("test_prepare_wait", _power, (np.zeros(43),), (int(k),))
    out = np.asarray(cache.traced("test_prepare_wait", _power, (x,), (int(k),)))  # at once: waits
    assert future.done()
    assert out.tobytes() == np.asarray(jax.jit(_power, static_argnums=1)(x, int(k))).tobytes()


def test_a_cancelled_preparation_compiles_nothing_and_the_call_still_runs():
    x = np.linspace(0.1, 2.0, 47)
    k = 3 + np.random.default_rng().integers(1000)
    with cache._TRACING:  # the preparation waits for its turn to trace
        future = cache.prepare("test_prepare_cancel", _power, (np.zeros(47),), (int(k),))
        cache.cancel_prepared()
    concurrent.futures.wait([future])  # done without tracing, or cancelled before it started
    assert future.cancelled() or future.exception() is None
    assert not any(key[0] == "test_prepare_cancel" for key in list(cache._LOADED) if isinstance(key, tuple))
    out = np.asarray(cache.traced("test_prepare_cancel", _power, (x,), (int(k),)))
    assert out.tobytes() == np.asarray(jax.jit(_power, static_argnums=1)(x, int(k))).tobytes()


def test_a_prepared_program_serves_any_design_start_and_guesses_and_other_shapes_compile_anew():
    """The key of a prepared program holds what the program is compiled for (structure, shapes,
    dtypes, static options); the design, the start and the guesses are its arguments. Prepared
    from the file's four-bar, the turn of a design with one parameter changed, of another start
    and of other guesses is the plain `jax.jit` of the same function, bit for bit, and differs from
    the file's; placeholders of another shape or dtype do not stand in (the call compiles anew)."""
    from jaxlink.analysis import motion
    from jaxlink.analysis.whole_curve import _arg

    mech = jaxlink.load("four-bar")
    rng = np.random.default_rng()
    samples = 3600 + int(rng.integers(1, 500))  # shapes this process has not compiled
    phis, p = motion._turn_inputs(mech, None, samples)
    cache.prepare("motion_turn", motion._turn_arrays, (_arg(mech, p), np.zeros_like(phis), np.zeros_like(p))).result()
    plain = jax.jit(motion._turn_arrays)
    base = [np.asarray(x) for x in plain(_arg(mech, p), phis, p)]
    p2 = p.copy()
    p2[mech.parameter_names.index("b")] *= 1.01  # one parameter
    guess = -np.asarray(mech.guess)  # φ3 = −30°, φ4 = −80°: the other assembly (test_cache_differential)
    variants = [(mech, phis, p2), (mech, phis + 0.3, p), (mech.replace(guess=guess), phis, p)]
    for m, ph, pp in variants:
        out, compiled = _compiles(lambda: [np.asarray(x) for x in cache.traced(
            "motion_turn", motion._turn_arrays, (_arg(m, pp), ph, pp))])
        assert compiled == 0
        want = [np.asarray(x) for x in plain(_arg(m, pp), ph, pp)]
        assert all(a.tobytes() == b.tobytes() for a, b in zip(out, want))
        assert out[0].tobytes() != base[0].tobytes()
    x = np.linspace(0.1, 2.0, 53)
    k = 3 + int(rng.integers(1000))
    cache.prepare("test_prepare_shapes", _power, (np.zeros(52),), (k,)).result()  # another length
    cache.prepare("test_prepare_shapes", _power, (np.zeros(53, np.float32),), (k,)).result()  # another dtype
    out, compiled = _compiles(lambda: np.asarray(cache.traced("test_prepare_shapes", _power, (x,), (k,))))
    assert compiled > 0
    assert out.dtype == np.float64
    assert out.tobytes() == np.asarray(jax.jit(_power, static_argnums=1)(x, k)).tobytes()
