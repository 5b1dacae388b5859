"""Scenes: what the simulated probe touches, on which board, with which faults.

A scene is a TOML file (read with :mod:`tomllib`). Every key is checked: an
unknown key, a missing field, a value of the wrong type or an unphysical value
raises :class:`SceneError` whose message starts with the file name and the
dotted key path, e.g. ``glass.toml: object.k_W_mK: must be > 0, got -1.0``.

Schema (units are in the key names; ``?`` marks optional keys, with defaults)
------------------------------------------------------------------------------
Top level::

    name?                      str    scene name (default: file stem)
    description?               str    free text
    seed?                      int    >= 0, seeds all sensor noise (default 0)
    contact_resistance_m2K_W?  float  >= 0, probe-object contact resistance (default 0)

``[object]`` (required) -- the touched solid::

    material?    str    a name from the material library (edge/physics/data/materials.csv), or
    k_W_mK?      float  > 0  conductivity     } all three instead of ``material``
    rho_kg_m3?   float  > 0  density          }
    c_J_kgK?     float  > 0  specific heat    }
    label?       str    display name
    back         str    "fixed" (held at the initial temperature), "insulated" or "infinite"
    thickness_m  float  > 0; required unless back = "infinite"

``[environment]`` (required)::

    initial_temperature_C   float  object temperature before the touch
    ambient_temperature_C   float  air, probe and board (cold-junction) temperature

``[heater]`` (required)::

    supply_voltage_V  float  > 0
    resistance_ohm    float  > 0 (the paper does not state R; the shipped scenes assume 50 ohm)

``[board]`` (required) -- which chips are fitted (omit a key: chip absent)::

    mcp9600?    int  I2C address 0x60..0x67 (thermocouple converter)
    ads1115?    int  I2C address 0x48..0x4B (flux sensor on AIN0-AIN1)
    ads122c04?  int  I2C address 0x40..0x4F (thermocouple on AIN0-AIN1, flux on AIN2-AIN3)
    stack?      str  "0.42" (default) or "0.40": probe layer stack, see edge.physics.solids

At least one thermocouple reader (mcp9600 or ads122c04) and one flux reader
(ads1115 or ads122c04) must be fitted; addresses must differ.

``[sensors]`` (optional)::

    thermocouple_time_constant_s?   float >= 0 (default 0: ideal fine wire)
    flux_sensitivity_V_per_W_m2?    float > 0  (default 0.56e-6, FHF05-like)
    flux_range_W_m2?                float > 0  (default 10000: output clips at +-range)
    mcp9600_emf_noise_rms_V?        float >= 0 (default 0)
    ads1115_noise_rms_V?            float >= 0 (default 0)
    ads122c04_noise_rms_V?          float >= 0 (default 0)

``[touch]`` (required)::

    start_s         float >= 0   probe placed on the object (virtual time)
    length_s        float > 0    probe lifted at start_s + length_s
    press_trigger?  bool         press the trigger button at start_s (default true)
    trigger_hold_s? float > 0    how long it is held (default 0.1)

``[[faults]]`` (optional, any number)::

    kind      str    one of FAULT_KINDS (below)
    at_s?     float  >= 0, start (default 0)
    until_s?  float  > at_s, end (default: never)
    params?   table  kind-specific:
        i2c_nack           address (int) or chip ("mcp9600" | "ads1115" | "ads122c04")
        bus_stuck          -
        open_thermocouple  -
        flux_saturation    voltage_V? (default 0.3 V: beyond both ADCs' flux ranges)
        heater_stuck_on    duty? (0 < duty <= 1, default 1)
        heater_dead        -
        supply_sag         factor (0 < factor <= 1) or voltage_V (> 0)
        no_contact         -

Material names are resolved in the validated material library,
:mod:`edge.physics.materials` (``edge/physics/data/materials.csv``); callers may pass their
own ``material_lookup``.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from edge.physics.probe import FLUX_SENSITIVITY_V_per_W_m2, STACKS, ProbeStack
from edge.physics.solids import Solid

__all__ = [
    "FAULT_KINDS",
    "BACKS",
    "SceneError",
    "ObjectSpec",
    "Environment",
    "HeaterSpec",
    "BoardSpec",
    "SensorSpec",
    "TouchSpec",
    "Fault",
    "Scene",
    "parse_scene",
    "read_scene",
    "scene_names",
    "scene_path",
    "library_material",
    "validate_fault",
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
CHIP_ADDRESSES = {
    "mcp9600": range(0x60, 0x68),
    "ads1115": range(0x48, 0x4C),
    "ads122c04": range(0x40, 0x50),
}
#: Default voltage a saturated flux channel shows: above the ADS1115's ±0.256 V
#: range and the ADS122C04's ±16 mV (gain 128), so either reports full scale.
FLUX_SATURATION_V = 0.3
_T_MIN_C = -270.0   # type K table range (edge.physics.typek); the thermocouple must read it
_T_MAX_C = 1372.0


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
        from edge.physics.probe import heater_power_W  # noqa: PLC0415

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
    """A parsed, validated scene (see the module docstring for the schema)."""

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


# ---------------------------------------------------------------------------
# Validation helpers


class _Ctx:
    """Carries the file name so every check can raise a located SceneError."""

    def __init__(self, file: str) -> None:
        self.file = file

    def fail(self, key: str, message: str) -> SceneError:
        return SceneError(self.file, key, message)

    def table(self, data: Mapping[str, Any], key: str, *, required: bool = True) -> dict | None:
        name = key.rsplit(".", 1)[-1]
        if name not in data:
            if required:
                raise self.fail(key, "missing required table")
            return None
        v = data[name]
        if not isinstance(v, dict):
            raise self.fail(key, f"must be a table, got {type(v).__name__}")
        return v

    def keys(self, data: Mapping[str, Any], prefix: str, allowed: tuple[str, ...]) -> None:
        for k in data:
            if k not in allowed:
                path = f"{prefix}.{k}" if prefix else k
                raise self.fail(path, f"unknown key (allowed: {', '.join(allowed)})")

    def number(self, data: Mapping[str, Any], prefix: str, name: str, *, default: Any = ...,
               gt: float | None = None, ge: float | None = None, le: float | None = None,
               lt: float | None = None) -> Any:
        key = f"{prefix}.{name}" if prefix else name
        if name not in data:
            if default is ...:
                raise self.fail(key, "missing required field")
            return default
        v = data[name]
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.fail(key, f"must be a number, got {type(v).__name__} {v!r}")
        v = float(v)
        if not math.isfinite(v):
            raise self.fail(key, f"must be finite, got {v!r}")
        for bound, ok, word in ((gt, lambda b: v > b, ">"), (ge, lambda b: v >= b, ">="),
                                (lt, lambda b: v < b, "<"), (le, lambda b: v <= b, "<=")):
            if bound is not None and not ok(bound):
                raise self.fail(key, f"must be {word} {bound:g}, got {v:g}")
        return v

    def integer(self, data: Mapping[str, Any], prefix: str, name: str, *, default: Any = ...) -> Any:
        key = f"{prefix}.{name}" if prefix else name
        if name not in data:
            if default is ...:
                raise self.fail(key, "missing required field")
            return default
        v = data[name]
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(key, f"must be an integer, got {type(v).__name__} {v!r}")
        return v

    def string(self, data: Mapping[str, Any], prefix: str, name: str, *, default: Any = ...,
               choices: tuple[str, ...] | None = None) -> Any:
        key = f"{prefix}.{name}" if prefix else name
        if name not in data:
            if default is ...:
                raise self.fail(key, "missing required field")
            return default
        v = data[name]
        if not isinstance(v, str):
            raise self.fail(key, f"must be a string, got {type(v).__name__} {v!r}")
        if choices is not None and v not in choices:
            raise self.fail(key, f"must be one of {', '.join(repr(c) for c in choices)}, got {v!r}")
        return v

    def boolean(self, data: Mapping[str, Any], prefix: str, name: str, *, default: bool) -> bool:
        key = f"{prefix}.{name}" if prefix else name
        if name not in data:
            return default
        v = data[name]
        if not isinstance(v, bool):
            raise self.fail(key, f"must be true or false, got {type(v).__name__} {v!r}")
        return v


# ---------------------------------------------------------------------------
# Material library (read from host's package data without importing host)

MaterialLookup = Callable[[str], tuple[float, float, float]]
def library_material(name: str) -> tuple[float, float, float]:
    """``(k_W_mK, rho_kg_m3, c_J_kgK)`` of library material ``name`` (edge.physics.materials).

    Raises KeyError for an unknown name.
    """
    from edge.physics.materials import load_materials  # noqa: PLC0415 - only scenes naming a material need it

    m = load_materials().get(name)
    return (m.k_W_mK, m.rho_kg_m3, m.c_J_kgK)


# ---------------------------------------------------------------------------
# Sections

_TOP_KEYS = ("name", "description", "seed", "contact_resistance_m2K_W", "object", "environment",
             "heater", "board", "sensors", "touch", "faults")
_PROPS = ("k_W_mK", "rho_kg_m3", "c_J_kgK")


def _parse_object(c: _Ctx, data: dict, lookup: MaterialLookup | None) -> ObjectSpec:
    o = c.table(data, "object")
    c.keys(o, "object", ("material", "label") + _PROPS + ("back", "thickness_m"))
    material = c.string(o, "object", "material", default=None)
    given = [p for p in _PROPS if p in o]
    if material is not None:
        if given:
            raise c.fail(f"object.{given[0]}", "give either object.material or k_W_mK/rho_kg_m3/c_J_kgK, not both")
        try:
            k, rho, cp = (lookup or library_material)(material)
        except KeyError:
            raise c.fail("object.material", f"unknown material {material!r} (not in the material library)") from None
        except LookupError as e:
            raise c.fail("object.material", f"cannot resolve {material!r}: {e}") from None
    else:
        if not given:
            raise c.fail("object.material", "missing required field (or give k_W_mK, rho_kg_m3 and c_J_kgK)")
        k = c.number(o, "object", "k_W_mK", gt=0.0)
        rho = c.number(o, "object", "rho_kg_m3", gt=0.0)
        cp = c.number(o, "object", "c_J_kgK", gt=0.0)
    back = c.string(o, "object", "back", choices=BACKS)
    if back == "infinite":
        thickness = c.number(o, "object", "thickness_m", default=None, gt=0.0)
    else:
        thickness = c.number(o, "object", "thickness_m", gt=0.0)
    label = c.string(o, "object", "label", default=material or "")
    return ObjectSpec(Solid(k, rho, cp), back, thickness, material, label)


def _parse_environment(c: _Ctx, data: dict) -> Environment:
    e = c.table(data, "environment")
    c.keys(e, "environment", ("initial_temperature_C", "ambient_temperature_C"))
    ti = c.number(e, "environment", "initial_temperature_C", ge=_T_MIN_C, le=_T_MAX_C)
    ta = c.number(e, "environment", "ambient_temperature_C", ge=_T_MIN_C, le=_T_MAX_C)
    return Environment(ti, ta)


def _parse_heater(c: _Ctx, data: dict) -> HeaterSpec:
    h = c.table(data, "heater")
    c.keys(h, "heater", ("supply_voltage_V", "resistance_ohm"))
    v = c.number(h, "heater", "supply_voltage_V", gt=0.0, le=1000.0)
    r = c.number(h, "heater", "resistance_ohm", gt=0.0)
    return HeaterSpec(v, r)


def _parse_board(c: _Ctx, data: dict) -> BoardSpec:
    b = c.table(data, "board")
    c.keys(b, "board", tuple(CHIP_ADDRESSES) + ("stack",))
    addrs: dict[str, int | None] = {}
    for chip, valid in CHIP_ADDRESSES.items():
        a = c.integer(b, "board", chip, default=None)
        if a is not None and a not in valid:
            raise c.fail(f"board.{chip}", f"address must be 0x{valid.start:02x}..0x{valid.stop - 1:02x}, got 0x{a:02x}"
                         if a >= 0 else f"address must be 0x{valid.start:02x}..0x{valid.stop - 1:02x}, got {a}")
        addrs[chip] = a
    used = [(a, chip) for chip, a in addrs.items() if a is not None]
    seen: dict[int, str] = {}
    for a, chip in used:
        if a in seen:
            raise c.fail(f"board.{chip}", f"address 0x{a:02x} is already used by {seen[a]}")
        seen[a] = chip
    if addrs["mcp9600"] is None and addrs["ads122c04"] is None:
        raise c.fail("board.mcp9600", "missing: fit a thermocouple reader (board.mcp9600 or board.ads122c04)")
    if addrs["ads1115"] is None and addrs["ads122c04"] is None:
        raise c.fail("board.ads1115", "missing: fit a flux-sensor reader (board.ads1115 or board.ads122c04)")
    stack = c.string(b, "board", "stack", default="0.42", choices=tuple(STACKS))
    return BoardSpec(addrs["mcp9600"], addrs["ads1115"], addrs["ads122c04"], stack)


def _parse_sensors(c: _Ctx, data: dict) -> SensorSpec:
    s = c.table(data, "sensors", required=False)
    if s is None:
        return SensorSpec()
    names = ("thermocouple_time_constant_s", "flux_sensitivity_V_per_W_m2", "flux_range_W_m2",
             "mcp9600_emf_noise_rms_V", "ads1115_noise_rms_V", "ads122c04_noise_rms_V")
    c.keys(s, "sensors", names)
    d = SensorSpec()
    return SensorSpec(
        thermocouple_time_constant_s=c.number(s, "sensors", names[0], default=d.thermocouple_time_constant_s,
                                              ge=0.0, le=10.0),
        flux_sensitivity_V_per_W_m2=c.number(s, "sensors", names[1], default=d.flux_sensitivity_V_per_W_m2,
                                             gt=0.0, le=1e-3),
        flux_range_W_m2=c.number(s, "sensors", names[2], default=d.flux_range_W_m2, gt=0.0),
        mcp9600_emf_noise_rms_V=c.number(s, "sensors", names[3], default=0.0, ge=0.0, le=1e-3),
        ads1115_noise_rms_V=c.number(s, "sensors", names[4], default=0.0, ge=0.0, le=1e-2),
        ads122c04_noise_rms_V=c.number(s, "sensors", names[5], default=0.0, ge=0.0, le=1e-3),
    )


def _parse_touch(c: _Ctx, data: dict) -> TouchSpec:
    t = c.table(data, "touch")
    c.keys(t, "touch", ("start_s", "length_s", "press_trigger", "trigger_hold_s"))
    start = c.number(t, "touch", "start_s", ge=0.0)
    length = c.number(t, "touch", "length_s", gt=0.0)
    press = c.boolean(t, "touch", "press_trigger", default=True)
    hold = c.number(t, "touch", "trigger_hold_s", default=0.1, gt=0.0)
    return TouchSpec(start, length, press, hold)


_FAULT_PARAMS = {
    "i2c_nack": ("address", "chip"),
    "bus_stuck": (),
    "open_thermocouple": (),
    "flux_saturation": ("voltage_V",),
    "heater_stuck_on": ("duty",),
    "heater_dead": (),
    "supply_sag": ("factor", "voltage_V"),
    "no_contact": (),
}


def _check_fault(c: _Ctx, f: Mapping[str, Any], prefix: str) -> Fault:
    c.keys(f, prefix, ("kind", "at_s", "until_s", "params"))
    kind = c.string(f, prefix, "kind", choices=FAULT_KINDS)
    at = c.number(f, prefix, "at_s", default=0.0, ge=0.0)
    until = c.number(f, prefix, "until_s", default=None, gt=at)
    p = f.get("params", {})
    pp = f"{prefix}.params"
    if not isinstance(p, dict):
        raise c.fail(pp, f"must be a table, got {type(p).__name__}")
    c.keys(p, pp, _FAULT_PARAMS[kind])
    params: dict[str, Any] = {}
    if kind == "i2c_nack":
        if ("address" in p) == ("chip" in p):
            raise c.fail(f"{pp}.address", "give exactly one of params.address or params.chip")
        if "chip" in p:
            params["chip"] = c.string(p, pp, "chip", choices=tuple(CHIP_ADDRESSES))
        else:
            a = c.integer(p, pp, "address")
            if not 0 <= a <= 0x7F:
                raise c.fail(f"{pp}.address", f"must be a 7-bit address 0..0x7f, got {a}")
            params["address"] = a
    elif kind == "flux_saturation":
        params["voltage_V"] = c.number(p, pp, "voltage_V", default=FLUX_SATURATION_V)
    elif kind == "heater_stuck_on":
        params["duty"] = c.number(p, pp, "duty", default=1.0, gt=0.0, le=1.0)
    elif kind == "supply_sag":
        if ("factor" in p) == ("voltage_V" in p):
            raise c.fail(f"{pp}.factor", "give exactly one of params.factor or params.voltage_V")
        if "factor" in p:
            params["factor"] = c.number(p, pp, "factor", gt=0.0, le=1.0)
        else:
            params["voltage_V"] = c.number(p, pp, "voltage_V", gt=0.0)
    return Fault(kind, at, until, params)


def validate_fault(kind: str, at_s: float = 0.0, until_s: float | None = None,
                   params: Mapping[str, Any] | None = None) -> Fault:
    """Build a :class:`Fault` from code with the same checks as a scene's ``[[faults]]``."""
    f: dict[str, Any] = {"kind": kind, "at_s": at_s, "params": dict(params or {})}
    if until_s is not None:
        f["until_s"] = until_s
    return _check_fault(_Ctx("<inject>"), f, "fault")


