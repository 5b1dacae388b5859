"""Thermal properties of solids and the probe's layer stack.

Units are SI throughout: k in W/m/K, density in kg/m^3, specific heat in
J/kg/K, lengths in m.

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

from edge.checks import finite_positive


@dataclass(frozen=True)
class Solid:
    """A homogeneous solid: conductivity, density and specific heat (SI)."""

    k_W_mK: float
    rho_kg_m3: float
    c_J_kgK: float

    def __post_init__(self) -> None:
        finite_positive("k_W_mK", self.k_W_mK)
        finite_positive("rho_kg_m3", self.rho_kg_m3)
        finite_positive("c_J_kgK", self.c_J_kgK)

    @property
    def rho_c_J_m3K(self) -> float:
        """Volumetric heat capacity, J/m^3/K."""
        return self.rho_kg_m3 * self.c_J_kgK

    @property
    def alpha_m2_s(self) -> float:
        """Thermal diffusivity, m^2/s."""
        return self.k_W_mK / self.rho_c_J_m3K

    @property
    def effusivity_W_s05_m2K(self) -> float:
        """Thermal effusivity sqrt(k rho c), W s^0.5 / m^2 / K."""
        return math.sqrt(self.k_W_mK * self.rho_c_J_m3K)


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
        from edge.hw.drivers.heater import heater_power_w  # noqa: PLC0415 - the drivers import this module

        return self.q_v_from_power(heater_power_w(1.0, voltage_V, resistance_ohm))


STACK_042 = ProbeStack()
STACK_040 = ProbeStack(sensing_thickness_m=0.38e-3)
DEFAULT_STACK = STACK_042

STACKS = {"0.42": STACK_042, "0.40": STACK_040}
