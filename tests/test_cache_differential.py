"""A cache never changes an answer (issue 23): every command that writes numbers gives the same
bytes with a cold cache, a warm cache and the cache off, and after changing one thing at a time
(a guess — the other assembly branch —, `[input] start`, a parameter, a constant in a loop,
`--set`, the input range, `--outputs`, the speed, the dtype) a warm run equals a cache-off run.

Three processes run the same list of commands in-process (`jaxlink.cli.main`), each writing what
the command printed and the files it wrote: *cold* (an empty cache directory, the commands in
order), *warm* (the same directory, the commands in reverse order, so a command meets the stored
traces of the ones that follow it in the list) and *off* (`JAXLINK_CACHE_DIR=""`). The lists hold
pairs of files of one structure that differ only in numbers: today's cache bug (a stored trace
keyed by the structure alone, with the guesses baked in) made the second of a pair print the
first's branch. `test_a_wrong_key_is_caught` runs the same comparison with the key deliberately
blind to the arguments' structure and asserts that it fails — the test can fail (for the table
of `kinematics` and for every stored program of `check`: the file's check at its guesses, the
start, the turn, the transmission angles, the outputs' jets)."""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

import jaxlink
from jaxlink.optimize import Evaluator, PathData, problem_from
from jaxlink.optimize.objectives import OBJECTIVES
from jaxlink.report.kinematics import kinematics_table

pytestmark = pytest.mark.xdist_group("cache_differential")

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCENES = ROOT / "jaxlink" / "scenes"
BENCH = ROOT / "benchmarks" / "fourbar-path" / "fourbar_path_benchmarks.json"
sys.path.insert(0, str(ROOT / "experiments" / "fourbar_plain"))
from generate import plain_text  # noqa: E402

# runs (name, argv) pairs in one process; argv's "{OUT}" is the output folder. `BLIND` makes the
# stored traces' key blind to the arguments' tree structure (a deliberately wrong key).
RUNNER = r"""
import contextlib, io, json, os, pathlib, sys
if os.environ.get("BLIND"):
    import jaxlink.cache as c
    c._tree_key = lambda treedef: "blind"
from jaxlink.cli import main
out = pathlib.Path(sys.argv[1])
for name, argv in json.loads(sys.argv[2]):
    argv = [a.replace("{OUT}", str(out)) for a in argv]
    so, se = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(so), contextlib.redirect_stderr(se):
        code = main(argv)
    text = f"exit {code}\n{so.getvalue()}\n--- stderr\n{se.getvalue()}"
    # a search's times are not results: its `evaluations` line and the JSON's timing keys go
    text = "\n".join(line for line in text.splitlines() if not line.startswith("evaluations "))
    (out / f"{name}.txt").write_text(text.replace(str(out), "{OUT}"))
for path in out.glob("*.json"):
    doc = json.loads(path.read_text())
    for key in ("wall_s", "search_wall_s", "compile_s", "trace"):
        doc.pop(key, None)
    path.write_text(json.dumps(doc, indent=1).replace(str(out), "{OUT}"))
for path in out.glob("*.*"):
    if not path.name.endswith((".txt", ".csv", ".json", ".best.toml")):
        path.unlink()
"""


def _variants(tmp_path: pathlib.Path) -> dict:
    """Files of one structure that differ in one number each (the four-bar scene's structure, and
    one `[input] start`), written to `tmp_path`."""
    base = (SCENES / "four-bar.toml").read_text()
    files = {
        "A": base,
        # the other assembly branch: only the guesses differ
        "B": base.replace("phi3 = 30.0", "phi3 = -30.0").replace("phi4 = 80.0", "phi4 = -80.0"),
        # another coupler length: only a parameter differs
        "C": base.replace("b = 60.0", "b = 58.0"),
    }
    # another [input] start (the guesses hold at 40 deg: the same branch as A, reached another way)
    files["D"] = base.replace('name = "phi2"\n', 'name = "phi2"\nstart = 40.0\n').replace(
        "phi3 = 30.0", "phi3 = 15.0").replace("phi4 = 80.0", "phi4 = 75.0")
    # a number inside the loops (the frame turned by 5 deg): part of the structure, not a parameter
    files["E"] = base.replace('"-d @ 0"', '"-d @ 5"')
    # a plain four-bar path-synthesis file (the literature case yu1): its search and its best file
    files["yu1"] = plain_text("yu1", json.loads(BENCH.read_text())["yu1"]["target"], angle_unit="deg")
    paths = {}
    for k, text in files.items():
        assert k in ("A", "yu1") or text != base
        paths[k] = tmp_path / f"{k}.toml"
        paths[k].write_text(text)
    return paths


