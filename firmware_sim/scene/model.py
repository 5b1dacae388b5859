"""The scene model: what the simulated probe touches, on which board, with which faults.

Frozen dataclasses filled by :mod:`firmware_sim.scene.parser` from a TOML
file (schema: :mod:`firmware_sim.scene.schema`), plus the error type every
scene check raises, :class:`SceneError`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, make_dataclass
from typing import Any, Mapping

from edge.hw.chips import CHIPS
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
    "AsBuiltSpec",
    "WORLDS",
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
    "converter_frozen",
)
BACKS = ("fixed", "insulated", "infinite")
#: Thermal worlds behind the chips: ``"ideal"`` (firmware_sim.world.ThermalWorld, the exact 1-D
#: solution of the estimator's own idealisation) and ``"faithful"`` (firmware_sim.rz.probe_world.
#: FaithfulWorld, the axisymmetric finite-volume probe with its as-built deviations).
WORLDS = ("ideal", "faithful")
#: Valid 7-bit addresses of each chip a board may carry (the chip registry's, from their register maps).
CHIP_ADDRESSES: dict[str, tuple[int, ...]] = {name: spec.addresses for name, spec in CHIPS.items()}
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


class _Board:
    """The methods of :class:`BoardSpec` (its fields come from the chip registry)."""

    @property
    def stack(self) -> ProbeStack:
        """The probe layer stack (see :mod:`edge.physics.solids`)."""
        return STACKS[self.stack_name]

    def address_of(self, chip: str) -> int | None:
        """Address of ``chip`` (a name in :data:`edge.hw.chips.CHIPS`), or None."""
        if chip not in CHIP_ADDRESSES:
            raise ValueError(f"chip must be one of {sorted(CHIP_ADDRESSES)}, got {chip!r}")
        return getattr(self, chip)


def _frozen(name: str, fields: list, doc: str, bases: tuple = ()) -> type:
    cls = make_dataclass(name, fields, bases=bases, frozen=True)
    cls.__module__, cls.__doc__ = __name__, doc
    return cls


#: Fitted chips (7-bit addresses, None = absent: one field per chip of :data:`edge.hw.chips.CHIPS`,
#: the scene file's ``[board]`` keys), probe stack name, thermal world and probe geometry (``probe``
#: names an :data:`edge.physics.geometry.PROBES` entry; only the faithful world resolves a heater
#: smaller than the object, the ideal world is 1-D).
BoardSpec = _frozen("BoardSpec", [
    *((name, "int | None", field(default=None)) for name in CHIPS),
    ("stack_name", str, field(default="0.42")),
    ("world", str, field(default="ideal")),
    ("probe", str, field(default="paper")),
], "Fitted chips by registry name (addresses, None = absent), probe stack name, thermal world, probe geometry.",
    (_Board,))

#: Sensor characteristics and noise (SI): each registry chip's input noise is
#: ``<chip>_<key>`` of its :attr:`edge.hw.chips.Chip.input_noise` (V rms, default 0).
SensorSpec = _frozen("SensorSpec", [
    ("thermocouple_time_constant_s", float, field(default=0.0)),
    ("flux_sensitivity_V_per_W_m2", float, field(default=FLUX_SENSITIVITY_V_per_W_m2)),
    ("flux_range_W_m2", float, field(default=10_000.0)),
    *((spec.setting_key(spec.input_noise.key), float, field(default=spec.input_noise.default))
      for spec in CHIPS.values()),
], "Sensor characteristics and noise (SI; one input noise per registry chip).")


@dataclass(frozen=True)
class AsBuiltSpec:
    """How the simulated probe was really built (``[as_built]``); the device is never told.

    Factors multiply the nominal values (the stack's sensing layer, the
    ``[sensors]`` flux sensitivity, the ``[heater]`` resistance, the probe's
    substrate); the lag, the TCR, lead resistance and positions are absolute.
    ``sensor_square`` makes the world read the thermopile's real square (with
    its offset) where the probe's default is the disk (the paper probe).
    ``draw_seed`` draws every deviation from the tolerances of
    :mod:`firmware_sim.asbuilt` instead (then no other key may be given).
    Used by the faithful world only.
    """

    sensing_thickness_factor: float = 1.0
    sensing_k_factor: float = 1.0
    flux_sensitivity_factor: float = 1.0
    heater_resistance_factor: float = 1.0
    thermocouple_time_constant_s: float | None = None   # None: the [sensors] value
    heater_tcr_per_K: float = 0.0
    heater_reference_C: float = 25.0
    heater_lead_resistance_ohm: float = 0.0
    substrate_k_factor: float = 1.0
    substrate_rho_c_factor: float = 1.0
    substrate_thickness_factor: float = 1.0
    sensor_square: bool = False
    sensor_offset_x_m: float = 0.0
    sensor_offset_y_m: float = 0.0
    thermocouple_r_m: float = 0.0
    thermocouple_height_m: float = 0.0
    draw_seed: int | None = None


@dataclass(frozen=True)
class TouchSpec:
    """When the probe is on the object (virtual seconds), and how it meets it.

    ``contact_resistance_m2K_W`` and the object temperature
    (``object_temperature_C``, or ``object_offset_K`` from ambient), when
    given, hold for every touch of the session and override the scene-wide
    values; ``contact_lead_s`` is how long the probe rests on the object
    before the heater goes on (the daemon's baseline covers it; negative:
    the heater goes on first and the probe lands late).
    """

    start_s: float
    length_s: float
    press_trigger: bool = True
    trigger_hold_s: float = 0.1
    #: Touch after touch: the probe is put on the object again ``repeat_gap_s`` after each touch.
    repeat: bool | None = None
    repeat_gap_s: float = 1.0
    contact_resistance_m2K_W: float | None = None
    object_temperature_C: float | None = None
    object_offset_K: float | None = None
    contact_lead_s: float = 0.0

    @property
    def end_s(self) -> float:
        return self.start_s + self.length_s

    @property
    def heater_on_s(self) -> float:
        """When the daemon of a sim session switches the heater on: ``contact_lead_s`` after contact."""
        return self.start_s + self.contact_lead_s


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
    as_built: AsBuiltSpec | None = None   # None: built as nominal

    @property
    def stack(self) -> ProbeStack:
        return self.board.stack

    @property
    def touch_contact_resistance_m2K_W(self) -> float:
        """Contact resistance of the scene's touches: ``[touch]``'s if given, else the scene-wide one."""
        rc = self.touch.contact_resistance_m2K_W
        return self.contact_resistance_m2K_W if rc is None else rc

    @property
    def object_temperature_C(self) -> float:
        """Object temperature when touched: ``[touch]``'s (absolute or offset from ambient), else the initial one."""
        t = self.touch
        if t.object_temperature_C is not None:
            return t.object_temperature_C
        if t.object_offset_K is not None:
            return self.environment.ambient_temperature_C + t.object_offset_K
        return self.environment.initial_temperature_C

    def q_v_W_m3(self, duty: float = 1.0, voltage_V: float | None = None) -> float:
        """Heater power density (W/m^3) at PWM ``duty`` on ``voltage_V`` (default: the supply)."""
        v = self.heater.supply_voltage_V if voltage_V is None else voltage_V
        return self.stack.q_v_from_power(duty * v * v / self.heater.resistance_ohm)
