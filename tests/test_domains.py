"""The domain of a value holds in every batched evaluator as it does in the file (`--set`):
a design with a value the file reader refuses (a negative or sub-nanometre link length) is
infeasible and counted, in a study and in a design search.

The reference is the reader itself (`loads(..., overrides=...)`: refused or not) and, for the
four-bar, Grashof's condition on |a| (a crank of −a is the crank of a turned half a turn: it
assembles, so only the domain can make it infeasible)."""

import pathlib

import numpy as np
import pytest

import jaxlink as jl
from jaxlink import study as st
from jaxlink.errors import MechanismError
from jaxlink.model import domains
from jaxlink.optimize import Evaluator, problem_from

ROOT = pathlib.Path(__file__).resolve().parents[1]

# the offset slider-crank of tests/test_study.py, fewer positions
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
positions = 24
samples = 64
metrics = ["stroke"]
distribution = "uniform"

[study.tolerances]
crank = 0.01
rod = 0.01
"""


def _accepted(text, **values) -> bool:
    try:
        jl.loads(text, overrides=values)
    except MechanismError:
        return False
    return True


@pytest.fixture(scope="module")
def slider():
    mech = jl.loads(SLIDER)
    return mech, st.Study(mech, st.read_study(mech))


def test_a_study_counts_a_design_outside_the_domain_infeasible(slider):
    """The same batch with the crank inside its domain (25, 5, 0 mm) and outside (−5, −25 mm: negative;
    1e-7 mm: below a nanometre): feasible exactly where the reader accepts the value."""
    mech, study = slider
    cranks = [25.0, 5.0, 0.0, -5.0, -25.0, 1e-7]
    x = np.asarray([[c, 80.0] for c in cranks])
    _v, ok, _labels = st.evaluate(study, x)
    accepted = np.asarray([_accepted(SLIDER, crank=c) for c in cranks])
    assert list(accepted) == [True, True, True, False, False, False]
    assert np.array_equal(ok, accepted)
    assert study.responses.outside(x) == 3
    # the differential: the same designs with |crank| are all feasible
    _v, ok_abs, _ = st.evaluate(study, np.abs(x[:5]))
    assert ok_abs.all()


def test_a_tolerance_wider_than_the_link_counts_the_negative_draws(slider):
    """A crank of 0.004 mm ± 0.01 mm (uniform): the Monte Carlo samples with a negative crank
    (0.3 of them) are infeasible and reported as outside the domain; every other sample feasible."""
    mech, study = slider
    rep = st.tolerance(mech, study=study.moved(np.asarray([0.004, 80.0])), samples=1024, worst=False)
    mc = rep.monte_carlo
    dx = st.draws(study.inputs, 1024)
    negative = int(np.count_nonzero(0.004 + dx[:, 0] < 0))
    assert 250 < negative < 370  # 0.3 × 1024 ± 4σ
    assert mc.outside == negative and mc.infeasible == negative and mc.feasible == 1024 - negative
    assert any(f"{negative} of 1024 Monte Carlo samples have a value outside its domain" in w for w in rep.warnings)
    assert not any("do not assemble" in w for w in rep.warnings)  # they are not called unassemblable


def test_a_sample_study_reports_the_designs_outside_the_domain(slider):
    mech, study = slider
    inputs = st.read_study(mech, method="sample", samples=64, ranges={"crank": [-10.0, 30.0], "rod": [79.0, 81.0]})
    rep = st.sample(mech, study=study.moved(inputs=inputs))
    negative = rep.values[:, 0] < 0
    assert 4 < negative.sum() < 28
    assert not rep.feasible[negative].any() and rep.feasible[~negative].all()
    assert any(f"{int(negative.sum())} of 64 designs have a value outside its domain" in w for w in rep.warnings)
    assert not any("do not assemble" in w for w in rep.warnings)


def test_the_design_search_counts_a_negative_link_infeasible():
    """Bounds [-60, 60] on the four-bar's crank: a design is feasible iff its crank is ≥ 0 and
    Grashof's crank with |a| (the closed form); the design with −a is the one with a turned half a
    turn, so without the domain it would count as feasible."""
    text = (ROOT / "jaxlink" / "scenes" / "four-bar.toml").read_text() + """
