"""[bodies], [joints], [loads], [environment]: what a wrong file is told (file, line, key, reason)."""

import subprocess
import sys

import numpy as np
import pytest

from jaxlink import load
from jaxlink.errors import MechanismError
from jaxlink.model import bodies as _bodies
from jaxlink.scenes import scene_paths

BASE = scene_paths()["slider-crank-mass"].read_text()


def model_of(tmp_path, text):
    path = tmp_path / "m.toml"
    path.write_text(text)
    return _bodies.model(load(str(path))), str(path)


def error_of(tmp_path, text) -> MechanismError:
    path = tmp_path / "m.toml"
    path.write_text(text)
    with pytest.raises(MechanismError) as info:
        _bodies.model(load(str(path)))
    assert info.value.file == str(path)
    return info.value


def line_of(text, needle):
    return next(i + 1 for i, line in enumerate(text.splitlines()) if needle in line)


def test_the_scene_parses_into_bodies_joints_and_loads(tmp_path):
    mdl, _ = model_of(tmp_path, BASE)
    assert mdl.body_names == ("crank", "rod", "slider")
    assert [(j.name, j.kind, j.a, j.b) for j in mdl.joints] == [
        ("O", "revolute", -1, 0), ("A", "revolute", 0, 1), ("B", "revolute", 1, 2), ("guide", "prismatic", -1, 2)]
    assert mdl.bodies[1].mass == 0.5 and mdl.bodies[1].inertia == 2.6667e-4
    assert mdl.forces[0].force == (-200.0, 0.0)
    assert (mdl.torques[0].body, mdl.torques[0].torque) == (1, 2.0)
    spring = mdl.springs[0]
    assert (spring.a, spring.b, spring.stiffness, spring.preload) == (-1, 2, 500.0, 10.0)
    assert spring.length == pytest.approx(0.060)  # mm in the file, SI inside
    assert mdl.gravity == (0.0, -9.81) and mdl.input_body == 0
    assert mdl.n_equations == mdl.n_unknowns == 9


def test_unknown_body_in_a_joint(tmp_path):
    text = BASE.replace('bodies = ["rod", "slider"]', 'bodies = ["rodd", "slider"]')
    e = error_of(tmp_path, text)
    assert e.key == "joints.B.bodies" and "unknown body 'rodd'" in e.reason and "did you mean 'rod'" in e.reason
    assert e.line == line_of(text, '"rodd"')


def test_body_without_joints(tmp_path):
    text = BASE.replace("[joints.O]", '[bodies.flywheel]\nangle = "psi12"\n\n[joints.O]')
    e = error_of(tmp_path, text)
    assert e.key == "bodies.flywheel" and "has no joints" in e.reason
    assert e.line == line_of(text, "[bodies.flywheel]")


def test_negative_mass(tmp_path):
    text = BASE.replace("mass = 0.5", "mass = -0.5")
    e = error_of(tmp_path, text)
    assert e.key == "bodies.rod.mass" and "negative" in e.reason
    assert e.line == line_of(text, "mass = -0.5")


def test_mass_without_centroid_and_inertia_without_angle(tmp_path):
    text = BASE.replace('mass = 0.8\ncentroid = ["h1 @ alpha1", "p14 @ alpha4"]', "mass = 0.8")
    e = error_of(tmp_path, text)
    assert e.key == "bodies.slider.mass" and "no 'centroid'" in e.reason
    text = BASE.replace('angle = "psi13"\n', "")
    e = error_of(tmp_path, text)
    assert e.key == "bodies.rod.inertia" and "no 'angle'" in e.reason


def test_unknown_name_and_wrong_unit_in_a_vector_sum(tmp_path):
    text = BASE.replace('centroid = ["h2 @ psi12", "h3/2 @ psi13"]', 'centroid = ["h2 @ psi12", "h4/2 @ psi13"]')
    e = error_of(tmp_path, text)
    assert e.key == "bodies.rod.centroid" and "unknown name 'h4'" in e.reason
    text = BASE.replace('centroid = ["h2 @ psi12", "h3/2 @ psi13"]', 'centroid = ["psi12 @ psi12"]')
    e = error_of(tmp_path, text)
    assert e.key == "bodies.rod.centroid" and "an angle where a length is expected" in e.reason


