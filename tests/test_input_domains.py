"""Every input value has a domain checked where it enters (the file, `--set`, the options,
`[optimize]`), and every wrong value is refused with exit status 2 and one message on standard
error that names where it came from (file and line, or the option). Issue 16's cases, by class."""

from __future__ import annotations

import contextlib
import io
import os
import pathlib
import re
import stat
import threading

import pytest

from jaxlink.cli import main

SCENES = pathlib.Path(__file__).resolve().parent.parent / "jaxlink" / "scenes"
FOUR_BAR = (SCENES / "four-bar.toml").read_text(encoding="utf-8")


def cli(*argv: str) -> tuple[int, str]:
    """(exit status, standard error) of `jaxlink ARGV`, in process."""
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            rc = main(list(argv))
        except SystemExit as exc:  # argparse's refusals
            rc = int(exc.code or 0)
    return rc, err.getvalue()


def refused(rc_err, *words: str) -> None:
    rc, err = rc_err
    assert rc == 2, err
    assert "internal error" not in err and "Traceback" not in err, err
    for w in words:
        assert w in err, (w, err)


def four_bar(tmp_path, old: str | None, new: str, *, encoding: str = "utf-8") -> str:
    text = FOUR_BAR.replace(old, new) if old else FOUR_BAR + new
    assert old is None or old in FOUR_BAR
    path = tmp_path / "m.toml"
    path.write_bytes(text.encode(encoding))
    return str(path)


# ----------------------------------------------------------------------------- the file


def test_latin1_file_is_refused_with_its_line(tmp_path):
    f = four_bar(tmp_path, "# crank", "# crank 90°", encoding="latin-1")
    refused(cli("check", f), "m.toml:11", "not UTF-8", "0xb0")


def test_deeply_nested_toml_is_refused(tmp_path):
    for depth in (20, 3000):
        f = four_bar(tmp_path, None, "\n[environment]\nx = " + "[" * depth + "]" * depth + "\n")
        refused(cli("check", f), "m.toml", "nested")


def test_a_sum_of_3000_names_is_solved(tmp_path):
    # 3000 × cx/3000 = cx: the same point as the file's
    f = four_bar(tmp_path, '"cx @ phi3"', '"' + " + ".join(["cx / 3000"] * 3000) + ' @ phi3"')
    rc, err = cli("kinematics", f, "--count", "3", "--outputs", "position")
    assert rc == 0, err


def test_deep_parentheses_are_refused_with_the_limit(tmp_path):
    f = four_bar(tmp_path, '"cx @ phi3"', '"' + "(" * 3000 + "cx" + ")" * 3000 + ' @ phi3"')
    refused(cli("check", f), "m.toml:30", "points.P[1]", "nested too deeply", "100 levels")
    f = four_bar(tmp_path, '"cx @ phi3"', '"' + "(" * 90 + "cx" + ")" * 90 + ' @ phi3"')
    assert cli("check", f)[0] == 0


@pytest.mark.parametrize("term", ['"(0/0, 0)"', '"cx / 0 @ phi3"'])
def test_division_by_zero_is_refused_by_check(tmp_path, term):
    f = four_bar(tmp_path, '"cx @ phi3"', term)
    refused(cli("check", f), "m.toml:30", "division by zero")


def test_non_finite_point_at_the_guess_is_refused_by_check(tmp_path):
    f = four_bar(tmp_path, '"cx @ phi3"', '"cx * (a - a) / (a - a) @ phi3"')
    refused(cli("check", f), "m.toml", "point 'P' is not finite")


@pytest.mark.parametrize("old,new,words", [
    ("a = 20.0", "a = " + "9" * 400, ("m.toml:11", "parameters.a", "400 digits", "1e+15")),
    ("phi3 = 30.0", "phi3 = 1e300", ("m.toml:23", "unknowns.phi3", "1e+300")),
    ("phi3 = 30.0", "phi3 = 1e7", ("m.toml:23", "unknowns.phi3", "out of range")),
    ('name = "phi2"', 'name = "phi2"\nstart = 1e300', ("input.start", "1e+300")),
    ("a = 20.0", "a = 1e-300", ("m.toml:11", "parameters.a", "out of range", "1e-09")),
    ("a = 20.0", "a = 2e12", ("m.toml:11", "out of range", "1e+06 m")),
])
def test_values_outside_their_domain_are_refused_on_their_line(tmp_path, old, new, words):
    refused(cli("check", four_bar(tmp_path, old, new)), *words)


