"""The examples and reference tables of docs/ are checked against the code, so that the
documentation cannot silently go stale.

- Every ```toml block of docs/reference/file-format.md whose first line is `# example: NAME` is
  a complete file. A good one must load (`jaxlink.loads`; a cam-follower scene with the scene
  loader), pass the checks `jaxlink optimize` makes of its `[optimize]` table, and assemble at
  its `[input] start`. A bad one (second line
  `# error: TEXT`) must raise `MechanismError` with TEXT in the message.
- Every ```python block of docs/ whose first line is `# example: NAME` is run, with float64
  enabled, in a fresh namespace and a temporary working directory.
- Every exported name of `jaxlink`, `jaxlink.optimize` and `jaxlink.cam` is named in
  docs/reference/python-api.md; every table and key the readers accept in
  docs/reference/file-format.md; every command and option of the command line in
  docs/reference/cli.md.
"""

from __future__ import annotations

import inspect
import pathlib
import re

import jax
import numpy as np
import pytest

import jaxlink as jl

jax.config.update("jax_enable_x64", True)

DOCS = pathlib.Path(__file__).resolve().parent.parent / "docs"
FILE_FORMAT = DOCS / "reference" / "file-format.md"
PYTHON_API = DOCS / "reference" / "python-api.md"
CLI = DOCS / "reference" / "cli.md"

# examples that cannot pass yet, with the reason (strict: an example that passes fails the test,
# so that the mark is removed)
XFAIL: dict[str, str] = {}

_FENCE = re.compile(r"^```(\w*)[^\n]*\n(.*?)^```[ \t]*$", re.S | re.M)
_NAME = re.compile(r"#\s*example:\s*(\S+)\s*$")
_ERROR = re.compile(r"#\s*error:\s*(.+?)\s*$")


def _examples(paths, lang):
    """(name, code, where, expected error or None) of every marked block of `lang`."""
    out = []
    for path in paths:
        text = path.read_text(encoding="utf-8")
        for m in _FENCE.finditer(text):
            if m.group(1) != lang:
                continue
            lines = m.group(2).splitlines()
            name = _NAME.match(lines[0]) if lines else None
            if not name:
                continue
            error = _ERROR.match(lines[1]) if len(lines) > 1 else None
            line = text.count("\n", 0, m.start()) + 2
            where = f"{path.relative_to(DOCS.parent)}:{line}"
            out.append((name.group(1), m.group(2), where, error.group(1) if error else None))
    return out


TOML_EXAMPLES = _examples([FILE_FORMAT], "toml")
PYTHON_EXAMPLES = _examples(sorted(DOCS.rglob("*.md")), "python")


def test_examples_are_found_and_named_uniquely():
    names = [e[0] for e in TOML_EXAMPLES + PYTHON_EXAMPLES]
    assert len(names) == len(set(names)), sorted(n for n in names if names.count(n) > 1)
    assert len([e for e in TOML_EXAMPLES if e[3] is None]) >= 10
    assert len([e for e in TOML_EXAMPLES if e[3] is not None]) >= 5
    assert len(PYTHON_EXAMPLES) >= 15


# ----------------------------------------------------------------------------- file examples


def _check_file(name: str, text: str):
    """Read a file as the commands would; returns the mechanism (None for a cam-follower scene)."""
    if re.search(r'^kind\s*=\s*"cam-follower"', text, re.M):
        from jaxlink.cam.scene import loads_scene

        loads_scene(text, file=f"{name}.toml")
        return None
    mech = jl.loads(text, file=f"{name}.toml")   # every table but [optimize]
    if "optimize" in mech.tables:
        from jaxlink.optimize import OBJECTIVES, problem_from

        OBJECTIVES.build(problem_from(mech))
    if "study" in mech.tables:
        from jaxlink.study import read_study

        read_study(mech)
    return mech


@pytest.mark.parametrize("name,text,where,error", TOML_EXAMPLES, ids=[e[0] for e in TOML_EXAMPLES])
def test_file_format_example(name, text, where, error):
    if error is not None:
        with pytest.raises(jl.MechanismError) as info:
            _check_file(name, text)
        assert error in str(info.value), f"{where}: the message is {str(info.value)!r}"
        return
    mech = _check_file(name, text)
    if mech is None:
        return
    # the guesses hold at [input] start: the file assembles there
    sol = jl.solve(mech, np.array([mech.input_start]))
    assert bool(sol.converged[0]), f"{where}: {jl.RESULTS.name(sol.result[0])} at [input] start"


def _solve_file(text, degrees):
    mech = jl.loads(text)
    sol = jl.solve(mech, np.deg2rad(np.asarray(degrees, dtype=float)))
    return mech, sol


