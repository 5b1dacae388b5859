"""The scene model: what the simulated probe touches, on which board, with which faults.

Frozen dataclasses filled by :mod:`firmware_sim.scene.parser` from a TOML
file (schema: :mod:`firmware_sim.scene.schema`), plus the error type every
scene check raises, :class:`SceneError`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

from edge.hw.regmaps import ads1115, ads122c04, mcp9600
from edge.physics.probe import FLUX_SENSITIVITY_V_per_W_m2, STACKS, ProbeStack, heater_power_W
from edge.physics.solids import Solid

__all__ = [
    "FAULT_KINDS",
    "BACKS",
    "CHIP_ADDRESSES",
    "FLUX_SATURATION_V",
    "SceneError",
    "ObjectSpec",
    "Environment",
    "HeaterSpec",
    "BoardSpec",
    "SensorSpec",
    "TouchSpec",
    "Fault",
    "Scene",
]

FAULT_KINDS = (
    "i2c_nack",
    "bus_stuck",
    "open_thermocouple",
    "flux_saturation",
    "heater_stuck_on",
    "heater_dead",
    "supply_sag",
    "no_contact",
)
BACKS = ("fixed", "insulated", "infinite")
#: Valid 7-bit addresses of each chip a board may carry (from the chips' register maps).
CHIP_ADDRESSES: dict[str, tuple[int, ...]] = {
    "mcp9600": mcp9600.ADDRESSES,
    "ads1115": ads1115.ADDRESSES,
    "ads122c04": ads122c04.ADDRESSES,
}
#: Default voltage a saturated flux channel shows: above the ADS1115's ±0.256 V
#: range and the ADS122C04's ±16 mV (gain 128), so either reports full scale.
FLUX_SATURATION_V = 0.3


class SceneError(ValueError):
    """A scene file is invalid.

    Attributes
    ----------
    key : str
        Dotted path of the offending key (``""`` for the whole file).
    file : str
        File name (or ``"<string>"``).
    """

    def __init__(self, file: str, key: str, message: str) -> None:
        self.file = file
        self.key = key
        where = f"{file}: {key}: " if key else f"{file}: "
        super().__init__(where + message)


# ---------------------------------------------------------------------------
# Parsed scene


@dataclass(frozen=True)
class ObjectSpec:
    """The touched object: properties, thickness (m) and back boundary."""

    solid: Solid
    back: str
    thickness_m: float | None
    material: str | None = None
    label: str = ""


@dataclass(frozen=True)
class Environment:
    """Object initial and ambient (air/probe/board) temperatures, °C."""

    initial_temperature_C: float
    ambient_temperature_C: float


@dataclass(frozen=True)
class HeaterSpec:
    """Heater supply (V) and film resistance (ohm)."""

    supply_voltage_V: float
    resistance_ohm: float

    @property
    def max_power_W(self) -> float:
        """Power at full duty, V**2 / R (W)."""
        return heater_power_W(1.0, self.supply_voltage_V, self.resistance_ohm)


@dataclass(frozen=True)
class BoardSpec:
    """Fitted chips (7-bit addresses, None = absent) and probe stack name."""

    mcp9600: int | None = None
    ads1115: int | None = None
    ads122c04: int | None = None
    stack_name: str = "0.42"

    @property
    def stack(self) -> ProbeStack:
        """The probe layer stack (see :mod:`edge.physics.solids`)."""
        return STACKS[self.stack_name]

    def address_of(self, chip: str) -> int | None:
        """Address of ``chip`` ("mcp9600", "ads1115", "ads122c04"), or None."""
        if chip not in CHIP_ADDRESSES:
            raise ValueError(f"chip must be one of {sorted(CHIP_ADDRESSES)}, got {chip!r}")
        return getattr(self, chip)


@dataclass(frozen=True)
class SensorSpec:
    """Sensor characteristics and noise (SI)."""

    thermocouple_time_constant_s: float = 0.0
    flux_sensitivity_V_per_W_m2: float = FLUX_SENSITIVITY_V_per_W_m2
    flux_range_W_m2: float = 10_000.0
    mcp9600_emf_noise_rms_V: float = 0.0
    ads1115_noise_rms_V: float = 0.0
    ads122c04_noise_rms_V: float = 0.0


@dataclass(frozen=True)
class TouchSpec:
    """When the probe is on the object (virtual seconds)."""

    start_s: float
    length_s: float
    press_trigger: bool = True
    trigger_hold_s: float = 0.1
    #: Touch after touch: the probe is put on the object again ``repeat_gap_s`` after each touch.
    repeat: bool | None = None
    repeat_gap_s: float = 1.0

    @property
    def end_s(self) -> float:
        return self.start_s + self.length_s


@dataclass(frozen=True)
class Fault:
    """One injected fault, active for ``at_s <= t < until_s`` (None: forever)."""

    kind: str
    at_s: float = 0.0
    until_s: float | None = None
    params: Mapping[str, Any] = field(default_factory=dict)

    def active(self, t_s: float) -> bool:
        """Whether the fault is in effect at virtual time ``t_s``."""
        return t_s >= self.at_s and (self.until_s is None or t_s < self.until_s)


@dataclass(frozen=True)
class Scene:
    """A parsed, validated scene (schema: :mod:`firmware_sim.scene.schema`)."""

    name: str
    object: ObjectSpec
    environment: Environment
    heater: HeaterSpec
    board: BoardSpec
    touch: TouchSpec
    sensors: SensorSpec = SensorSpec()
    contact_resistance_m2K_W: float = 0.0
    seed: int = 0
    faults: tuple[Fault, ...] = ()
    description: str = ""
    source: str = "<string>"

    @property
    def stack(self) -> ProbeStack:
        return self.board.stack

    def q_v_W_m3(self, duty: float = 1.0, voltage_V: float | None = None) -> float:
        """Heater power density (W/m^3) at PWM ``duty`` on ``voltage_V`` (default: the supply)."""
        v = self.heater.supply_voltage_V if voltage_V is None else voltage_V
        return self.stack.q_v_from_power(duty * v * v / self.heater.resistance_ohm)
