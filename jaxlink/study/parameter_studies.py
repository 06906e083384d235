"""Dakota's parameter studies: the designs a `vector`, `list` or `centered` study evaluates, read
from `[study]` (file units), every one evaluated in one batched call (`parameter_study`) and
reported as a `sample` study's (`SampleReport`: study.csv, one row per design, its feasibility
flag and its scalar responses). With a `checkpoint.Checkpoint` the designs run in batches of
`chunk`, each batch's rows written as it ends and a killed study resumed exactly as `sample`'s
(the batches done read back, the others evaluated: the same rows bit for bit).

- `vector` (Dakota's `vector_parameter_study`): `final = { NAME = value, … }` and `steps = n`
  (default 10): the n + 1 designs x_k = x₀ + (k / n) (x_final − x₀), k = 0 … n, from the file's
  design x₀ to the final point along a straight line (the parameters not named keep the file's
  values);
- `list` (`list_parameter_study`): `list = { NAME = [v₁, v₂, …], … }` (columns of equal length):
  those designs, in order;
- `centered` (`centered_parameter_study`): `step = { NAME = Δ, … }` (Δ > 0) and `steps = k`
  (default 1): the file's design first, then for each named parameter in order the 2k designs
  x₀ + i Δ e_j, i = −k … −1, 1 … k (one parameter moved at a time): 1 + 2 k T designs.

The studied parameters are the named ones; each becomes a `Range` over the values it takes (its
`low`, `high` the least and largest, for the manifest), so the study's compiled batch is that of
a `sample` study over them. The designs are read by `given.read_designs` into
`StudyInputs.designs`.
"""

from __future__ import annotations

import time

import numpy as np

from . import resources as _resources
from .inputs import StudyInputs
from .responses import outside_warning
from .sampling import SampleReport, _Evaluator, _study, _units


def parameter_study(mech, inputs: StudyInputs | None = None, *, chunk=None, options=None, progress=None,
                    study=None, checkpoint=None):
    """Evaluate the designs of a `vector`, `list` or `centered` study (`inputs.designs`, see the
    module doc) in batches of `chunk` (one batched call where they fit one).

    **Arguments:** as `sample` (`checkpoint`: a `checkpoint.Checkpoint`, every batch's rows written
    as they come, a saved study resumed; `progress` called with the designs done after each batch).
    **Returns:** a `SampleReport` (`grid_shape` None), its rows the designs in the order above; an
    infeasible design kept and flagged, as `sample`'s.
    """
    t0 = time.perf_counter()
    study = _study(mech, inputs, study, chunk, options)
    inputs = study.inputs
    if inputs.method not in ("vector", "list", "centered") or not inputs.designs:
        raise ValueError("parameter_study needs the inputs of a vector, list or centered study")
    ev = _Evaluator(study)
    values = np.asarray(inputs.designs, float)
    _resources.check(study, inputs.method, len(values), checkpoint=checkpoint, option="designs")
    scalar = np.asarray([k is None for (_, _, k) in ev.labels], bool)
    done = 0
    saved = None if checkpoint is None else checkpoint.load()
    if saved is not None:
        done, state = saved
        ev.nominal = state["nominal"]
    vs, oks = [], []
    for c, a in enumerate(range(0, len(values), study.chunk)):
        if c < done:
            assert checkpoint is not None
            z = checkpoint.load_chunk(c)
            v, ok = z["responses"], z["feasible"]
            if not np.array_equal(z["x"], values[a:a + study.chunk]):
                from ..errors import MechanismError

                raise MechanismError(f"{checkpoint.dir}: chunk {c} of the checkpoint holds other designs; run "
                                     "without --resume to start afresh")
        else:
            v, ok = ev(values[a:a + study.chunk])
            v = v[:, scalar]
            if checkpoint is not None:
                checkpoint.save_chunk(c, x=values[a:a + study.chunk], feasible=ok, responses=v)
                checkpoint.save(c + 1, {"nominal": ev.nominal})
        vs.append(v)
        oks.append(ok)
        if progress is not None:
            progress(len(ok))
    assert ev.nominal is not None
    feasible = np.concatenate(oks)
    responses = np.concatenate(vs)
    warnings = []
    outside = study.responses.outside(values)
    bad = int(np.count_nonzero(~feasible)) - outside  # the others are outside the domain: their own warning
    if bad:
        warnings.append(f"{bad} of {len(feasible)} designs do not assemble over the whole cycle on the nominal's "
                        f"branch ({study.responses.certificate}): kept and flagged (feasible = 0), their responses "
                        "left empty")
    if outside:
        warnings.append(outside_warning(outside, len(values)))
    labels = tuple((name, unit) for (name, unit, k) in ev.labels if k is None)
    timings = {"evaluate": ev.seconds, "total": time.perf_counter() - t0}
    return SampleReport(inputs, inputs.parameters, _units(mech, inputs), np.asarray(study.x0), values, feasible,
                        labels, responses, ev.nominal[scalar], None, study.responses.certificate, warnings, timings)
