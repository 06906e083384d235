"""A study's files: every array of its result in `study.npz` and the rest in `study.json`
(`jaxlink.study.archive`), written by `write_archive` and read back by `read` — what `replot`
(`jaxlink.report.replot`) redraws from.

study.json then holds, beside the manifest's own keys, `mechanism` (`name`, `input_name`,
`input_kind`, `length_unit_m`, `angle_unit_rad`: what the plots print), `options` (every input of
the study: the `[study]` keys as read, with the command line's), `sizes`, and `report` (the
result's tree, its arrays named by their keys in study.npz).
"""

from __future__ import annotations

import json
import pathlib
from typing import NamedTuple


class _Units(NamedTuple):
    length: float
    angle: float


class MechanismNames(NamedTuple):
    """What the plots read of a mechanism (`name`, `input_name`, `input_kind`, `units`, `file`):
    rebuilt from study.json by `replot`."""

    name: str
    input_name: str
    input_kind: str
    units: _Units
    file: str


def mechanism_json(mech) -> dict:
    return {"name": mech.name, "input_name": mech.input_name, "input_kind": mech.input_kind,
            "length_unit_m": float(mech.units.length), "angle_unit_rad": float(mech.units.angle)}


def inputs_json(inputs) -> dict:
    """Every field of a `StudyInputs`, readable (tolerances and ranges as tables)."""
    out = {}
    for k, v in inputs._asdict().items():
        if k in ("tolerances", "ranges"):
            v = [t._asdict() for t in v]
        elif k == "limits":
            v = [{"output": n, "low": lo if lo > -1e308 else "-inf", "high": hi if hi < 1e308 else "inf"}
                 for n, lo, hi in v]
        elif isinstance(v, tuple):
            v = list(v)
        out[k] = v
    return json.loads(json.dumps(out, default=list))


def write_archive(d: pathlib.Path, mech, rep, data: dict) -> pathlib.Path:
    """Write `rep`'s arrays to d/study.npz and add `mechanism`, `options` and `report` to the
    manifest `data` (in place). Returns the npz's path."""
    from ..study import archive

    tree, arrays = archive.pack(rep)
    path = d / "study.npz"
    archive.save_npz(path, arrays)
    data["mechanism"] = mechanism_json(mech)
    data["options"] = inputs_json(rep.inputs)
    data["report"] = tree
    return path


def read(out_dir):
    """(manifest, report, mechanism names) of the study written into `out_dir`."""
    from ..errors import MechanismError
    from ..study import archive

    d = pathlib.Path(out_dir)
    meta, npz = d / "study.json", d / "study.npz"
    if not meta.is_file() or not npz.is_file():
        raise MechanismError(f"{d}: no study.json and study.npz to redraw from (written by `jaxlink study --out "
                             f"{d}`)")
    data = json.loads(meta.read_text(encoding="utf-8"))
    if "report" not in data or "mechanism" not in data:
        raise MechanismError(f"{meta}: written by an older jaxlink without the report's arrays; run the study again")
    rep = archive.unpack(data["report"], archive.load_npz(npz))
    m = data["mechanism"]
    names = MechanismNames(m["name"], m["input_name"], m["input_kind"],
                           _Units(m["length_unit_m"], m["angle_unit_rad"]), data.get("file", ""))
    return data, rep, names