def _commands(paths: dict) -> list:
    cmds = []
    for k, path in paths.items():
        if k == "yu1":
            continue
        if k in "ABE":  # `check` of C and D (a parameter, the input start) adds nothing to kin-C, kin-D
            cmds.append((f"check-{k}", ["check", str(path)]))
        cmds.append((f"kin-{k}", ["kinematics", str(path), "--count", "9", "--step", "40",
                                  "--csv", f"{{OUT}}/kin-{k}.csv"]))
    a = str(paths["A"])
    cmds += [
        ("set-b", ["kinematics", a, "--count", "9", "--step", "40", "--set", "b=62", "--csv", "{OUT}/set-b.csv"]),
        ("range", ["kinematics", a, "--start", "10", "--step", "15", "--count", "9", "--csv", "{OUT}/range.csv"]),
        ("outputs", ["kinematics", a, "--count", "9", "--step", "40", "--outputs", "position,rates",
                     "--csv", "{OUT}/outputs.csv"]),
        ("speed", ["kinematics", a, "--count", "9", "--step", "40", "--rpm", "300", "--csv", "{OUT}/speed.csv"]),
        ("f32", ["kinematics", a, "--count", "9", "--step", "40", "--dtype", "float32", "--csv", "{OUT}/f32.csv"]),
        # every built-in linkage scene, and the reactions of the one with masses
        ("feed", ["kinematics", "sewing-feed", "--count", "8", "--step", "45", "--csv", "{OUT}/feed.csv"]),
        ("needle", ["kinematics", "needle-arachne", "--count", "8", "--step", "45", "--csv", "{OUT}/needle.csv"]),
        ("slider", ["kinematics", "slider-crank", "--count", "8", "--step", "45", "--csv", "{OUT}/slider.csv"]),
        ("reactions", ["reactions", "slider-crank-mass", "--count", "8", "--step", "45", "--rpm", "600",
                       "--csv", "{OUT}/reactions.csv"]),
        # the designer's numbers through every stored program of `check` (issue 24, start-up): a
        # triple-rocker of A's structure (limit positions: branch points, bisection on the reach
        # margins) and the Whitworth quick return (RPR and RRP dyads, a slider's stroke)
        ("check-rocker", ["check", a, "--set", "d=90"]),
        ("check-whitworth", ["check", "whitworth"]),
    ]
    # a small search, then its best file (another four-bar file of the structure ran before it)
    y = str(paths["yu1"])
    kin = _best_kinematics("yu1", y)[1][2:-2]  # the inputs of the best file's table: the same program
    cmds += [
        ("kin-yu1", ["kinematics", y, *kin, "--csv", "{OUT}/kin-yu1.csv"]),
        ("opt-yu1", ["optimize", y, "--method", "montecarlo", "--budget", "48", "--seed", "3",
                     "--progress", "off", "--out", "{OUT}/opt-yu1.json"]),
    ]
    return cmds


