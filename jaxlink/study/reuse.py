"""The compiled `Study` of a Python call made without `study=`, kept for the next identical call.

`jaxlink.study.tolerance(mech, inputs)`, `sample`, `sensitivity`, `morris`, `regression`, `dgsm`,
`parameter_study` and the stopping rule build a `tolerance.Study` when none is given; a `Study`
compiles its batch, Jacobian and certificate (seconds on a 2-core CPU), so a new one each call
compiled everything again. `study_for` keeps the Studies it builds (the `STUDIES` most recently
used) keyed on everything that changes a Study's compiled programs or its answers:

- the mechanism: its structure (`Structure.key`: loops, points, units, tables, …), its labels
  (name, file, description: the messages name the file) and its numbers (the parameters' and the
  guess's dtype, shape and bytes — a mechanism whose numbers changed in place is another key);
- the inputs: every field of `StudyInputs` (`archive.pack`: method, seed, samples, tolerances and
  their distributions, ranges, designs, correlation, positions, points, metrics, limits, …, the
  arrays by their bytes);
- the solver options (`NewtonOptions`), the chunk as given, and JAX's device and process counts,
  backend and x64 mode.

A `Study` holds no result of a call (the nominal it caches is a function of the key), so a reused
one gives the same numbers bit for bit as a fresh one (`tests/test_study_reuse.py`). The Study
kept holds a copy of a NumPy parameter vector (not the caller's array, which may change later).
"""

from __future__ import annotations

import collections
import json
import threading

import jax
import numpy as np

from . import archive

#: the most Studies kept (each holds its compiled programs)
STUDIES = 8

_kept: collections.OrderedDict = collections.OrderedDict()
_lock = threading.Lock()


def _numbers(a) -> tuple:
    a = np.asarray(a)
    return str(a.dtype), a.shape, a.tobytes()


def study_key(mech, inputs, options, chunk) -> tuple:
    """The key of `study_for` (see the module doc): a hashable tuple."""
    s = mech.structure
    tree, arrays = archive.pack(inputs)
    return (s.key, s.name, s.file, s.description, _numbers(mech.parameters), _numbers(mech.guess),
            json.dumps(tree, sort_keys=True), tuple((k, _numbers(v)) for k, v in sorted(arrays.items())),
            options, chunk, jax.device_count(), jax.process_count(), jax.default_backend(),
            bool(jax.config.read("jax_enable_x64")))


def study_for(mech, inputs, *, options=None, chunk=None):
    """The `Study` of `mech` and `inputs` (`options` default `NewtonOptions()`, `chunk` designs per
    batch as `Study`'s), built at the first call with this key (see the module doc) and reused by
    the later ones: a second identical call compiles nothing."""
    from ..solvers.options import NewtonOptions
    from .tolerance import Study

    options = options or NewtonOptions()
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
    study = Study(mech, inputs, options=options, chunk=chunk)
    with _lock:
        _kept[key] = study
        while len(_kept) > STUDIES:
            _kept.popitem(last=False)
    return study


def clear() -> None:
    """Forget every Study kept."""
    with _lock:
        _kept.clear()
