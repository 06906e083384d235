"""Every table of the file format refuses a key it does not read (issue 46 item 1): a misspelt
key is named with its file, its line and the key it was probably meant to be, through the one
error path of the command line (`jaxlink check` for a linkage file, every table `[optimize]` and
`[study]` included; the scene loader of `simulate` and `jamming` for a cam-follower scene).

The walk below gives one misspelt key per table of docs/reference/file-format.md; the last test
checks that it covers every table the readers know."""

from __future__ import annotations

import pathlib
import re

import pytest

from jaxlink.cam import scene as cam_scene
from jaxlink.cli import main
from jaxlink.errors import MechanismError

# A four-bar in the loop form with every linkage table: bodies, joints, a load, gravity, a search
# and a study (each small: nothing here is solved or compiled before the keys are checked).
LOOP = """\
[mechanism]
name = "walk"
length_unit = "mm"
angle_unit = "deg"

[parameters]
a = 20.0
b = 60.0
c = 45.0
d = { value = 55.0, unit = "mm" }

[input]
name = "phi2"
body = "crank"

[unknowns]
phi3 = 50.0
phi4 = 80.0

[loops]
main = ["a @ phi2", "b @ phi3", "-c @ phi4", "-d @ 0"]

[points]
P = ["a @ phi2", "b/2 @ phi3"]

[bodies.crank]
angle = "phi2"

[bodies.coupler]
angle = "phi3"

[bodies.rocker]
angle = "phi4"

[joints.A0]
bodies = ["ground", "crank"]
at = ["(0, 0)"]

[joints.A]
bodies = ["crank", "coupler"]
at = ["a @ phi2"]

[joints.B]
bodies = ["coupler", "rocker"]
at = ["a @ phi2", "b @ phi3"]

[joints.B0]
bodies = ["ground", "rocker"]
at = ["d @ 0"]

[loads.work]
kind = "force"
body = "rocker"
at = ["d @ 0", "c @ phi4"]
force = [0.0, -1.0]

[environment]
gravity = [0.0, -9.81]

[dynamics]

[optimize]
variables = { a = [15, 25], b = [50, 70] }
samples = 36
targets = [[0.0, 0.0], [10.0, 10.0], [20.0, 0.0]]
placement = { x = "a", y = "b", angle = "a" }

[study]
method = "tolerance"
samples = 0

[study.tolerances]
a = 0.05
b = { tol = 0.05, distribution = "uniform" }
"""

# A slider-crank sketch with masses on a link and on the slider's block.
SKETCH = """\
[mechanism]
length_unit = "mm"
angle_unit = "deg"

[sketch]
frame = ["O1"]

[sketch.input]
crank = "crank"
name = "phi2"

[sketch.joints]
O1 = [0, 0]
A = [21.650635094610966, 12.5]
B = [101.64907257935190, 12.0]

[sketch.links]
crank = ["O1", "A"]
rod = ["A", "B"]

[sketch.sliders]
B = { on = "frame", along = [1, 0] }

[sketch.masses]
rod = { mass = 0.2, inertia = 1e-4 }
B = { mass = 0.1, inertia = 0.0 }
"""

SCENE = """\
[mechanism]
name = "walk-scene"
kind = "cam-follower"
description = "every table"

[dynamics]
m = 1.5e-3
log_decrement = 0.7

[machine]
D = 0.096

[cam]
chord = 1e-4

[[cam.geometry]]
name = "R10-45"
R = 0.010
descent_deg = 45.0

[simulate]
method = "explicit"

[jamming]
tol = 1e-3
"""

# (table, base, line replaced, its misspelt version, the misspelt key, the key it is meant to be)
WALK = [
    ("mechanism", LOOP, 'length_unit = "mm"', 'lenght_unit = "mm"', "lenght_unit", "length_unit"),
    ("parameters.d", LOOP, 'd = { value = 55.0, unit = "mm" }', 'd = { value = 55.0, unti = "mm" }', "unti",
     "unit"),
    ("input", LOOP, 'body = "crank"', 'body = "crank"\nstrat = 0.0', "strat", "start"),
    ("bodies.coupler", LOOP, 'angle = "phi3"', 'angle = "phi3"\nmas = 0.0', "mas", "mass"),
    ("joints.A", LOOP, 'at = ["a @ phi2"]', 'at = ["a @ phi2"]\nknid = "revolute"', "knid", "kind"),
    ("loads.work", LOOP, 'force = [0.0, -1.0]', 'force = [0.0, -1.0]\ndescripton = "x"', "descripton",
     "description"),
    ("environment", LOOP, 'gravity = [0.0, -9.81]', 'gravty = [0.0, -9.81]', "gravty", "gravity"),
    ("dynamics", LOOP, '[dynamics]', '[dynamics]\nm = 1.0', "m", None),
    ("optimize", LOOP, 'samples = 36', 'sampels = 36', "sampels", "samples"),
    ("optimize.placement", LOOP, 'placement = { x = "a", y = "b", angle = "a" }',
     'placement = { x = "a", y = "b", angel = "a" }', "angel", "angle"),
    ("study", LOOP, 'samples = 0', 'samples = 0\nseeed = 1', "seeed", "seed"),
    ("study.tolerances.b", LOOP, 'b = { tol = 0.05, distribution = "uniform" }',
     'b = { tol = 0.05, distributon = "uniform" }', "distributon", "distribution"),
    ("sketch", SKETCH, 'frame = ["O1"]', 'frame = ["O1"]\nfrme = ["O1"]', "frme", "frame"),
    ("sketch.input", SKETCH, 'name = "phi2"', 'nmae = "phi2"', "nmae", "name"),
    ("sketch.sliders.B", SKETCH, 'B = { on = "frame", along = [1, 0] }', 'B = { on = "frame", alnog = [1, 0] }',
     "alnog", "along"),
    ("sketch.masses.rod", SKETCH, 'rod = { mass = 0.2, inertia = 1e-4 }', 'rod = { mass = 0.2, inertai = 1e-4 }',
     "inertai", "inertia"),
    ("sketch.masses.B", SKETCH, 'B = { mass = 0.1, inertia = 0.0 }', 'B = { mass = 0.1, inerta = 0.0 }', "inerta",
     "inertia"),
]
SCENE_WALK = [
    ("mechanism", 'description = "every table"', 'descripton = "every table"', "descripton", "description"),
    ("dynamics", "log_decrement = 0.7", "log_decrment = 0.7", "log_decrment", "log_decrement"),
    ("machine", "D = 0.096", "D0 = 0.096", "D0", "D"),
    ("cam", "chord = 1e-4", "chrod = 1e-4", "chrod", "chord"),
    ("cam.geometry", "descent_deg = 45.0", "descent = 45.0", "descent", "descent_deg"),
    ("simulate", 'method = "explicit"', 'methd = "explicit"', "methd", "method"),
    ("jamming", "tol = 1e-3", "toll = 1e-3", "toll", "tol"),
]


