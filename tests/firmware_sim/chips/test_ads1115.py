import pytest

from edge.hw.drivers.ads1115 import ADS1115
from edge.hw.regmaps.ads1115 import PGA_FSR_V, REGISTERS, code_to_volts, volts_to_code
from edge.hw.faults import SensorFault
from firmware_sim.bus import SimBus
from firmware_sim.chips.ads1115 import ADS1115Emulator
from firmware_sim.clock import VirtualClock

ADDR = 0x48


def make(inputs=lambda mux, t: 0.0, **kw):
    clock = VirtualClock()
    bus = SimBus(clock=clock, rng=3)
    chip = bus.attach(ADDR, ADS1115Emulator(clock, inputs, **kw))
    return clock, bus, chip


def rd(bus, reg):
    return int.from_bytes(bytes(bus.read_i2c_block_data(ADDR, reg, 2)), "big")


def wr(bus, reg, value):
    bus.write_i2c_block_data(ADDR, reg, [value >> 8, value & 0xFF])


def s16(v):
    return v - 0x10000 if v & 0x8000 else v


def test_reset_values():
    _, bus, _ = make()
    assert rd(bus, 0x01) == 0x8583
    assert rd(bus, 0x02) == 0x8000
    assert rd(bus, 0x03) == 0x7FFF
    assert REGISTERS.CONFIG.decode(0x8583) == {
        "OS": 1, "MUX": "AIN0_AIN1", "PGA": 2.048, "MODE": "single", "DR": 128,
        "COMP_MODE": "traditional", "COMP_POL": "active_low", "COMP_LAT": "nonlatching",
        "COMP_QUE": "disable"}


def test_word_read_is_byte_swapped_by_smbus():
    _, bus, _ = make()
    assert bus.read_word_data(ADDR, 0x01) == 0x8385


@pytest.mark.parametrize("pga, fsr", list(PGA_FSR_V.items()))
def test_code_volts_at_each_pga(pga, fsr):
    v = 0.3 * fsr
    clock, bus, _ = make(lambda mux, t: v)
    cfg = REGISTERS.CONFIG.encode(0x8583, OS=1)
    cfg = (cfg & ~0x0E00) | (pga << 9)
    wr(bus, 0x01, cfg)
    clock.advance(1 / 128)
    code = s16(rd(bus, 0x00))
    assert code == round(0.3 * 32768)
    assert code_to_volts(code, fsr) == pytest.approx(v, abs=fsr / 32768)


def test_lsb_and_clipping():
    assert code_to_volts(1, 0.256) == pytest.approx(7.8125e-6)
    assert code_to_volts(1, 4.096) == pytest.approx(125e-6)
    assert volts_to_code(1.0, 0.256) == 0x7FFF
    assert volts_to_code(-1.0, 0.256) == -0x8000
    clock, bus, _ = make(lambda mux, t: -3.0)   # beyond -2.048 V
    wr(bus, 0x01, 0x8583)
    clock.advance(0.01)
    assert rd(bus, 0x00) == 0x8000


def test_single_shot_os_bit_timing():
    clock, bus, chip = make(lambda mux, t: 0.5)
    wr(bus, 0x01, 0x8583 | 0x00E0)            # 860 SPS, single shot, start
    assert not rd(bus, 0x01) & 0x8000          # converting
    clock.advance(1 / 860 * 0.99)
    assert not rd(bus, 0x01) & 0x8000
    clock.advance(1 / 860 * 0.02)
    assert rd(bus, 0x01) & 0x8000              # done
    assert s16(rd(bus, 0x00)) == round(0.5 * 32768 / 2.048)
    clock.advance(1.0)
    assert chip.conversions == 1               # powered down after one conversion


def test_continuous_rate_and_mux_labels():
    seen = []

    def inputs(mux, t):
        seen.append(mux)
        return 0.001 * t

    clock, bus, chip = make(inputs)
    wr(bus, 0x01, (0x8583 & ~0x0100 & ~0x7000) | (4 << 12))   # continuous, AIN0_GND
    clock.advance(10 / 128 + 1e-6)
    rd(bus, 0x00)
    assert chip.conversions == 10
    assert set(seen) == {"AIN0_GND"}
    assert not rd(bus, 0x01) & 0x8000          # OS reads 0 in continuous mode