def test_unknown_key_is_named_with_a_suggestion(tmp_path):
    e = error_of(tmp_path, BASE.replace("inertia = 2.0e-4", "inertai = 2.0e-4"))
    assert e.key == "bodies.crank.inertai" and "did you mean 'inertia'" in e.reason


def test_prismatic_joint_needs_an_axis(tmp_path):
    e = error_of(tmp_path, BASE.replace('axis = "alpha4"\n', ""))
    assert e.key == "joints.guide" and "needs 'axis'" in e.reason


def test_redundant_joint_is_statically_indeterminate(tmp_path):
    text = BASE + '\n[joints.B2]\nbodies = ["rod", "slider"]\nat = ["h1 @ alpha1", "p14 @ alpha4"]\n'
    e = error_of(tmp_path, text)
    assert e.key == "joints" and "statically indeterminate" in e.reason and "mobility" in e.reason


def test_input_body_must_be_a_body(tmp_path):
    e = error_of(tmp_path, BASE.replace('body = "crank"\n\n[unknowns]', 'body = "krank"\n\n[unknowns]'))
    assert e.key == "input.body" and "did you mean 'crank'" in e.reason


def test_bad_loads_and_gravity(tmp_path):
    e = error_of(tmp_path, BASE.replace("force = [-200.0, 0.0]", "force = -200.0"))
    assert e.key == "loads.work.force"
    e = error_of(tmp_path, BASE.replace("stiffness = 500.0", "stiffness = -500.0"))
    assert e.key == "loads.return_spring.stiffness" and "negative" in e.reason
    e = error_of(tmp_path, BASE.replace('kind = "spring"', 'kind = "sprung"'))
    assert e.key == "loads.return_spring.kind"
    e = error_of(tmp_path, BASE.replace("gravity = [0.0, -9.81]", "gravity = -9.81"))
    assert e.key == "environment.gravity"


def test_files_without_bodies_still_load_and_reactions_says_why(tmp_path):
    mech = load("four-bar")  # kinematics needs no bodies
    assert mech.bodies is None
    r = subprocess.run([sys.executable, "-m", "jaxlink.cli", "reactions", "four-bar"], capture_output=True, text=True)
    assert r.returncode == 2
    assert "four-bar.toml" in r.stderr and "[bodies]" in r.stderr and "no bodies" in r.stderr


def test_points_that_do_not_move_with_their_body_are_named(tmp_path):
    from jaxlink.analysis.kinetostatics import rigidity_errors
    from jaxlink.solvers.assemble import solve

    mdl, path = model_of(tmp_path, BASE)
    mech = load(path)
    phis = np.deg2rad(np.arange(0.0, 360.0, 30.0))
    assert rigidity_errors(mech, solve(mech, phis).q, phis) == []
    # the rod's centroid written without the crank: it is then not on the rod
    bad = BASE.replace('centroid = ["h2 @ psi12", "h3/2 @ psi13"]', 'centroid = ["h3/2 @ psi13"]')
    path2 = tmp_path / "bad.toml"
    path2.write_text(bad)
    mech = load(str(path2))
    errors = rigidity_errors(mech, solve(mech, phis).q, phis)
    assert len(errors) == 1 and "the centroid is not fixed in body 'rod'" in errors[0]
    # the missing crank vector (25 mm) turns in the rod's frame: it drifts by about its diameter
    drift = float(errors[0].split("changes by ")[1].split(" mm")[0])
    assert 45.0 < drift <= 50.0


# ----------------------------------------------------------------------------- checked at load, lines of the text