def test_check_of_a_cam_scene_names_the_commands_that_handle_it():
    refused(cli("check", "sinker-cam"), "cam-follower", "jaxlink simulate")


def test_a_directory_or_a_pipe_as_file_is_said_to_be_one(tmp_path):
    refused(cli("check", str(tmp_path)), "is a directory")
    fifo = tmp_path / "p.toml"
    os.mkfifo(fifo)
    refused(cli("check", str(fifo)), "is a named pipe")


def test_set_is_blamed_on_the_option():
    rc, err = cli("kinematics", "four-bar", "--set", "a=-5", "--count", "2")
    refused((rc, err), "--set a=-5", "negative")
    assert "four-bar.toml:" not in err
    refused(cli("kinematics", "four-bar", "--set", "a=1e-300"), "--set a=1e-300", "out of range")
    refused(cli("kinematics", "four-bar", "--set", "a=" + "9" * 400), "--set", "finite")


# ----------------------------------------------------------------------------- the options


@pytest.mark.parametrize("args,words", [
    (("--step", "1e-300"), ("--step", "1000000")),
    (("--count", "1e20"), ("--count",)),
    (("--count", str(10**20)), ("--count", "at most 1000000")),
    (("--start", "nan"), ("--start", "not a finite")),
    (("--start", "inf"), ("--start", "not a finite")),
    (("--start", "1e300"), ("--start", "out of range")),
    (("--start", "1e9"), ("--start", "out of range")),
    (("--rpm", "nan"), ("--rpm", "not a finite")),
    (("--omega", "nan"), ("--omega", "not a finite")),
    (("--rpm", "inf"), ("--rpm", "not a finite")),
    (("--rpm", "1e300"), ("--rpm", "rpm")),
    (("--omega=-1e7",), ("--omega", "rad/s")),
    (("--plot", "out.xyz"), ("--plot out.xyz", ".png")),
    (("--animate", "out.mp4"), ("--animate", ".gif")),
    (("--csv", "/dev/full"), ("--csv /dev/full", "No space left")),
])
def test_kinematics_options_outside_their_domain(args, words):
    if "/dev/full" in args and not (os.path.exists("/dev/full") and stat.S_ISCHR(os.stat("/dev/full").st_mode)):
        pytest.skip("no /dev/full device")
    few = () if {"--count", "--step"} & set(args) else ("--count", "3")
    refused(cli("kinematics", "four-bar", *few, *args), *words)


def test_outputs_through_a_file_or_into_a_folder_are_refused_before_the_solve(tmp_path):
    (tmp_path / "f").write_text("")
    refused(cli("kinematics", "four-bar", "--csv", str(tmp_path / "f" / "x.csv")), "--csv", "is a file, not a folder")
    refused(cli("reactions", "slider-crank-mass", "--csv", str(tmp_path)), "--csv", "is a folder")
    refused(cli("kinematics", "four-bar", "--csv", str(tmp_path / "no" / "x.csv")), "--csv", "does not exist")


def _opt(*args):
    return cli("optimize", "sewing-feed-opt", "--method", "montecarlo", "--budget", "4", *args)


@pytest.mark.parametrize("args,words", [
    (("--seed", "-1"), ("--seed -1", "0 to 4294967295")),
    (("--chunk", "0"), ("--chunk 0", "from 1")),
    (("--chunk", "-5"), ("--chunk -5",)),
    (("--starts", "0"), ("--starts 0",)),
    (("--budget", "0"), ("--budget 0",)),
    (("--out", "/dev/stdout"), ("--out /dev/stdout", "checkpoint")),
])
def test_optimize_options_outside_their_domain(args, words):
    refused(_opt(*args), *words)


@pytest.mark.parametrize("key,value,words", [
    ("report_samples", "0", ("optimize.report_samples", "from 3")),
    ("iterations", "-3", ("optimize.iterations",)),
    ("starts", "0", ("optimize.starts",)),
    ("chunk", "0", ("optimize.chunk",)),
    ("seed", "-1", ("optimize.seed",)),
    ("budget", "0", ("optimize.budget",)),
    ("stroke", "-20", ("optimize.stroke", "> 0")),
    ("sign_changes", "-1", ("optimize.sign_changes",)),
    ("samples", "100000000", ("optimize.samples", "100000")),
    ("samples", "100000", ("optimize.samples", "GiB")),
])
def test_optimize_keys_outside_their_domain_name_the_file_and_key(tmp_path, key, value, words):
    text = (SCENES / "sewing-feed-opt.toml").read_text(encoding="utf-8")
    path = tmp_path / "opt.toml"
    text = re.sub(rf"^{key} = .*$", "", text, flags=re.M)  # the file's own value, if any
    path.write_text(text.replace("[optimize]\n", f"[optimize]\n{key} = {value}\n"), encoding="utf-8")
    rc, err = cli("optimize", str(path), "--method", "montecarlo", "--budget", "4",
                  *(("--chunk", "100000") if value == "100000" else ()))
    refused((rc, err), "opt.toml", *words)
    assert "--chunk " not in err.split("GiB")[0] or value == "100000"


