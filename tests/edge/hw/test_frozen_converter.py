"""A converter that freezes is a sensor fault the device sees (ISSUE #35 §5).

The simulator's ``converter_frozen`` fault stops one chip's conversions (firmware_sim.chips.freeze);
the drivers believe the chips' own new-data indications -- MCP9600 STATUS.TH_UPDATE, ADS1115
CONFIG.OS in single shot, ADS122C04 DRDY -- and raise SensorFault naming the chip when a
conversion is overdue. An unchanged temperature alone is never called a fault (a touch on metal
moves the hot junction by less than one LSB). All on the board's virtual clock.
"""

from __future__ import annotations

import pytest

from edge.hw.chips import max_sample_rate_Hz
from edge.hw.drivers.ads1115 import ADS1115
from edge.hw.drivers.ads122c04 import ADS122C04
from edge.hw.drivers.mcp9600 import MCP9600
from edge.hw.faults import SensorFault
from edge.protocol.errors import CommandError, ErrorCode
from edge.service.daemon import Daemon
from firmware_sim import Simulator, load_scene
from firmware_sim.run import config_for_scene
from firmware_sim.scene.model import SceneError
from tests.support.daemons import FakeEstimator

pytestmark = pytest.mark.hil


def _mcp(sim):
    drv = MCP9600(sim.board().i2c, sim.scene.board.mcp9600, sleep=sim.clock.sleep)  # clock: the sim clock's
    drv.configure(adc_resolution_bits=16)
    return drv


def test_a_frozen_mcp9600_is_seen_within_its_conversion_time_and_recovers():
    sim = load_scene("glass_15V")
    drv = _mcp(sim)
    assert drv.clock == sim.clock.monotonic
    period = 0.1
    for _ in range(20):  # a working converter at 10 Hz: never a fault
        sim.advance(period)
        drv.read_hot_junction_C()
    t_freeze = sim.now() + 0.01
    sim.inject("converter_frozen", at_s=t_freeze, until_s=t_freeze + 2.0, chip="mcp9600")
    with pytest.raises(SensorFault) as ei:
        for _ in range(10):
            sim.advance(period)
            drv.read_hot_junction_C()
    assert ei.value.sensor == "mcp9600@0x60" and ei.value.reason == "timeout" and "stuck" in str(ei.value)
    # Seen once the conversion due after the last clear is overdue: within two sample periods.
    assert sim.now() - t_freeze <= 2 * period + 1e-9
    assert sim.now() - t_freeze >= drv.conversion_time_s  # not before a conversion was even due
    sim.advance_to(t_freeze + 2.0 + period)  # the freeze ends: the same driver reads again
    for _ in range(5):
        sim.advance(period)
        drv.read_hot_junction_C()


def test_an_unchanging_temperature_is_no_fault():
    """A steady input (a touch on metal moves the junction by under 0.0625 C): the same register value for
    50 reads, every one accepted -- the chip's update flag is what counts, not the value."""
    sim = Simulator(load_scene("glass_15V").scene)
    drv = _mcp(sim)
    sim.chips["mcp9600"].hot_junction_C = lambda t: 25.03
    values = set()
    for _ in range(50):
        sim.advance(0.1)
        values.add(drv.read_hot_junction_C())
    assert len(values) == 1


def test_a_frozen_ads1115_single_shot_is_a_timeout_naming_it_and_recovers():
    sim = load_scene("glass_15V")
    ads = ADS1115(sim.board().i2c, sim.scene.board.ads1115, on_saturation="flag", sleep=sim.clock.sleep)
    ads.configure(fsr_V=0.256, data_rate_sps=128)
    ads.read_single_shot_V()
    sim.inject("converter_frozen", until_s=sim.now() + 1.0, chip="ads1115")
    t0 = sim.now()
    with pytest.raises(SensorFault) as ei:
        ads.read_single_shot_V()
    assert (ei.value.sensor, ei.value.reason) == ("ads1115@0x48", "timeout") and "CONFIG.OS" in str(ei.value)
    assert sim.now() - t0 <= 3.0 / 128 + 0.011  # three conversion times plus 10 ms
    sim.advance(1.0)
    ads.read_single_shot_V()  # thawed: the pending conversion finished, a new one runs