def test_conversion_ready_pin():
    clock, bus, chip = make(lambda mux, t: 0.1)
    wr(bus, 0x03, 0x8000)
    wr(bus, 0x02, 0x0000)
    assert chip.alert_pin_high                 # comparator disabled: pulled up
    wr(bus, 0x01, 0x8583 & ~0x3)               # COMP_QUE=0, start single shot
    assert chip.alert_pin_high
    clock.advance(1 / 128 + 1e-6)
    assert not chip.alert_pin_high             # active low: conversion ready
    wr(bus, 0x01, (0x8583 & ~0x3) & ~0x0100)   # continuous
    n = chip.rdy_pulses
    clock.advance(5 / 128 + 1e-6)
    rd(bus, 0x00)
    assert chip.rdy_pulses - n == 5


def test_traditional_comparator_with_hysteresis():
    level = {"v": 0.0}
    clock, bus, chip = make(lambda mux, t: level["v"])
    wr(bus, 0x03, 1000)
    wr(bus, 0x02, 500)
    wr(bus, 0x01, (0x8583 & ~0x3 & ~0x0100))   # continuous, queue 1
    clock.advance(0.01)
    assert not chip.alert_asserted
    level["v"] = 1100 * 2.048 / 32768
    clock.advance(0.01)
    assert chip.alert_asserted
    level["v"] = 700 * 2.048 / 32768           # between thresholds: stays asserted
    clock.advance(0.01)
    assert chip.alert_asserted
    level["v"] = 400 * 2.048 / 32768
    clock.advance(0.01)
    assert not chip.alert_asserted


# ---- driver ------------------------------------------------------------------

def flux_inputs(q_W_m2):
    return lambda mux, t: q_W_m2 * 0.56e-6 if mux == "AIN0_AIN1" else 0.0


def test_driver_single_shot_flux_voltage():
    clock, bus, _ = make(flux_inputs(5000.0))
    drv = ADS1115(bus, ADDR, sleep=clock.sleep)
    drv.configure(mux="AIN0_AIN1", fsr_V=0.256, data_rate_sps=860)
    t0 = clock.now()
    v = drv.read_single_shot_V()
    assert v == pytest.approx(2.8e-3, abs=7.9e-6)
    assert drv.read_single_shot_code() == round(2.8e-3 / 7.8125e-6)
    assert clock.now() - t0 == pytest.approx(2 / 860, rel=1e-6)
    cfg = drv.read_config()
    assert (cfg["PGA"], cfg["DR"], cfg["MUX"]) == (0.256, 860, "AIN0_AIN1")


def test_driver_continuous_mode():
    clock, bus, chip = make(lambda mux, t: 1e-3 * t)
    drv = ADS1115(bus, ADDR, sleep=clock.sleep)
    drv.configure(fsr_V=0.256, data_rate_sps=250)
    drv.start_continuous()
    clock.advance(0.1)
    v1 = drv.read_latest_V()
    clock.advance(0.1)
    v2 = drv.read_latest_V()
    assert v2 - v1 == pytest.approx(1e-4, abs=2e-5)
    drv.stop_continuous()
    n = chip.conversions
    clock.advance(1.0)
    assert chip.register("CONFIG") & 0x8000
    assert chip.conversions <= n + 1


def test_driver_saturation_raise_and_flag():
    clock, bus, _ = make(flux_inputs(1e6))     # far beyond ±0.256 V
    drv = ADS1115(bus, ADDR, sleep=clock.sleep)
    drv.configure()
    with pytest.raises(SensorFault) as ei:
        drv.read_single_shot_V()
    assert ei.value.reason == "saturated" and ei.value.sensor == "ads1115@0x48"
    drv2 = ADS1115(bus, ADDR, on_saturation="flag", sleep=clock.sleep)
    drv2.configure()
    assert drv2.read_single_shot_V() == pytest.approx(0.256 * 32767 / 32768)
    assert drv2.saturated


def test_driver_retries_then_fault():
    clock, bus, _ = make(flux_inputs(100.0))
    drv = ADS1115(bus, ADDR, attempts=6, sleep=clock.sleep)
    drv.configure()
    bus.flaky(0.3)
    vals = [drv.read_single_shot_V() for _ in range(20)]
    assert all(v == pytest.approx(56e-6, abs=8e-6) for v in vals)
    bus.clear_faults()
    bus.nack(ADDR)
    with pytest.raises(SensorFault) as ei:
        drv.read_single_shot_V()
    assert ei.value.reason == "i2c"


def test_driver_argument_checks():
    _, bus, _ = make()
    with pytest.raises(ValueError, match="address"):
        ADS1115(bus, 0x60)
    with pytest.raises(ValueError, match="PGA"):
        ADS1115(bus, ADDR).configure(fsr_V=0.3)
    with pytest.raises(ValueError, match="on_saturation"):
        ADS1115(bus, ADDR, on_saturation="ignore")