def test_optimize_out_to_a_named_pipe_writes_to_the_pipe(tmp_path):
    fifo = tmp_path / "result.json"
    os.mkfifo(fifo)
    got = []

    def reader():  # the reader of the pipe: each rewrite of OUT opens and closes it once
        while True:
            with open(fifo, encoding="utf-8") as fh:
                data = fh.read()
            got.append(data)
            if '"complete": true' in data:
                return

    t = threading.Thread(target=reader, daemon=True)
    t.start()
    rc, err = _opt("--out", str(fifo), "--chunk", "4")
    t.join(timeout=60)
    assert rc == 0, err
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)  # still a pipe, not replaced by a file
    assert got and '"complete": true' in got[-1]


def test_search_time_and_checkpoint_interval_have_domains():
    """`[optimize] time`, `--time` and `run(time=, checkpoint_s=)` are refused outside their domains."""
    import jaxlink as jl
    from jaxlink.cli import main
    from jaxlink.optimize import problem_from, run

    mech = jl.load("sewing-feed-opt")
    for bad in (-1, 0, float("nan"), float("inf"), "x"):
        with pytest.raises(jl.MechanismError, match=r"optimize\.time"):
            problem_from(mech, {"time": bad})
    problem = problem_from(mech)
    with pytest.raises(jl.MechanismError, match="time"):
        run(problem, "montecarlo", budget=8, time=float("nan"))
    with pytest.raises(jl.MechanismError, match="checkpoint_s"):
        run(problem, "montecarlo", budget=8, checkpoint_s=-1)
    assert main(["optimize", "sewing-feed-opt", "--method", "montecarlo", "--time", "nan"]) == 2


# ----------------------------------------------------------------------------- [optimize] in every command

@pytest.mark.parametrize("scene,key,value,words", [
    ("needle-dwell", "stroke", "07:32:00", ("'stroke' must be a number", "datetime.time")),  # a TOML time
    ("needle-dwell", "crank", "[20.0]", ("[20.0] is not a parameter",)),
    ("needle-dwell", "arm_offset", "1e300", ("1e+300 is not a parameter",)),
    ("needle-arachne", "crank", "[20.0]", ("[20.0] is not a parameter",)),  # roles only, no search
    ("sewing-feed-opt", "gradient_solver", '"adam"', ("'gradient_solver' must be one of",)),
    ("sewing-feed-opt", "variables", "{ l2 = [4, 0] }", ("lower < upper",)),
])
@pytest.mark.parametrize("command", ["check", "kinematics", "reactions"])
def test_every_command_validates_optimize(tmp_path, scene, key, value, words, command):
    """Issue 23 item 6: `check`, `kinematics` and `reactions` refuse a bad `[optimize]` value as
    `optimize` does — exit 2, the file, the key's line, the key and why — before solving anything."""
    text = (SCENES / f"{scene}.toml").read_text(encoding="utf-8")
    text = re.sub(rf"^{key} = .*$", "", text, flags=re.M)
    text = text.replace("[optimize]\n", f"[optimize]\n{key} = {value}\n")
    path = tmp_path / "o.toml"
    path.write_text(text, encoding="utf-8")
    line = text.splitlines().index(f"{key} = {value}") + 1
    refused(cli(command, str(path)), f"o.toml:{line} [optimize.{key}", *words)


def test_optimize_table_of_every_scene_is_valid_and_compiles_nothing():
    """The built-in scenes' `[optimize]` tables pass (needle-arachne's has roles and no search);
    validating them compiles nothing (`check` stays fast)."""
    import logging

    import jax

    import jaxlink as jl
    from jaxlink.optimize.problem import check_table
    from jaxlink.scenes import scene_paths

    mechs = []
    for name in scene_paths():
        with contextlib.suppress(jl.MechanismError):  # the cam scene is no linkage
            mechs.append(jl.load(name))
    assert sum("optimize" in m.tables for m in mechs) >= 5
    records = []
    handler = logging.Handler()
    handler.emit = records.append  # type: ignore[method-assign]
    logger = logging.getLogger("jax")
    logger.addHandler(handler)
    try:
        with jax.log_compiles(True):
            for m in mechs:
                check_table(m)
    finally:
        logger.removeHandler(handler)
    assert not [r for r in records if "ompil" in r.getMessage()], [r.getMessage() for r in records][:3]