def test_a_frozen_ads122c04_never_sets_drdy_and_recovers():
    sim = load_scene("alu_20V_ads122c04")
    adc = ADS122C04(sim.board().i2c, sim.scene.board.ads122c04, on_saturation="flag", sleep=sim.clock.sleep)
    adc.reset()
    adc.configure(gain=128, data_rate_sps=1000)
    adc.read_flux_voltage_V()
    sim.inject("converter_frozen", until_s=sim.now() + 1.0, chip="ads122c04")
    with pytest.raises(SensorFault) as ei:
        adc.read_flux_voltage_V()
    assert (ei.value.sensor, ei.value.reason) == ("ads122c04@0x40", "timeout") and "DRDY" in str(ei.value)
    sim.advance(1.0)
    adc.read_flux_voltage_V()


def test_the_fault_names_a_fitted_chip():
    sim = load_scene("glass_15V")
    with pytest.raises(ValueError, match="not fitted"):
        sim.inject("converter_frozen", chip="ads122c04")
    with pytest.raises(SceneError, match="chip"):
        sim.inject("converter_frozen")


def _daemon(tmp_path, scene="glass_15V"):
    sim = load_scene(scene)
    cfg = config_for_scene(sim.scene, tmp_path, {"measurement": {"trigger_button": False, "cooldown_s": 2.0}})
    d = Daemon(cfg, sim.board(), estimator=FakeEstimator())
    sim.advance_to(0.6)  # the scene's touch has begun
    return sim, d, cfg


def test_a_thermocouple_converter_frozen_mid_heating_stops_the_heater_and_nothing_latches(tmp_path):
    sim, d, cfg = _daemon(tmp_path)
    assert d.measure()["status"] == "ok"
    t1 = sim.now()
    sim.add_touch(t1, 6.0, press_trigger=False)
    period = 1.0 / min(cfg.measurement.sample_rate_Hz, max_sample_rate_Hz(cfg.sensors))   # the rate sampled
    # Heater on after the cool-down and the baseline (as the first touch: 0.5 s after it began);
    # frozen a second into the heating, for a few seconds.
    t_freeze = t1 + cfg.measurement.cooldown_s + cfg.measurement.baseline_s + 1.0
    sim.inject("converter_frozen", at_s=t_freeze, until_s=t_freeze + 3.0, chip="mcp9600")
    with pytest.raises(CommandError) as ei:
        d.measure()
    assert ei.value.code == ErrorCode.SENSOR_FAULT and "mcp9600@0x60" in ei.value.message
    on_a, on_b = sim.heater_intervals()[-1]
    assert on_a < t_freeze < on_b <= t_freeze + 2 * period + 1e-6  # stopped within two sample periods
    rec = d.history.get(2)
    assert (rec["status"], rec["reason"]) == ("failed", "sensor_fault") and "mcp9600@0x60" in rec["error"]
    st = d._cmd_status({})
    assert st["can_measure"] is True and st["faults"] == [] and st["heater_fault"] is False
    assert st["heater_on"] is False and sim.parts.chip.level(sim.parts.heater_enable_offset) == 0
    # Nothing latched: once the converter runs again the next touch measures.
    sim.advance_to(t_freeze + 3.0)
    sim.add_touch(sim.now(), 6.0, press_trigger=False)
    assert d.measure()["status"] == "ok"
    d.close()


def test_a_frozen_flux_converter_stops_the_touch_too(tmp_path):
    sim, d, cfg = _daemon(tmp_path)
    sim.inject("converter_frozen", at_s=sim.now() + cfg.measurement.baseline_s + 0.5, chip="ads1115")
    with pytest.raises(CommandError) as ei:
        d.measure()
    assert ei.value.code == ErrorCode.SENSOR_FAULT and "ads1115@0x48" in ei.value.message
    assert d.history.get(1)["reason"] == "sensor_fault" and d._cmd_status({})["can_measure"] is True
    assert sim.heater_on_time_s() < 1.0
    d.close()