def _best_kinematics(name: str, scene: str) -> tuple:
    """`kinematics` of the best file `{OUT}/opt-NAME.best.toml` at the inputs of the search's report
    (`report_samples` over a revolution from its first input), with its velocities and
    accelerations (at ω = 1: the derivatives with respect to the input)."""
    pr = problem_from(jaxlink.load(scene))
    n = Evaluator(pr, chunk=8).report_samples
    start = float(np.rad2deg(pr.phis[0]))
    return (f"best-{name}", ["kinematics", f"{{OUT}}/opt-{name}.best.toml", "--start", repr(start),
                             "--step", repr(360.0 / n), "--count", str(n), "--csv", f"{{OUT}}/best-{name}.csv"])


def _objective_from_csv(best_file: pathlib.Path, csv_text: str) -> float:
    """The search's objective computed from the kinematics CSV of its best file."""
    mech = jaxlink.load(str(best_file))
    pr = problem_from(mech)
    obj = OBJECTIVES.build(pr)
    rows = np.genfromtxt(csv_text.splitlines(), delimiter=",", names=True, dtype=None, encoding=None)
    assert np.all(rows["converged"] == 1)
    lf = mech.units.length
    pn = mech.point_names[pr.point]

    def xy(fmt):
        cols = [fmt.format(pn, c) for c in "xy"]
        return np.stack([rows[c] for c in cols], axis=1) / lf if cols[0] in rows.dtype.names else None

    q = np.stack([rows[f"{n}_{'rad' if k == 'angle' else 'm'}"] for n, k in zip(mech.unknown_names,
                                                                               mech.unknown_kinds)], axis=1)
    data = PathData(jnp.asarray(xy("{}_{}_m")), jnp.asarray(xy("{}_v{}_m_s")), jnp.asarray(xy("{}_a{}_m_s2")),
                    jnp.asarray(q), jnp.asarray(mech.parameters))
    return float(obj.value(data))


