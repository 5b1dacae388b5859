"""The chip registry: every converter the probe can be built with, in one place.

A chip is described once, as data (:class:`Chip`): its register map (the
module in :mod:`edge.hw.regmaps` the driver and the simulator's emulator
share), its driver class, the *roles* it can play on the probe and on which
input it plays each, its ``[sensors]`` settings, its noise and resolution
model, and how it is opened and read.  Everything that used to choose by
chip name reads this registry instead:

* configuration (:mod:`edge.service.config`) builds the ``[sensors]``
  section's keys from :attr:`Chip.settings` and the role choices from
  :func:`names_for`;
* :func:`edge.measure.sensors.make_sensors` opens the chips the
  configuration names for the two roles through :attr:`Chip.open` and reads
  them through :attr:`Chip.readers`;
* the instrument models (:mod:`edge.measure.instrument`) combine the chips'
  :attr:`Chip.models`;
* the simulator registers an emulator per chip (:mod:`firmware_sim.chips`)
  and wires each role's input to the matching signal of its thermal world;
* the chip contract test runs over :data:`CHIPS`.

Roles
-----
``"thermocouple"`` (:data:`THERMOCOUPLE`)
    The type K thermocouple at the bottom of the sensing layer: the chip
    reports the hot-junction temperature (°C), cold-junction compensated.
``"flux"`` (:data:`FLUX`)
    The heat-flux sensor: the chip reports its voltage (V).

Adding a chip: its register map in :mod:`edge.hw.regmaps`, its driver in
:mod:`edge.hw.drivers`, a :class:`Chip` entry here, its emulator in
:mod:`firmware_sim.chips` registered against the entry, and a
:class:`Pair` in ``tests/firmware_sim/test_chip_contract.py``.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field
from types import MappingProxyType, ModuleType
from typing import Any, Callable, Mapping

from edge.hw.drivers.ads1115 import ADS1115
from edge.hw.drivers.ads122c04 import ADS122C04
from edge.hw.drivers.mcp9600 import MCP9600
from edge.hw.regmaps import ads1115 as ads1115_map
from edge.hw.regmaps import ads122c04 as ads122c04_map
from edge.hw.regmaps import mcp9600 as mcp9600_map
from edge.physics.probe import FLUX_SENSITIVITY_V_per_W_m2
from edge.physics.typek import seebeck_uV_per_K

__all__ = [
    "THERMOCOUPLE",
    "FLUX",
    "ROLES",
    "THERMOCOUPLE_C",
    "THERMOCOUPLE_EMF_V",
    "THERMOCOUPLE_OPEN",
    "COLD_JUNCTION_C",
    "FLUX_V",
    "SIGNALS",
    "ROLE_SIGNALS",
    "TYPE_K_SEEBECK_V_per_K",
    "ADS122C04_STEP_V",
    "Setting",
    "NoiseModel",
    "RoleReader",
    "Chip",
    "CHIPS",
    "BOARDS",
    "DEFAULT_CHIPS",
    "chip",
    "names_for",
    "chip_settings",
    "thermocouple_resolution_K",
    "max_sample_rate_Hz",
    "sample_rate_Hz",
]

#: Role: the thermocouple, read as a hot-junction temperature (°C).
THERMOCOUPLE = "thermocouple"
#: Role: the heat-flux sensor, read as a voltage (V).
FLUX = "flux"
ROLES = (THERMOCOUPLE, FLUX)

# What the probe board connects to a chip's inputs (:attr:`Chip.wiring`); the simulator's thermal
# worlds offer each as a signal of the same name (firmware_sim.world_protocol.World).
#: The thermocouple's hot-junction temperature (°C), for a chip that converts the EMF itself.
THERMOCOUPLE_C = "thermocouple_C"
#: The thermocouple's differential EMF (V).
THERMOCOUPLE_EMF_V = "thermocouple_emf_V"
#: Whether the thermocouple is disconnected (a status the chip detects).
THERMOCOUPLE_OPEN = "thermocouple_open"
#: The board's temperature (°C): the cold junction, the chip's die.
COLD_JUNCTION_C = "cold_junction_C"
#: The heat-flux sensor's voltage (V).
FLUX_V = "flux_voltage_V"
SIGNALS = (THERMOCOUPLE_C, THERMOCOUPLE_EMF_V, THERMOCOUPLE_OPEN, COLD_JUNCTION_C, FLUX_V)
#: The signal a role is read from, per kind of input: a temperature input or a voltage input.
ROLE_SIGNALS = {THERMOCOUPLE: (THERMOCOUPLE_C, THERMOCOUPLE_EMF_V), FLUX: (FLUX_V,)}

#: Type K sensitivity near room temperature (V/K): turns an EMF step into a temperature step.
TYPE_K_SEEBECK_V_per_K = float(seebeck_uV_per_K(25.0)) * 1e-6
#: ADS122C04 step at gain 128 with the internal 2.048 V reference (24-bit two's complement).
ADS122C04_STEP_V = ads122c04_map.INTERNAL_VREF_V / 128 / 2 ** 23


@dataclass(frozen=True)
class Setting:
    """One ``[sensors]`` key of a chip, ``<chip>_<key>`` in the configuration.

    ``kind``, ``default``, ``doc`` and ``bounds`` are those of
    :class:`edge.schema.Field` (``choices``, ``lo``, ``hi``).
    """

    key: str
    kind: str
    default: Any
    doc: str
    bounds: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class NoiseModel:
    """How one role's readings look in the instrument models (SI units).

    ``rate_Hz`` is the sampling rate, ``lsb`` the step of one reading (K for
    the thermocouple, W/m^2 of flux at the nominal sensitivity for the flux
    sensor) and ``noise`` the input-referred RMS noise in the same unit
    (datasheet typicals plus pick-up on a short cable).
    """

    rate_Hz: float
    lsb: float
    noise: float

    def reading_sd(self, noise: float | None = None) -> float:
        """One reading's standard deviation: ``noise`` (default this model's) and the step as uniform
        rounding, ``lsb / sqrt(12)``, in quadrature (same unit)."""
        return math.hypot(self.noise if noise is None else noise, self.lsb / math.sqrt(12.0))


@dataclass(frozen=True)
class RoleReader:
    """One role read through an opened chip.

    Parameters
    ----------
    read : callable () -> (float, bool)
        The reading (°C for the thermocouple, V for the flux sensor) and
        whether the converter clipped.
    age_s : float
        Mean age of a reading when it is read: a continuously converting
        chip holds a value taken one conversion ago on average (s).
    lag_s : float
        A single shot samples its input at the centre of its conversion,
        which ends its read: half a conversion (s; 0 when continuous).
    """

    read: Callable[[], tuple[float, bool]]
    age_s: float = 0.0
    lag_s: float = 0.0


@dataclass(frozen=True)
class Chip:
    """Everything the code base knows about one converter chip.

    Attributes
    ----------
    name : str
        Registry key, also the prefix of its ``[sensors]`` keys and the key
        of its address in a simulator scene's ``[board]``.
    part : str
        Part number as printed (logs, documentation).
    regmap : module
        Its register map and datasheet constants (:mod:`edge.hw.regmaps`).
    driver : type
        Its driver class (:mod:`edge.hw.drivers`).
    roles : mapping role -> str
        The roles it can play and the input it plays each on (a multiplexer
        label such as ``"AIN0_AIN1"``, or ``"hot_junction"``).
    wiring : mapping input -> signal
        What the probe board connects to each of its inputs (one of
        :data:`SIGNALS`); every role's input is wired to a signal of
        :data:`ROLE_SIGNALS`. Unwired inputs see 0 V (tied to ground).
    settings : tuple of Setting
        Its ``[sensors]`` keys besides the address.
    models : mapping role -> NoiseModel
        Its noise and resolution model per role (instrument models).
    open : callable (bus, settings, **retry) -> driver
        Build, identify and configure the driver; ``settings`` maps each
        :attr:`settings` key and ``"address"`` to the configured value.
    readers : mapping role -> callable (device, settings) -> RoleReader
    resolution_K : callable settings -> float, optional
        The thermometer's step (K) at ``settings`` (thermocouple role).
    sample_rate_limit_Hz : callable settings -> float, optional
        Fastest sampling whose every temperature reading is a new conversion.
    input_noise : Setting
        Its input-referred noise per conversion (V rms) as a simulated scene's
        ``[sensors]`` key ``<chip>_<key>`` sets it (default 0: noiseless).
    """

    name: str
    part: str
    regmap: ModuleType
    driver: type
    roles: Mapping[str, str]
    wiring: Mapping[str, str]
    settings: tuple[Setting, ...]
    models: Mapping[str, NoiseModel]
    open: Callable[..., Any]
    readers: Mapping[str, Callable[[Any, Mapping[str, Any]], RoleReader]]
    resolution_K: Callable[[Mapping[str, Any]], float] | None = None
    sample_rate_limit_Hz: Callable[[Mapping[str, Any]], float] | None = None
    input_noise: Setting = Setting("noise_rms_V", "float", 0.0, "input noise", {"lo": 0.0, "hi": 1e-3})

    def __post_init__(self) -> None:
        for role in self.roles:
            if role not in ROLES:
                raise ValueError(f"{self.name}: unknown role {role!r}; roles: {ROLES}")
            if role not in self.readers or role not in self.models:
                raise ValueError(f"{self.name}: role {role!r} needs a reader and a noise model")
            if self.wiring.get(self.roles[role]) not in ROLE_SIGNALS[role]:
                raise ValueError(f"{self.name}: the {role} input {self.roles[role]!r} is not wired to "
                                 f"one of {ROLE_SIGNALS[role]}")
        for pin, signal in self.wiring.items():
            if signal not in SIGNALS:
                raise ValueError(f"{self.name}: input {pin!r} wired to unknown signal {signal!r}")
        if THERMOCOUPLE in self.roles and (self.resolution_K is None or self.sample_rate_limit_Hz is None):
            raise ValueError(f"{self.name}: a thermocouple chip needs resolution_K and sample_rate_limit_Hz")

    @property
    def addresses(self) -> tuple[int, ...]:
        """The I2C addresses the chip can be strapped to (its register map's)."""
        return tuple(self.regmap.ADDRESSES)

    @property
    def default_address(self) -> int:
        """The driver's (and the configuration's) default address: the first strap option."""
        return self.addresses[0]

    def setting_key(self, key: str) -> str:
        """The ``[sensors]`` key of one of its settings, e.g. ``"mcp9600_adc_bits"``."""
        return f"{self.name}_{key}"


# ---------------------------------------------------------------------------------------------
# MCP9600: thermocouple EMF-to-temperature converter, converts continuously


def _mcp9600_open(bus: Any, st: Mapping[str, Any], **retry: Any) -> MCP9600:
    mcp = MCP9600(bus, st["address"], **retry)
    mcp.probe()
    mcp.configure(adc_resolution_bits=st["adc_bits"])
    return mcp


def _mcp9600_thermocouple(mcp: MCP9600, st: Mapping[str, Any]) -> RoleReader:
    def read() -> tuple[float, bool]:
        return mcp.read_hot_junction_C(), False
    # Converts continuously: a reading is on average one conversion old and has no single-shot lag.
    return RoleReader(read, age_s=mcp.conversion_time_s, lag_s=0.0)


# ---------------------------------------------------------------------------------------------
# ADS1115: 16-bit ADC, flux sensor in single shots


def _ads1115_open(bus: Any, st: Mapping[str, Any], **retry: Any) -> ADS1115:
    ads = ADS1115(bus, st["address"], on_saturation="flag", **retry)
    ads.configure(mux=_ADS1115_FLUX_INPUT, fsr_V=st["fsr_V"], data_rate_sps=st["data_rate_sps"])
    return ads


def _ads1115_flux(ads: ADS1115, st: Mapping[str, Any]) -> RoleReader:
    def read() -> tuple[float, bool]:
        v = ads.read_single_shot_V()
        return v, ads.saturated
    return RoleReader(read, lag_s=0.5 / st["data_rate_sps"])   # a conversion lasts 1 / DR


_ADS1115_FLUX_INPUT = "AIN0_AIN1"


# ---------------------------------------------------------------------------------------------
# ADS122C04: 24-bit ADC, thermocouple EMF and flux in single shots, one chip for both roles


def _ads122c04_open(bus: Any, st: Mapping[str, Any], **retry: Any) -> ADS122C04:
    adc = ADS122C04(bus, st["address"], on_saturation="flag", **retry)
    adc.reset()
    adc.configure(gain=st["gain"], data_rate_sps=st["data_rate_sps"])
    return adc


def _ads122c04_thermocouple(adc: ADS122C04, st: Mapping[str, Any]) -> RoleReader:
    channel, gain = _ADS122C04_INPUTS[THERMOCOUPLE], st["gain"]

    def read() -> tuple[float, bool]:
        t = adc.read_thermocouple_C(channel, gain)
        return t, adc.saturated
    return RoleReader(read, age_s=0.0, lag_s=0.5 * adc.conversion_time_s)


def _ads122c04_flux(adc: ADS122C04, st: Mapping[str, Any]) -> RoleReader:
    channel, gain = _ADS122C04_INPUTS[FLUX], st["gain"]

    def read() -> tuple[float, bool]:
        v = adc.read_flux_voltage_V(channel, gain)
        return v, adc.saturated
    return RoleReader(read, lag_s=0.5 * adc.conversion_time_s)


def _ads122c04_sample_rate_Hz(st: Mapping[str, Any]) -> float:
    # The thermocouple and then the flux in single shots: two conversions per sample plus the I2C reads.
    dr = ads122c04_map.DATA_RATES_NORMAL_SPS.index(int(st["data_rate_sps"]))
    per_sample = 2 * ads122c04_map.conversion_time_s(dr, False, True) + 2e-3
    return min(200.0, 1.0 / per_sample)


_ADS122C04_INPUTS = {THERMOCOUPLE: "AIN0_AIN1", FLUX: "AIN2_AIN3"}


def _registry(*chips: Chip) -> Mapping[str, Chip]:
    return MappingProxyType({c.name: c for c in chips})


#: Every chip the probe can be built with, by name.
CHIPS: Mapping[str, Chip] = _registry(
    Chip(
        name="mcp9600", part="MCP9600", regmap=mcp9600_map, driver=MCP9600,
        roles={THERMOCOUPLE: "hot_junction"},
        wiring={"hot_junction": THERMOCOUPLE_C, "cold_junction": COLD_JUNCTION_C, "open_circuit": THERMOCOUPLE_OPEN},
        settings=(Setting("adc_bits", "int", 16, "MCP9600 ADC resolution (18: 320 ms, 16: 80 ms per conversion)",
                          {"choices": (12, 14, 16, 18)}),),
        # The instrument model runs it at 16 bit (80-ms conversions, 12.5 Hz): its ADC resolves 8 uV of
        # EMF, 0.197 K steps (the 0.0625 K register LSB only pays off at 18 bit, 320 ms per conversion).
        models={THERMOCOUPLE: NoiseModel(rate_Hz=12.5, lsb=mcp9600_map.adc_step_V(16) / TYPE_K_SEEBECK_V_per_K,
                                         noise=0.02)},
        open=_mcp9600_open,
        readers={THERMOCOUPLE: _mcp9600_thermocouple},
        resolution_K=lambda st: mcp9600_map.adc_step_V(int(st["adc_bits"])) / TYPE_K_SEEBECK_V_per_K,
        sample_rate_limit_Hz=lambda st: 1.0 / mcp9600_map.CONVERSION_TIME_s[int(st["adc_bits"])],
        input_noise=Setting("emf_noise_rms_V", "float", 0.0, "MCP9600 input noise", {"lo": 0.0, "hi": 1e-3}),
    ),
    Chip(
        name="ads1115", part="ADS1115", regmap=ads1115_map, driver=ADS1115,
        roles={FLUX: _ADS1115_FLUX_INPUT},
        wiring={_ADS1115_FLUX_INPUT: FLUX_V},   # AIN2, AIN3 tied to GND
        settings=(Setting("fsr_V", "float", 0.256, "ADS1115 full-scale range, V",
                          {"choices": (0.256, 0.512, 1.024, 2.048, 4.096, 6.144)}),
                  Setting("data_rate_sps", "int", 860, "ADS1115 data rate, samples/s",
                          {"choices": (8, 16, 32, 64, 128, 250, 475, 860)})),
        # The instrument model: +-0.256 V (7.8125 uV LSB = 14 W/m^2 of the FHF05's 0.56 uV per W/m^2) at 128 SPS.
        models={FLUX: NoiseModel(rate_Hz=128.0, lsb=ads1115_map.code_to_volts(1, 0.256) / FLUX_SENSITIVITY_V_per_W_m2,
                                 noise=3.0)},
        open=_ads1115_open,
        readers={FLUX: _ads1115_flux},
        input_noise=Setting("noise_rms_V", "float", 0.0, "ADS1115 input noise", {"lo": 0.0, "hi": 1e-2}),
    ),
    Chip(
        name="ads122c04", part="ADS122C04", regmap=ads122c04_map, driver=ADS122C04,
        roles=dict(_ADS122C04_INPUTS),
        wiring={_ADS122C04_INPUTS[THERMOCOUPLE]: THERMOCOUPLE_EMF_V, _ADS122C04_INPUTS[FLUX]: FLUX_V,
                "temperature": COLD_JUNCTION_C},   # its internal sensor is the cold junction
        settings=(Setting("gain", "int", 128, "ADS122C04 PGA gain", {"choices": (1, 2, 4, 8, 16, 32, 64, 128)}),
                  Setting("data_rate_sps", "int", 1000, "ADS122C04 data rate (normal mode), samples/s",
                          {"choices": (20, 45, 90, 175, 330, 600, 1000)})),
        # The instrument model: both sensors at gain 128 (0.12 uV LSB), 90 SPS.
        models={THERMOCOUPLE: NoiseModel(rate_Hz=90.0, lsb=ADS122C04_STEP_V / TYPE_K_SEEBECK_V_per_K, noise=0.004),
                FLUX: NoiseModel(rate_Hz=90.0, lsb=ADS122C04_STEP_V / FLUX_SENSITIVITY_V_per_W_m2, noise=1.0)},
        open=_ads122c04_open,
        readers={THERMOCOUPLE: _ads122c04_thermocouple, FLUX: _ads122c04_flux},
        resolution_K=lambda st: ADS122C04_STEP_V * 128 / st["gain"] / TYPE_K_SEEBECK_V_per_K,
        sample_rate_limit_Hz=_ads122c04_sample_rate_Hz,
        input_noise=Setting("noise_rms_V", "float", 0.0, "ADS122C04 input noise", {"lo": 0.0, "hi": 1e-3}),
    ),
)


#: The boards the probe is built as: the chip that plays each role. The reference board (the
#: ``[sensors]`` defaults) converts the thermocouple on an MCP9600 and the flux on an ADS1115; the
#: precision board reads both on one 24-bit ADS122C04.
BOARDS: Mapping[str, Mapping[str, str]] = MappingProxyType({
    "reference": MappingProxyType({THERMOCOUPLE: "mcp9600", FLUX: "ads1115"}),
    "precision": MappingProxyType({THERMOCOUPLE: "ads122c04", FLUX: "ads122c04"}),
})
#: The reference board's chip per role: the ``[sensors]`` defaults.
DEFAULT_CHIPS: Mapping[str, str] = BOARDS["reference"]


def chip(name: str) -> Chip:
    """The registry entry ``name`` (ValueError naming the known chips if there is none)."""
    try:
        return CHIPS[name]
    except KeyError:
        raise ValueError(f"unknown chip {name!r}; known: {sorted(CHIPS)}") from None


def names_for(role: str) -> tuple[str, ...]:
    """Names of the chips that can play ``role``, in registry order."""
    if role not in ROLES:
        raise ValueError(f"unknown role {role!r}; roles: {ROLES}")
    return tuple(c.name for c in CHIPS.values() if role in c.roles)


def chip_settings(spec: Chip, sensors_cfg: Any) -> dict[str, Any]:
    """``spec``'s settings (and ``"address"``) read from a ``[sensors]`` section, by their short keys."""
    keys = ("address",) + tuple(s.key for s in spec.settings)
    return {k: getattr(sensors_cfg, spec.setting_key(k)) for k in keys}


def _thermocouple_chip(sensors_cfg: Any) -> tuple[Chip, dict[str, Any]]:
    spec = chip(sensors_cfg.thermocouple)
    return spec, chip_settings(spec, sensors_cfg)


def thermocouple_resolution_K(sensors_cfg: Any) -> float:
    """Temperature step (K) of the configured thermocouple converter near room temperature.

    One ADC step of thermocouple EMF divided by the type K Seebeck
    coefficient at 25 °C, at the ``[sensors]`` section's settings.
    """
    spec, st = _thermocouple_chip(sensors_cfg)
    return spec.resolution_K(st)


def max_sample_rate_Hz(sensors_cfg: Any) -> float:
    """Fastest sampling whose every temperature reading is a new conversion, Hz (``[sensors]`` section).

    From the converters' conversion times (:mod:`edge.hw.regmaps`): the MCP9600
    converts continuously, 320 / 80 / 20 / 5 ms at 18 / 16 / 14 / 12 bit,
    so faster reads only repeat a value (12.5 Hz at the default 16 bit); the
    ADS122C04 reads the thermocouple and then the flux in single shots, two
    conversions per sample (1000 SPS: ~1.1 ms each) plus the I2C traffic,
    so it can sample at the protocol's 200 Hz ceiling; the ADS1115 (flux
    only, 860 SPS: 1.2 ms) never limits.
    """
    spec, st = _thermocouple_chip(sensors_cfg)
    return spec.sample_rate_limit_Hz(st)


def sample_rate_Hz(sensors_cfg: Any, asked_Hz: float) -> float:
    """The rate a touch samples at when ``asked_Hz`` is asked (configured or requested), Hz.

    Capped at :func:`max_sample_rate_Hz` of the ``[sensors]`` section's converters: a faster read
    would only repeat a conversion. The one place MEASURE, the profiles, the idle readiness poll
    and the simulator's rigs take their rate from.
    """
    return min(float(asked_Hz), max_sample_rate_Hz(sensors_cfg))
