"""Scene TOML text -> :class:`~firmware_sim.scene.model.Scene`, checked by :mod:`edge.schema`.

Each table is checked against its fields in :mod:`firmware_sim.scene.schema`
with :func:`edge.schema.check_table`; the rules that tie fields together are
checked here. Every failure is an :class:`edge.schema.SchemaError` with the
dotted key path, turned into a :class:`~firmware_sim.scene.model.SceneError`
(``"<file>: <dotted.key>: <message>"``) in one place.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, Callable, Mapping

from edge.hw.chips import FLUX, THERMOCOUPLE, names_for
from edge.physics.geometry import get_probe
from edge.physics.materials import load_materials
from edge.physics.solids import Solid
from edge.schema import Field, SchemaError, check_table, check_value

from firmware_sim.scene.model import (
    CHIP_ADDRESSES,
    AsBuiltSpec,
    BoardSpec,
    Environment,
    Fault,
    HeaterSpec,
    ObjectSpec,
    Scene,
    SceneError,
    SensorSpec,
    TouchSpec,
)
from firmware_sim.scene.schema import (
    AS_BUILT_FIELDS,
    BOARD_FIELDS,
    T_MAX_C,
    T_MIN_C,
    ENVIRONMENT_FIELDS,
    FAULT_FIELDS,
    FAULT_PARAM_FIELDS,
    HEATER_FIELDS,
    OBJECT_FIELDS,
    PROPERTY_NAMES,
    SENSOR_FIELDS,
    TOP_FIELDS,
    TOUCH_FIELDS,
)

__all__ = ["MaterialLookup", "library_material", "parse_scene", "validate_fault"]

#: Shortest baseline a sim session gives the daemon before heater-on (firmware_sim.run.config_for_scene).
_SHORTEST_BASELINE_S = 0.2

#: Resolves ``object.material``: name -> ``(k_W_mK, rho_kg_m3, c_J_kgK)``; KeyError if unknown.
MaterialLookup = Callable[[str], tuple[float, float, float]]


def library_material(name: str) -> tuple[float, float, float]:
    """``(k_W_mK, rho_kg_m3, c_J_kgK)`` of library material ``name`` (edge.physics.materials).

    Raises KeyError for an unknown name.
    """
    m = load_materials().get(name)
    return (m.k_W_mK, m.rho_kg_m3, m.c_J_kgK)


# ---------------------------------------------------------------------------
# Tables (each raises SchemaError with the dotted path)


def _object(data: Any, lookup: MaterialLookup | None) -> ObjectSpec:
    o = check_table(data, OBJECT_FIELDS, "object")
    material = o.get("material")
    given = [p for p in PROPERTY_NAMES if p in o]
    if material is not None:
        if given:
            raise SchemaError(f"object.{given[0]}",
                              "give either object.material or k_W_mK/rho_kg_m3/c_J_kgK, not both")
        try:
            k, rho, cp = (lookup or library_material)(material)
        except KeyError:
            raise SchemaError("object.material",
                              f"unknown material {material!r} (not in the material library)") from None
        except LookupError as e:
            raise SchemaError("object.material", f"cannot resolve {material!r}: {e}") from None
    else:
        if not given:
            raise SchemaError("object.material", "missing required field (or give k_W_mK, rho_kg_m3 and c_J_kgK)")
        for p in PROPERTY_NAMES:
            if p not in o:
                raise SchemaError(f"object.{p}", "missing required field")
        k, rho, cp = (o[p] for p in PROPERTY_NAMES)
    thickness = o.get("thickness_m")
    if thickness is None and o["back"] != "infinite":
        raise SchemaError("object.thickness_m", "missing required field")
    label = o.get("label", material or "")
    return ObjectSpec(Solid(k, rho, cp), o["back"], thickness, material, label)


def _board(data: Any) -> BoardSpec:
    b = check_table(data, BOARD_FIELDS, "board")
    seen: dict[int, str] = {}
    for chip, valid in CHIP_ADDRESSES.items():
        a = b.get(chip)
        if a is None:
            continue
        if a not in valid:
            span = f"0x{min(valid):02x}..0x{max(valid):02x}"
            raise SchemaError(f"board.{chip}", f"address must be {span}, got " + (f"0x{a:02x}" if a >= 0 else str(a)))
        if a in seen:
            raise SchemaError(f"board.{chip}", f"address 0x{a:02x} is already used by {seen[a]}")
        seen[a] = chip
    for role, what in ((THERMOCOUPLE, "thermocouple"), (FLUX, "flux-sensor")):
        able = names_for(role)
        if all(b.get(chip) is None for chip in able):
            raise SchemaError(f"board.{able[0]}", f"missing: fit a {what} reader ("
                              + " or ".join(f"board.{chip}" for chip in able) + ")")
    if get_probe(b["probe"]).estimator != "thick_body" and b["world"] != "faithful":
        raise SchemaError("board.probe", f'probe {b["probe"]!r} needs world = "faithful" '
                          "(the ideal world is 1-D: it knows no heater smaller than the object)")
    return BoardSpec(**{chip: b.get(chip) for chip in CHIP_ADDRESSES}, stack_name=b["stack"], world=b["world"],
                     probe=b["probe"])


def _touch(data: Any, env: Mapping[str, Any]) -> TouchSpec:
    t = check_table(data, TOUCH_FIELDS, "touch")
    if "object_temperature_C" in t and "object_offset_K" in t:
        raise SchemaError("touch.object_offset_K", "give touch.object_temperature_C or touch.object_offset_K, not both")
    if "object_offset_K" in t:
        # The offset must land where the thermocouple reads, like an absolute temperature.
        check_value(Field("float", lo=T_MIN_C, hi=T_MAX_C), env["ambient_temperature_C"] + t["object_offset_K"],
                    "touch.object_offset_K")
    if t["contact_lead_s"] < 0 and t["start_s"] + t["contact_lead_s"] < _SHORTEST_BASELINE_S:
        raise SchemaError("touch.contact_lead_s",
                          f"the heater would go on at {t['start_s'] + t['contact_lead_s']:g} s; a late touch needs "
                          f"touch.start_s + touch.contact_lead_s >= {_SHORTEST_BASELINE_S} s (the daemon's baseline)")
    if t["contact_lead_s"] >= t["length_s"]:
        raise SchemaError("touch.contact_lead_s",
                          f"must be < touch.length_s ({t['length_s']} s: the heating happens during the touch), "
                          f"got {t['contact_lead_s']}")
    return TouchSpec(**t)


def _as_built(data: Any, board: BoardSpec) -> AsBuiltSpec:
    a = check_table(data, AS_BUILT_FIELDS, "as_built")
    if board.world != "faithful":
        # The ideal world is the nominal probe by construction: a deviation it would ignore is an error.
        raise SchemaError("as_built", 'needs board.world = "faithful" (the ideal world is the nominal probe)')
    if a.get("draw_seed") is not None and len(data) > 1:
        others = sorted(k for k in data if k != "draw_seed")
        raise SchemaError("as_built", f"draw_seed draws every deviation: it cannot be combined with "
                                      f"{', '.join(others)}")
    offset = a.get("sensor_offset_x_m") or a.get("sensor_offset_y_m")
    if offset and not a.get("sensor_square") and board.probe == "paper":
        raise SchemaError("as_built", "sensor_offset_x_m / sensor_offset_y_m need sensor_square = true on the "
                                      "paper probe")
    return AsBuiltSpec(**a)


def _exactly_one(p: Mapping[str, Any], a: str, b: str, path: str) -> None:
    if (a in p) == (b in p):
        raise SchemaError(f"{path}.{a}", f"give exactly one of params.{a} or params.{b}")


def _fault(data: Any, path: str) -> Fault:
    f = check_table(data, FAULT_FIELDS, path)
    kind, at, until = f["kind"], f["at_s"], f.get("until_s")
    if until is not None:
        check_value(Field("float", lo=at, lo_open=True), until, f"{path}.until_s")
    pp = f"{path}.params"
    raw = f.get("params", {})
    params = check_table(raw, FAULT_PARAM_FIELDS[kind], pp)
    if kind == "i2c_nack":
        _exactly_one(raw, "address", "chip", pp)
    elif kind == "supply_sag":
        _exactly_one(raw, "factor", "voltage_V", pp)
    return Fault(kind, at, until, params)


def validate_fault(kind: str, at_s: float = 0.0, until_s: float | None = None,
                   params: Mapping[str, Any] | None = None) -> Fault:
    """Build a :class:`Fault` from code with the same checks as a scene's ``[[faults]]``.

    Raises :class:`SceneError` located at ``<inject>: fault.<key>``.
    """
    f: dict[str, Any] = {"kind": kind, "at_s": at_s, "params": dict(params or {})}
    if until_s is not None:
        f["until_s"] = until_s
    try:
        return _fault(f, "fault")
    except SchemaError as e:
        raise SceneError("<inject>", e.path, e.message) from None


def _scene(data: Mapping[str, Any], source: str, name: str | None, lookup: MaterialLookup | None) -> Scene:
    top = check_table(data, TOP_FIELDS)
    obj = _object(top["object"], lookup)
    e = check_table(top["environment"], ENVIRONMENT_FIELDS, "environment")
    h = check_table(top["heater"], HEATER_FIELDS, "heater")
    board = _board(top["board"])
    sensors = SensorSpec(**check_table(top["sensors"], SENSOR_FIELDS, "sensors")) if "sensors" in top else SensorSpec()
    touch = _touch(top["touch"], e)
    as_built = _as_built(top["as_built"], board) if "as_built" in top else None
    faults = []
    for i, raw in enumerate(top.get("faults", [])):
        fault = _fault(raw, f"faults[{i}]")
        chip = fault.params.get("chip")
        if chip is not None and board.address_of(chip) is None:
            raise SchemaError(f"faults[{i}].params.chip", f"{chip} is not fitted on this board")
        faults.append(fault)
    return Scene(
        name=top["name"] if "name" in top else (name or Path(source).stem),
        object=obj,
        environment=Environment(**e),
        heater=HeaterSpec(**h),
        board=board,
        touch=touch,
        sensors=sensors,
        contact_resistance_m2K_W=top["contact_resistance_m2K_W"],
        seed=top["seed"],
        faults=tuple(faults),
        description=top["description"],
        source=source,
        as_built=as_built,
    )


def parse_scene(text: str, *, source: str = "<string>", name: str | None = None,
                material_lookup: MaterialLookup | None = None) -> Scene:
    """Parse and validate scene TOML ``text``.

    Parameters
    ----------
    text : str
        TOML document (schema: :mod:`firmware_sim.scene.schema`).
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
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise SceneError(source, "", f"not valid TOML: {e}") from None
    try:
        return _scene(data, source, name, material_lookup)
    except SchemaError as e:
        raise SceneError(source, e.path, e.message) from None
