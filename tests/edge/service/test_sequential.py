"""Sequential decision, touch after touch, readiness and per-profile sampling on the simulated probe."""

from __future__ import annotations

import pytest

from edge.recognition import KnownObject, ObjectSet
from edge.service.config import Config
from edge.service.daemon import Daemon
from edge.service.requests import max_sample_rate_Hz, measure_params
from firmware_sim.run import config_for_scene
from firmware_sim.simulator import load_scene
from tests.support.faithful import DEVICE_DT_s, world_step

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module", autouse=True)
def _device_world_step(faithful_world_test_step):
    """The faithful worlds under these daemons march at ``DEVICE_DT_s`` (tests/support/faithful.py): these tests
    assert what the daemon does with the record (decides, stops early, names the object, samples at the profile's
    rate), not the world's accuracy; every assertion holds at 40 ms as at the suite's 20 ms."""
    with world_step(DEVICE_DT_s):
        yield

P = KnownObject.from_properties
SET = ObjectSet([P("foam", "foam", 0.035, 30, 1400), P("pmma", "polymer", 0.185, 1178.35, 1429),
                 P("glass", "glass", 1.0, 2500, 750), P("steel", "alloy", 17, 7900, 500)])


def _daemon(scene, tmp_path, overrides=None, **kw):
    sim = load_scene(scene)
    sim.repeat_touches()  # as in a thermotouch sim session
    d = Daemon(config_for_scene(sim.scene, tmp_path, overrides), sim.board(), **kw)
    return sim, d


def _spy_status(d, seen):
    make = d._make_decision

    def spy(params):
        dec = make(params)
        real = dec.update

        def update(*a):
            seen.append(d._cmd_status({}))  # what a host polling STATUS sees while the heater is on
            return real(*a)
        dec.update = update
        return dec
    d._make_decision = spy
    d.sequence = None  # rebuilt with the spy


def test_status_carries_the_running_answer_while_heating(tmp_path):
    sim, d = _daemon("pmma_15V", tmp_path, object_set=lambda: SET)
    seen = []
    _spy_status(d, seen)
    try:
        rec = d.measure()
    finally:
        d.close()
        sim.close()
    answers = [s["answer"] for s in seen if "answer" in s]
    assert all(s["state"] == "measuring" and s["ready"] is False for s in seen)
    assert answers and answers[-1]["object"] == "pmma" and answers[-1]["elapsed_s"] > 1.5
    assert "decided" not in rec["flags"] and not rec["result"]["decision"]["stopped_early"]
    assert rec["heater_on_s"] == pytest.approx(rec["contact_time_s"], abs=0.02)


def test_until_decided_stops_heating_early(tmp_path):
    # Pinned at 10 Hz: the decision's 4th sample, and so the stop, then comes at 0.7 s, where the full
    # estimate's u (~27 %) lets the 15 % check below hold; at the reference board's 12.5 Hz it stops at
    # 0.56 s with u ~30 % (424 +- 129 there: within its u, not within 15 %).
    sim, d = _daemon("pmma_15V", tmp_path, {"measurement": {"sample_rate_Hz": 10.0}}, object_set=lambda: SET)
    try:
        rec = d.measure(until_decided=True)
    finally:
        d.close()
        sim.close()
    assert rec["status"] == "ok" and "decided" in rec["flags"] and "no_contact" not in rec["flags"]
    dec = rec["result"]["decision"]
    assert dec["object"] == "pmma" and dec["posterior"] >= 0.95 and dec["stopped_early"]
    assert rec["heater_on_s"] < rec["contact_time_s"] - 0.5
    assert abs(dec["elapsed_s"] - rec["heater_on_s"]) < 0.2
    assert rec["result"]["effusivity_W_s05_m2K"] == pytest.approx(558.0, rel=0.15)  # the full estimate stays


def test_touch_after_touch_in_a_sim_session_and_ready(tmp_path):
    sim, d = _daemon("pmma_15V", tmp_path)
    try:
        for i in range(3):
            rec = d.measure()
            assert rec["status"] == "ok" and "no_contact" not in rec["flags"], (i, rec["flags"])
            assert rec["result"]["effusivity_W_s05_m2K"] == pytest.approx(558.0, rel=0.1), i
            assert d._cmd_status({})["ready"] is False  # just heated: no settled window yet
            ready_at = None
            for k in range(30):
                sim.advance(0.1)
                if d._cmd_status({})["ready"]:
                    ready_at = k
                    break
            assert ready_at is not None and ready_at >= 4  # a baseline window (0.5 s) of settled readings
        assert len(sim.world.touches) >= 3
    finally:
        d.close()
        sim.close()


def test_readiness_polls_no_faster_than_the_converters_deliver(tmp_path):
    from edge.hw.chips import max_sample_rate_Hz

    sim, d = _daemon("pmma_15V", tmp_path, {"measurement": {"sample_rate_Hz": 200.0}})
    try:
        cap_Hz = max_sample_rate_Hz(d.config.sensors)
        assert cap_Hz < 200.0  # the scene's converters are slower than the configured rate
        reads = []
        real = d.sensors.read
        d.sensors.read = lambda: reads.append(1) or real()
        step_s, span_s = 0.005, 1.0
        for _ in range(int(round(span_s / step_s))):
            sim.advance(step_s)
            d._cmd_status({})
        # One reading per conversion the converters deliver (+1: the first poll), not one per STATUS.
        assert 0.8 * span_s * cap_Hz <= len(reads) <= span_s * cap_Hz + 1, (len(reads), cap_Hz)
    finally:
        d.close()
        sim.close()


