import pytest

from edge.physics import typek
from edge.hw.drivers.ads122c04 import ADS122C04
from edge.hw.regmaps.ads122c04 import (
    REGISTERS,
    code_to_volts,
    conversion_time_s,
    crc16_ccitt,
    rdata_frame,
    rreg,
    temperature_code_to_C,
    wreg,
)
from edge.hw.faults import SensorFault
from firmware_sim.bus import SimBus
from firmware_sim.chips.ads122c04 import ADS122C04Emulator
from firmware_sim.clock import VirtualClock

ADDR = 0x40

# Datasheet Table 13: temperature -> 14-bit code.
TEMP_TABLE = [(128.0, 0x1000), (127.96875, 0x0FFF), (100.0, 0x0C80), (75.0, 0x0960),
              (50.0, 0x0640), (25.0, 0x0320), (0.25, 0x0008), (0.03125, 0x0001), (0.0, 0x0000),
              (-0.25, 0x3FF8), (-25.0, 0x3CE0), (-40.0, 0x3B00)]


def make(inputs=lambda mux, t: 0.0, **kw):
    clock = VirtualClock()
    bus = SimBus(clock=clock, rng=9)
    chip = bus.attach(ADDR, ADS122C04Emulator(clock, inputs, **kw))
    return clock, bus, chip


def rdata(bus, n=3):
    return int.from_bytes(bytes(bus.read_i2c_block_data(ADDR, 0x10, n)[:3]), "big")


@pytest.mark.parametrize("t_C, code14", TEMP_TABLE)
def test_temperature_code_conversion_table(t_C, code14):
    assert temperature_code_to_C(code14 << 10) == t_C


@pytest.mark.parametrize("t_C, code14", TEMP_TABLE[1:])   # 128 °C is the sensor's limit
def test_chip_temperature_sensor_produces_table_codes(t_C, code14):
    clock, bus, _ = make(temperature_C=lambda t: t_C)
    bus.write_byte_data(ADDR, wreg(1), 0x01)       # TS=1
    bus.write_byte(ADDR, 0x08)                     # START
    clock.advance(0.051)
    assert rdata(bus) == code14 << 10


def test_commands_reset_rreg_wreg():
    _, bus, chip = make()
    for r in range(4):
        assert bus.read_byte_data(ADDR, rreg(r)) == 0x00
    bus.write_byte_data(ADDR, wreg(0), 0x3E)
    bus.write_byte_data(ADDR, wreg(3), 0xA4)
    assert bus.read_byte_data(ADDR, 0x20 | (0 << 2)) == 0x3E
    assert bus.read_byte_data(ADDR, rreg(3)) == 0xA4
    assert REGISTERS.CONFIG0.decode(0x3E) == {"MUX": "AIN1_AIN0", "GAIN": 128, "PGA_BYPASS": 0}
    bus.write_byte(ADDR, 0x06)                     # RESET
    assert [bus.read_byte_data(ADDR, rreg(r)) for r in range(4)] == [0, 0, 0, 0]
    bus.write_byte(ADDR, 0x07)                     # 0000011x: also RESET
    bus.write_byte_data(ADDR, wreg(2), 0x80)       # DRDY is read-only
    assert bus.read_byte_data(ADDR, rreg(2)) == 0x00


def test_single_shot_timing_and_drdy():
    clock, bus, chip = make(lambda mux, t: 0.5)
    bus.write_byte(ADDR, 0x08)
    t_ss = 51213 / 1.024e6                         # Table 12, 20 SPS single-shot
    clock.advance(t_ss - 1e-5)
    assert not bus.read_byte_data(ADDR, rreg(2)) & 0x80
    clock.advance(2e-5)
    assert bus.read_byte_data(ADDR, rreg(2)) & 0x80
    assert bus.read_byte_data(ADDR, rreg(2)) & 0x80       # RREG does not clear DRDY
    assert rdata(bus) == round(0.5 / 2.048 * 2 ** 23)
    assert not bus.read_byte_data(ADDR, rreg(2)) & 0x80   # RDATA clears it
    clock.advance(1.0)
    assert chip.conversions == 1


