"""The compiled `Study` of a Python call made without `study=`, kept for the next identical call.

`jaxlink.study.tolerance(mech, inputs)`, `sample`, `sensitivity`, `morris`, `regression`, `dgsm`,
`parameter_study` and the stopping rule build a `tolerance.Study` when none is given; a `Study`
compiles its batch, Jacobian and certificate (seconds on a 2-core CPU), so a new one each call
compiled everything again. `study_for` keeps the Studies it builds (the `STUDIES` most recently
used) keyed on everything that changes a Study's compiled programs or its answers:

- the mechanism: its structure (`Structure.key`: loops, points, units, tables, …), its labels
  (name, file, description: the messages name the file) and its numbers (the parameters' and the
  guess's dtype, shape and bytes — a mechanism whose numbers changed in place is another key);
- the inputs: every field of `StudyInputs` (`_frozen`: method, seed, samples, tolerances and
  their distributions, ranges, designs, correlation, positions, points, metrics, limits, …, the
  arrays by their bytes, a float by its exact hexadecimal value);
- the solver options (`NewtonOptions`), the chunk as given, and JAX's device and process counts,
  backend and x64 mode.

A `Study` holds no result of a call (the nominal it caches is a function of the key), so a reused
one gives the same numbers bit for bit as a fresh one (`tests/test_study_reuse.py`). The Study
kept holds a copy of a NumPy parameter vector (not the caller's array, which may change later).
"""

from __future__ import annotations

import collections
import threading

import jax
import numpy as np

#: the most Studies kept (each holds its compiled programs)
STUDIES = 8

_kept: collections.OrderedDict = collections.OrderedDict()
_lock = threading.Lock()


def _numbers(a) -> tuple:
    a = np.asarray(a)
    return str(a.dtype), a.shape, a.tobytes()


def _frozen(obj):
    """A hashable image of `obj` that two objects share only when every value is the same: a
    NamedTuple by its type and fields, an array by dtype, shape and bytes, a float by its exact
    hexadecimal value (NaN included), containers item by item."""
    if isinstance(obj, tuple) and hasattr(obj, "_fields"):
        return (type(obj).__qualname__, tuple((f, _frozen(getattr(obj, f))) for f in obj._fields))
    if isinstance(obj, np.ndarray) or isinstance(obj, jax.Array):
        return ("array",) + _numbers(obj)
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float):
        return ("float", obj.hex())
    if obj is None or isinstance(obj, (str, bool, int)):
        return (type(obj).__name__, obj)
    if isinstance(obj, (tuple, list)):
        return (type(obj).__name__, tuple(_frozen(v) for v in obj))
    if isinstance(obj, dict):
        return ("dict", tuple(sorted((str(k), _frozen(v)) for k, v in obj.items())))
    raise TypeError(f"study_for: cannot key a {type(obj).__name__}")


def study_key(mech, inputs, options, chunk) -> tuple:
    """The key of `study_for` (see the module doc): a hashable tuple."""
    s = mech.structure
    return (s.key, s.name, s.file, s.description, _numbers(mech.parameters), _numbers(mech.guess),
            _frozen(inputs), options, chunk, jax.device_count(), jax.process_count(), jax.default_backend(),
            bool(jax.config.read("jax_enable_x64")))


def kept(mech, inputs, options, chunk, make):
    """The Study kept under `study_key(mech, inputs, options, chunk)`, else `make(mech, inputs)` kept
    (with a copy of a NumPy parameter vector or guess, not the caller's array, which may change
    later). `tolerance.study_for` is the public entry (this module imports no Study: the
    package's modules import it)."""
    key = study_key(mech, inputs, options, chunk)
    with _lock:
        study = _kept.get(key)
        if study is not None:
            _kept.move_to_end(key)
            return study
    p, g = mech.parameters, mech.guess
    if isinstance(p, np.ndarray) or isinstance(g, np.ndarray):
        mech = mech.replace(parameters=np.array(p) if isinstance(p, np.ndarray) else p,
                            guess=np.array(g) if isinstance(g, np.ndarray) else g)
    study = make(mech, inputs)
    with _lock:
        _kept[key] = study
        while len(_kept) > STUDIES:
            _kept.popitem(last=False)
    return study


def clear() -> None:
    """Forget every Study kept."""
    with _lock:
        _kept.clear()