def test_the_guesses_choose_the_branch():
    """The open and the crossed four-bar of section 11 differ only in their guesses: the coupler
    joint B lies on one side of the diagonal A -> B0 in one and on the other side in the other,
    at every crank angle (the two assembly branches)."""
    files = {name: text for name, text, _, _ in TOML_EXAMPLES}
    degrees = np.arange(0.0, 360.0, 10.0)
    phi = np.deg2rad(degrees)
    sides = []
    for name in ("four-bar", "four-bar-crossed"):
        mech, sol = _solve_file(files[name], degrees)
        assert bool(sol.converged.all()), name
        p = dict(zip(mech.parameter_names, mech.parameters))
        q = np.asarray(sol.q)
        diag = np.stack([p["d"] - p["a"] * np.cos(phi), -p["a"] * np.sin(phi)], axis=1)   # B0 - A
        link = np.stack([np.cos(q[:, 0]), np.sin(q[:, 0])], axis=1)                         # along A -> B
        sides.append(diag[:, 0] * link[:, 1] - diag[:, 1] * link[:, 0])
    assert np.all(sides[0] > 0) and np.all(sides[1] < 0)


def test_input_start_example_reaches_only_its_arc():
    """The limited crank of section 5 cannot be assembled at 0° (d − a < b − c) but is from its
    start at 90°, over the arc where |A − B0| ≥ b − c."""
    files = {name: text for name, text, _, _ in TOML_EXAMPLES}
    degrees = np.arange(0.0, 360.0, 5.0)
    mech, sol = _solve_file(files["input-start"], degrees)
    p = dict(zip(mech.parameter_names, mech.parameters))
    phi = np.deg2rad(degrees)
    reach = np.hypot(p["a"] * np.cos(phi) - p["d"], p["a"] * np.sin(phi))   # |A - B0|
    reachable = reach > p["b"] - p["c"] + 1e-6
    conv = np.asarray(sol.converged)
    assert not conv[0] and np.asarray(sol.result)[0] == jl.RESULTS.cannot_assemble
    assert np.array_equal(conv, reachable)


def test_a_loop_may_start_at_any_vertex():
    """The needle six-bar with its second loop written from the needle B and walked backwards has
    the same motion as the built-in scene `needle-arachne`, whose second loop starts at C0."""
    files = {name: text for name, text, _, _ in TOML_EXAMPLES}
    degrees = np.arange(0.0, 360.0, 10.0)
    mine, sol = _solve_file(files["loop-any-start"], degrees)
    scene = jl.load("needle-arachne")
    ref = jl.solve(scene, np.deg2rad(degrees))
    assert bool(sol.converged.all()) and bool(ref.converged.all())
    assert mine.unknown_names == scene.unknown_names
    np.testing.assert_allclose(np.asarray(sol.q), np.asarray(ref.q), atol=1e-9)


def test_a_loop_is_drawn_where_the_mechanism_puts_it():
    """The drawing of the loop written from B (section 7) has the same joints as the drawing of the
    scene: both loops are placed where the linkage is, whatever vertex a loop starts at."""
    drawing = pytest.importorskip("jaxlink.report.drawing")
    files = {name: text for name, text, _, _ in TOML_EXAMPLES}
    degrees = np.arange(0.0, 360.0, 10.0)
    joints = []
    for mech in (jl.loads(files["loop-any-start"]), jl.load("needle-arachne")):
        phis = np.deg2rad(degrees)
        sol = jl.solve(mech, phis)
        d = drawing.drawing(mech, np.asarray(sol.q), phis, mech.parameters, np.asarray(sol.converged))
        joints.append(np.asarray(d.joints))                         # (N, J, 2)
    mine, ref = joints
    assert mine.shape == ref.shape and ref.shape[1] >= 5           # A0, A, C, C0, D, B
    for k in range(ref.shape[1]):                                  # every joint of one is one of the other
        dist = np.linalg.norm(mine - ref[:, k:k + 1], axis=-1).max(axis=0)
        assert dist.min() < 1e-9, f"joint {k} of the scene is not in the drawing of the example"


# ----------------------------------------------------------------------------- Python examples


@pytest.mark.parametrize(
    "name,code,where",
    [pytest.param(n, c, w, marks=[pytest.mark.xfail(reason=XFAIL[n], strict=True)] if n in XFAIL else [])
     for n, c, w, _ in PYTHON_EXAMPLES],
    ids=[e[0] for e in PYTHON_EXAMPLES],
)
def test_python_example(name, code, where, tmp_path, monkeypatch, capsys):
    from jaxlink.optimize import OBJECTIVES

    monkeypatch.chdir(tmp_path)
    # an example may register an objective: it is forgotten after the example (the built-in ones
    # are registered first, so that the copies below hold them)
    assert "points" in OBJECTIVES
    monkeypatch.setattr(OBJECTIVES, "_factories", dict(OBJECTIVES._factories))
    monkeypatch.setattr(OBJECTIVES, "_keys", dict(OBJECTIVES._keys))
    exec(compile(code, where, "exec"), {"__name__": f"docs_example_{name}"})


