"""A study's resources are estimated before it starts (`jaxlink.study.resources`): a study that
would not fit in memory, or whose checkpoint would not fit on its disk, is refused with the
option, the estimate and what is available — before anything is allocated (a fake, tiny
available memory and free disk here, not the machine's). The estimates are held against what the
study really allocates (tracemalloc) and writes (the checkpoint's bytes). A worst case whose
candidates all fail to assemble says "none feasible", not a worst deviation of 0."""

import json
import pathlib
import tracemalloc

import numpy as np
import pytest

import jaxlink as jl
from jaxlink import study as st
from jaxlink.errors import MechanismError
from jaxlink.study import resources
from jaxlink.study import sampling as _sampling
from jaxlink.study.checkpoint import Checkpoint, resume_key

ROOT = pathlib.Path(__file__).resolve().parents[1]

SLIDER = """
[mechanism]
length_unit = "mm"
angle_unit = "deg"

[sketch]
frame = ["O1"]

[sketch.input]
crank = "crank"

[sketch.joints]
O1 = [0, 0]
A = [21.650635094610966, 12.5]
B = [101.64907257935190, 12.0]

[sketch.links]
crank = ["O1", "A"]
rod = ["A", "B"]

[sketch.sliders]
B = { on = "frame", along = [1, 0] }

[study]
method = "sensitivity"
positions = 16
samples = 64
chunk = 1024
metrics = ["stroke"]

[study.tolerances]
crank = 0.01
rod = 0.01

[study.ranges]
crank = [24.0, 26.0]
rod = [80.0, 81.0]
"""


@pytest.fixture(scope="module")
def slider():
    mech = jl.loads(SLIDER)
    return mech, st.Study(mech, st.read_study(mech))


def _no_allocation(*_a, **_k):
    raise AssertionError("allocated before the estimate refused")


def test_a_sensitivity_study_too_large_is_refused_before_allocating(slider, monkeypatch):
    """10^8 base samples with 100 bootstrap resamples: (10 × 100 + 16) bytes × 10^8 = 102 GB of
    bootstrap counts (an int64 draw and a uint16 count per sample and resample); with 1 GB
    available the study is refused naming the option, the estimate and the memory, and the
    largest count that fits — the bootstrap counts never drawn."""
    mech, study = slider
    monkeypatch.setattr(resources, "available_memory", lambda: 10**9)
    monkeypatch.setattr(_sampling, "bootstrap_counts", _no_allocation)
    with pytest.raises(MechanismError) as e:
        st.sensitivity(mech, study=study, samples=10**8)
    msg = str(e.value)
    assert "samples = 100000000" in msg and "--samples" in msg and "study.samples" in msg
    assert "about 102 GB of memory" in msg and "of the 1 GB available" in msg and "--bootstrap" in msg
    fit = int(msg.split("at most ")[1].split()[0])
    assert 0.9 * 0.5e9 / 1016 < fit <= 0.5e9 / 1016  # half of 1 GB at 1016 bytes a base sample


def test_the_bootstrap_estimate_against_what_is_allocated(slider):
    """The bootstrap counts' estimate ((10 R + 16) N bytes, and the batch) against tracemalloc's peak
    of the real draw: at least the peak, what grows with N within 1 % of it."""
    _mech, study = slider
    n, r = 20000, study.inputs.bootstrap
    from jaxlink.study.sobol import bootstrap_counts

    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        bootstrap_counts(n, r, [0, 1])
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    need = resources.estimate(study, "sensitivity", n)
    grows = need.per * n
    assert peak <= need.memory and 0.99 * peak <= grows <= 1.01 * peak, (peak, grows, need.memory)