def parse_scene(text: str, *, source: str = "<string>", name: str | None = None,
                material_lookup: MaterialLookup | None = None) -> Scene:
    """Parse and validate scene TOML ``text``.

    Parameters
    ----------
    text : str
        TOML document (schema in the module docstring).
    source : str
        File name used in error messages.
    name : str, optional
        Default scene name when the document has no ``name``.
    material_lookup : callable name -> (k_W_mK, rho_kg_m3, c_J_kgK), optional
        Resolves ``object.material`` (raise KeyError for unknown names);
        default: the packaged material library.

    Raises
    ------
    SceneError
        Naming the file and the dotted key of the first problem.
    """
    c = _Ctx(source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(source, "", f"not valid TOML: {e}") from None
    c.keys(data, "", _TOP_KEYS)
    scene_name = c.string(data, "", "name", default=name or Path(source).stem)
    description = c.string(data, "", "description", default="")
    seed = c.integer(data, "", "seed", default=0)
    if seed < 0:
        raise c.fail("seed", f"must be >= 0, got {seed}")
    rc = c.number(data, "", "contact_resistance_m2K_W", default=0.0, ge=0.0, le=1.0)
    obj = _parse_object(c, data, material_lookup)
    env = _parse_environment(c, data)
    heater = _parse_heater(c, data)
    board = _parse_board(c, data)
    sensors = _parse_sensors(c, data)
    touch = _parse_touch(c, data)
    raw_faults = data.get("faults", [])
    if not isinstance(raw_faults, list):
        raise c.fail("faults", "must be an array of tables ([[faults]])")
    faults = []
    for i, f in enumerate(raw_faults):
        if not isinstance(f, dict):
            raise c.fail(f"faults[{i}]", f"must be a table, got {type(f).__name__}")
        fault = _check_fault(c, f, f"faults[{i}]")
        if fault.kind == "i2c_nack" and "chip" in fault.params and board.address_of(fault.params["chip"]) is None:
            raise c.fail(f"faults[{i}].params.chip", f"{fault.params['chip']} is not fitted on this board")
        faults.append(fault)
    return Scene(scene_name, obj, env, heater, board, touch, sensors, rc, seed, tuple(faults),
                 description, source)


# ---------------------------------------------------------------------------
# Files

_SCENES_DIR = Path(__file__).with_name("scenes")


def scene_names() -> list[str]:
    """Names of the scenes shipped with the package, sorted."""
    return sorted(p.stem for p in _SCENES_DIR.glob("*.toml"))


def scene_path(path_or_name: str | Path) -> Path:
    """A scene file: an existing path, or the name of a shipped scene (``"glass_15V"``)."""
    p = Path(path_or_name)
    if p.is_file():
        return p
    if isinstance(path_or_name, str) and "/" not in path_or_name and "\\" not in path_or_name:
        shipped = _SCENES_DIR / (path_or_name if path_or_name.endswith(".toml") else f"{path_or_name}.toml")
        if shipped.is_file():
            return shipped
        raise FileNotFoundError(
            f"no scene file {path_or_name!r} and no shipped scene of that name "
            f"(shipped: {', '.join(scene_names())})")
    raise FileNotFoundError(f"scene file not found: {p}")


def read_scene(path_or_name: str | Path, *, material_lookup: MaterialLookup | None = None) -> Scene:
    """Read and validate a scene file or shipped scene name (see :func:`parse_scene`)."""
    p = scene_path(path_or_name)
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise SceneError(p.name, "", f"not UTF-8 text: {e}") from None
    return parse_scene(text, source=p.name, name=p.stem, material_lookup=material_lookup)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise SceneError(f"cannot write a value of type {type(v).__name__} to a scene")


def dump_scene_toml(data: Mapping[str, Any]) -> str:
    """TOML text for a scene mapping (scalars, tables of scalars, arrays of tables)."""
    head = [f"{k} = {_toml_value(v)}" for k, v in data.items() if not isinstance(v, (dict, list))]
    body = []
    for k, v in data.items():
        if isinstance(v, dict):
            body.append(f"\n[{k}]")
            body += [f"{kk} = {_toml_value(vv)}" for kk, vv in v.items()]
        elif isinstance(v, list):
            for item in v:
                body.append(f"\n[[{k}]]")
                body += [f"{kk} = {_toml_value(vv)}" for kk, vv in item.items()]
    return "\n".join(head + body) + "\n"


def scene_variant(path_or_name: str | Path, dest_dir: str | Path, *, suffix: str,
                  **tables: Mapping[str, Any]) -> Path:
    """Write a copy of a scene with whole tables replaced (e.g. ``board={...}``); return its path.

    The copy is validated like any scene; its name gets ``suffix``.
    """
    src = scene_path(path_or_name)
    data = tomllib.loads(src.read_text())
    data["name"] = f"{data.get('name', src.stem)}{suffix}"
    for key, table in tables.items():
        data[key] = dict(table)
    dest = Path(dest_dir) / f"{src.stem}{suffix}.toml"
    dest.parent.mkdir(parents=True, exist_ok=True)
    text = dump_scene_toml(data)
    parse_scene(text, source=str(dest))
    dest.write_text(text)
    return dest


#: The precision board: thermocouple EMF and flux on the 24-bit ADS122C04.
PRECISION_BOARD = {"ads122c04": 0x40, "stack": "0.42"}
