"""Each kind of bad mechanism file is refused with a message naming the file, line, key and reason;
the command line exits non-zero without a traceback."""

import pathlib
import subprocess
import sys

import numpy as np
import pytest

import jaxlink as jl

GOOD = """\
[mechanism]
name = "t"
length_unit = "mm"
angle_unit = "deg"

[parameters]
a = 20.0
b = 60.0
c = 45.0
d = 55.0

[input]
name = "phi2"

[unknowns]
phi3 = 30.0
phi4 = 80.0

[loops]
main = ["a @ phi2", "b @ phi3", "-c @ phi4", "-d @ 0"]
"""

CASES = {
    # name: (replace old -> new, words the message must contain, line)
    "unknown_name": (("-d @ 0", "-dd @ 0"), ["unknown name 'dd'", "did you mean 'd'", "loops.main[3]"], 20),
    "param_and_unknown": (("phi4 = 80.0", "phi4 = 80.0\na = 1.0"), ["'a' is both a parameter and an unknown"], 18),
    "count": (("phi4 = 80.0", "phi4 = 80.0\nphi5 = 1.0"), ["2 scalar equations but there are 3 unknowns"], 15),
    "nonfinite": (("b = 60.0", "b = nan"), ["'b' = nan is not finite", "parameters.b"], 8),
    "negative_length": (("c = 45.0", "c = -45.0"), ["length 'c' = -45.0 is negative"], 9),
    "empty_loop": (('main = ["a @ phi2", "b @ phi3", "-c @ phi4", "-d @ 0"]', 'main = []'),
                   ["loops.main is empty"], 20),
    "bad_unit": (('length_unit = "mm"', 'length_unit = "inch"'), ["bad length unit 'inch'"], 3),
    "syntax": (('"b @ phi3"', '"b @ * phi3"'), ["syntax error at column 5", "unexpected '*'", "loops.main[1]"], 20),
    "mixed_units": (('"b @ phi3"', '"b @ phi3 + a"'),
                    ["'a' is used as an angle in \"b @ phi3 + a\" but as a length in \"a @ phi2\""], 20),
    "area_as_length": (('"b @ phi3"', '"c * c @ phi3"'),
                       ["inconsistent units", "it is length^2 where a length is expected"], 20),
}


def _bad(case):
    (old, new), _, _ = CASES[case]
    assert old in GOOD
    return GOOD.replace(old, new, 1)


def test_good_file_loads():
    mech = jl.loads(GOOD, file="good.toml")
    assert mech.unknown_names == ("phi3", "phi4")


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_file_message(case, tmp_path):
    path = tmp_path / f"{case}.toml"
    path.write_text(_bad(case))
    with pytest.raises(jl.MechanismError) as info:
        jl.load(str(path))
    msg = str(info.value)
    _, words, line = CASES[case]
    assert msg.startswith(f"{path}:{line}"), msg
    for w in words:
        assert w in msg, (w, msg)


@pytest.mark.parametrize("case", ["unknown_name", "syntax", "count"])
def test_cli_exits_nonzero_without_traceback(case, tmp_path):
    path = tmp_path / f"{case}.toml"
    path.write_text(_bad(case))
    for cmd in (["check", str(path)], ["kinematics", str(path)]):
        r = subprocess.run([sys.executable, "-m", "jaxlink.cli", *cmd], capture_output=True, text=True)
        assert r.returncode == 2, r.stderr
        assert "Traceback" not in r.stderr
        assert r.stderr.startswith(f"jaxlink {cmd[0]}: error: {path}:"), r.stderr


