"""No ordinary request latches the device (ISSUE #35 §3): a touch too short to judge is refused before heating."""

import pytest

from edge.measure.signal import min_contact_time_s
from edge.protocol.errors import CommandError, ErrorCode
from edge.service.daemon import Daemon
from edge.service.requests import measure_params
from firmware_sim import load_scene
from firmware_sim.run import config_for_scene
from tests.support.daemons import FakeEstimator

pytestmark = pytest.mark.hil


def test_the_shortest_touch_follows_the_sample_rate():
    assert min_contact_time_s(10.0) == 0.5 and min_contact_time_s(12.5) == 0.5
    assert min_contact_time_s(4.0) == pytest.approx(1.25)  # five samples at 4 Hz


@pytest.mark.parametrize("scene", ["glass_15V", "pmma_15V", "alu_20V"])
def test_a_too_short_touch_is_a_bad_argument_and_the_device_measures_after_it(tmp_path, scene):
    sim = load_scene(scene)
    cfg = config_for_scene(sim.scene, tmp_path, {"measurement": {"trigger_button": False}})
    d = Daemon(cfg, sim.board(), estimator=FakeEstimator())
    sim.advance_to(0.6)  # the scene's touch has begun
    try:
        for t in (0.1, 0.26, 0.49):
            with pytest.raises(CommandError) as ei:
                d.measure(contact_time_s=t)
            assert ei.value.code == ErrorCode.BAD_ARGUMENT and ei.value.field == "contact_time_s"
            assert "too short" in str(ei.value)
            st = d._cmd_status({})
            assert st["heater_fault"] is False and st["state"] != "fault" and st["can_measure"] is True
        assert d.history.count() == 0  # refused before anything heated
        assert sim.parts.chip.level(sim.parts.heater_enable_offset) == 0
        res = d.measure(contact_time_s=min_contact_time_s(measure_params(d.config, d.heater.max_power_W)
                                                          .sample_rate_Hz))
        assert res["status"] == "ok", res
        assert d._cmd_status({})["heater_fault"] is False
    finally:
        d.close()


def test_no_cool_down_then_an_armed_touch_does_not_latch(tmp_path):
    """ISSUE #35 §3: cooldown_s = 0 followed by an armed MEASURE latched HEATER FAULT."""
    sim = load_scene("glass_15V")
    cfg = config_for_scene(sim.scene, tmp_path, {"measurement": {"trigger_button": False, "cooldown_s": 0.0}})
    d = Daemon(cfg, sim.board(), estimator=FakeEstimator())
    sim.advance_to(0.6)
    try:
        assert d.measure(contact_time_s=1.0)["status"] == "ok"
        assert d.measure(contact_time_s=1.0, arm_s=2.0, settle_s=0.2)["status"] in ("ok", "aborted")
        st = d._cmd_status({})
        assert st["heater_fault"] is False and st["can_measure"] is True and d.heater.disabled is None
        assert d.measure(contact_time_s=1.0)["status"] == "ok"
    finally:
        d.close()
