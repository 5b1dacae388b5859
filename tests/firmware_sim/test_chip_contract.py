"""One contract for every driver/emulator pair: the edge driver and the simulator's chip agree.

The pairs come from the chip registry (:data:`edge.hw.chips.CHIPS`: driver
class and shared register map) and the emulator registry
(:data:`firmware_sim.chips.registry.EMULATORS`); what the contract needs beyond
them -- how to identify the chip, how the driver performs one conversion, known
inputs -- is described once per chip (:class:`Pair`). Every test below then runs
on every registry chip; a chip added to the registry without its pair fails
:func:`test_every_registry_chip_has_an_emulator_and_a_contract_pair`.
Chip-specific behaviour stays in ``tests/firmware_sim/chips/test_*.py``.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from types import ModuleType
from typing import Any, Callable

import pytest

from edge.hw.chips import CHIPS, FLUX, ROLE_SIGNALS, ROLES, THERMOCOUPLE, names_for
from edge.hw.drivers.ads1115 import ADS1115
from edge.hw.drivers.ads122c04 import ADS122C04
from edge.hw.drivers.mcp9600 import MCP9600
from edge.hw.faults import SensorFault
from edge.hw.registers import Register
from edge.hw.regmaps import ads1115 as ads1115_map
from edge.hw.regmaps import ads122c04 as ads122c04_map
from edge.hw.regmaps import mcp9600 as mcp9600_map
from edge.physics import typek
from firmware_sim.bus import SimBus
from firmware_sim.chips.ads1115 import ADS1115Emulator
from firmware_sim.chips.ads122c04 import ADS122C04Emulator
from firmware_sim.chips.mcp9600 import MCP9600Emulator
from firmware_sim.chips.registry import EMULATORS
from firmware_sim.clock import VirtualClock
from firmware_sim.wiring import WIRING


@dataclass(frozen=True)
class Pair:
    """What the contract needs to know about one driver/emulator pair."""

    name: str
    driver: type
    regmap: ModuleType
    #: (clock, known input) -> emulator; the input is a voltage, or a temperature for the MCP9600.
    emulator: Callable[[VirtualClock, float], Any]
    #: How the driver addresses a register in read_register/write_register.
    reg_key: Callable[[Register], Any]
    #: Identify the chip (raise on a mismatch).
    identify: Callable[[Any], None]
    #: Registers whose writes start or stop conversions (their read-back differs by design).
    control: tuple[str, ...]
    #: Conversion rates the regmap lists, how the driver configures one, and the datasheet time.
    rates: tuple[Any, ...]
    configure_rate: Callable[[Any, Any], None]
    datasheet_time_s: Callable[[Any], float]
    #: One conversion with the driver (waits on the clock); returns the reading in volts.
    convert: Callable[[Any], float]
    #: Known inputs and the reading each should give, and the LSB of that reading.
    cases: tuple[tuple[float, float], ...]
    lsb_V: Callable[[Any], float]


# ---- MCP9600: ID register; hot-junction conversion per ADC resolution; reading = thermocouple EMF

def _mcp_identify(drv: MCP9600) -> None:
    assert drv.probe() == (mcp9600_map.DEVICE_ID, 0x11)


def _mcp_convert(drv: MCP9600) -> float:
    drv.start_burst(1)
    drv.wait_for_update()
    return drv.read_raw_emf_V()


def _emf_V(t_hot_C: float, t_cold_C: float = 25.0) -> float:
    return (typek.emf_mV(t_hot_C) - typek.emf_mV(t_cold_C)) * 1e-3


MCP = Pair(
    name="mcp9600",
    driver=MCP9600,
    regmap=mcp9600_map,
    emulator=lambda clock, t_hot_C: MCP9600Emulator(clock, lambda t: t_hot_C, lambda t: 25.0),
    reg_key=lambda reg: reg.name,
    identify=_mcp_identify,
    control=("DEVICE_CONFIG",),
    rates=tuple(mcp9600_map.ADC_RESOLUTIONS_BITS),
    configure_rate=lambda drv, bits: drv.configure(adc_resolution_bits=bits, mode="shutdown"),
    datasheet_time_s=lambda bits: mcp9600_map.CONVERSION_TIME_s[bits],
    convert=_mcp_convert,
    cases=((25.0, 0.0), (61.3, _emf_V(61.3)), (-10.0, _emf_V(-10.0)), (300.0, _emf_V(300.0))),
    lsb_V=lambda drv: mcp9600_map.adc_step_V(drv.adc_resolution_bits),
)


# ---- ADS1115: no ID register (identified by its power-on CONFIG); single shot at 1/DR

def _ads1115_identify(drv: ADS1115) -> None:
    cfg = ads1115_map.REGISTERS.CONFIG
    assert drv.read_config() == cfg.decode(cfg.reset)


ADS1115_PAIR = Pair(
    name="ads1115",
    driver=ADS1115,
    regmap=ads1115_map,
    emulator=lambda clock, v: ADS1115Emulator(clock, lambda mux, t: v if mux == "AIN0_AIN1" else 0.0),
    reg_key=lambda reg: reg.name,
    identify=_ads1115_identify,
    control=("CONFIG",),
    rates=tuple(ads1115_map.DATA_RATES_SPS),
    configure_rate=lambda drv, sps: drv.configure(data_rate_sps=sps),
    datasheet_time_s=lambda sps: 1.0 / sps,
    convert=lambda drv: drv.read_single_shot_V(),
    cases=((0.0, 0.0), (1.234e-3, 1.234e-3), (-5.6e-3, -5.6e-3), (0.2, 0.2)),
    lsb_V=lambda drv: ads1115_map.code_to_volts(1, drv.fsr_V),
)


# ---- ADS122C04: no ID register (identified by its register image after RESET); Table 12 times

def _ads122c04_identify(drv: ADS122C04) -> None:
    drv.reset()
    expect = {}
    for reg in ads122c04_map.REGISTERS:
        expect.update(reg.decode(reg.reset))
    assert drv.read_config() == expect


def _ads122c04_rate(drv: ADS122C04, rate: tuple[int, bool]) -> None:
    dr_code, turbo = rate
    drv.configure(data_rate_sps=ads122c04_map.data_rate_sps(dr_code, turbo), turbo=turbo)


ADS122C04_PAIR = Pair(
    name="ads122c04",
    driver=ADS122C04,
    regmap=ads122c04_map,
    emulator=lambda clock, v: ADS122C04Emulator(clock, lambda mux, t: v if mux == "AIN0_AIN1" else 0.0),
    reg_key=lambda reg: reg.address,
    identify=_ads122c04_identify,
    control=(),
    rates=tuple((dr, turbo) for turbo in (False, True) for dr in range(len(ads122c04_map.DATA_RATES_NORMAL_SPS))),
    configure_rate=_ads122c04_rate,
    datasheet_time_s=lambda rate: ads122c04_map.conversion_time_s(rate[0], rate[1], single_shot=True),
    convert=lambda drv: drv.read_voltage_V("AIN0_AIN1", gain=1),
    cases=((0.0, 0.0), (1.234e-3, 1.234e-3), (-0.123, -0.123), (1.5, 1.5)),
    lsb_V=lambda drv: ads122c04_map.code_to_volts(1, drv.gain),
)

_DESCRIBED = {p.name: p for p in (MCP, ADS1115_PAIR, ADS122C04_PAIR)}
#: One pair per registry chip, in registry order (a chip without a described pair has none: see the test below).
PAIRS = [_DESCRIBED[name] for name in CHIPS if name in _DESCRIBED]
pairs = pytest.mark.parametrize("pair", PAIRS, ids=[p.name for p in PAIRS])


def rig(pair: Pair, known_input: float | None = None, *, address: int | None = None, **driver_kw):
    """A virtual clock, a bus with the emulator at the default address, and a driver at ``address``.

    ``known_input`` defaults to the pair's second case (in range, non-zero).
    """
    known_input = pair.cases[1][0] if known_input is None else known_input
    clock = VirtualClock()
    bus = SimBus(clock=clock, rng=1)
    default = pair.regmap.ADDRESSES[0]
    bus.attach(default, pair.emulator(clock, known_input))
    drv = pair.driver(bus, default if address is None else address, sleep=clock.sleep, **driver_kw)
    return clock, bus, drv


def plain_registers(pair: Pair, *, writable: bool) -> list[Register]:
    """Registers whose value is only what was written or reset (no results, flags or control)."""
    return [r for r in pair.regmap.REGISTERS
            if not r.volatile and not (writable and (r.read_only or r.name in pair.control))]


# ---- the registries


def test_every_registry_chip_has_an_emulator_and_a_contract_pair():
    assert set(CHIPS) == set(EMULATORS) == set(_DESCRIBED)
    for name, spec in CHIPS.items():
        pair, emu = _DESCRIBED[name], EMULATORS[name]
        # The pair's driver and register map are the registry's; the emulator reads that same map.
        assert (pair.driver, pair.regmap) == (spec.driver, spec.regmap), name
        assert emu.chip is spec and isinstance(pair.emulator(VirtualClock(), pair.cases[1][0]), emu.cls), name
        assert spec.driver.CHIP == name and spec.addresses == tuple(spec.regmap.ADDRESSES)


def test_every_role_has_a_chip_and_every_role_input_is_wired_to_its_signal():
    for role in ROLES:
        assert names_for(role), role
        for name in names_for(role):
            spec = CHIPS[name]
            wires = [w for w in WIRING if w.part == name and w.pin == spec.roles[role]]
            assert len(wires) == 1 and wires[0].signal in ROLE_SIGNALS[role], (name, role)
    assert set(names_for(THERMOCOUPLE)) | set(names_for(FLUX)) == set(CHIPS)


# ---- identity and addressing


@pairs
def test_driver_identifies_the_chip_at_its_default_address(pair):
    default = inspect.signature(pair.driver).parameters["address"].default
    assert default == pair.regmap.ADDRESSES[0]
    assert tuple(pair.driver.ADDRESSES) == tuple(pair.regmap.ADDRESSES)
    _, _, drv = rig(pair)
    assert drv.address == default and drv.name == f"{pair.name}@0x{default:02x}"
    pair.identify(drv)


@pairs
def test_wrong_address_is_refused_with_a_sensor_fault(pair):
    other = pair.regmap.ADDRESSES[1]               # a valid address where no chip answers
    _, bus, drv = rig(pair, address=other, attempts=2, backoff_s=0.0)
    with pytest.raises(SensorFault) as ei:
        pair.identify(drv)
    assert ei.value.reason == "i2c" and ei.value.sensor == f"{pair.name}@0x{other:02x}"
    assert isinstance(ei.value.__cause__, OSError)
    outside = next(a for a in range(0x08, 0x78) if a not in pair.regmap.ADDRESSES)
    with pytest.raises(ValueError, match="address"):
        pair.driver(bus, outside)


# ---- registers through the bus


@pairs
def test_every_readable_register_reads_its_reset_value_before_configuration(pair):
    _, _, drv = rig(pair)
    regs = plain_registers(pair, writable=False)
    assert regs, "the regmap declares no plain register"
    for reg in regs:
        assert drv.read_register(pair.reg_key(reg)) == reg.reset, reg.name


@pairs
def test_writable_registers_read_back_what_was_written(pair):
    _, _, drv = rig(pair)
    regs = plain_registers(pair, writable=True)
    assert regs, "the regmap declares no plain writable register"
    for reg in regs:
        mask = 0
        for bf in reg.fields.values():
            mask |= bf.mask
        for pattern in (0x55, 0xAA):
            value = mask & int.from_bytes(bytes([pattern]) * reg.width_bytes, "big")
            drv.write_register(pair.reg_key(reg), value)
            assert drv.read_register(pair.reg_key(reg)) == value, (reg.name, hex(value))


# ---- timing and readings


@pairs
def test_conversion_wait_is_the_regmap_datasheet_time(pair):
    for rate in pair.rates:
        clock, _, drv = rig(pair)
        pair.configure_rate(drv, rate)
        t0 = clock.now()
        pair.convert(drv)
        assert clock.now() - t0 == pytest.approx(pair.datasheet_time_s(rate), abs=1e-9), rate


@pairs
def test_a_known_input_reads_within_one_lsb(pair):
    for known_input, expected in pair.cases:
        _, _, drv = rig(pair, known_input)
        reading = pair.convert(drv)
        assert abs(reading - expected) <= pair.lsb_V(drv) + 1e-15, (known_input, reading, expected)


# ---- bus faults


@pairs
@pytest.mark.parametrize("fault, reason", [("nack", "i2c"), ("stuck", "timeout")])
def test_bus_faults_surface_as_sensor_faults(pair, fault, reason):
    _, bus, drv = rig(pair, attempts=2, backoff_s=0.0)
    pair.identify(drv)
    if fault == "nack":
        bus.nack(drv.address)
    else:
        bus.stuck()
    with pytest.raises(SensorFault) as ei:
        pair.convert(drv)
    assert ei.value.reason == reason and ei.value.sensor == drv.name
    assert isinstance(ei.value.__cause__, OSError)
    bus.clear_faults()
    pair.identify(drv)                              # the chip answers again once the bus recovers


def test_the_scene_format_fits_every_registry_chip_and_its_noise():
    import dataclasses

    from firmware_sim.scene.model import BoardSpec, SensorSpec
    from firmware_sim.scene.schema import BOARD_FIELDS, SENSOR_FIELDS

    assert set(CHIPS) <= {f.name for f in dataclasses.fields(BoardSpec)} and set(CHIPS) <= set(BOARD_FIELDS)
    for emu in EMULATORS.values():
        assert emu.noise_setting in SENSOR_FIELDS and getattr(SensorSpec(), emu.noise_setting) == 0.0