def test_cli_unknown_scene_and_bad_set(tmp_path):
    r = subprocess.run([sys.executable, "-m", "jaxlink.cli", "check", "no-such-scene"], capture_output=True, text=True)
    assert r.returncode == 2 and "neither a file nor a built-in scene" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run([sys.executable, "-m", "jaxlink.cli", "kinematics", "four-bar", "--set", "zz=1"],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "--set zz: no such parameter" in r.stderr


def test_loads_of_text_gives_the_line_of_the_text():
    """`loads` of a string (no file on disk) still names the line of the mistake."""
    with pytest.raises(jl.MechanismError) as info:
        jl.loads(_bad("unknown_name"), file="inline.toml")
    assert str(info.value).startswith("inline.toml:20") and info.value.key == "loops.main[3]"


def test_nonfinite_loops_are_found_at_the_input_start():
    """The load-time evaluation is at `[input] start`, where the guesses hold: sqrt(cos φ) is
    finite at φ = 0 but not at φ = 180°."""
    text = GOOD.replace('"-d @ 0"', '"-d * sqrt(cos(phi2)) @ 0"')
    jl.loads(text, file="t.toml")  # start 0: cos φ = 1
    bad = text.replace('name = "phi2"', 'name = "phi2"\nstart = 180.0')
    with pytest.raises(jl.MechanismError) as info:
        jl.loads(bad, file="t.toml")
    assert "non-finite" in info.value.reason and "[input] start" in info.value.reason
    assert info.value.key == "loops.main" and info.value.line == 21  # one line added above it


def test_set_values_are_read_like_the_cam_scenes():
    from jaxlink.files.overrides import parse_numbers, parse_set

    assert parse_set(["C=1e5", "cam.arc=polygon", "f=[0.1, 0.12]", "n=3"]) == [
        ("C", 1e5), ("cam.arc", "polygon"), ("f", [0.1, 0.12]), ("n", 3)]
    assert parse_numbers(["a=.5", "b = 2", "c=-1e-3"]) == {"a": 0.5, "b": 2.0, "c": -1e-3}
    for item, words in (("a", "expected NAME=VALUE"), ("a=x", "'x' is not a number"),
                        ("a=inf", "must be finite"), ("a=[1]", "is not a number")):
        with pytest.raises(jl.MechanismError, match=words):
            parse_numbers([item])


def test_an_item_of_a_multiline_list_gets_its_own_line():
    text = GOOD.replace('main = ["a @ phi2", "b @ phi3", "-c @ phi4", "-d @ 0"]',
                        'main = [\n  "a @ phi2",\n  "b @ phi3",\n  "-c @ phi4",\n  "-dd @ 0",\n]')
    with pytest.raises(jl.MechanismError) as info:
        jl.loads(text, file="t.toml")
    assert info.value.key == "loops.main[3]" and info.value.line == text.splitlines().index('  "-dd @ 0",') + 1


def test_locator_tables_arrays_of_tables_and_array_lines():
    from jaxlink.files.locator import Locator

    loc = Locator("[a]\nx = [\n  [1, 2],\n  [3, 4],\n]\ny = 1\n[[b.c]]\nz = 1\n[[b.c]]\nz = 2\n[d.e]\nw = 1\n")
    assert loc.line("a", "y") == 6  # the line `[1, 2],` of an array starts no table
    assert loc.line("a", "x", item="[3, 4]") == 4
    assert loc.line("b.c", "z", index=1) == 10 and loc.line("b.c") == 7
    assert loc.line("d", "e") == 11  # a sub-table written as its own header
    assert loc.line("a", "nope") is None and loc.line("zz") is None


def test_pi_and_points_from_points():
    """`pi` is the angle π rad in any file; a point may start from a point defined above; the
    rewritten four-bar traces the same coupler path as the scene."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxlink as jl

    base = (pathlib.Path(jl.__file__).parent / "scenes" / "four-bar.toml").read_text()
    old = 'P = ["a @ phi2", "cx @ phi3", "cy @ phi3 + 90"]'
    assert old in base
    m = jl.loads(base.replace(old, 'A = ["a @ phi2"]\nP = ["A", "cx @ phi3", "cy @ phi3 + pi/2"]\nQ = ["-A"]'))
    phis = np.deg2rad(np.arange(0.0, 360.0, 10.0))
    s, s0 = jl.solve(m, phis), jl.solve(jl.load("four-bar"), phis)
    np.testing.assert_allclose(np.asarray(s.points[:, 1]), np.asarray(s0.points[:, 0]), rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(s.points[:, 2]), -np.asarray(s.points[:, 0]), rtol=0, atol=0)
    for bad, words in (('P = ["Z", "cx @ phi3"]', "'Z' is not a point"),
                       ('P = ["P", "cx @ phi3"]', "before it is defined")):
        with pytest.raises(jl.MechanismError, match=words):
            jl.loads(base.replace(old, bad))
    with pytest.raises(jl.MechanismError, match="reserved"):
        jl.loads(base.replace("cx = 30.0", "pi = 30.0"))
