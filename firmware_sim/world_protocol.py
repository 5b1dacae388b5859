"""What a thermal world is to the simulator: the :class:`World` protocol and the signals every world shares.

The simulator has two thermal worlds -- the exact 1-D :class:`firmware_sim.world.ThermalWorld`
("ideal") and the axisymmetric :class:`firmware_sim.rz.probe_world.FaithfulWorld` ("faithful")
-- and nothing outside them may tell them apart: the simulator, the wiring table
(:mod:`firmware_sim.wiring`) and the benches talk to :class:`World` only.  A world knows
nothing of chips: it offers *signals* (the thermocouple's hot junction and EMF, the cold
junction, the flux sensor's voltage, the thermocouple's open state), and the wiring table
says which chip pin sees which signal.

:class:`SensorSignals` holds the part of the signals that is the same in every world (the
thermocouple EMF from its junction temperatures, the flux-sensor voltage from the sensed flux,
the faults that override them); a world supplies the physics underneath
(``thermocouple_C``, ``cold_junction_C``, ``sensed_flux_W_m2``,
``flux_sensitivity_V_per_W_m2``, ``_active``).

``stream`` names the caller of a signal (one chip input, e.g. ``"ads1115:flux"``): a world
that evaluates lazily may use it to recognise each caller's sampling grid and evaluate ahead
on it (the ideal world does); a world that marches in time ignores it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol, Sequence, runtime_checkable

import numpy as np

from edge.physics import typek
from edge.physics.schedule import PowerSchedule
from firmware_sim.scene.model import FLUX_SATURATION_V, Fault, Scene

__all__ = ["World", "WorldState", "Truth", "SensorSignals", "OPEN_TC_INPUT_V", "REPEAT_RELEASE_S"]

#: What an open thermocouple input shows a voltage-reading ADC (burn-out current
#: sources pull it towards the rail): far above full scale at gain 128.
OPEN_TC_INPUT_V = 1.65
#: A repeat touch ends this long after the heater's switch-off within it (s).
REPEAT_RELEASE_S = 0.5


class WorldState(NamedTuple):
    """The world at one instant (temperatures in °C, flux in W/m^2)."""

    t_s: float
    surface_C: float       # T_f, bottom of the sensing layer (probe side of any contact resistance)
    thermocouple_C: float  # surface_C through the thermocouple's lag
    q_f_W_m2: float        # heat flux from the probe into what it touches
    contact: bool


@dataclass(frozen=True)
class Truth:
    """Exact series for checks: times (s), °C, W/m^2, contact flag, q_v (W/m^3)."""

    t_s: np.ndarray
    surface_C: np.ndarray
    thermocouple_C: np.ndarray
    q_f_W_m2: np.ndarray
    contact: np.ndarray
    q_v_W_m3: np.ndarray


@runtime_checkable
class World(Protocol):
    """A thermal world: the probe, the object, the heater and the touches on a simulated clock.

    Attributes
    ----------
    scene : Scene
        What it simulates.
    clock : SimClock
        Its time base ("now" separates the settled past from the provisional future).
    stack
        The probe stack it heats (``heater_area_m2``, ``heater_thickness_m``: the film's energy).
    """

    scene: Scene
    clock: Any
    stack: Any

    # ---- signals (what the wiring table connects to chip pins)

    def thermocouple_C(self, t_s: float, *, stream: str = "thermocouple") -> float:
        """Hot-junction temperature (°C) the thermocouple reports at ``t_s`` (its bead lag included)."""

    def cold_junction_C(self, t_s: float) -> float:
        """Board (cold-junction, ADC die) temperature (°C)."""

    def thermocouple_open(self, t_s: float) -> bool:
        """Whether the thermocouple is disconnected at ``t_s``."""

    def thermocouple_emf_V(self, t_s: float, *, stream: str = "thermocouple_emf") -> float:
        """Differential thermocouple EMF at the ADC pins (V); the rail when open."""

    def flux_voltage_V(self, t_s: float, *, stream: str = "flux") -> float:
        """Flux-sensor output (V), clipped to the sensor's range, or a saturation fault's level."""

    def heater_power_W(self, t_s: float) -> float:
        """Electrical power in the heater film at ``t_s`` (W)."""

    # ---- truth and state

    def state(self, t_s: float) -> WorldState:
        """The world at ``t_s`` (>= 0)."""

    def truth(self, t_s: Sequence[float]) -> Truth:
        """Series at times ``t_s`` for checks."""

    def power_schedule(self, t_end_s: float | None = None) -> PowerSchedule:
        """The heater's power density as a piecewise-constant schedule up to ``t_end_s``."""

    # ---- what happens to it

    @property
    def faults(self) -> tuple[Fault, ...]:
        """Faults the world itself plays (scene and injected)."""

    def add_fault(self, fault: Fault, *, now_s: float | None = None) -> None:
        """Play ``fault`` from its ``at_s`` on."""

    def add_touch(self, start_s: float, length_s: float) -> None:
        """Put the probe on the object at ``start_s`` for ``length_s``."""

    def contact_at(self, t_s: float) -> bool:
        """Whether the probe touches the object at ``t_s``."""

    def repeat_touches(self) -> None:
        """Touch after touch: put the probe down again after each touch (``[touch] repeat``)."""


class SensorSignals:
    """The signals every world derives the same way from its physics (a mix-in).

    The host class supplies ``scene``, ``thermocouple_C(t, stream=...)``,
    ``cold_junction_C(t)``, ``sensed_flux_W_m2(t, stream=...)`` (what the flux
    sensor integrates, W/m^2), ``flux_sensitivity_V_per_W_m2`` and
    ``_active(kind, t)`` (its faults of ``kind`` active at ``t``).
    """

    def thermocouple_open(self, t_s: float) -> bool:
        """Whether the thermocouple is disconnected at ``t_s`` (an ``open_thermocouple`` fault)."""
        return bool(self._active("open_thermocouple", t_s))

    def thermocouple_emf_V(self, t_s: float, *, stream: str = "thermocouple_emf") -> float:
        """Differential thermocouple EMF at the ADC pins (V): ``E(T_hot) - E(T_cold)``; the rail when open."""
        if self.thermocouple_open(t_s):
            return OPEN_TC_INPUT_V
        return (typek.emf_mV(self.thermocouple_C(t_s, stream=stream))
                - typek.emf_mV(self.cold_junction_C(t_s))) * 1e-3

    def flux_voltage_V(self, t_s: float, *, stream: str = "flux") -> float:
        """Flux-sensor output (V): its sensitivity times the sensed flux clipped to the sensor's range,
        or a ``flux_saturation`` fault's level."""
        sat = self._active("flux_saturation", t_s)
        if sat:
            return float(sat[-1].params.get("voltage_V", FLUX_SATURATION_V))
        rng = self.scene.sensors.flux_range_W_m2
        q = min(max(self.sensed_flux_W_m2(t_s, stream=stream), -rng), rng)
        return self.flux_sensitivity_V_per_W_m2 * q
