import errno

import pytest
from smbus2 import i2c_msg

from edge.physics import typek
from edge.hw.drivers.mcp9600 import MCP9600
from edge.hw.regmaps.mcp9600 import REGISTERS
from edge.hw.faults import SensorFault
from firmware_sim.bus import SimBus
from firmware_sim.chips.mcp9600 import MCP9600Emulator
from firmware_sim.clock import VirtualClock

ADDR = 0x60


def make(hot=lambda t: 25.0, cold=lambda t: 25.0, **kw):
    clock = VirtualClock()
    bus = SimBus(clock=clock, rng=5)
    chip = bus.attach(ADDR, MCP9600Emulator(clock, hot, cold, **kw))
    return clock, bus, chip


def be16(bus, reg):
    """Third-party style: plain smbus2 word read, swapped to the chip's MSB-first order."""
    w = bus.read_word_data(ADDR, reg)
    return ((w & 0xFF) << 8) | (w >> 8)


def signed16(v):
    return v - 0x10000 if v & 0x8000 else v


# ---- register-level behaviour (talks only smbus2 API calls) -------------------

def test_datasheet_codes_25C_and_minus_10C():
    clock, bus, chip = make(hot=lambda t: 25.0, cold=lambda t: 25.0)
    clock.advance(0.33)
    assert be16(bus, 0x00) == 0x0190           # +25.0 °C
    assert be16(bus, 0x02) == 0x0190
    clock2, bus2, _ = make(hot=lambda t: -10.0, cold=lambda t: -10.0)
    clock2.advance(0.33)
    assert be16(bus2, 0x00) == 0xFF60          # -10.0 °C
    assert signed16(be16(bus2, 0x00)) / 16 == -10.0


def test_device_id_and_revision():
    _, bus, _ = make()
    assert bus.read_i2c_block_data(ADDR, 0x20, 2) == [0x40, 0x11]


def test_identity_th_equals_delta_plus_tc_and_accuracy():
    clock, bus, _ = make(hot=lambda t: 61.3, cold=lambda t: 23.4)
    clock.advance(0.65)
    th, td, tc = (signed16(be16(bus, r)) for r in (0, 1, 2))
    assert th == td + tc
    assert tc / 16 == 23.375                   # truncated to 0.0625
    assert abs(th / 16 - 61.3) <= 0.0625 + 0.05


def test_sum_method_differs_from_nist_method():
    c1, b1, _ = make(hot=lambda t: 80.0, cold=lambda t: 25.0, cjc_method="sum")
    c2, b2, _ = make(hot=lambda t: 80.0, cold=lambda t: 25.0)
    c1.advance(0.33)
    c2.advance(0.33)
    assert be16(b2, 0) / 16 == pytest.approx(80.0, abs=0.07)
    assert be16(b1, 0) / 16 - 80.0 > 0.5       # T(E)+Tc over-reads above the cold junction


def test_raw_adc_register_quantised_to_resolution():
    clock, bus, _ = make(hot=lambda t: 30.0, cold=lambda t: 25.0)
    clock.advance(0.33)
    raw = bus.read_i2c_block_data(ADDR, 0x03, 3)
    code = int.from_bytes(bytes(raw), "big")
    e = (typek.emf_mV(30.0) - typek.emf_mV(25.0)) * 1e-3
    assert code == round(e / 2e-6)
    bus.write_byte_data(ADDR, 0x06, 0x60)       # 12-bit: 128 µV steps = 64 units
    clock.advance(0.006)
    code12 = int.from_bytes(bytes(bus.read_i2c_block_data(ADDR, 0x03, 3)), "big")
    assert code12 % 64 == 0 and abs(code12 * 2e-6 - e) <= 64e-6


def test_cold_junction_quarter_degree_resolution():
    clock, bus, _ = make(cold=lambda t: 23.4)
    bus.write_byte_data(ADDR, 0x06, 0x80)
    clock.advance(0.07)
    assert be16(bus, 0x02) & 0x3 == 0
    assert be16(bus, 0x02) / 16 == 23.25


