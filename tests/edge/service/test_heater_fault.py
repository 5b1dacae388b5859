"""Heater-fault detection on the simulator's faults: a heater that heats when off, or not when on."""

import numpy as np
import pytest

from edge.measure.signal import heat_while_off, no_heat_while_on
from edge.measure.watchdog import Limits
from edge.protocol.errors import CommandError, ErrorCode
from edge.service.daemon import Daemon
from firmware_sim import load_scene
from firmware_sim.run import config_for_scene
from tests.support.daemons import FakeEstimator

pytestmark = pytest.mark.hil
LIMITS = Limits(10.0, 80.0)


def _daemon(tmp_path):
    sim = load_scene("glass_15V")
    cfg = config_for_scene(sim.scene, tmp_path, {"measurement": {"trigger_button": False, "cooldown_s": 2.0}})
    d = Daemon(cfg, sim.board(), estimator=FakeEstimator())
    sim.advance_to(0.6)  # the scene's touch has begun
    return sim, d


def _assert_faulted(sim, d, mid):
    st = d._cmd_status({})
    assert st["heater_fault"] is True and st["state"] == "fault" and st["faults"]
    assert st["heater_on"] is False
    rec = d.history.get(mid)
    assert rec["status"] == "failed" and rec["reason"] == "heater_fault" and "heater_fault" in rec["flags"]
    assert sim.parts.chip.level(sim.parts.heater_enable_offset) == 0  # enable line dropped
    with pytest.raises(CommandError) as ei:  # refuses to measure until restart
        d.measure()
    assert ei.value.code == ErrorCode.BAD_STATE
    assert d.heater.disabled is not None


def test_heater_stuck_on_is_caught_in_the_cool_down(tmp_path):
    sim, d = _daemon(tmp_path)
    first = d.measure()
    assert first["status"] == "ok"
    assert d._cmd_status({})["heater_fault"] is False
    sim.inject("heater_stuck_on")  # the switch fails closed after the first touch
    with pytest.raises(CommandError) as ei:
        d.measure()
    assert ei.value.code == ErrorCode.INTERNAL and "HEATER FAULT" in ei.value.message
    assert "cool-down" in ei.value.message and "heater off" in ei.value.message
    _assert_faulted(sim, d, 2)
    # Caught before heating: the heater was not switched on for the second touch.
    assert d.history.get(2)["heater_on_s"] == 0.0
    d.close()


def test_dead_heater_is_caught_in_the_heating_phase(tmp_path):
    sim, d = _daemon(tmp_path)
    sim.inject("heater_dead")
    with pytest.raises(CommandError) as ei:
        d.measure()
    assert "HEATER FAULT" in ei.value.message and "no heat with the heater on" in ei.value.message
    _assert_faulted(sim, d, 1)
    assert d.history.get(1, series=True)["result"] is None  # nothing estimated from it
    d.close()


def test_a_healthy_heater_is_not_a_fault_on_any_paper_scene_touch(tmp_path):
    sim, d = _daemon(tmp_path)
    assert d.measure()["status"] == "ok"
    assert d.measure()["status"] == "ok"  # in air by now: a healthy cool-down and a no_contact heating
    assert d._cmd_status({})["heater_fault"] is False
    d.close()


def test_heat_while_off_rules():
    t = np.linspace(0.0, 2.0, 21)
    # Stuck on in air: warming, no flux.
    assert heat_while_off(t, 25 + 1.0 * t, np.full(t.size, 10.0), LIMITS)
    # Stuck on in contact: warming with heat leaving the probe.
    assert heat_while_off(t, 25 + 0.4 * t, np.full(t.size, 1300.0), LIMITS)
    # Healthy cool-down: cooling, heat still leaving the probe.
    assert heat_while_off(t, 30 - 1.0 * t, np.full(t.size, 600.0), LIMITS) is None
    # A warmer object warms the probe: the flux is reversed.
    assert heat_while_off(t, 25 + 1.0 * t, np.full(t.size, -2000.0), LIMITS) is None
    # ... also a warm object of low effusivity (PMMA 1 K above the probe: ~100 W/m^2 in, 0.5 K up;
    # the faithful world's pmma_15V_faithful scene was refused as a heater fault before).
    assert heat_while_off(t, 25 + 0.3 * t, np.full(t.size, -100.0), LIMITS) is None
    # A flux into the probe within the noise of a mean does not explain a rise: still a fault.
    assert heat_while_off(t, 25 + 0.3 * t, np.full(t.size, -20.0), LIMITS)
    # Quantised, steady: no rise.
    assert heat_while_off(t, np.full(t.size, 25.0), np.full(t.size, 14.0), LIMITS) is None


def test_no_heat_while_on_rules():
    T0 = 25.0
    n = 20
    assert no_heat_while_on(np.full(n, T0), np.zeros(n), T0, 4.5, LIMITS)  # dead
    assert no_heat_while_on(np.full(n, T0 + 0.2), np.full(n, 1300.0), T0, 4.5, LIMITS) is None  # metal
    assert no_heat_while_on(np.full(n, T0 + 4.0), np.full(n, 5.0), T0, 4.5, LIMITS) is None  # in air
    assert no_heat_while_on(np.full(n, T0 + 0.4), np.full(n, 110.0), T0, 1.28, LIMITS) is None  # PMMA, 8 V
    assert no_heat_while_on(np.full(n, T0), np.zeros(n), T0, 0.5, LIMITS) is None  # too little power to tell
