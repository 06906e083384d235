"""The `sinker-cam` scene file and the `jaxlink simulate` / `jaxlink jamming` commands."""

import csv
import json
import math

import numpy as np
import pytest

from jaxlink import cli
from jaxlink.cam.scene import load_scene
from jaxlink.errors import MechanismError
from jaxlink.scenes import describe, scene_paths


def test_builtin_scene():
    assert "sinker-cam" in scene_paths()
    assert describe(scene_paths()["sinker-cam"])
    sc = load_scene("sinker-cam")
    assert sc.name == "sinker-cam"
    assert [g.name for g in sc.geometries] == ["R10-45", "R20-45", "R10-50", "R20-50",
                                               "R10-55", "R20-55"]
    assert float(sc.params.m) == 1.5e-3 and float(sc.params.C) == 3.5e4
    assert float(sc.params.k_over_m) == pytest.approx(1065.8, abs=0.05)
    assert float(sc.params.R_sum) == pytest.approx(3.2014 + 3.1216 + 6.323)
    assert sc.speed == pytest.approx(1.7593, abs=1e-4)
    assert sc.geometries[4].descent_angle == pytest.approx(math.radians(55))


def test_set_overrides():
    sc = load_scene("sinker-cam", ["C=1e6", "f=0.12", "cam.arc=polygon",
                                   "simulate.geometry=R20-55", "k_over_m=1066"])
    assert float(sc.params.C) == 1e6 and sc.f_values == [0.12]
    assert float(sc.params.k_over_m) == 1066.0 and sc.k_over_m_fixed
    assert sc.geometries[0].arc == "polygon" and sc.sim_geometries == ["R20-55"]
    # k/m follows C through the log decrement unless fixed
    assert float(load_scene("sinker-cam", ["C=1e4"]).params.k_over_m) == pytest.approx(
        1065.77 * math.sqrt(1e4 / 3.5e4), rel=1e-4)


@pytest.mark.parametrize("setting, key", [
    ("C=-5", "dynamics.C"), ("m=0", "dynamics.m"), ("f=[0.1, 1.5]", "dynamics.f"),
    ("damping=sometimes", "dynamics.damping"), ("cam.arc=spline", "cam.arc"),
    ("simulate.method=euler", "simulate.method"), ("bogus=1", "bogus"),
    ("geometry=R10-45", "geometry"),
])
def test_bad_values_name_the_key(setting, key):
    with pytest.raises(MechanismError) as exc:
        load_scene("sinker-cam", [setting])
    assert exc.value.key == key
    assert "sinker-cam.toml" in str(exc.value)


def test_bad_file_line_numbers(tmp_path):
    text = scene_paths()["sinker-cam"].read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("R = 0.020                     # m\ndescent_deg = 55.0",
                                "R = 0.020                     # m\ndescent_deg = 95.0")
                   .replace('kind = "cam-follower"', 'kind = "cam-follower"\nspeed = 3'))
    with pytest.raises(MechanismError) as exc:
        load_scene(str(bad))
    assert exc.value.key == "mechanism.speed" and exc.value.line == 10
    bad.write_text(text.replace("D = 0.096", "D = 0.096\nrpm = 300"))
    with pytest.raises(MechanismError) as exc:
        load_scene(str(bad))
    assert exc.value.key == "machine.rpm" and exc.value.line is not None
    bad.write_text(text.replace('kind = "cam-follower"', 'kind = "linkage"'))
    with pytest.raises(MechanismError, match="cam-follower"):
        load_scene(str(bad))


def test_cli_simulate(tmp_path, capsys):
    out_csv, out_png = tmp_path / "s.csv", tmp_path / "s.png"
    rc = cli.main(["simulate", "sinker-cam", "--set", "f=[0.1, 0.15]", "--csv", str(out_csv),
                   "--plot", str(out_png)])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "R10-55" in printed and "3295.8" in printed
    with open(out_csv) as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["geometry", "f", "t_s", "yz_m", "y_m", "v_m_s", "a_m_s2",
                             "lag_m", "N_N", "contact"]
    assert len(rows) == 2 * 2001
    f01 = [r for r in rows if float(r["f"]) == 0.1]
    lag = np.array([float(r["lag_m"]) for r in f01])
    yz = np.array([float(r["yz_m"]) for r in f01])
    y = np.array([float(r["y_m"]) for r in f01])
    np.testing.assert_allclose(lag, yz - y, atol=1e-12)
    n = np.array([float(r["N_N"]) for r in f01])
    assert np.all(n[lag < -1e-9] == 0) and n.max() > 0
    assert float(f01[-1]["t_s"]) == pytest.approx(11.30e-3, abs=1e-6)
    assert max(float(r["a_m_s2"]) for r in f01) == pytest.approx(3296, rel=0.01)
    assert out_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_jamming(tmp_path, capsys):
    text = scene_paths()["sinker-cam"].read_text()
    start = text.index("[[cam.geometry]]")
    end = text.index("[simulate]")
    keep = ('[[cam.geometry]]\nname = "R10-50"\nR = 0.010\ndescent_deg = 50.0\n\n')
    scene = tmp_path / "one.toml"
    scene.write_text(text[:start] + keep + text[end:].replace('["R10-55"]', '["R10-50"]'))
    out = tmp_path / "j.json"
    assert cli.main(["jamming", str(scene), "--out", str(out), "--tol", "1e-3"]) == 0
    data = json.loads(out.read_text())
    assert list(data) == ["R10-50"] and set(data["R10-50"]) == {"static_f", "dynamic_f"}
    assert abs(data["R10-50"]["static_f"] - 0.1627) < 1e-4
    assert abs(data["R10-50"]["dynamic_f"] - 0.1636) < 1e-3
    assert cli.main(["jamming", str(scene), "--tol", "0"]) == 2
    assert "--tol" in capsys.readouterr().err


def test_geometry_entries_and_text_get_their_lines():
    """The scene reader uses the linkage files' Locator: an entry of [[cam.geometry]] is found by
    its index, and a scene given as text (edited, not on disk) gets the lines of that text."""
    from jaxlink.cam.scene import loads_scene

    text = scene_paths()["sinker-cam"].read_text()
    old = 'name = "R10-50"\nR = 0.010                     # m\ndescent_deg = 50.0'
    assert old in text
    bad = text.replace(old, 'name = "R10-50"\nR = 0.010\n\ndescent_deg = 25.0')
    with pytest.raises(MechanismError) as exc:
        loads_scene(bad, file="edited.toml")
    lines = bad.splitlines()
    assert exc.value.key == "cam.geometry[2].descent_deg" and exc.value.file == "edited.toml"
    assert lines[exc.value.line - 1].startswith("descent_deg = 25.0")
    bad = text.replace(old, 'name = "R10-50"\nR = -0.010\ndescent_deg = 50.0')
    with pytest.raises(MechanismError) as exc:
        loads_scene(bad)
    assert exc.value.key == "cam.geometry[2].R" and bad.splitlines()[exc.value.line - 1] == "R = -0.010"


def test_set_suggests_the_name():
    with pytest.raises(MechanismError, match="did you mean 'dynamics.damping'"):
        load_scene("sinker-cam", ["dynamics.dampng=always"])
