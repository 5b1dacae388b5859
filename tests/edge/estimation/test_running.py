"""The running effusivity and the sequential decision on it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from edge.recognition import KnownObject, ObjectSet
from edge.estimation.running import RunningEffusivity, SequentialDecision, duhamel_m
from edge.measure.instrument import INSTRUMENTS
from edge.physics.solids import Solid
from host.evaluate import TouchSimulator

PMMA = Solid(0.185, 1178.0, 1429.0)


def test_duhamel_m_of_a_constant_flux_is_its_half_integral():
    t = np.arange(1, 51) * 0.02
    q = np.full(t.size, 300.0)
    for x in (0.1, 0.5, 1.0):
        assert duhamel_m(x, t, q) == pytest.approx(2 * 300.0 * math.sqrt(x / math.pi), rel=1e-12)
    assert duhamel_m(0.0, t, q) == 0.0


def _feed(est, touch):
    qT = np.interp(touch.tT, touch.tq, touch.q)
    for a, b, c in zip(touch.tT, touch.T, qT):
        est.add(a, b, c)


@pytest.mark.parametrize("inst", ["ads122c04", "mcp9600"])
def test_running_estimate_matches_the_truth_within_its_uncertainty(inst):
    touch = TouchSimulator(PMMA, duration_s=2.0).touch(7.7e7, inst, np.random.default_rng(3))
    r = RunningEffusivity(0.0, INSTRUMENTS[inst].T_lsb_K)
    _feed(r, touch)
    e, u = r.estimate()
    assert abs(math.log(e / PMMA.effusivity_W_s05_m2K)) < 3 * u
    assert 0.02 <= u < 0.1


def _set():
    P = KnownObject.from_properties
    return ObjectSet([P("foam", "foam", 0.035, 30, 1400), P("pmma", "polymer", 0.185, 1178, 1429),
                      P("glass", "glass", 1.0, 2500, 750), P("steel", "alloy", 17, 7900, 500)])


def test_sequential_decision_decides_early_and_right_not_before_min_time():
    touch = TouchSimulator(PMMA, duration_s=2.0).touch(7.7e7, "ads122c04", np.random.default_rng(4))
    d = SequentialDecision(_set(), 0.95, 0.3)
    qT = np.interp(touch.tT, touch.tq, touch.q)
    for a, b, c in zip(touch.tT, touch.T, qT):
        ans = d.update(a, b, c)
        if d.decided is not None:
            break
    assert d.decided is not None and d.decided.object == "pmma" and d.decided.posterior >= 0.95
    assert 0.3 <= d.decided.elapsed_s < 1.0
    assert ans is d.decided


def test_no_decision_when_the_threshold_cannot_be_reached():
    touch = TouchSimulator(PMMA, duration_s=1.0).touch(7.7e7, "ads122c04", np.random.default_rng(5))
    d = SequentialDecision(_set(), 1.0, 0.3)
    _feed(d.running, touch)
    assert d.decided is None


def test_refit_cadence_stretches_the_interval_when_a_refit_takes_more_than_its_share():
    from edge.estimation.running import RefitCadence

    now = [0.0]
    cad = RefitCadence(0.1, 0.3, max_share=0.2, timer=lambda: now[0])

    def fit(cost_s):
        def f():
            now[0] += cost_s
            return "answer"
        return f

    assert not cad.due(0.29) and cad.due(0.3)
    assert cad.run(0.3, fit(2.0)) == "answer"         # the first pays one-time costs: not a measure
    assert cad.next_s == pytest.approx(0.4) and not cad.due(0.39) and cad.due(0.4)
    cad.run(0.4, fit(0.05))                            # 50 ms: at most 20 % of the time -> 0.25 s later
    assert cad.next_s == pytest.approx(0.65) and not cad.due(0.6)
    cad.run(0.65, fit(0.06))                           # the shorter of the last two: 50 ms again
    assert cad.next_s == pytest.approx(0.9)
    cad.run(0.9, fit(1.0))                             # one slow refit (a pause) does not stop them
    assert cad.next_s == pytest.approx(0.9 + 0.06 / 0.2)
    with pytest.raises(RuntimeError):                  # a failing fit still counts and schedules
        cad.run(1.2, lambda: (_ for _ in ()).throw(RuntimeError("boom")))
    assert len(cad.spent_s) == 5 and cad.next_s == pytest.approx(1.3)
    with pytest.raises(ValueError, match="every_s"):
        RefitCadence(0.0)
    with pytest.raises(ValueError, match="max_share"):
        RefitCadence(0.1, max_share=0.0)


@pytest.mark.parametrize("e, u, want", [(1000.0, 20.0, 0.02), (None, 20.0, None), (1000.0, None, None),
                                        (1000.0, float("inf"), None), (1000.0, float("nan"), None),
                                        (0.0, 20.0, None), (float("inf"), 20.0, None), (1000.0, 0.0, None)])
def test_a_refit_decides_only_on_an_estimate_with_a_finite_e_and_u(e, u, want):
    from edge.estimation.running import RefitDecision

    got = RefitDecision.u_ln_e(e, u)
    assert got == (pytest.approx(want) if want is not None else None)


def test_a_set_calibrated_per_contact_time_names_with_that_time_and_never_decides_before_it():
    objs = (KnownObject.from_properties("pmma", "polymer", 0.185, 1178.0, 1429.0, 0.05),
            KnownObject.from_properties("glass", "glass", 1.0, 2500.0, 750.0, 0.05))
    table = {0.5: {"temperature": 9.0, "z_crit": 6.0}, 2.0: {"temperature": 1.0, "z_crit": 2.5}}
    s = ObjectSet(objs, contact_calibration=table)
    e = PMMA.effusivity_W_s05_m2K
    d = SequentialDecision(s, 0.9, 0.0)
    early = d._answer(0.3, e, 0.01, 10)          # posterior >= 0.9, but before the calibrated 0.5 s
    assert early.posterior >= 0.9 and not early.decided and d.decided is None
    at_half = d._answer(0.6, e, 0.01, 12)
    at_two = SequentialDecision(s, 0.9, 0.0)._answer(2.0, e, 0.01, 40)
    # The 0.5-s calibration (T = 9) is less sure than the 2-s one (T = 1) of the same e and u.
    assert at_half.posterior < at_two.posterior
    assert at_half.decided and d.decided is at_half