def _misspelt(base: str, old: str, new: str, key: str) -> tuple[str, int]:
    """The file with `old` replaced by `new`, and the 1-based line of `key = ...` in it."""
    assert base.count(old) == 1 or old.startswith("[")
    text = base.replace(old, new, 1)
    line = next(i + 1 for i, s in enumerate(text.splitlines()) if re.search(rf"(^|[{{,]\s*){key}\s*=", s))
    return text, line


def _expect(message: str, path: pathlib.Path, line: int, key: str, meant: str | None) -> None:
    assert f"{path}:{line}" in message, message
    assert f"unknown key '{key}'" in message, message
    if meant is not None:
        assert f"did you mean '{meant}'?" in message, message


def test_the_walk_files_are_good(tmp_path, capsys):
    """The bases load, `[optimize]` and `[study]` included: each refusal below is the misspelt key's."""
    for name, base in (("loop.toml", LOOP), ("sketch.toml", SKETCH)):
        path = tmp_path / name
        path.write_text(base, encoding="utf-8")
        assert main(["check", str(path)]) == 0, capsys.readouterr().err
    path = tmp_path / "scene.toml"
    path.write_text(SCENE, encoding="utf-8")
    cam_scene.load_scene(str(path))


@pytest.mark.parametrize("table, base, old, new, key, meant", WALK, ids=[w[0] for w in WALK])
def test_a_misspelt_key_is_refused(table, base, old, new, key, meant, tmp_path, capsys):
    text, line = _misspelt(base, old, new, key)
    path = tmp_path / "walk.toml"
    path.write_text(text, encoding="utf-8")
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("jaxlink check: error: ") and "\n" not in err, err
    _expect(err, path, line, key, meant)
    assert f"[{table}]" in err, err


@pytest.mark.parametrize("table, old, new, key, meant", SCENE_WALK, ids=[w[0] for w in SCENE_WALK])
def test_a_misspelt_key_of_a_cam_scene_is_refused(table, old, new, key, meant, tmp_path):
    text, line = _misspelt(SCENE, old, new, key)
    path = tmp_path / "scene.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(MechanismError) as info:
        cam_scene.load_scene(str(path))
    _expect(str(info.value), path, line, key, meant)
    assert f"[{table}]" in str(info.value)


def test_the_walk_covers_every_table():
    """Every table the readers know, and every table of keys inside one, is in the walk (the
    tables of names — parameters, unknowns, loops, points, the sketch's joints and links, the
    search's variables, the study's ranges and other NAME = value tables — have no keys to misspell)."""
    from jaxlink.files import reader

    names = {"parameters", "unknowns", "loops", "points"}
    walked = {w[0].split(".")[0] for w in WALK}
    assert set(reader.KNOWN_TABLES) - names <= walked
    assert set(cam_scene._SCHEMA) | {"cam.geometry"} <= {w[0] for w in SCENE_WALK}


@pytest.mark.parametrize("old, new, name, meant", [
    ("variables = { a = [15, 25], b = [50, 70] }", "variables = { aa = [15, 25], b = [50, 70] }", "aa", "a"),
    ("a = 0.05", "aa = 0.05", "aa", "a"),
    ("a = 0.05", 'a = 0.05\n\n[study.ranges]\nbb = [50, 70]', "bb", "b"),
])
def test_a_misspelt_name_in_a_table_of_names(old, new, name, meant, tmp_path):
    """The tables of names (a search's variables, a study's tolerances and ranges) name the
    parameter a misspelt name was probably meant to be, on its line."""
    from jaxlink.files.reader import load
    from jaxlink.optimize.problem import check_table
    from jaxlink.study.inputs import read_study

    text, line = _misspelt(LOOP, old, new, name)
    path = tmp_path / "walk.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(MechanismError) as info:
        mech = load(str(path))
        check_table(mech)
        read_study(mech)
    message = str(info.value)
    assert f"{path}:{line}" in message and f"'{name}' is not a parameter (did you mean '{meant}'?)" in message, message
