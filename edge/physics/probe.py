"""The probe: its layer stack, its heater's power model and its flux sensor's nominal sensitivity.

One home for every formula and constant that describes the probe itself;
the heater driver, configuration, sequence, simulator and training set all
read them from here. Units are SI throughout (lengths in m).

The stacking
------------
The paper (Ma & Zhang 2024, section 2.2 and Table 1) puts a 20 um heater on a
0.4 mm sensing layer, both of the same polyimide-like material, on the object,
with the top (substrate side) insulated.  Its explicit scheme on a 40 um grid
makes node 1 the heater's half cell and puts the interface node on the grid,
which only fits if the interface is 0.40 mm below the top (heater inside the
top 20 um of a 0.40 mm stack).  Read literally, the text stacks a 20 um heater
*on* a 0.40 mm sensing layer, i.e. the interface is 0.42 mm below the top.
Both are offered:

* :data:`STACK_042` (default) - heater 20 um + sensing 0.40 mm, interface at 0.42 mm;
* :data:`STACK_040` - the 40-um-grid reading, interface at 0.40 mm.

The choice changes T_f by several percent (see ``bench/forward_bench.py``), so
the simulator, training set and estimator must use the same stack.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from edge.checks import finite_positive, positive_number, unit_fraction
from edge.physics.solids import Solid

#: Nominal sensitivity of the FHF05-class heat-flux sensor, V per W/m^2 (0.56 uV per W/m^2).
#: The datasheet value; a probe's own value comes from calibration.
FLUX_SENSITIVITY_V_per_W_m2 = 0.56e-6

# What an UNCALIBRATED probe knows about itself (1 sigma): the prior of calibration and the
# uncertainty an uncalibrated measurement carries.  Thermopile films differ from their type
# sensitivity by several per cent, laminated layers from their nominal thickness likewise, and a
# bead's lag is not on any datasheet (0 assumed, tens of ms typical of fine wire under a film).
#: Relative spread of the flux sensor's sensitivity around FLUX_SENSITIVITY_V_per_W_m2.
FLUX_SENSITIVITY_U_REL = 0.05
#: Relative spread of the sensing layer's effective thickness (thermopile to object).
SENSING_THICKNESS_U_REL = 0.05
#: Relative spread of the sensing layer's conductivity (its rho c taken as nominal).
SENSING_K_U_REL = 0.05
#: Spread of the thermocouple's bead time constant around 0 (s).
THERMOCOUPLE_TAU_U_s = 0.05


def heater_power_W(duty: float, supply_voltage_V: float, resistance_ohm: float) -> float:
    """Mean electrical power (W) at PWM duty ``duty`` (0..1): ``d * V**2 / R``.

    The one statement of the heater's power model: a resistive film switched
    by PWM dissipates the duty fraction of its full-on power V^2/R.
    """
    d = unit_fraction("duty", duty)
    v = positive_number("supply_voltage_V", supply_voltage_V)
    r = positive_number("resistance_ohm", resistance_ohm)
    return d * v * v / r


def duty_for_power(power_W: float, supply_voltage_V: float, resistance_ohm: float) -> float:
    """PWM duty (0..1) that gives mean power ``power_W`` (W); the inverse of :func:`heater_power_W`.

    Raises ValueError if the supply cannot deliver that much (duty > 1).
    """
    p = float(power_W)
    if not (p >= 0 and math.isfinite(p)):
        raise ValueError(f"power_W must be a finite number >= 0, got {power_W!r}")
    p_max = heater_power_W(1.0, supply_voltage_V, resistance_ohm)
    if p > p_max * (1 + 1e-12):
        raise ValueError(
            f"power_W={p} W exceeds the maximum {p_max:.6g} W of a {resistance_ohm} ohm heater "
            f"on {supply_voltage_V} V"
        )
    return min(1.0, p / p_max)


#: Heater and sensing layer material, paper Table 1.
PROBE_MATERIAL = Solid(k_W_mK=0.214, rho_kg_m3=1951.6, c_J_kgK=1064.6)


@dataclass(frozen=True)
class ProbeStack:
    """Layer geometry of the probe, top (insulated) to the object.

    Parameters
    ----------
    heater_thickness_m : float
        Thickness of the heating layer in which q_v is released (m).
    sensing_thickness_m : float
        Thickness of the sensing layer between heater and object (m).
    material : Solid
        Material of both layers (paper Table 1).
    heater_area_m2 : float
        Heated area, used to convert electrical power to q_v (55 x 60 mm).
    """

    heater_thickness_m: float = 20e-6
    sensing_thickness_m: float = 0.4e-3
    material: Solid = field(default=PROBE_MATERIAL)
    heater_area_m2: float = 0.055 * 0.060

    def __post_init__(self) -> None:
        finite_positive("heater_thickness_m", self.heater_thickness_m)
        finite_positive("sensing_thickness_m", self.sensing_thickness_m)
        finite_positive("heater_area_m2", self.heater_area_m2)

    @property
    def total_thickness_m(self) -> float:
        """Depth of the object surface below the insulated top (m)."""
        return self.heater_thickness_m + self.sensing_thickness_m

    def q_v_from_power(self, power_W: float) -> float:
        """Heater power density q_v (W/m^3) for an electrical power (W)."""
        return float(power_W) / (self.heater_area_m2 * self.heater_thickness_m)

    def q_v_from_voltage(self, voltage_V: float, resistance_ohm: float) -> float:
        """Heater power density q_v (W/m^3) for a supply voltage across the heater resistance."""
        return self.q_v_from_power(heater_power_W(1.0, voltage_V, resistance_ohm))


STACK_042 = ProbeStack()
STACK_040 = ProbeStack(sensing_thickness_m=0.38e-3)
DEFAULT_STACK = STACK_042

STACKS = {"0.42": STACK_042, "0.40": STACK_040}


#: The shipped probe's heater geometry, views of the default stack.
HEATER_AREA_m2 = DEFAULT_STACK.heater_area_m2
HEATER_THICKNESS_m = DEFAULT_STACK.heater_thickness_m
HEATER_VOLUME_m3 = HEATER_AREA_m2 * HEATER_THICKNESS_m


def volumetric_heat_W_m3(
    power_W: float,
    *,
    area_m2: float = HEATER_AREA_m2,
    thickness_m: float = HEATER_THICKNESS_m,
) -> float:
    """Volumetric heat source q_v (W/m^3) of power ``power_W`` spread over the heater film."""
    p = float(power_W)
    if not (p >= 0 and math.isfinite(p)):
        raise ValueError(f"power_W must be a finite number >= 0, got {power_W!r}")
    stack = ProbeStack(heater_thickness_m=positive_number("thickness_m", thickness_m),
                       heater_area_m2=positive_number("area_m2", area_m2))
    return stack.q_v_from_power(p)