def test_conversion_time_table():
    assert conversion_time_s(0, False, True) == pytest.approx(50.01e-3, abs=1e-5)
    assert conversion_time_s(0, False, False) == pytest.approx(49.99e-3, abs=1e-5)
    assert conversion_time_s(6, False, True) == pytest.approx(1.04e-3, abs=1e-5)
    assert conversion_time_s(0, True, False) == pytest.approx(25.00e-3, abs=1e-5)
    assert conversion_time_s(2, True, True) == pytest.approx(5.65e-3, abs=1e-5)
    with pytest.raises(ValueError):
        conversion_time_s(7, False, True)


def test_continuous_mode_rate_and_counter():
    clock, bus, chip = make(lambda mux, t: 0.1)
    bus.write_byte_data(ADDR, wreg(1), (6 << 5) | 0x08 | 0x00)   # 1000 SPS, continuous
    bus.write_byte_data(ADDR, wreg(2), 0x40)                     # DCNT
    bus.write_byte(ADDR, 0x08)
    clock.advance(1061 / 1.024e6 + 9 * 1036 / 1.024e6 + 1e-6)
    frame = bytes(bus.read_i2c_block_data(ADDR, 0x10, 4))
    assert frame[0] == 10 and chip.conversions == 10
    bus.write_byte(ADDR, 0x02)                                   # POWERDOWN
    clock.advance(0.1)
    bus.read_byte_data(ADDR, rreg(0))
    assert chip.conversions == 10


@pytest.mark.parametrize("gain", [1, 2, 4, 8, 16, 32, 64, 128])
def test_gain_scaling_and_clipping(gain):
    v = 0.5 * 2.048 / gain
    clock, bus, _ = make(lambda mux, t: v)
    bus.write_byte_data(ADDR, wreg(0), (gain.bit_length() - 1) << 1)
    bus.write_byte(ADDR, 0x08)
    clock.advance(0.06)
    code = rdata(bus)
    assert code == 1 << 22
    assert code_to_volts(code, gain) == pytest.approx(v)
    clock2, bus2, _ = make(lambda mux, t: 4 * v)
    bus2.write_byte_data(ADDR, wreg(0), (gain.bit_length() - 1) << 1)
    bus2.write_byte(ADDR, 0x08)
    clock2.advance(0.06)
    assert rdata(bus2) == 0x7FFFFF


def test_monitors_and_shorted_inputs():
    clock, bus, _ = make(lambda mux, t: 1.0, avdd_V=3.3)
    bus.write_byte_data(ADDR, wreg(0), 13 << 4)      # (AVDD-AVSS)/4
    bus.write_byte(ADDR, 0x08)
    clock.advance(0.06)
    assert code_to_volts(rdata(bus), 1) == pytest.approx(0.825, abs=1e-6)
    bus.write_byte_data(ADDR, wreg(0), 14 << 4)      # shorted
    bus.write_byte(ADDR, 0x08)
    clock.advance(0.06)
    assert rdata(bus) == 0


def test_crc_and_inverted_frames():
    payload = bytes([0x12, 0x34, 0x56])
    assert rdata_frame(0x123456, None, "off") == payload
    assert rdata_frame(0x123456, None, "inverted") == payload + bytes([0xED, 0xCB, 0xA9])
    assert crc16_ccitt(b"123456789") == 0x29B1    # CRC-16/CCITT-FALSE check value
    assert rdata_frame(0x123456, 7, "crc16")[-2:] == crc16_ccitt(bytes([7]) + payload).to_bytes(2, "big")


# ---- driver ------------------------------------------------------------------

def probe_world(t_hot, t_cj, flux_W_m2):
    emf = (typek.emf_mV(t_hot) - typek.emf_mV(t_cj)) * 1e-3

    def inputs(mux, t):
        return {"AIN0_AIN1": emf, "AIN2_AIN3": flux_W_m2 * 0.56e-6}.get(mux, 0.0)
    return inputs


