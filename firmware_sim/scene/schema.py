"""The scene file schema: every table's fields as :class:`edge.schema.Field` data.

A scene is a TOML file. Each table below is declared as a mapping of
:class:`~edge.schema.Field` and checked by the one validation engine,
:mod:`edge.schema` (:func:`~edge.schema.check_table`); the rules that tie
fields together (material or properties, thickness unless the back is
infinite, chip addresses, exactly-one-of fault parameters) live in
:mod:`firmware_sim.scene.parser`. Any failure is a
:class:`~firmware_sim.scene.model.SceneError` whose message starts with the
file name and the dotted key path, e.g.
``glass.toml: object.k_W_mK: must be > 0, got -1.0``.

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
    world?      str  "ideal" (default: exact 1-D, the estimator's idealisation) or "faithful"
                     (axisymmetric finite volumes: foam, finite heater, convection, as-built deviations)
    probe?      str  a name in edge.physics.geometry.PROBES: "paper" (default) or "small-heater";
                     a probe head whose estimator is not 1-D ("thick_body") needs world = "faithful"

At least one thermocouple reader (mcp9600 or ads122c04) and one flux reader
(ads1115 or ads122c04) must be fitted; addresses must differ.

``[as_built]`` (optional; world = "faithful" only) -- how the probe was
really built; the device is never told (the daemon's configuration keeps the
nominal values)::

    sensing_thickness_factor?      float  sensing layer thickness / nominal (default 1)
    sensing_k_factor?              float  sensing layer conductivity / nominal (default 1)
    flux_sensitivity_factor?       float  true thermopile sensitivity / [sensors] value (default 1)
    heater_resistance_factor?      float  true film resistance / [heater] value (default 1)
    thermocouple_time_constant_s?  float  >= 0, true bead lag (default: the [sensors] value)
    heater_tcr_per_K?              float  film temperature coefficient of resistance (default 0)
    heater_reference_C?            float  temperature of the stated resistance (default 25)
    heater_lead_resistance_ohm?    float  >= 0, leads in series with the film (default 0)
    substrate_k_factor?, substrate_rho_c_factor?, substrate_thickness_factor?
                                   float  backing foam as built / the probe's (default 1)
    sensor_square?                 bool   read the thermopile's real square (the small-heater
                                          probe always does; default: the probe's footprint)
    sensor_offset_x_m?, sensor_offset_y_m?
                                   float  the square's centre off the heater's axis (default 0;
                                          needs the square)
    thermocouple_r_m?              float  >= 0, thermocouple's distance from the axis (default 0)
    thermocouple_height_m?         float  >= 0, junction above the sensing layer's bottom face (default 0)
    draw_seed?                     int    >= 0: draw every deviation per probe from
                                          firmware_sim.asbuilt's tolerances (alone in the table)

Factors lie in [0.5, 2].

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
    repeat?         bool         touch after touch (default: on in ``thermotouch sim``
                                 and --sim sessions, off for a bare Simulator): repeat_gap_s after
                                 each touch the probe is put on the object again and
                                 stays until 0.5 s after the next heating ends, so a
                                 session measures again and again with the probe in
                                 air in between (touches added by hand turn it off)
    repeat_gap_s?   float > 0    time in air between touches (default 1.0)
    contact_resistance_m2K_W?  float >= 0  this session's touches (overrides the top-level value)
    object_temperature_C?      float       object temperature at each touch (overrides
                                           environment.initial_temperature_C), or
    object_offset_K?           float       the same as an offset from ambient (not both)
    contact_lead_s?            float       the probe rests on the object this long before the
                                           heater goes on (< length_s; default 0); negative: the
                                           heater goes on first (a late touch), at >= 0.2 s

``[[faults]]`` (optional, any number)::

    kind      str    one of FAULT_KINDS (firmware_sim.scene.model)
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
        converter_frozen   chip ("mcp9600" | "ads1115" | "ads122c04"): completes no conversion

Material names are resolved in the validated material library,
:mod:`edge.physics.materials` (``edge/physics/data/materials.csv``); callers may pass their
own ``material_lookup``.
"""

from __future__ import annotations

from typing import Mapping

from edge.hw.chips import CHIPS
from edge.physics.geometry import PROBES
from edge.physics.probe import STACKS
from edge.schema import Field
from firmware_sim.scene.model import (
    BACKS,
    CHIP_ADDRESSES,
    FAULT_KINDS,
    FLUX_SATURATION_V,
    WORLDS,
    AsBuiltSpec,
    SensorSpec,
)

__all__ = [
    "T_MIN_C",
    "T_MAX_C",
    "TOP_FIELDS",
    "OBJECT_FIELDS",
    "PROPERTY_NAMES",
    "ENVIRONMENT_FIELDS",
    "HEATER_FIELDS",
    "BOARD_FIELDS",
    "SENSOR_FIELDS",
    "AS_BUILT_FIELDS",
    "TOUCH_FIELDS",
    "FAULT_FIELDS",
    "FAULT_PARAM_FIELDS",
]

