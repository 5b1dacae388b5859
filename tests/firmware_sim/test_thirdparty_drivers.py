"""Unmodified third-party drivers on the emulated chips: Pimoroni's mcp9600 and ads1015.

Both talk through ``i2cdevice`` with smbus2's ``read_i2c_block_data`` /
``write_i2c_block_data`` only. The ads1015 driver (1.0.0) polls the CONFIG OS
bit with ``time.sleep(0.001)`` against a ``time.time()`` timeout, and tells an
ADS1015 from an ADS1115 by timing ten conversions at DR=0b100 (1600 SPS on an
ADS1015, 128 SPS on an ADS1115): a mean >= 1/128 s means ADS1115. On the
default virtual clock nothing moves simulated time while it polls, so the
conversion never finishes; with ``clock="wall"`` the emulated conversion takes
its datasheet 7.8 ms of real time. With ``clock="bus"`` each poll's bus
transactions move time, so the conversion also finishes.

The packages are in the ``dev`` extra; the tests skip when they are missing.
"""

import numpy as np
import pytest

import firmware_sim

mcp9600 = pytest.importorskip("mcp9600")
ads1015 = pytest.importorskip("ads1015")
pytest.importorskip("i2cdevice")

MCP_ADDR = 0x60          # glass_15V's board
ADS_ADDR = 0x48


@pytest.fixture
def sim_factory():
    sims = []

    def make(clock, scene="glass_15V"):
        sim = firmware_sim.load_scene(scene, clock=clock)
        sims.append(sim)
        return sim

    yield make
    for sim in sims:
        sim.close()


def _bracket(fn, t0, t1, n=25):
    """min and max of ``fn`` on [t0, t1]."""
    vals = [fn(t) for t in np.linspace(max(t0, 0.0), t1, n)]
    return min(vals), max(vals)


# ---- MCP9600 -----------------------------------------------------------------------------

@pytest.mark.parametrize("clock", ["virtual", "wall", "bus"])
def test_pimoroni_mcp9600_reads_the_emulated_chip(sim_factory, clock):
    sim = sim_factory(clock)
    # Heat the probe so the thermocouple leaves ambient (the heater is on from t=0).
    sim.inject("heater_stuck_on", duty=1.0)        # from now on
    sim.advance_to(2.0)                       # a jump on the wall clock
    dev = mcp9600.MCP9600(i2c_addr=MCP_ADDR, i2c_dev=sim.bus)   # checks CHIP_ID itself
    assert dev._mcp9600.get("CHIP_ID").id == 0x40
    t_before = sim.now()
    hot = dev.get_hot_junction_temperature()
    cold = dev.get_cold_junction_temperature()
    delta = dev.get_temperature_delta()
    t_after = sim.now()
    # The hot-junction register holds the last 18-bit conversion (320 ms), sampled at its
    # centre: compare with the scene's truth over the last two conversion windows.
    lo, hi = _bracket(sim.world.thermocouple_C, t_before - 0.7, t_after)
    assert hi > 25.2                          # the truth really moved off ambient
    assert lo - 0.15 <= hot <= hi + 0.15      # 0.0625 °C steps, ~0.03 °C noise
    ambient = sim.scene.environment.ambient_temperature_C
    assert cold == pytest.approx(ambient, abs=0.0625)
    assert delta == pytest.approx(hot - cold, abs=0.0625 + 1e-9)
    assert dev.get_thermocouple_type() == "K"


# ---- ADS1115 through the ads1015 driver ----------------------------------------------------

def test_pimoroni_ads1015_detects_ads1115_on_wall_clock(sim_factory):
    sim = sim_factory("wall")
    adc = ads1015.ADS1015(i2c_addr=ADS_ADDR, i2c_dev=sim.bus)
    chip = sim.chips["ads1115"]
    n0 = chip.conversions
    assert adc.detect_chip_type() == ads1015.DEVICE_ADS1115
    # The driver times ten conversions it starts itself, each on a chip found idle: ten at least.
    # Before them it sets single-shot mode by a read-modify-write of CONFIG that writes back the OS
    # bit it read, 1 on an idle chip: as on the real ADS1115, that starts one conversion more. On a
    # quiet machine it is still running when the timed loop starts and stands in for the loop's
    # first (10 in all); if the driver's thread is held up for a conversion time (7.8 ms of wall
    # time) before the loop, the chip has finished it and converts 11.
    assert chip.conversions - n0 in (10, 11)


def test_pimoroni_ads1015_detects_ads1115_on_bus_clock(sim_factory):
    # Each ~1 ms poll moves simulated time by its 0.4 ms of bus traffic, so the driver's
    # wall-clock measurement of a conversion is never shorter than the simulated 7.8 ms.
    sim = sim_factory("bus")
    adc = ads1015.ADS1015(i2c_addr=ADS_ADDR, i2c_dev=sim.bus)
    assert adc.detect_chip_type() == ads1015.DEVICE_ADS1115


def test_pimoroni_ads1015_times_out_on_virtual_clock(sim_factory):
    """Why the wall clock exists: nothing advances the virtual clock while the driver polls."""
    sim = sim_factory("virtual")
    adc = ads1015.ADS1015(i2c_addr=ADS_ADDR, i2c_dev=sim.bus)
    t0 = sim.now()
    with pytest.raises(ads1015.ADS1015TimeoutError):
        adc.detect_chip_type(timeout=0.05)
    assert sim.now() == t0


def test_pimoroni_ads1015_reads_a_set_voltage(sim_factory):
    sim = sim_factory("wall")
    adc = ads1015.ADS1015(i2c_addr=ADS_ADDR, i2c_dev=sim.bus)
    assert adc.detect_chip_type() == ads1015.DEVICE_ADS1115
    chip = sim.chips["ads1115"]
    levels = {"AIN0_GND": 1.2345, "AIN1_GND": -0.0, "AIN2_GND": 0.5, "AIN3_GND": 2.0}
    chip.inputs = lambda mux, t: levels.get(mux, 0.0)
    noise = sim.scene.sensors.ads1115_noise_rms_V
    for channel, mux, gain in [("in0/gnd", "AIN0_GND", 2.048), ("in2/gnd", "AIN2_GND", 0.512),
                               ("in3/gnd", "AIN3_GND", 4.096)]:
        adc.set_programmable_gain(gain)
        lsb = gain / 32768
        v = adc.get_voltage(channel)
        assert v == pytest.approx(levels[mux], abs=lsb + 6 * noise)
    # Beyond full scale the code clips at 0x7FFF.
    adc.set_programmable_gain(1.024)
    assert adc.get_voltage("in3/gnd") == pytest.approx(1.024 * 0x7FFF / 32768)


def test_pimoroni_ads1015_reads_the_scene_flux_voltage(sim_factory):
    sim = sim_factory("wall")
    adc = ads1015.ADS1015(i2c_addr=ADS_ADDR, i2c_dev=sim.bus)
    assert adc.detect_chip_type() == ads1015.DEVICE_ADS1115
    sim.inject("heater_stuck_on", duty=1.0)        # from now on
    sim.advance_to(1.2)                      # into the touch: the flux sensor sees q_f ~ 700 W/m²
    adc.set_programmable_gain(0.256)
    t_before = sim.now()
    v = adc.get_voltage("in0/in1")           # AIN0-AIN1: the flux sensor
    t_after = sim.now()
    lo, hi = _bracket(sim.world.flux_voltage_V, t_before, t_after)
    assert hi > 1e-4                         # a real signal, > 12 LSB
    tol = 0.256 / 32768 + 6 * sim.scene.sensors.ads1115_noise_rms_V
    assert lo - tol <= v <= hi + tol
