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


def test_points_smooth_value_is_the_soft_min_over_all_segments_and_its_gradient_is_exact():
    """The smoothed `points` objective takes its soft-min over the 7 segments around each
    target's nearest path point: on a path where no distant segment nearly ties, it equals the
    soft-min over all N segments (computed here directly, with a larger temperature than the
    default so that the soft part is not negligible), lies within [SSE − T τ log 7, SSE], and its
    gradient in the path matches central differences."""
    import jax

    from jaxlink.optimize.objectives.path import points_objective, segment_distances2

    rng = np.random.default_rng(3)
    t = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    xy = np.stack([3.0 * np.cos(t) + 0.4 * np.cos(2 * t), 2.0 * np.sin(t)], axis=1)
    targets = xy[rng.choice(360, 30, replace=False)] + 0.05 * rng.standard_normal((30, 2))

    class P:  # the two keys the objective reads
        def option(self, key, default=None):
            return {"targets": targets.tolist(), "smoothing": 3e-3}.get(key, default)

        def error(self, msg, key):
            return ValueError(msg)

    obj = points_objective(P())
    diag = float(np.hypot(*(targets.max(0) - targets.min(0))))
    tau = (3e-3 * diag) ** 2
    d2 = np.asarray(segment_distances2(jnp.asarray(xy), jnp.asarray(targets)))
    m = d2.min(axis=1, keepdims=True)
    full = float(np.sum(m[:, 0] - tau * np.log(np.sum(np.exp(-(d2 - m) / tau), axis=1))))
    smooth = float(obj.smooth(PathData(jnp.asarray(xy))))
    sse = float(obj.value(PathData(jnp.asarray(xy))))
    assert smooth == pytest.approx(full, rel=1e-8)  # the segments further away: ~5e-10 here
    assert sse - 30 * tau * math.log(7) <= smooth <= sse
    g = np.asarray(jax.grad(lambda z: obj.smooth(PathData(z)))(jnp.asarray(xy)))
    near = [int(np.argmin(np.sum((xy - targets[k]) ** 2, 1))) for k in (0, 5)]
    for i, j in [(near[0], 0), (near[1], 1)]:
        h = 1e-6
        e = np.zeros_like(xy)
        e[i, j] = h
        fd = (float(obj.smooth(PathData(jnp.asarray(xy + e))))
              - float(obj.smooth(PathData(jnp.asarray(xy - e))))) / (2 * h)
        assert g[i, j] == pytest.approx(fd, rel=1e-5, abs=1e-9)
        assert g[i, j] != 0.0