# ----------------------------------------------------------------------------- completeness


def _public(module):
    # a package that imports its names when first used (`jaxlink.optimize`) lists them in `__all__`
    names = {n for n, v in vars(module).items() if not inspect.ismodule(v)} | set(getattr(module, "__all__", ()))
    return sorted(n for n in names if not n.startswith("_"))


@pytest.mark.parametrize("module", ["jaxlink", "jaxlink.optimize", "jaxlink.cam", "jaxlink.study", "jaxlink.synthesis"])
def test_python_api_names_every_export(module):
    import importlib

    text = PYTHON_API.read_text(encoding="utf-8")
    mod = importlib.import_module(module)
    missing = [n for n in _public(mod) if not re.search(r"`[^`\n]*\b" + re.escape(n) + r"\b[^`\n]*`", text)]
    assert not missing, f"docs/reference/python-api.md does not name {module}.{', '.join(missing)}"


def test_file_format_names_every_table_and_key():
    from jaxlink.cam import scene
    from jaxlink.files import bodies, reader
    from jaxlink.optimize import OBJECTIVES, problem

    text = FILE_FORMAT.read_text(encoding="utf-8")
    expected = {f"[{t}" for t in reader.KNOWN_TABLES}
    expected |= set(bodies.BODY_KEYS) | set(bodies.JOINT_KEYS) | set(bodies.ENV_KEYS)
    expected |= {k for keys in bodies.LOAD_KEYS.values() for k in keys} | set(bodies.LOAD_KEYS)
    expected |= set(problem.KNOWN_KEYS) | OBJECTIVES.known_keys() | set(OBJECTIVES)
    expected |= {f"[{t}" for t in scene._SCHEMA} | {k for keys in scene._SCHEMA.values() for k in keys}
    expected |= set(scene._GEOMETRY_KEYS)
    expected |= set(reader.LENGTH_UNITS) | set(reader.ANGLE_UNITS)
    expected |= set(reader.MECHANISM_KEYS) | set(reader.INPUT_KEYS) | set(reader.PARAMETER_KEYS)
    expected |= set(problem.PLACEMENT_KEYS)
    from jaxlink.files import sketch, sketch_bodies

    expected |= sketch._SKETCH_KEYS | sketch._INPUT_KEYS | sketch._SLIDER_KEYS | sketch_bodies._MASS_KEYS
    from jaxlink.study import inputs as study_inputs

    expected |= set(study_inputs.KNOWN_KEYS) | set(study_inputs.TOLERANCE_KEYS) | set(study_inputs.METRICS)
    expected |= set(study_inputs.DISTRIBUTIONS) | set(study_inputs.METHODS)
    missing = sorted(k for k in expected if f"`{k}" not in text and f'"{k}"' not in text)
    assert not missing, f"docs/reference/file-format.md does not document {missing}"


def test_cli_reference_names_every_command_and_option():
    import argparse

    from jaxlink.cli import build_parser

    text = CLI.read_text(encoding="utf-8")
    sections = re.split(r"^## ", text, flags=re.M)
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    missing = []
    for command, p in sub.choices.items():
        section = next((s for s in sections if s.startswith(f"`jaxlink {command}`")), None)
        if section is None:
            missing.append(f"## `jaxlink {command}`")
            continue
        for action in p._actions:
            for opt in action.option_strings:
                if opt.startswith("--") and opt != "--help" and f"`{opt}" not in section:
                    missing.append(f"{command} {opt}")
            if not action.option_strings and action.dest not in ("help",):
                if action.metavar and action.metavar not in section:
                    missing.append(f"{command} {action.metavar}")
    assert not missing, f"docs/reference/cli.md does not document {missing}"


# ----------------------------------------------------------------------------- links


def _slug(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(path: pathlib.Path) -> set:
    text = re.sub(r"^```.*?^```", "", path.read_text(encoding="utf-8"), flags=re.S | re.M)
    return {_slug(m.group(1)) for m in re.finditer(r"^#+\s+(.+?)\s*$", text, re.M)}


def test_links_between_docs_resolve():
    """Every relative link of docs/ points to an existing file, and to an existing heading of a
    markdown file when it names one."""
    broken = []
    for path in sorted(DOCS.rglob("*.md")):
        text = re.sub(r"^```.*?^```", "", path.read_text(encoding="utf-8"), flags=re.S | re.M)
        for m in re.finditer(r"\]\(([^)\s]+)\)", text):
            target = m.group(1)
            if re.match(r"[a-z]+:", target):
                continue
            file, _, anchor = target.partition("#")
            dest = (path.parent / file).resolve() if file else path
            if not dest.exists():
                broken.append(f"{path.relative_to(DOCS.parent)}: {target}")
            elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
                broken.append(f"{path.relative_to(DOCS.parent)}: {target} (no such heading)")
    assert not broken, broken