def test_no_contact_scene_is_still_flagged(tmp_path):
    sim, d = _daemon("pmma_15V_no_contact", tmp_path)
    try:
        rec = d.measure()
    finally:
        d.close()
        sim.close()
    assert "no_contact" in rec["flags"]


def test_quick_profile_rate_per_board(tmp_path):
    ref = Config()
    prec = Config({"sensors": {"thermocouple": "ads122c04", "flux_adc": "ads122c04"}})
    assert max_sample_rate_Hz(ref.sensors) == pytest.approx(12.5)
    assert max_sample_rate_Hz(prec.sensors) >= 50.0
    assert measure_params(prec, 10.0, sample_rate_Hz=50.0).sample_rate_Hz == 50.0
    assert measure_params(ref, 10.0, sample_rate_Hz=50.0).sample_rate_Hz == pytest.approx(12.5)
    sim = load_scene("alu_20V_ads122c04")  # precision board: thermocouple and flux on the ADS122C04
    d = Daemon(config_for_scene(sim.scene, tmp_path, {"sensors": {"thermocouple": "ads122c04"}}), sim.board())
    try:
        rec = d.measure(contact_time_s=0.5, sample_rate_Hz=50.0)
        full = d.history.get(rec["measurement_id"], series=True)
    finally:
        d.close()
        sim.close()
    assert rec["sample_rate_Hz"] == 50.0 and len(full["grid_t_s"]) >= 20


def test_until_decided_on_the_small_heater_decides_on_the_devices_own_estimate(tmp_path):
    from edge.estimation.running import EstimatorDecision

    sim, d = _daemon("glass_15V_small", tmp_path, object_set=lambda: SET)
    try:
        params = measure_params(d.config, d.heater.max_power_W)
        assert type(d._make_decision(params)) is EstimatorDecision
        rec = d.measure(until_decided=True)
        assert rec["status"] == "ok" and "decided" in rec["flags"]
        decision = rec["result"]["decision"]
        assert decision["source"] == "device_estimate" and decision["stopped_early"]
        assert decision["object"] == "glass" and decision["elapsed_s"] < params.contact_time_s / 2
        assert rec["heater_on_s"] < params.contact_time_s / 2
        # The decision is the result's own estimator on a prefix: the result names the same object.
        assert rec["result"]["object"] == "glass" and "decision_disagrees" not in rec["flags"]
        assert max(h.fraction for h in sim.pwm.history()[-1:]) == 0.0   # and the heater is off
    finally:
        d.close()
        sim.close()
    # Without until_decided the whole profile measures, with its running answer undecided.  On a
    # device of its own: a second touch on the same one would first sit out its cool-down, 5 s of
    # the faithful world (most of this test's cost) that this answer does not depend on; touch after
    # touch on one device is test_touch_after_touch_in_a_sim_session_and_ready's.
    sim, d = _daemon("glass_15V_small", tmp_path / "full", object_set=lambda: SET)
    try:
        full = d.measure()
        assert full["status"] == "ok" and "decided" not in full["flags"]
        assert full["result"]["decision"]["object"] == "glass" and not full["result"]["decision"]["stopped_early"]
        assert full["heater_on_s"] == pytest.approx(params.contact_time_s, abs=0.05)
    finally:
        d.close()
        sim.close()


@pytest.mark.parametrize("where", ["attach_record", "update"])
def test_a_failing_running_decision_never_fails_the_touch(tmp_path, where):
    # The sequence hands its record to any decision that takes one (attach_record), then feeds it.
    sim, d = _daemon("pmma_15V", tmp_path, object_set=lambda: SET)
    make = d._make_decision

    def broken(params):
        dec = make(params)

        def boom(*a, **kw):
            raise RuntimeError("decision bug")
        setattr(dec, where, boom)
        return dec
    d._make_decision = broken
    d.sequence = None
    try:
        rec = d.measure(until_decided=True)
        assert rec["status"] == "ok" and "decided" not in rec["flags"]
        assert rec["result"]["object"] == "pmma" and "decision" not in rec["result"]
        assert rec["heater_on_s"] == pytest.approx(measure_params(d.config, d.heater.max_power_W).contact_time_s, abs=0.05)
    finally:
        d.close()
        sim.close()


def test_a_calibrated_device_decides_on_the_sensor_chain(tmp_path):
    from edge.estimation.running import ChainDecision
    from edge.estimation.running import SequentialDecision
    from tests.support.calibrations import sample_calibration

    sim, d = _daemon("glass_15V_faithful", tmp_path, object_set=lambda: SET)
    try:
        params = measure_params(d.config, d.heater.max_power_W)
        dec = d._make_decision(params)
        assert type(dec) is SequentialDecision   # uncalibrated: the thick-body fit of the raw reading
        cal = sample_calibration()
        d.calibration.install(cal.to_json_compact(), None)
        dec = d._make_decision(params)
        assert isinstance(dec, ChainDecision) and dec.calibration == cal
        rec = d.measure(until_decided=True)
        assert rec["status"] == "ok"
        decision = rec["result"]["decision"]
        assert decision["source"] == "sensor_chain" and decision["object"] == "glass"
        # The decision and the result are the same estimate: nothing to disagree about.
        assert rec["result"]["object"] == "glass" and "decision_disagrees" not in rec["flags"]
    finally:
        d.close()
        sim.close()