def test_loads_of_text_names_the_line_of_a_bad_joint():
    from jaxlink import loads

    text = BASE.replace('kind = "prismatic"', 'kind = "prismatik"')
    with pytest.raises(MechanismError) as info:
        loads(text, file="inline.toml")  # no file on disk: the line comes from the text
    e = info.value
    assert e.file == "inline.toml" and e.key == "joints.guide.kind"
    assert e.line == line_of(text, 'kind = "prismatik"') and "did you mean 'prismatic'" in e.reason
    text = BASE.replace('bodies = ["crank", "rod"]', 'bodies = ["crank", "crank"]')
    with pytest.raises(MechanismError) as info:
        loads(text)
    assert info.value.key == "joints.A.bodies" and info.value.line == line_of(text, '["crank", "crank"]')


def test_an_edited_file_gets_the_line_of_the_text_that_was_parsed(tmp_path):
    """The text differs from the file on disk (lines added above the mistake): the line is the text's."""
    from jaxlink import loads

    path = tmp_path / "m.toml"
    path.write_text(BASE)
    edited = BASE.replace("[parameters]\n", "[parameters]\n# a\n# b\n# c\n").replace(
        'bodies = ["rod", "slider"]', 'bodies = ["rodd", "slider"]')
    with pytest.raises(MechanismError) as info:
        loads(edited, file=str(path))
    assert info.value.line == line_of(edited, '"rodd"') != line_of(BASE, 'bodies = ["rod", "slider"]')
    assert info.value.key == "joints.B.bodies"


def test_check_reports_a_bad_body_key_with_file_line_and_key(tmp_path):
    path = tmp_path / "m.toml"
    text = BASE.replace("inertia = 2.6667e-4", "inertai = 2.6667e-4")
    path.write_text(text)
    r = subprocess.run([sys.executable, "-m", "jaxlink.cli", "check", str(path)], capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert f"{path}:{line_of(text, 'inertai')}" in r.stderr and "[bodies.rod.inertai]" in r.stderr
    assert "did you mean 'inertia'" in r.stderr


def test_check_reports_a_bad_input_body_and_a_missing_body_table(tmp_path):
    path = tmp_path / "m.toml"
    text = BASE.replace('body = "crank"\n\n[unknowns]', 'body = "krank"\n\n[unknowns]')
    path.write_text(text)
    r = subprocess.run([sys.executable, "-m", "jaxlink.cli", "check", str(path)], capture_output=True, text=True)
    assert r.returncode == 2 and f"{path}:{line_of(text, 'krank')}" in r.stderr and "[input.body]" in r.stderr
    # joints that name no declared body: the file has [joints] but no [bodies]
    start, stop = BASE.index("[bodies.crank]"), BASE.index("[joints.O]")
    with pytest.raises(MechanismError) as info:
        load_text(tmp_path, BASE[:start] + BASE[stop:])
    assert info.value.key == "bodies" and "no bodies" in info.value.reason


def load_text(tmp_path, text):
    path = tmp_path / "t.toml"
    path.write_text(text)
    return load(str(path))


def test_gravity_alone_is_checked_and_gives_no_body_model(tmp_path):
    start = BASE.index("[bodies.crank]")
    mech = load_text(tmp_path, BASE[:start] + "[environment]\ngravity = [0.0, -9.81]\n")
    assert mech.bodies is None
    with pytest.raises(MechanismError) as info:
        load_text(tmp_path, BASE[:start] + "[environment]\ngravty = [0.0, -9.81]\n")
    assert info.value.key == "environment.gravty" and "did you mean 'gravity'" in info.value.reason


def test_grubler_counts_the_parsed_joints():
    from jaxlink.model.structure import structure

    info = structure(load("slider-crank-mass"))
    # u = ground + crank, rod, slider; s = O, A, B, guide: n = 3·3 − 2·4 = 1, k = 4 − 4 + 1 = 1
    assert info["grubler"] == {"members": 4, "joint_count": 4, "mobility": 1, "loops": 1}
    info = structure(load("sewing-feed"))
    # six members and seven revolute joints: n = 3·5 − 2·7 = 1, two independent loops
    assert info["grubler"] == {"members": 6, "joint_count": 7, "mobility": 1, "loops": 2}
    assert structure(load("four-bar"))["grubler"] is None