# ----------------------------------------------------------------------------- domains follow the use

TINY_PIVOT = """\
[mechanism]
name = "tiny-pivot"
length_unit = "mm"
angle_unit = "deg"
[parameters]
a = 20.0
b = 60.0
c = 45.0
p1x = 55.0
p1y = 3.8e-9     # the frame pivot's y: a rounding residue of 0
[input]
name = "phi2"
[unknowns]
phi3 = 30.0
phi4 = 80.0
[loops]
main = ["a @ phi2", "b @ phi3", "-c @ phi4", "-(p1x, p1y)"]
[points]
P = ["a @ phi2", "30 @ phi3", "(0, p1y)"]
"""


def test_a_tiny_coordinate_is_accepted_and_solved():
    """Issue 23 item 7: a coordinate (or an offset) may be any small number; the four-bar with its
    frame pivot at (55 mm, 3.8e-9 mm) solves as Freudenstein's with d = 55 mm (the pivot's y moves
    the angles by about 1e-10 rad)."""
    import numpy as np
    from closed_forms import fourbar_freudenstein

    import jaxlink as jl

    mech = jl.loads(TINY_PIVOT, file="tiny.toml")
    assert mech.parameters[mech.parameter_index("p1y")] == 3.8e-12  # SI
    phis = np.deg2rad([0.0, 90.0])
    sol = jl.solve(mech, phis)
    assert bool(np.all(sol.converged))
    ref = np.stack(fourbar_freudenstein(0.020, 0.060, 0.045, 0.055, phis, -1), 1)
    err = (np.asarray(sol.q) - ref + np.pi) % (2 * np.pi) - np.pi  # angles modulo a turn
    assert np.abs(err).max() < 1e-9


@pytest.mark.parametrize("old,new,words", [
    ("a = 20.0", "a = 3.8e-9", ("tiny.toml:6", "[parameters.a]", "link length 'a' = 3.8e-09 mm is out of range",
                                "a link length is 0 or 1e-09 to 1e+06 m")),
    ("p1x = 55.0", "p1x = 2e9", ("tiny.toml:9", "[parameters.p1x]", "length 'p1x' = 2e+09 mm is out of range",
                                 "-1e+06 to 1e+06 m")),
])
def test_a_link_length_keeps_its_domain(tmp_path, old, new, words):
    """A link length (a parameter alone as the LENGTH of a loop's term) is still 0 or 1e-9 m to
    1e6 m; a coordinate is within ±1e6 m."""
    path = tmp_path / "tiny.toml"
    path.write_text(TINY_PIVOT.replace(old, new), encoding="utf-8")
    refused(cli("check", str(path)), *words)


# ----------------------------------------------------------------------------- the command line's conventions


@pytest.mark.parametrize("broken,line", [
    ("b = [60.0, 1.0", 12),                 # `]` forgotten: TOML reads on to `c = 45.0` (line 13)
    ("b = [60.0, 1.0  # coupler\n\n# x", 12),  # a comment, a blank line and a comment line after it
    ("b = [\n  60.0\n  1.0\n]", 13),        # a ',' missing after 60.0 (line 13); TOML stops at 1.0
])
def test_an_unclosed_array_is_refused_on_its_own_line(tmp_path, broken, line):
    """tomllib finds a forgotten `]` only at the next value, a line or more later ("Unclosed array
    (at line 13, column 1)" for line 12): the message names the line where the `]` or `,` is
    missing (the line written broken here)."""
    f = four_bar(tmp_path, "b = 60.0     # coupler", broken)
    assert FOUR_BAR.splitlines()[11].startswith("b = 60.0")  # line 12 of the file
    refused(cli("check", f), f"m.toml:{line}: not valid TOML", f"missing on line {line}")


