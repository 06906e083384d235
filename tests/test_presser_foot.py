"""Presser foot (seed 000 ch. 12, spec/feed-six-bar.md §4): experiments/presser_foot.py, with the feed
point's vertical acceleration from jaxlink's kinematics, against the seed's and the spec's numbers."""

import importlib.util
import pathlib

import numpy as np
import pytest

PATH = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "presser_foot.py"


@pytest.fixture(scope="module")
def pf():
    spec = importlib.util.spec_from_file_location("presser_foot", PATH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def kin(pf):
    return pf.feed_point(5.0)


def test_kinematic_inputs_match_the_seed_and_the_reference_run(pf, kin):
    assert pf.at(kin, 195.0, "y") == pytest.approx(56.54e-3, abs=5e-6)  # spec: y = 56.54 mm at 195°
    assert pf.at(kin, 195.0, "ay") == pytest.approx(15.474, abs=1e-3)
    assert pf.at(kin, 385.0, "ay") == pytest.approx(30.832, abs=1e-3)
    assert pf.at(kin, 295.0, "ay") == pytest.approx(-424.44, abs=0.01)  # the seed's +424.45 is a sign typo
    top = int(np.argmax(kin["y"]))
    assert kin["deg"][top] == 290.0
    assert kin["y"][top] == pytest.approx(57.945e-3, abs=5e-7)
    assert kin["ay"][top] == pytest.approx(-425.71, abs=0.01)


def test_preload_bound(pf, kin):
    a2 = -pf.at(kin, 295.0, "ay")
    assert pf.preload_bound(a2, 1.3e-3) == pytest.approx(1.910e-3, abs=5e-7)  # the seed's "y0 > 1.9 mm"
    assert pf.preload_bound(a2, 1.13e-3) == pytest.approx(2.080e-3, abs=5e-7)


def test_lifting_forces(pf, kin):
    f1, f2a, f3 = pf.seed_lifting_forces(2.0e-3, 1.13e-3, -pf.at(kin, 295.0, "ay"), pf.at(kin, 385.0, "ay"))
    assert round(f1, 3) == 6.435 and f1 == pytest.approx(6.4354, abs=5e-5)
    # seed 5.696 from the rounded a_3 = 30.83; with the exact 30.832 it is 5.69548 (spec: 5.6955)
    assert abs(f3 - 5.696) < 1e-3 and f3 == pytest.approx(5.6955, abs=5e-5)
    assert f2a == pytest.approx(-0.248, abs=5e-4)  # the chosen y0 = 2.0 mm is short with b = 1.13 mm
    # the consistent form reduces to the seed's (12.3) when a_y = 0 and the foot is not lifted
    assert pf.contact_force(0.0, 0.0, 2.0e-3) == pytest.approx(f1, abs=1e-12)