T_MIN_C = -270.0   # type K table range (edge.physics.typek); the thermocouple must read it
T_MAX_C = 1372.0

_POSITIVE = {"lo": 0.0, "lo_open": True}
_NON_NEGATIVE = {"lo": 0.0}
_TEMPERATURE = {"lo": T_MIN_C, "hi": T_MAX_C}

TOP_FIELDS: Mapping[str, Field] = {
    "name": Field("str", None, "scene name (default: file stem)"),
    "description": Field("str", "", "free text"),
    "seed": Field("int", 0, "seeds all sensor noise", lo=0),
    "contact_resistance_m2K_W": Field("float", 0.0, "probe-object contact resistance", lo=0.0, hi=1.0),
    "object": Field("table", doc="the touched solid"),
    "environment": Field("table", doc="temperatures"),
    "heater": Field("table", doc="heater supply and film"),
    "board": Field("table", doc="fitted chips"),
    "sensors": Field("table", None, "sensor characteristics and noise"),
    "touch": Field("table", doc="when the probe is on the object"),
    "as_built": Field("table", None, "how the probe was really built (faithful world; never told to the device)"),
    "faults": Field("list", None, "[[faults]]: injected faults"),
}

#: The three properties that replace ``object.material``.
PROPERTY_NAMES = ("k_W_mK", "rho_kg_m3", "c_J_kgK")

OBJECT_FIELDS: Mapping[str, Field] = {
    "material": Field("str", None, "a name from the material library"),
    "label": Field("str", None, "display name (default: the material name)"),
    "k_W_mK": Field("float", None, "conductivity", **_POSITIVE),
    "rho_kg_m3": Field("float", None, "density", **_POSITIVE),
    "c_J_kgK": Field("float", None, "specific heat", **_POSITIVE),
    "back": Field("str", doc="back boundary", choices=BACKS),
    "thickness_m": Field("float", None, "required unless back = infinite", **_POSITIVE),
}

ENVIRONMENT_FIELDS: Mapping[str, Field] = {
    "initial_temperature_C": Field("float", doc="object temperature before the touch", **_TEMPERATURE),
    "ambient_temperature_C": Field("float", doc="air, probe and board (cold-junction) temperature", **_TEMPERATURE),
}

HEATER_FIELDS: Mapping[str, Field] = {
    "supply_voltage_V": Field("float", doc="heater supply", lo=0.0, lo_open=True, hi=1000.0),
    "resistance_ohm": Field("float", doc="film resistance", **_POSITIVE),
}

#: Chip addresses are ints here; the parser checks them against CHIP_ADDRESSES.
BOARD_FIELDS: Mapping[str, Field] = {
    **{chip: Field("int", None, f"I2C address of the {chip}") for chip in CHIP_ADDRESSES},
    "stack": Field("str", "0.42", "probe layer stack (edge.physics.probe.STACKS)", choices=tuple(STACKS)),
    "world": Field("str", "ideal", "thermal world behind the chips", choices=WORLDS),
    "probe": Field("str", "paper", "probe geometry (edge.physics.geometry.PROBES)", choices=tuple(PROBES)),
}

#: A few per cent is what a build deviates by; the bounds only catch typos (a factor of 100, a sign).
_FACTOR = {"lo": 0.5, "hi": 2.0}
_NOMINAL = AsBuiltSpec()
AS_BUILT_FIELDS: Mapping[str, Field] = {
    "sensing_thickness_factor": Field("float", 1.0, "sensing layer thickness / nominal", **_FACTOR),
    "sensing_k_factor": Field("float", 1.0, "sensing layer conductivity / nominal", **_FACTOR),
    "flux_sensitivity_factor": Field("float", 1.0, "true thermopile sensitivity / nominal", **_FACTOR),
    "heater_resistance_factor": Field("float", 1.0, "true film resistance / nominal", **_FACTOR),
    "thermocouple_time_constant_s": Field("float", None, "true bead lag (default: [sensors])", lo=0.0, hi=10.0),
    "heater_tcr_per_K": Field("float", _NOMINAL.heater_tcr_per_K, "film temperature coefficient of resistance",
                              lo=-0.01, hi=0.01),
    "heater_reference_C": Field("float", _NOMINAL.heater_reference_C, "temperature of the stated resistance",
                                **_TEMPERATURE),
    "heater_lead_resistance_ohm": Field("float", 0.0, "leads in series with the film", lo=0.0, hi=100.0),
    "substrate_k_factor": Field("float", 1.0, "backing foam conductivity / the probe's", **_FACTOR),
    "substrate_rho_c_factor": Field("float", 1.0, "backing foam volumetric heat capacity / the probe's", **_FACTOR),
    "substrate_thickness_factor": Field("float", 1.0, "backing foam thickness / the probe's", **_FACTOR),
    "sensor_square": Field("bool", False, "read the thermopile's real square (default: the probe's footprint)"),
    "sensor_offset_x_m": Field("float", 0.0, "square's centre off the heater's axis along x", lo=-0.005, hi=0.005),
    "sensor_offset_y_m": Field("float", 0.0, "square's centre off the heater's axis along y", lo=-0.005, hi=0.005),
    "thermocouple_r_m": Field("float", 0.0, "thermocouple's distance from the axis", lo=0.0, hi=0.005),
    "thermocouple_height_m": Field("float", 0.0, "junction's height above the sensing layer's bottom face",
                                   lo=0.0, hi=0.001),
    "draw_seed": Field("int", None, "draw every deviation from firmware_sim.asbuilt's tolerances", lo=0),
}