def test_every_unknown_option_gets_its_commands_usage_and_a_suggestion():
    """An unknown option is refused by its sub-command (its usage, exit 2) with the closest option
    it has, or the commands that have it; a mistyped choice gets the closest choice."""
    import argparse

    from jaxlink.cli import build_parser

    rc, err = cli("kinematics", "four-bar", "--rmp", "60")
    refused((rc, err), "usage: jaxlink kinematics", "unrecognized arguments: --rmp 60", "did you mean '--rpm'?")
    refused(cli("kinematics", "four-bar", "--rmp=60"), "did you mean '--rpm'?")
    refused(cli("check", "four-bar", "--rpm", "60"), "usage: jaxlink check", "--rpm is an option of kinematics")
    refused(cli("kinematics", "four-bar", "--change-points", "smoth"), "did you mean 'smooth'?")
    # every option of every sub-command, with its second and third letters swapped
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    for command, p in sub.choices.items():
        for flag in (s for a in p._actions for s in a.option_strings if s.startswith("--") and len(s) > 5):
            typo = flag[:3] + flag[4] + flag[3] + flag[5:]
            if any(typo in a.option_strings for a in p._actions):
                continue
            rc, err = cli(command, "x", typo, "1")
            assert rc == 2 and f"usage: jaxlink {command}" in err and f"did you mean '{flag}'?" in err, (command, err)


@pytest.mark.parametrize("args,option,formats", [
    (("kinematics", "four-bar", "--csv", "out.xlsx"), "--csv out.xlsx", ".csv"),
    (("kinematics", "four-bar", "--json", "x.txt"), "--json x.txt", ".json"),
    (("kinematics", "four-bar", "--plot", "x.docx"), "--plot x.docx", ".png"),
    (("kinematics", "four-bar", "--export", "x.png"), "--export x.png", ".dxf"),
    (("reactions", "slider-crank-mass", "--csv", "x.txt"), "--csv x.txt", ".csv"),
    (("reactions", "slider-crank-mass", "--plot", "x"), "--plot x", ".png"),
    (("simulate", "sinker-cam", "--csv", "x.xls"), "--csv x.xls", ".csv"),
    (("jamming", "sinker-cam", "--out", "x.txt"), "--out x.txt", ".json"),
    (("optimize", "sewing-feed-opt", "--method", "montecarlo", "--out", "r.txt"), "--out r.txt", ".json"),
])
def test_an_unknown_output_extension_is_refused_before_any_work(tmp_path, monkeypatch, args, option, formats):
    monkeypatch.chdir(tmp_path)
    refused(cli(*args), option, "unknown format", formats)
    assert list(tmp_path.iterdir()) == []


def test_scenes_shows_each_path_and_copies_a_scene_to_edit(tmp_path, monkeypatch):
    """`jaxlink scenes` prints each scene's file under its name; `--copy NAME [DEST]` writes that
    file's bytes (to NAME.toml here, into a folder, or to a .toml path), refuses to overwrite
    without --force, and suggests the scene a mistyped name was meant to be."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["scenes"]) == 0
    lines = out.getvalue().splitlines()
    for path in sorted(SCENES.glob("*.toml")):
        k = next(i for i, line in enumerate(lines) if line.split()[0] == path.stem)
        assert lines[k + 1].strip() == str(path)
    monkeypatch.chdir(tmp_path)
    base = (SCENES / "four-bar.toml").read_bytes()
    assert cli("scenes", "--copy", "four-bar") == (0, "")
    assert (tmp_path / "four-bar.toml").read_bytes() == base
    (tmp_path / "four-bar.toml").write_text("mine", encoding="utf-8")
    refused(cli("scenes", "--copy", "four-bar"), "four-bar.toml exists", "--force")
    assert (tmp_path / "four-bar.toml").read_text(encoding="utf-8") == "mine"  # not overwritten
    assert cli("scenes", "--copy", "four-bar", "--force")[0] == 0
    assert (tmp_path / "four-bar.toml").read_bytes() == base
    (tmp_path / "d").mkdir()
    assert cli("scenes", "--copy", "slider-crank", "d")[0] == 0
    assert (tmp_path / "d" / "slider-crank.toml").read_bytes() == (SCENES / "slider-crank.toml").read_bytes()
    assert cli("scenes", "--copy", "whitworth", "mine.toml")[0] == 0
    assert (tmp_path / "mine.toml").read_bytes() == (SCENES / "whitworth.toml").read_bytes()
    refused(cli("scenes", "--copy", "four-bra"), "'four-bra' is not a built-in scene", "did you mean 'four-bar'?")
    refused(cli("scenes", "--copy", "four-bar", "x.txt"), "--copy x.txt", ".toml")
    assert cli("check", "mine.toml")[0] == 0  # the copy is a file to give as FILE


def test_optimize_without_method_runs_the_documented_default(monkeypatch):
    """No --method: the gradient search, the one docs/methods/optimize.md lets size itself (no
    budget needed), said so on the summary's first line. The search itself is replaced by a
    stub (the gradient search compiles for about 25 s); every other step is the command's."""
    import types

    import jaxlink.optimize as jo

    called = []

    def fake_run(ev, method, **kw):
        called.append(method)
        return types.SimpleNamespace(method=method, parameters={"l2": 1.0}, value=0.5, metrics={}, fallback=0,
                                     evaluations=1, designs=1, infeasible_fraction=0.0, wall_s=0.0,
                                     search_wall_s=0.0, compile_s=0.0, extra={}, best_file=None)

    monkeypatch.setattr(jo, "run", fake_run)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["optimize", "sewing-feed-opt", "--progress", "off"]) == 0
        assert main(["optimize", "sewing-feed-opt", "--method", "montecarlo", "--progress", "off"]) == 0
    refused(cli("optimize", "sewing-feed-opt", "--uniform", "coordinate"), "--uniform coordinate", "--method uniform")
    assert called == ["gradient", "montecarlo"]
    heads = [line for line in out.getvalue().splitlines() if line.startswith("method")]
    assert heads == ["method      gradient (the default; --method uniform or montecarlo for the others)",
                     "method      montecarlo"]
    text = (pathlib.Path(__file__).resolve().parent.parent / "docs" / "reference" / "cli.md").read_text()
    assert "| `--method` | `uniform`, `montecarlo`, `gradient` | `gradient` |" in text