def _run(folder: pathlib.Path, cmds: list, cache, blind: bool = False) -> dict:
    assert len({name for name, _ in cmds}) == len(cmds)
    folder.mkdir()
    env = dict(os.environ, JAXLINK_CACHE_DIR=str(cache))
    if blind:
        env["BLIND"] = "1"
    r = subprocess.run([sys.executable, "-c", RUNNER, str(folder), json.dumps(cmds)], env=env,
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    return {p.name: p.read_text() for p in sorted(folder.iterdir())}


def _differences(a: dict, b: dict) -> list:
    assert a.keys() == b.keys()
    return [name for name in a if a[name] != b[name]]


# the built-in search scenes other than the feed (its six-bar runs as `feed` in all three modes,
# and `optimize` as the plain four-bar's search: 19 s of the suite for nothing new)
SEARCH_SCENES = ("needle-dwell",)


def _search_commands(scene: str) -> list:
    """A built-in search scene: its kinematics at the inputs of its search's report, a search of a
    few designs, and the kinematics of its best file at the same inputs (one stored program)."""
    best = _best_kinematics(scene, scene)
    return [(f"kin-{scene}", ["kinematics", scene, *best[1][2:-2], "--csv", f"{{OUT}}/kin-{scene}.csv"]),
            (f"opt-{scene}", ["optimize", scene, "--method", "montecarlo", "--budget", "16", "--seed", "2",
                              "--progress", "off", "--out", f"{{OUT}}/opt-{scene}.json"]),
            best]


@pytest.fixture(scope="session")
def runs(tmp_path_factory):
    """The same commands cold, warm (reversed, each search still before the table of its best
    file) and off. The built-in search scenes run cold and warm only (their searches compile the
    most; `optimize` of the plain four-bar file is the cache-off comparison of a search).

    Made once per test run: in a folder shared by the pytest-xdist workers, under a file lock,
    and read back by any worker that needs it again (xdist set this fixture up twice otherwise)."""
    import fcntl
    import pickle

    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # shared by the workers of this run
    tmp = root / "differential"
    done = root / "differential.pickle"
    with open(root / "differential.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if done.exists():
            return pickle.loads(done.read_bytes())
        tmp.mkdir()
        paths = _variants(tmp)
        cmds = _commands(paths) + [_best_kinematics("yu1", str(paths["yu1"]))]
        groups = [[c] for c in cmds[:-2]] + [cmds[-2:]]
        assert [c[0] for c in groups[-1]] == ["opt-yu1", "best-yu1"]
        searches = [_search_commands(scene) for scene in SEARCH_SCENES]
        cache = tmp / "xla"
        out = {
            "cold": _run(tmp / "cold", cmds + sum(searches, []), cache),
            "warm": _run(tmp / "warm", sum(groups[::-1] + searches[::-1], []), cache),
            "off": _run(tmp / "off", cmds, ""),
        }
        result = (tmp, paths, cmds, out)
        done.write_bytes(pickle.dumps(result))
        return result


def test_cold_warm_and_off_give_the_same_bytes(runs):
    _, _, cmds, out = runs
    for name, argv in cmds:  # what each command printed, and every file it wrote
        assert f"{name}.txt" in out["off"]
        assert all(a.replace("{OUT}/", "") in out["off"] for a in argv if a.startswith("{OUT}/"))
    assert _differences({k: v for k, v in out["cold"].items() if k in out["off"]}, out["off"]) == []
    assert _differences({k: v for k, v in out["warm"].items() if k in out["off"]}, out["off"]) == []
    assert _differences(out["cold"], out["warm"]) == []
    for name, text in out["off"].items():
        if name.endswith(".txt"):
            assert "internal error" not in text, text


def test_the_variants_give_their_own_numbers(runs):
    """The pairs are not the same computation: B is the mirror branch (the rocker below the frame),
    C and D and --set differ from A. So equal bytes above mean each got its own answer."""
    _, _, _, out = runs
    rows = {k: np.genfromtxt(out["off"][f"kin-{k}.csv"].splitlines(), delimiter=",", names=True)
            for k in "ABCDE"}
    assert np.all(rows["A"]["phi4_rad"] > 0) and np.all(rows["B"]["phi4_rad"] < 0)
    assert not np.allclose(rows["A"]["P_x_m"], rows["C"]["P_x_m"])
    # D starts its guesses at 40 deg on A's branch: the same positions at the same inputs
    np.testing.assert_allclose(rows["D"]["P_x_m"], rows["A"]["P_x_m"], rtol=0, atol=1e-15)
    assert not np.allclose(rows["A"]["P_x_m"], rows["E"]["P_x_m"])
    assert out["off"]["set-b.csv"] != out["off"]["kin-A.csv"]
    # the triple-rocker's limits: ±acos((a² + d² − (b + c)²) / (2ad)), printed to 10 digits
    limit = np.degrees(np.arccos((20.0**2 + 90.0**2 - 105.0**2) / (2 * 20.0 * 90.0)))
    assert f"phi2 from {-limit:.10g}° to {limit:.10g}° (limit positions" in out["off"]["check-rocker.txt"]
    assert "turns fully" in out["off"]["check-A.txt"] and "time ratio" in out["off"]["check-whitworth.txt"]
    f32 = np.genfromtxt(out["off"]["f32.csv"].splitlines(), delimiter=",", names=True)
    assert not np.array_equal(f32["P_x_m"], rows["A"]["P_x_m"])  # float32 numbers ...
    np.testing.assert_allclose(f32["P_x_m"], rows["A"]["P_x_m"], rtol=0, atol=1.2e-4 * 0.06)  # ... near float64


def test_the_python_api_gives_the_same_numbers(runs):
    """In-process (this test process, its own cache), through the library: the same numbers as
    the command line's CSV, bit for bit."""
    _, paths, _, out = runs
    for k in "AB":
        mech = jaxlink.load(str(paths[k]))
        phis = np.deg2rad(40.0 * np.arange(9))
        table = kinematics_table(mech, phis)
        csv = np.genfromtxt(out["off"][f"kin-{k}.csv"].splitlines(), delimiter=",", names=True)
        for col in ("phi3_rad", "phi4_rad", "P_x_m", "P_y_m", "P_vx_m_s", "P_ay_m_s2"):
            np.testing.assert_array_equal(table.column(col), csv[col], err_msg=f"{k} {col}")
        sol = jaxlink.solve(mech, phis)
        np.testing.assert_array_equal(np.asarray(sol.points)[:, 0, 0], csv["P_x_m"])


def test_optimize_then_kinematics_of_its_best_file_reproduces_the_objective(runs):
    """`optimize` followed by `kinematics` of its best file, one after another with a cache (cold
    and warm) and without: the objective computed from the CSV is the reported one (1e-9)."""
    tmp, _, _, out = runs
    for mode in ("cold", "warm", "off"):
        doc = json.loads(out[mode]["opt-yu1.json"])
        assert doc["best"]["feasible"], out[mode]["opt-yu1.txt"]
        got = _objective_from_csv(tmp / mode / "opt-yu1.best.toml", out[mode]["best-yu1.csv"])
        assert got == pytest.approx(doc["best"]["objective"], rel=1e-9), mode


@pytest.mark.parametrize("scene", SEARCH_SCENES)
def test_every_search_scene_reproduces_through_the_cache(runs, scene):
    """A built-in search scene (`SEARCH_SCENES`): `optimize` (a few designs), then `kinematics` of its best file,
    in one process with a cache, after the scene's own kinematics at the same inputs; cold and
    warm. The objective from each CSV is the reported one (1e-9)."""
    tmp, _, _, out = runs
    for mode in ("cold", "warm"):
        doc = json.loads(out[mode][f"opt-{scene}.json"])
        got = _objective_from_csv(tmp / mode / f"opt-{scene}.best.toml", out[mode][f"best-{scene}.csv"])
        assert got == pytest.approx(doc["best"]["objective"], rel=1e-9), mode


def _damage(paths) -> int:
    """Every other file truncated to half, the others with one bit flipped in the middle."""
    n = 0
    for i, path in enumerate(sorted(paths)):
        blob = bytearray(path.read_bytes())
        if i % 2:
            blob[len(blob) // 2] ^= 0x01
            path.write_bytes(bytes(blob))
        else:
            path.write_bytes(bytes(blob[: len(blob) // 2]))
        n += 1
    return n


def test_a_damaged_or_truncated_entry_is_recomputed(runs):
    """Every stored trace truncated or with one bit changed: a warm run re-traces and gives the
    same bytes (never loads a damaged program). Then every entry of JAX's compilation cache too:
    JAX finds them damaged (its compressed entries carry a checksum), says so and compiles again;
    the tables are the same bytes."""
    tmp, _, cmds, out = runs
    cache = tmp / "xla"
    assert _damage(cache.glob("trace-*")) > 5
    kin = [c for c in cmds if c[0].startswith("kin-")]
    again = _run(tmp / "damaged", kin, cache)
    assert _differences(again, {k: v for k, v in out["off"].items() if k in again}) == []
    # files only: on a GPU, XLA keeps its autotuning results in a folder beside the entries
    assert _damage(p for p in cache.iterdir() if p.is_file() and not p.name.startswith("trace-")) > 5
    again = _run(tmp / "damaged-xla", [c for c in kin if c[0] in ("kin-A", "kin-E")], cache)
    for name, text in again.items():
        ref = out["off"][name]
        assert (text == ref) if name.endswith(".csv") else (text.split("\n")[0] == ref.split("\n")[0] == "exit 0")


def test_a_wrong_key_is_caught(runs):
    """The same comparison with the stored traces' key blind to the arguments' structure (the
    mechanism's `Structure.key`: E's frame angle inside its loop) must find differences: the
    differential test would fail on such a key."""
    tmp, _, cmds, out = runs
    cmds = [c for c in cmds if c[0] in ("kin-A", "kin-E", "check-A", "check-E")]
    blind = _run(tmp / "blind", cmds, tmp / "blind-xla", blind=True)
    assert _differences(blind, {k: v for k, v in out["off"].items() if k in blind}) == [
        "check-E.txt", "kin-E.csv", "kin-E.txt"]
