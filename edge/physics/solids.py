"""Thermal properties of homogeneous solids (SI units: k in W/m/K, density in
kg/m^3, specific heat in J/kg/K)."""


from __future__ import annotations

import math
from dataclasses import dataclass

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