def test_the_command_line_refuses_with_a_user_error(tmp_path, monkeypatch, capsys):
    """`jaxlink study --samples 100000000` (sensitivity; regression) exits 2 (a user error, not the
    internal error's 3) with one line naming --samples, the estimate and the memory available."""
    from jaxlink.cli import main

    src = tmp_path / "slider.toml"
    src.write_text(SLIDER)
    monkeypatch.setattr(resources, "available_memory", lambda: 2 * 10**9)
    for method in ("sensitivity", "regression"):
        rc = main(["study", str(src), "--method", method, "--samples", "100000000", "--no-plot", "--progress", "off"])
        err = capsys.readouterr().err
        assert rc == 2, err
        assert "--samples" in err and "GB of memory" in err and "of the 2 GB available" in err
        assert "internal error" not in err


def test_a_checkpoint_too_large_for_its_disk_is_refused_and_its_estimate_bounds_what_it_writes(slider, tmp_path,
                                                                                                monkeypatch):
    """A regression keeps (and its checkpoint writes) every response of every design. Its
    checkpoint's estimate against the bytes it really writes (256 designs); with 100 kB free the
    same study of 10^5 designs is refused before it starts, naming the folder and the free space;
    a sensitivity's checkpoint (sums only) does not grow with the samples."""
    mech, study = slider
    inputs = study.inputs._replace(method="regression")
    reg = study.moved(inputs=inputs)
    ck = Checkpoint(tmp_path / "ck", resume_key(mech, inputs, chunk=reg.chunk, what="regression"))
    st.regression(mech, study=reg, samples=256, checkpoint=ck)
    written = sum(p.stat().st_size for p in (tmp_path / "ck").iterdir())
    need = resources.estimate(reg, "regression", 256)
    assert 0.5 * need.checkpoint <= written <= need.checkpoint, (written, need.checkpoint)
    monkeypatch.setattr(resources, "free_disk", lambda _path: 10**5)
    ck2 = Checkpoint(tmp_path / "ck2", resume_key(mech, inputs, chunk=reg.chunk, what="regression"))
    monkeypatch.setattr(reg, "_batch", _no_allocation)
    with pytest.raises(MechanismError) as e:
        st.regression(mech, study=reg, samples=10**5, checkpoint=ck2)
    msg = str(e.value)
    assert "the checkpoint of this regression study" in msg and str(tmp_path / "ck2") in msg
    assert "of the 100 kB free there" in msg and "at most" in msg
    small, big = (resources.estimate(study, "sensitivity", n).checkpoint for n in (64, 10**8))
    assert small == big


FOUR_BAR_STUDY = """
[study]
positions = 36
samples = 0
metrics = ["stroke"]
distribution = "uniform"

[study.tolerances]
d = 0.01
"""


def test_a_worst_case_with_no_feasible_corner_says_none_feasible():
    """A four-bar with b = d and a = c − 0.005 (a crank-rocker by 0.005 mm): d ± 0.01 both break
    Grashof's condition (d + 0.01: a + d > b + c; d − 0.01: a + b > c + d), so both corners of the
    box fail to assemble — the worst case is "none feasible" (no value), not "0 found"."""
    from jaxlink.report import tolerance as rt

    text = (ROOT / "jaxlink" / "scenes" / "four-bar.toml").read_text() + FOUR_BAR_STUDY
    mech = jl.loads(text, overrides={"a": 20.0, "b": 55.0, "c": 20.005, "d": 55.0})
    a, b, c, d = 20.0, 55.0, 20.005, 55.0
    for dd in (d - 0.01, d + 0.01):
        s = sorted([a, b, c, dd])
        assert s[0] + s[3] > s[1] + s[2]  # not Grashof: the crank does not turn fully
    assert a + max(b, d) <= b + c  # the nominal is Grashof
    rep = st.tolerance(mech, samples=0, worst=True)
    wc = rep.worst
    assert wc.candidates == 2 and wc.infeasible == 2
    assert set(wc.status) == {"none feasible"} and np.all(np.isnan(wc.value))
    text = rt.summary(mech, rep)
    assert "none feasible" in text and " found" not in text.split("worst case over")[1]
    data = rt.worst_case_json(rep)
    assert all(o["worst"] is None and o["status"] == "none feasible" for o in data["outputs"])
    json.dumps(data, allow_nan=False)
