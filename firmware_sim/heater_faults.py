"""What the scene's heater faults do to the heater's drive: one statement for every world."""

from __future__ import annotations

from typing import Sequence

from firmware_sim.scene.model import Fault

__all__ = ["HEATER_FAULTS", "WORLD_FAULTS", "active", "effective_duty", "supply_voltage"]

#: Fault kinds that change the heater's power.
HEATER_FAULTS = ("heater_stuck_on", "heater_dead", "supply_sag")
#: Fault kinds a thermal world plays (the bus faults live on the SimBus).
WORLD_FAULTS = ("open_thermocouple", "flux_saturation", "no_contact") + HEATER_FAULTS


def active(faults: Sequence[Fault], kind: str, t_s: float) -> list[Fault]:
    """The faults of ``kind`` active at ``t_s``."""
    return [f for f in faults if f.kind == kind and f.active(t_s)]


def effective_duty(faults: Sequence[Fault], t_s: float, commanded: float) -> float:
    """Duty at ``t_s``: the commanded one, unless a dead or stuck-on heater overrides it."""
    if active(faults, "heater_dead", t_s):
        return 0.0
    stuck = active(faults, "heater_stuck_on", t_s)
    if stuck:
        return float(stuck[-1].params.get("duty", 1.0))
    return commanded


def supply_voltage(faults: Sequence[Fault], t_s: float, nominal_V: float) -> float:
    """Supply voltage (V) at ``t_s``: nominal, or sagged (to a voltage or by a factor)."""
    v = nominal_V
    for f in active(faults, "supply_sag", t_s):
        v = f.params["voltage_V"] if "voltage_V" in f.params else v * f.params["factor"]
    return v