_DEFAULT_SENSORS = SensorSpec()
SENSOR_FIELDS: Mapping[str, Field] = {
    "thermocouple_time_constant_s": Field("float", _DEFAULT_SENSORS.thermocouple_time_constant_s,
                                          "first-order lag of the thermocouple", lo=0.0, hi=10.0),
    "flux_sensitivity_V_per_W_m2": Field("float", _DEFAULT_SENSORS.flux_sensitivity_V_per_W_m2,
                                         "flux sensor output per flux", lo=0.0, lo_open=True, hi=1e-3),
    "flux_range_W_m2": Field("float", _DEFAULT_SENSORS.flux_range_W_m2, "output clips at +-range", **_POSITIVE),
    # Each registry chip's input noise (edge.hw.chips.Chip.input_noise).
    **{spec.setting_key(spec.input_noise.key): Field(spec.input_noise.kind, spec.input_noise.default,
                                                     spec.input_noise.doc, **spec.input_noise.bounds)
       for spec in CHIPS.values()},
}

TOUCH_FIELDS: Mapping[str, Field] = {
    "start_s": Field("float", doc="probe placed on the object (virtual time)", **_NON_NEGATIVE),
    "length_s": Field("float", doc="probe lifted at start_s + length_s", **_POSITIVE),
    "press_trigger": Field("bool", True, "press the trigger button at start_s"),
    "trigger_hold_s": Field("float", 0.1, "how long the trigger is held", **_POSITIVE),
    "repeat": Field("bool", None, "touch after touch: the probe is put down again repeat_gap_s after a touch "
                    "(default: on in a thermotouch sim session, off for a bare Simulator)"),
    "repeat_gap_s": Field("float", 1.0, "time in air between repeat touches", **_POSITIVE),
    "contact_resistance_m2K_W": Field("float", None, "contact resistance of each touch (overrides the top level)",
                                      lo=0.0, hi=1.0),
    "object_temperature_C": Field("float", None, "object temperature at each touch", **_TEMPERATURE),
    "object_offset_K": Field("float", None, "object temperature at each touch, from ambient", lo=-200.0, hi=200.0),
    "contact_lead_s": Field("float", 0.0, "contact this long before heater-on (< length_s; < 0: after)",
                            lo=-10.0, hi=60.0),
}

#: ``until_s`` must also exceed ``at_s``; the parser checks that bound.
FAULT_FIELDS: Mapping[str, Field] = {
    "kind": Field("str", doc="fault kind", choices=FAULT_KINDS),
    "at_s": Field("float", 0.0, "start", **_NON_NEGATIVE),
    "until_s": Field("float", None, "end (default: never)"),
    "params": Field("table", None, "kind-specific parameters"),
}

#: Parameters per fault kind. For i2c_nack and supply_sag exactly one of the
#: two must be given (the parser checks that).
FAULT_PARAM_FIELDS: Mapping[str, Mapping[str, Field]] = {
    "i2c_nack": {
        "address": Field("int", None, "7-bit I2C address", lo=0, hi=0x7F),
        "chip": Field("str", None, "a fitted chip", choices=tuple(CHIP_ADDRESSES)),
    },
    "bus_stuck": {},
    "open_thermocouple": {},
    "flux_saturation": {"voltage_V": Field("float", FLUX_SATURATION_V, "voltage the flux channel shows")},
    "heater_stuck_on": {"duty": Field("float", 1.0, "stuck duty", lo=0.0, lo_open=True, hi=1.0)},
    "heater_dead": {},
    "supply_sag": {
        "factor": Field("float", None, "supply scaled by factor", lo=0.0, lo_open=True, hi=1.0),
        "voltage_V": Field("float", None, "supply drops to voltage_V", **_POSITIVE),
    },
    "no_contact": {},
    "converter_frozen": {"chip": Field("str", doc="the fitted chip that freezes", choices=tuple(CHIP_ADDRESSES))},
}