@pytest.mark.parametrize("bits, code, t_conv", [(18, 0x00, 0.320), (16, 0x20, 0.080),
                                                 (14, 0x40, 0.020), (12, 0x60, 0.005)])
def test_conversion_time_per_resolution(bits, code, t_conv):
    clock, bus, chip = make(hot=lambda t: 20.0 + 100.0 * t)
    bus.write_byte_data(ADDR, 0x06, code)
    bus.write_byte_data(ADDR, 0x04, 0x00)       # clear TH update
    clock.advance(t_conv * 0.99)
    assert not bus.read_byte_data(ADDR, 0x04) & 0x40
    clock.advance(t_conv * 0.02)
    assert bus.read_byte_data(ADDR, 0x04) & 0x40


def test_status_flags_cleared_by_zero_not_set_by_one():
    clock, bus, _ = make()
    clock.advance(0.33)
    assert bus.read_byte_data(ADDR, 0x04) & 0x40
    bus.write_byte_data(ADDR, 0x04, 0x00)
    assert bus.read_byte_data(ADDR, 0x04) == 0x00
    bus.write_byte_data(ADDR, 0x04, 0xFF)
    assert bus.read_byte_data(ADDR, 0x04) == 0x00


def test_open_thermocouple_sets_input_range_and_freezes_th():
    opened = {"v": False}
    clock, bus, chip = make(hot=lambda t: 40.0, open_circuit=lambda t: opened["v"])
    clock.advance(0.33)
    th_before = be16(bus, 0x00)
    opened["v"] = True
    clock.advance(0.33)
    assert bus.read_byte_data(ADDR, 0x04) & 0x10
    assert be16(bus, 0x00) == th_before
    opened["v"] = False
    clock.advance(0.33)
    assert not bus.read_byte_data(ADDR, 0x04) & 0x10


def test_shutdown_stops_and_burst_runs_n_samples():
    clock, bus, chip = make(hot=lambda t: 30.0 + t)
    bus.write_byte_data(ADDR, 0x06, 0x61)       # 12-bit, shutdown
    n0 = chip.conversions
    clock.advance(1.0)
    assert chip.conversions == n0
    bus.write_byte_data(ADDR, 0x04, 0x00)
    bus.write_byte_data(ADDR, 0x06, 0x60 | (3 << 2) | 0x2)   # burst of 8 at 5 ms
    clock.advance(0.039)
    assert not bus.read_byte_data(ADDR, 0x04) & 0x80
    clock.advance(0.002)
    assert bus.read_byte_data(ADDR, 0x04) & 0x80
    assert chip.conversions == n0 + 8
    assert REGISTERS.DEVICE_CONFIG.get(bus.read_byte_data(ADDR, 0x06), "MODE") == "shutdown"
    clock.advance(1.0)
    assert chip.conversions == n0 + 8


def test_filter_slows_a_step():
    step = lambda t: 25.0 if t < 1.0 else 35.0
    c0, b0, _ = make(hot=step)
    c1, b1, _ = make(hot=step)
    b1.write_byte_data(ADDR, 0x05, 0x02)        # filter n=2, 18-bit conversions
    c0.advance(3.0)
    c1.advance(3.0)
    assert be16(b0, 0) / 16 == pytest.approx(35.0, abs=0.1)
    assert 26.0 < be16(b1, 0) / 16 < 34.0


def test_i2c_rdwr_split_and_combined_reads():
    clock, bus, _ = make(hot=lambda t: 25.0)
    clock.advance(0.33)
    wr, rd = i2c_msg.write(ADDR, [0x00]), i2c_msg.read(ADDR, 2)
    bus.i2c_rdwr(wr)
    bus.i2c_rdwr(rd)
    assert list(rd) == [0x01, 0x90]
    rd2 = i2c_msg.read(ADDR, 2)
    bus.i2c_rdwr(i2c_msg.write(ADDR, [0x20]), rd2)
    assert list(rd2) == [0x40, 0x11]


# ---- driver against the model ------------------------------------------------------

