"""The objective registry (jaxlink/optimize/objectives/): explicit registration, no import cycle,
generic path objectives without scene defaults, scene objectives with theirs."""

import dataclasses
import math
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

from jaxlink import MechanismError, loads
from jaxlink.optimize import PathData, problem_from
from jaxlink.optimize.objectives import OBJECTIVES, Objective, Registry
from jaxlink.scenes import scene_paths


def _without(scene, *keys):
    """The scene's text with the `[optimize]` lines that set `keys` removed."""
    lines = scene_paths()[scene].read_text().splitlines()
    return "\n".join(ln for ln in lines if ln.split("=")[0].strip() not in keys) + "\n"


def test_builtin_objectives_and_their_keys():
    assert list(OBJECTIVES) == ["points", "ellipse", "feed", "dwell"]
    assert {"slider", "coupler", "rocker", "rod", "arm_offset", "crank", "four_bar", "guide_angle"} <= set(
        OBJECTIVES.keys_of("dwell"))
    assert {"axes", "rpm"} <= set(OBJECTIVES.keys_of("ellipse"))


def test_register_is_explicit_and_once():
    calls = []

    class Builtin:
        @staticmethod
        def register_objectives(reg):
            calls.append("builtin")
            reg("a", lambda problem: None, keys=("ka",))

    reg = Registry(lambda: (Builtin,))
    assert calls == []  # nothing registered before the registry is used
    reg.register("b", lambda problem: None, keys=("kb",))
    assert calls == ["builtin"] and list(reg) == ["a", "b"]
    assert reg.known_keys() == {"ka", "kb"}
    with pytest.raises(ValueError, match="already registered"):
        reg.register("a", lambda problem: None)
    assert list(reg) == ["a", "b"] and calls == ["builtin"]


def test_no_import_cycle():
    """The dwell metrics do not import the design search; the registry imports the scene modules
    only when it is first used."""
    code = (
        "import sys\n"
        "import jaxlink.analysis.dwell\n"
        "assert not [m for m in sys.modules if m.startswith('jaxlink.optimize')]\n"
        "import jaxlink.optimize.objectives as o\n"
        "assert 'jaxlink.scenes.needle_dwell' not in sys.modules\n"
        "assert 'dwell' in o.OBJECTIVES and 'jaxlink.scenes.needle_dwell' in sys.modules\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr


def test_custom_objective_plugs_in():
    """A factory registered on a registry is built from a `Problem` like the built-in ones."""
    reg = Registry(lambda: ())

    def spread(problem):
        f = lambda path: jnp.sum(jnp.var(path.xy, axis=0))
        return Objective("spread", 0, f, f, lambda path: {"spread": f(path)})

    reg.register("spread", spread)
    mech = loads(scene_paths()["sewing-feed-opt"].read_text(), file="feed.toml")
    obj = reg.build(dataclasses.replace(problem_from(mech), objective="spread"))
    assert obj.name == "spread"
    t = 2 * np.pi * np.arange(64) / 64
    circle = PathData(jnp.stack([2.0 * np.cos(t), 2.0 * np.sin(t)], axis=1))
    assert float(obj.value(circle)) == pytest.approx(4.0, rel=1e-12)  # var(r cos) + var(r sin) = r²


def test_ellipse_needs_its_axes_from_the_file():
    """No scene's numbers as defaults: without `axes` the file is wrong, named by its key."""
    mech = loads(_without("sewing-feed-opt", "axes"), file="no-axes.toml")
    with pytest.raises(MechanismError) as exc:
        OBJECTIVES.build(problem_from(mech))
    assert exc.value.key == "optimize.axes"


def test_ellipse_without_rpm_reports_no_accelerations():
    mech = loads(_without("sewing-feed-opt", "rpm"), file="no-rpm.toml")
    obj = OBJECTIVES.build(problem_from(mech))
    t = 2 * np.pi * np.arange(36) / 36
    xy = np.stack([2.5 * np.cos(t), np.sin(t)], axis=1)
    m = obj.metrics(PathData(jnp.asarray(xy), jnp.asarray(xy), -jnp.asarray(xy)))
    assert "peak_acceleration_m_s2" not in m and obj.report_order == 0
    assert float(m["two_a"]) == pytest.approx(5.0) and float(obj.value(PathData(jnp.asarray(xy)))) < 1e-28


def test_feed_objective_keeps_the_feed_defaults():
    """The `feed` objective (jaxlink/scenes/sewing_feed.py) brings the sewing feed's input speed
    5490 rpm when the file sets none: peak |a| of a circle r at ω is r ω²."""
    mech = loads(_without("sewing-feed-opt", "rpm"), file="no-rpm.toml")
    obj = OBJECTIVES.build(problem_from(mech, {"objective": "feed"}))
    r = 2.5  # mm
    t = 2 * np.pi * np.arange(72) / 72
    xy = r * np.stack([np.cos(t), np.sin(t)], axis=1)
    m = obj.metrics(PathData(jnp.asarray(xy), jnp.asarray(xy), -jnp.asarray(xy)))
    omega = 5490 * 2 * math.pi / 60
    assert float(m["peak_acceleration_m_s2"]) == pytest.approx(r * 1e-3 * omega**2, rel=1e-12)