def test_driver_thermocouple_with_internal_cold_junction():
    clock, bus, _ = make(probe_world(31.234, 24.5, 3000.0), temperature_C=lambda t: 24.5)
    drv = ADS122C04(bus, ADDR, sleep=clock.sleep)
    drv.reset()
    drv.configure(gain=128, data_rate_sps=90)
    assert drv.read_temperature_C() == 24.5
    assert drv.read_thermocouple_C() == pytest.approx(31.234, abs=0.002)
    assert drv.read_thermocouple_C(cold_junction_C=24.5) == pytest.approx(31.234, abs=0.002)
    assert drv.read_flux_voltage_V() == pytest.approx(3000 * 0.56e-6, abs=1e-7)
    assert drv.read_config()["TS"] == 0            # temperature mode switched off again


def test_driver_resolves_millikelvin_rise():
    temps = {"v": 30.0}
    clock, bus, _ = make(lambda mux, t: (typek.emf_mV(temps["v"]) - typek.emf_mV(25.0)) * 1e-3)
    drv = ADS122C04(bus, ADDR, sleep=clock.sleep)
    drv.configure(gain=128)
    a = drv.read_thermocouple_C(cold_junction_C=25.0)
    temps["v"] = 30.01
    b = drv.read_thermocouple_C(cold_junction_C=25.0)
    assert b - a == pytest.approx(0.01, abs=0.0005)


def test_driver_continuous_and_crc_modes():
    clock, bus, _ = make(lambda mux, t: 1e-3)
    drv = ADS122C04(bus, ADDR, sleep=clock.sleep)
    drv.configure(gain=1, data_rate_sps=1000, continuous=True, data_counter=True, crc="crc16")
    drv.start()
    assert drv.read_voltage_V() == pytest.approx(1e-3, abs=1e-6)
    drv.configure(gain=1, crc="inverted")
    assert drv.read_voltage_V() == pytest.approx(1e-3, abs=1e-6)


def test_driver_detects_corrupted_frames():
    clock, bus, chip = make(lambda mux, t: 1e-3)
    drv = ADS122C04(bus, ADDR, attempts=3, sleep=clock.sleep)
    drv.configure(crc="crc16")
    real = chip.i2c_read
    chip.i2c_read = lambda n: bytes([real(n)[0] ^ 0x01]) + real(n)[1:]   # flip a bit
    with pytest.raises(SensorFault) as ei:
        drv.read_voltage_V()
    assert ei.value.reason == "crc"


def test_driver_saturation_and_timeout_and_args():
    clock, bus, chip = make(lambda mux, t: 1.0)
    drv = ADS122C04(bus, ADDR, sleep=clock.sleep)
    drv.configure(gain=128)
    with pytest.raises(SensorFault) as ei:
        drv.read_voltage_V()
    assert ei.value.reason == "saturated" and ei.value.sensor == "ads122c04@0x40"
    chip._start = lambda now: None                 # a chip that never converts
    with pytest.raises(SensorFault) as ei:
        drv.read_voltage_V()
    assert ei.value.reason == "timeout"
    with pytest.raises(ValueError, match="data_rate_sps"):
        drv.configure(data_rate_sps=50)
    with pytest.raises(ValueError, match="pga_bypass"):
        drv.configure(gain=8, pga_bypass=True)


def test_driver_retries_flaky_bus():
    clock, bus, _ = make(probe_world(40.0, 25.0, 0.0))
    bus.flaky(0.25)
    drv = ADS122C04(bus, ADDR, attempts=8, sleep=clock.sleep)
    drv.configure(gain=64, data_rate_sps=1000)
    vals = [drv.read_thermocouple_C(cold_junction_C=25.0) for _ in range(10)]
    assert all(v == pytest.approx(40.0, abs=0.002) for v in vals)
    assert bus.stats["flaky"] > 0