@pytest.mark.parametrize("transport", ["split", "combined", "smbus"])
def test_driver_reads_temperatures(transport):
    clock, bus, _ = make(hot=lambda t: 47.0, cold=lambda t: 22.0)
    drv = MCP9600(bus, ADDR, transport=transport, sleep=clock.sleep)
    assert drv.probe() == (0x40, 0x11)
    drv.configure(adc_resolution_bits=18)
    assert drv.read_config()["TYPE"] == "K"
    drv.wait_for_update()
    r = drv.read()
    assert r.cold_C == 22.0
    assert r.hot_C == pytest.approx(47.0, abs=0.07)
    assert r.hot_C == r.delta_C + r.cold_C
    assert drv.read_raw_emf_V() == pytest.approx((typek.emf_mV(47.0) - typek.emf_mV(22.0)) * 1e-3, abs=2e-6)


def test_wait_for_update_uses_virtual_time():
    clock, bus, _ = make()
    drv = MCP9600(bus, ADDR, sleep=clock.sleep)
    drv.configure(adc_resolution_bits=14)
    t0 = clock.now()
    drv.wait_for_update()
    assert 0.0 < clock.now() - t0 <= 0.020 + drv.conversion_time_s / 8 + 1e-9


def test_driver_open_thermocouple_fault():
    clock, bus, chip = make()
    drv = MCP9600(bus, ADDR, sleep=clock.sleep)
    drv.configure(adc_resolution_bits=12)
    chip.set_open(True)
    drv.wait_for_update()
    with pytest.raises(SensorFault) as ei:
        drv.read_hot_junction_C()
    assert ei.value.reason == "open_thermocouple" and ei.value.sensor == "mcp9600@0x60"
    assert "mcp9600@0x60" in str(ei.value) and "open_thermocouple" in str(ei.value)


def test_driver_recovers_from_clock_stretch_flakiness():
    clock, bus, _ = make(hot=lambda t: 33.0)
    bus.flaky(0.3, ADDR, reads_only=True)
    drv = MCP9600(bus, ADDR, attempts=8, sleep=clock.sleep)
    clock.advance(0.33)
    values = [drv.read_hot_junction_C() for _ in range(50)]
    assert all(v == pytest.approx(33.0, abs=0.07) for v in values)
    assert bus.stats["flaky"] > 10 and drv.retries >= bus.stats["flaky"] // 2


def test_driver_gives_up_after_bound_with_backoff():
    clock, bus, _ = make()
    sleeps = []
    drv = MCP9600(bus, ADDR, attempts=3, backoff_s=0.001, sleep=sleeps.append)
    bus.nack(ADDR)
    with pytest.raises(SensorFault) as ei:
        drv.read_cold_junction_C()
    assert ei.value.reason == "i2c" and ei.value.sensor == "mcp9600@0x60"
    assert isinstance(ei.value.__cause__, OSError) and ei.value.__cause__.errno == errno.EREMOTEIO
    assert sleeps == [0.001, 0.002]
    assert bus.stats["nack"] == 3


def test_driver_timeout_reason_on_stuck_bus():
    clock, bus, _ = make()
    drv = MCP9600(bus, ADDR, attempts=2, sleep=clock.sleep)
    bus.stuck()
    with pytest.raises(SensorFault) as ei:
        drv.probe()
    assert ei.value.reason == "timeout"


def test_driver_wrong_id_and_bad_arguments():
    clock = VirtualClock()
    bus = SimBus(clock=clock)
    chip = bus.attach(ADDR, MCP9600Emulator(clock, lambda t: 25.0))
    chip.regs[0x20] = 0x4111
    with pytest.raises(SensorFault) as ei:
        MCP9600(bus, ADDR, sleep=clock.sleep).probe()
    assert ei.value.reason == "not_found"
    with pytest.raises(ValueError, match="address"):
        MCP9600(bus, 0x48)
    with pytest.raises(ValueError, match="ADC_RESOLUTION"):
        MCP9600(bus, ADDR).configure(adc_resolution_bits=10)