def test_ctrl_c_in_optimize_says_what_was_saved_and_how_to_resume(tmp_path):
    """SIGINT to `jaxlink optimize --out r.json` after its first checkpoint: exit 130, the best so
    far printed and saved (r.json `"complete": false`, `"stopped_by": "interrupted"`, r.best.toml),
    the state in r.state.npz, and standard error says so and how --resume continues. Before: one
    line, "interrupted", and r.json as of the last checkpoint (up to 2 s older)."""
    import json
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "r.json"
    cmd = [sys.executable, "-m", "jaxlink.cli", "optimize", "sewing-feed-opt", "--method", "montecarlo",
           "--budget", "100000000", "--chunk", "4", "--seed", "1", "--progress", "off", "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while not out.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert out.exists(), proc.stderr.read() if proc.poll() is not None else "no checkpoint in 300 s"
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert doc["complete"] is False and doc["stopped_by"] == "interrupted"
    assert 0 < doc["evaluations"] < 100000000 and (tmp_path / "r.state.npz").is_file()
    assert doc["best_file"] == str(tmp_path / "r.best.toml") and (tmp_path / "r.best.toml").is_file()
    log = [json.loads(line) for line in (tmp_path / "r.log.jsonl").read_text().splitlines()]
    assert log[-1]["evaluations"] == doc["evaluations"]  # the state saved is the last chunk's
    best = ", ".join(f"{k} = {v:.6g}" for k, v in doc["best"]["parameters"].items())
    assert f"best        {best}" in stdout and "stopped     interrupted (Ctrl-C)" in stdout
    for words in (f"interrupted after {doc['evaluations']} evaluations", f"saved the best so far in {out}",
                  "r.best.toml", "r.state.npz", "--resume"):
        assert words in stderr, (words, stderr)


def test_ctrl_c_in_optimize_without_out_prints_the_best_so_far(monkeypatch):
    """Without --out a Ctrl-C (here raised by the search's third chunk) ends the search as its end
    would: the best so far printed, the command says nothing was written and how --out and --resume
    keep a search, exit 130."""
    import jaxlink.optimize.searches.runner as runner

    real = runner.searcher

    def interrupted_after_two(*a, **kw):
        search = real(*a, **kw)
        step, calls = search.step, [0]

        def stepping(st):
            calls[0] += 1
            if calls[0] == 3:
                raise KeyboardInterrupt
            return step(st)

        search.step = stepping
        return search

    monkeypatch.setattr(runner, "searcher", interrupted_after_two)
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        rc = main(["optimize", "sewing-feed-opt", "--method", "montecarlo", "--budget", "64", "--chunk", "4",
                   "--progress", "off"])
    assert rc == 130, err.getvalue()
    assert "evaluations 8 (8 designs" in out.getvalue() and "best        l2 = " in out.getvalue()
    assert "interrupted after 8 evaluations: the best design so far is printed above; nothing was written" \
        in err.getvalue() and "--resume" in err.getvalue()