[optimize]
point = "P"
variables = { a = [-60, 60] }
samples = 24
objective = "points"
targets = [[30, 40], [10, 50]]
"""
    pr = problem_from(jl.loads(text, file="four-bar-opt.toml"))
    ev = Evaluator(pr, chunk=64)
    a = np.asarray([20.0, -20.0, 10.0, -10.0, 50.0, -50.0])
    res = ev.evaluate(pr.to_unit(a[:, None]))
    b, c, d = 60.0, 45.0, 55.0
    lengths = np.stack([np.abs(a), np.full_like(a, b), np.full_like(a, c), np.full_like(a, d)], axis=1)
    s, big = lengths.min(1), lengths.max(1)
    grashof_crank = (np.abs(a) == s) & (s + big <= lengths.sum(1) - s - big)
    assert list(grashof_crank) == [True, True, True, True, False, False]
    assert np.array_equal(res["feasible"], grashof_crank & (a >= 0))
    assert np.array_equal(res["feasible"], grashof_crank & np.asarray([_accepted(text, a=v) for v in a]))
    assert np.all(np.isinf(res["value"][~res["feasible"]]))
    assert not ev.report(pr.to_unit(np.asarray([-20.0])))["certified"]


def test_the_domains_agree_with_the_reader():
    """`domains.inside` (jittable) against the reader's refusals, value by value, for each kind."""
    import jax

    mech = jl.load("four-bar")  # a..d link lengths, cx, cy point lengths (≥ 0), in mm
    p0 = np.asarray(mech.parameters)
    fn = jax.jit(lambda p: domains.inside(mech, p))
    text = (ROOT / "jaxlink" / "scenes" / "four-bar.toml").read_text()
    for name in ("a", "cx"):
        i = mech.parameter_names.index(name)
        for v in (20.0, 0.0, -1e-3, -20.0, 1e-7, 2e9):
            p = p0.copy()
            p[i] = v * 1e-3
            assert bool(fn(p)) == _accepted(text, **{name: v}) == bool(domains.inside(mech, p)), (name, v)
    assert not bool(fn(np.full_like(p0, np.nan)))


def test_a_synthesized_design_outside_the_domain_does_not_pass():
    """The planted four-bar's coupler curve as the target at several scales (mm): the candidate
    passes the synthesis's check exactly where its written file is accepted by the reader — a
    crank of 3e-7 mm (below a nanometre) or a frame 1e8 mm away (beyond 1000 km) is refused by
    both; the distance (scale-free) is the same at every scale."""
    from jaxlink.synthesis import distance as D
    from jaxlink.synthesis import topology as T
    from jaxlink.synthesis.mechanism import placed_pose, to_sketch
    from jaxlink.synthesis.search import score
    from jaxlink.synthesis.target import make_target
    from jaxlink.synthesis.tracer import trace_exact

    four = T.topologies()[0]
    pose = np.array([[0, 0], [1.0, 0], [0, 0], [0.3, 0.0], [1.1, 0.8], [0.5, 0.9]])  # test_synthesis.py's
    curve = trace_exact(four, pose, np.linspace(0, 2 * np.pi, 400, endpoint=False))[0][:, four.traced]
    oks, accepted, dists = [], [], []
    for s in (40.0, 1e-5, 1e-6, 1e-8, 1e8):
        tgt = make_target(curve * s + [100 * s, 50 * s], closed=True, unit="mm")
        m, asm = score(four, pose, 0.0, 2 * np.pi, tgt, n_trace=1000, n_points=D.N_POINTS)
        oks.append(asm.ok)
        dists.append(m.distance)
        try:
            jl.loads(to_sketch(four, placed_pose(four, pose, 0.0, m), unit="mm").toml())
            accepted.append(True)
        except MechanismError as e:
            assert "out of range" in str(e)
            accepted.append(False)
    assert accepted == [True, True, False, False, False] and oks == accepted
    assert max(dists) - min(dists) < 1e-9 and max(dists) < 1e-3


def test_every_study_method_counts_its_designs_outside_the_domain(slider):
    """A range [−10, 30] mm on the crank: each method's warning counts exactly the designs it drew
    with a negative crank (rebuilt independently from the sequence: Sobol' A, B and the AB_j of
    `sensitivity`; the regression's own designs; Morris's trajectories; the DGSM's designs)."""
    mech, study = slider
    ranges = {"crank": [-10.0, 30.0], "rod": [79.0, 81.0]}
    lo, hi = np.asarray([[-10.0, 79.0], [30.0, 81.0]])

    def count(rep, n):
        hits = [w for w in rep.warnings if "have a value outside its domain" in w]
        assert len(hits) == 1 and hits[0].split(" of ")[1].split()[0] == str(n), rep.warnings
        return int(hits[0].split()[0])

    inputs = st.read_study(mech, method="sensitivity", samples=16, ranges=ranges)
    rep = st.sensitivity(mech, study=study.moved(inputs=inputs))
    u = np.concatenate(list(st.unit_blocks("sobol", 4, 16, inputs.seed)))
    a, b = lo + u[:, :2] * (hi - lo), lo + u[:, 2:] * (hi - lo)
    ab = [np.where(np.arange(2) == j, b, a) for j in range(2)]
    assert count(rep, 16 * 4) == sum(int((x[:, 0] < 0).sum()) for x in [a, b, *ab]) > 0

    inputs = st.read_study(mech, method="regression", samples=32, ranges=ranges)
    rep = st.regression(mech, study=study.moved(inputs=inputs))
    assert count(rep, 32) == int((rep.values[:, 0] < 0).sum()) > 0

    inputs = st.read_study(mech, method="morris", samples=8, ranges=ranges)
    rep = st.morris(mech, study=study.moved(inputs=inputs))
    traj = st.trajectories([np.arange(0, 1), np.arange(1, 2)], 8, inputs.morris_levels, inputs.seed)[0].reshape(-1, 2)
    assert count(rep, 8 * 3) == int((st.box_values(inputs, study.x0, traj)[:, 0] < 0).sum()) > 0
