"""Property-based tests (hypothesis) over the inputs: the expression grammar, the file reader
(mutated built-in scene files), the command options and the `[optimize]` keys. Each asserts
only the allowed outcomes: solved with finite values (exit 0), refused with a message on standard
error naming what was wrong (a `MechanismError`, exit 2, never "internal error" or a traceback),
or "cannot assemble" (exit 1, the warning on standard error).

The number of examples is small in CI; set `JAXLINK_FUZZ_EXAMPLES` for a longer run on demand,
e.g. `JAXLINK_FUZZ_EXAMPLES=2000 python -m pytest -n 0 tests/test_fuzz_inputs.py` (the CLI tests
run a tenth of that, at least the CI number).
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import pathlib
import re

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import jaxlink as jl
from jaxlink.cam.scene import loads_scene
from jaxlink.cli import main
from jaxlink.files import expr
from jaxlink.files.reader import loads
from jaxlink.optimize import problem_from

SCENES = pathlib.Path(__file__).resolve().parent.parent / "jaxlink" / "scenes"
LINKAGES = ("four-bar", "slider-crank", "slider-crank-mass", "sewing-feed", "needle-dwell", "sewing-feed-opt")
TEXTS = {n: (SCENES / f"{n}.toml").read_text(encoding="utf-8") for n in (*LINKAGES, "sinker-cam")}

FUZZ = int(os.environ.get("JAXLINK_FUZZ_EXAMPLES", "0"))
FAST = settings(max_examples=FUZZ or 25, deadline=None, derandomize=not FUZZ,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
SLOW = settings(max_examples=max(FUZZ // 10, 4), deadline=None, derandomize=not FUZZ,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def cli(*argv: str) -> tuple[int, str, str]:
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            rc = main(list(argv))
        except SystemExit as exc:
            rc = int(exc.code or 0)
    return rc, out.getvalue(), err.getvalue()


def allowed(rc: int, err: str) -> None:
    assert "internal error" not in err and "Traceback" not in err, err
    assert rc in (0, 1, 2), (rc, err)
    if rc == 2:
        assert "error:" in err, err
    if rc == 1:
        assert err.strip(), "exit 1 without a message"


# ----------------------------------------------------------------------------- expressions

NAMES = ("a", "b", "c", "d", "cx", "cy", "phi2", "phi3", "phi4", "pi", "sin", "q")
ATOMS = st.one_of(st.sampled_from(NAMES), st.sampled_from(("0", "1", "2.5", "1e3", "1e400", "9" * 30, ".5", "1e")))


def _exprs(max_leaves=12):
    return st.recursive(
        ATOMS,
        lambda inner: st.one_of(
            st.tuples(inner, st.sampled_from("+-*/"), inner).map(lambda t: f"{t[0]} {t[1]} {t[2]}"),
            inner.map(lambda e: f"({e})"),
            inner.map(lambda e: f"-{e}"),
            st.tuples(st.sampled_from(("sin", "cos", "sqrt", "atan2", "foo")), inner).map(lambda t: f"{t[0]}({t[1]})"),
        ),
        max_leaves=max_leaves,
    )


TERMS = st.one_of(
    st.tuples(_exprs(), _exprs()).map(lambda t: f"{t[0]} @ {t[1]}"),
    st.tuples(_exprs(), _exprs()).map(lambda t: f"({t[0]}, {t[1]})"),
    st.text(alphabet="ab()+-*/@,. 0123456789e", max_size=40),
    st.integers(1, 4000).map(lambda n: "(" * n + "cx" + ")" * n + " @ phi3"),
    st.integers(1, 4000).map(lambda n: " + ".join(["cx"] * n) + " @ phi3"),
)


@FAST
@given(term=TERMS)
def test_expression_parses_or_is_a_syntax_error(term):
    try:
        t = expr.parse_term(term)
    except expr.ExprSyntaxError as exc:
        assert "syntax error at column" in str(exc)
        return
    assert expr.depth(t.nodes()[0]) <= expr.MAX_DEPTH


@FAST
@given(term=TERMS)
def test_a_point_of_any_expression_loads_or_is_refused_on_its_line(term):
    text = TEXTS["four-bar"].replace('"cx @ phi3"', '"' + term.replace("\\", "") + '"')
    try:
        mech = loads(text, file="m.toml")
    except jl.MechanismError as exc:
        assert exc.file == "m.toml" and (exc.line is not None or exc.key), str(exc)
        return
    assert mech.point_names == ("P",)


# ----------------------------------------------------------------------------- the file reader

VALUES = st.one_of(
    st.integers(-10**500, 10**500).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(lambda x: repr(x).replace("inf", "inf").replace("nan", "nan")),
    st.sampled_from(('"mm"', '"deg"', '"x"', "true", "[]", "[1, 2]", "{}", "{ value = 1 }", '"a @ phi2"',
                     '["a @ phi2"]', "[[[[1]]]]", "1979-05-27", "-0.0", "1e-300", "1e300", "0")),
)


@st.composite
def mutated(draw, names=LINKAGES):
    name = draw(st.sampled_from(names))
    lines = TEXTS[name].splitlines()
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(lines) - 1))
        how = draw(st.sampled_from(("value", "value", "delete", "duplicate", "key", "bytes")))
        line = lines[i]
        if how == "value" and "=" in line:
            lines[i] = line.split("=", 1)[0] + "= " + draw(VALUES)
        elif how == "delete":
            del lines[i]
        elif how == "duplicate":
            lines.insert(i, line)
        elif how == "key" and "=" in line:
            lines[i] = draw(st.sampled_from(("x", "phi3", "a", "1a", "name", "pi"))) + " =" + line.split("=", 1)[1]
        elif how == "bytes":
            lines[i] = line + draw(st.sampled_from((" # 90°", " \x00", "[", "]", '"', " = 1")))
        if not lines:
            lines = [""]
    return name, "\n".join(lines) + "\n"


@FAST
@given(case=mutated())
def test_mutated_linkage_files_load_or_are_refused_naming_the_file(case):
    _, text = case
    try:
        mech = loads(text, file="m.toml")
    except jl.MechanismError as exc:
        assert exc.file == "m.toml", str(exc)
        return
    import numpy as np

    assert np.all(np.isfinite(mech.parameters)) and np.all(np.isfinite(mech.guess))
    if "optimize" in mech.tables:
        try:
            problem_from(mech)
        except jl.MechanismError as exc:
            assert exc.file == "m.toml" and exc.key and exc.key.startswith("optimize"), str(exc)


@FAST
@given(case=mutated(("sinker-cam",)))
def test_mutated_cam_scenes_load_or_are_refused_naming_the_file(case):
    _, text = case
    try:
        loads_scene(text, file="s.toml")
    except jl.MechanismError as exc:
        assert exc.file == "s.toml" or str(exc).startswith("--set"), str(exc)


@SLOW
@given(case=mutated(("four-bar", "slider-crank-mass")))
def test_check_of_mutated_files(tmp_path_factory, case):
    _, text = case
    path = tmp_path_factory.mktemp("m") / "m.toml"
    path.write_text(text, encoding="utf-8")
    rc, _, err = cli("check", str(path))
    allowed(rc, err)
    if rc == 2:
        assert str(path) in err, err


# ----------------------------------------------------------------------------- [optimize] keys

OPT_KEYS = ("samples", "report_samples", "starts", "presample", "iterations", "chunk", "budget", "seed",
            "memory", "al_rho", "al_every", "stroke", "sign_changes", "start", "circuits", "objective", "point")


@FAST
@given(key=st.sampled_from(OPT_KEYS), value=VALUES, scene=st.sampled_from(("sewing-feed-opt", "needle-dwell")))
def test_optimize_keys_are_checked_naming_the_file_and_key(key, value, scene):
    text = re.sub(rf"^{key} = .*$", "", TEXTS[scene], flags=re.M)
    text = text.replace("[optimize]\n", f"[optimize]\n{key} = {value}\n")
    try:
        mech = loads(text, file="o.toml")
        problem_from(mech)
    except jl.MechanismError as exc:
        assert exc.file == "o.toml", str(exc)


# ----------------------------------------------------------------------------- command options

NUMBER_TEXT = st.one_of(
    st.sampled_from(("nan", "inf", "-inf", "1e300", "-1e300", "1e-300", "0", "-0", "x", "", "1e9", "400")),
    st.floats(-1e4, 1e4, allow_nan=False).map(repr),
)


@st.composite
def kinematics_args(draw):
    args = ["kinematics", draw(st.sampled_from(("four-bar", "slider-crank")))]
    step = draw(st.one_of(st.none(), NUMBER_TEXT))
    count = draw(st.one_of(st.sampled_from(("1", "3", "0", "-2", "1e20", str(10**20))), st.just("4")))
    args += ["--count", count]
    if step is not None:
        args.append(f"--step={step}")
    for option in ("--start", "--rpm", "--omega"):
        if draw(st.booleans()):
            args.append(f"{option}={draw(NUMBER_TEXT)}")
    if draw(st.booleans()):
        args.append("--outputs=" + draw(st.sampled_from(("position", "rates", "velocity,x", ""))))
    if draw(st.booleans()):
        args += ["--set", draw(st.sampled_from(("a=-5", "a=1e-300", "a=1e300", "zz=1", "a", "a=[1]", "h2=10")))]
    return args


@SLOW
@given(args=kinematics_args())
def test_kinematics_options(tmp_path_factory, args):
    out = tmp_path_factory.mktemp("k") / "k.csv"
    rc, _, err = cli(*args, "--csv", str(out))
    allowed(rc, err)
    if rc == 2:
        assert "--" in err or "argument" in err or "FILE" in err or ".toml" in err, err
    if rc in (0, 1):
        rows = list(csv.DictReader(open(out)))
        for row in rows:
            if row["converged"] == "1":
                assert all(math.isfinite(float(v)) for k, v in row.items() if k not in ("result", "converged")), row


@SLOW
@given(option=st.sampled_from(("--seed", "--chunk", "--budget", "--starts")),
       value=st.sampled_from(("-1", "0", "1e3", "x", str(2**40), str(10**20))))
def test_optimize_options_are_refused_naming_the_option(option, value):
    rc, _, err = cli("optimize", "sewing-feed-opt", "--method", "montecarlo", f"{option}={value}", "--budget=2"
                     if option != "--budget" else "--seed=0")
    allowed(rc, err)
    if rc == 2:
        assert option in err, err


@pytest.mark.parametrize("cmd", ["simulate", "jamming"])
def test_cam_commands_refuse_bad_values(cmd):
    for extra in (["--set", "C=nan"], ["--set", "f=[]"], ["--set", "m=-1"], ["--set", "C=" + "9" * 400]):
        rc, _, err = cli(cmd, "sinker-cam", *extra)
        allowed(rc, err)
        assert rc == 2, err
