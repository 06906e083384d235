"""A study's result as files, read back exactly: every array in one `.npz` (`numpy.savez`, the
float64 values bit for bit) and the rest — names, labels, counts, the inputs — as a JSON tree, so
that `--replot` redraws the plots, and `--resume` continues, without evaluating a design.

`pack(obj)` → (tree, arrays): a NamedTuple of this package becomes `{"__type__": NAME, "fields":
{...}}`, an array `{"__array__": KEY}` (KEY its path, `first_order.jacobian`), a tuple
`{"__tuple__": [...]}`, a non-finite float `{"__float__": "inf"}`; lists, dicts, str, int, float,
bool and None stay as they are. `unpack(tree, arrays)` rebuilds the same object (tuples as tuples,
numpy scalars as Python numbers). Only the types of `TYPES` are rebuilt: anything else is refused.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def _types() -> dict:
    from .dgsm import DGSMIndices, DGSMReport
    from .inputs import Range, StudyInputs, Tolerance
    from .morris import MorrisIndices, MorrisReport
    from .regression import RegressionIndices, RegressionReport
    from .robust import RobustMap
    from .sampling import SampleReport, SensitivityReport
    from .second_order import SecondOrder
    from .sobol import SobolIndices
    from .tolerance import FirstOrder, MonteCarlo, ToleranceReport
    from .worstcase import WorstCase

    return {t.__name__: t for t in (Range, StudyInputs, Tolerance, SampleReport, SensitivityReport, SobolIndices,
                                    FirstOrder, MonteCarlo, ToleranceReport, WorstCase, RobustMap, MorrisIndices,
                                    MorrisReport, RegressionIndices, RegressionReport, DGSMIndices, DGSMReport,
                                    SecondOrder)}


def pack(obj, prefix: str = "", arrays: dict | None = None) -> tuple[Any, dict]:
    """(JSON tree, {key: array}) of `obj` (see the module doc)."""
    arrays = {} if arrays is None else arrays
    return _pack(obj, prefix, arrays), arrays


def _pack(obj, key: str, arrays: dict):
    if isinstance(obj, tuple) and hasattr(obj, "_fields"):
        name = type(obj).__name__
        if name not in _types():
            raise TypeError(f"archive: cannot store a {name}")
        return {"__type__": name,
                "fields": {f: _pack(getattr(obj, f), f"{key}.{f}" if key else f, arrays) for f in obj._fields}}
    if isinstance(obj, np.ndarray) or (hasattr(obj, "__array__") and not isinstance(obj, (str, bytes))
                                       and not np.isscalar(obj)):
        arrays[key] = np.asarray(obj)
        return {"__array__": key}
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return {"__float__": repr(obj)}
    if obj is None or isinstance(obj, (str, bool, int, float)):
        return obj
    if isinstance(obj, tuple):
        return {"__tuple__": [_pack(v, f"{key}.{i}", arrays) for i, v in enumerate(obj)]}
    if isinstance(obj, list):
        return [_pack(v, f"{key}.{i}", arrays) for i, v in enumerate(obj)]
    if isinstance(obj, dict):
        return {str(k): _pack(v, f"{key}.{k}", arrays) for k, v in obj.items()}
    raise TypeError(f"archive: cannot store {type(obj).__name__} at {key!r}")


def unpack(tree, arrays) -> Any:
    """The object packed as `tree` with its `arrays` (a mapping key → array, e.g. an open npz)."""
    types = _types()

    def walk(t):
        if isinstance(t, dict):
            if "__type__" in t:
                cls = types.get(t["__type__"])
                if cls is None:
                    raise ValueError(f"archive: unknown type {t['__type__']!r}")
                return cls(**{k: walk(v) for k, v in t["fields"].items()})
            if "__array__" in t:
                return np.asarray(arrays[t["__array__"]])
            if "__tuple__" in t:
                return tuple(walk(v) for v in t["__tuple__"])
            if "__float__" in t:
                return float(t["__float__"])
            return {k: walk(v) for k, v in t.items()}
        if isinstance(t, list):
            return [walk(v) for v in t]
        return t

    return walk(tree)


def save_npz(path, arrays: dict) -> None:
    """Write `arrays` to `path` atomically (a temporary file, then renamed)."""
    import os
    import pathlib

    path = pathlib.Path(path)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def load_npz(path) -> dict:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}
