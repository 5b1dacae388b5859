"""Probe geometries as data: heater, layer stack, flux sensor and thermocouple.

A touch with the paper's large heater (55 x 60 mm) on a thick object is
one-dimensional at the thermocouple and determines the effusivity only;
conductivity and diffusivity need a length scale the heat has to spread
over.  A small heater disk supplies one (its radius): the axisymmetric
model (:mod:`edge.physics.axisym`) reads everything it needs from a
:class:`ProbeGeometry`, and :data:`PROBES` holds the shipped ones.

Conventions
-----------
z points down from the top of the heater film; the heater film (thickness
``heater_thickness_m``) releases its power uniformly inside a disk of
``heater_radius_m``; the sensing layer lies under it; the object under the
sensing layer.  Above the heater is the substrate (``None``: the heater's
top is insulated, the paper's 1-D model).  A rectangular heater is
represented by the disk of equal area (:meth:`ProbeGeometry.with_rectangular_heater`),
which is what an axisymmetric model can do with it; the axis sees the
rectangle's far edges only through a small lateral term in any case.

The flux sensor reads the axial (downward) heat flux averaged over its
depth range in the sensing layer (``sensor_depth_m``, measured from the
top of the sensing layer) and over its footprint (its real rectangle where ``sensor_square_m`` says, else its equal-area disk); the thermocouple
sits at ``thermocouple_r_m`` from the axis on the sensing-layer/object
interface, on the probe side of any contact resistance.  Units SI.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from edge.checks import finite_nonnegative, finite_positive
from edge.physics.probe import PROBE_MATERIAL
from edge.physics.solids import Solid

__all__ = ["PU_FOAM", "SENSOR_SIDE_m", "PAPER_POWER_W", "ProbeGeometry", "PROBES", "get_probe"]

#: Rigid PU foam above the heater (issue: k ~ 0.03 W/m/K, rho ~ 40 kg/m^3, c ~ 1400 J/kg/K).
PU_FOAM = Solid(k_W_mK=0.03, rho_kg_m3=40.0, c_J_kgK=1400.0)
#: Side of the square thermopile flux sensor (10 x 10 mm).
SENSOR_SIDE_m = 0.010
#: The device's configured default heater power on the paper's heater (thermotouch-edge.example.toml).
PAPER_POWER_W = 5.0
_PAPER_HEATER_AREA_m2 = 0.055 * 0.060


@dataclass(frozen=True)
class ProbeGeometry:
    """An axisymmetric probe: heater disk, layer stack, flux sensor, thermocouple.

    Parameters
    ----------
    name : str
        Identifier (the key in :data:`PROBES` for shipped probes).
    heater_radius_m : float
        Radius of the heated disk (for a rectangle: the equal-area disk).
    heater_thickness_m : float
        Thickness of the heater film in which the power is released.
    sensing_thickness_m : float
        Thickness of the sensing layer between heater and object.
    sensing : Solid
        Material of the sensing layer.
    heater_material : Solid
        Material of the heater film.
    substrate : Solid or None
        Backing above the heater (None: insulated heater top).
    substrate_thickness_m : float
        Thickness of the substrate (its top is insulated).
    probe_radius_m : float
        Radius of the probe's layers (the model treats them as laterally
        infinite; kept for the reference model and for checks that the
        heat stays well inside it).
    sensor_radius_m : float
        Radius of the flux sensor's equal-area disk, centred on the axis (the read-out when
        ``sensor_square_m`` is None).
    sensor_square_m : (float, float) or None
        Sides (x, y) of the flux sensor's real rectangular footprint: when given, the model reads the
        sensor over it exactly (:mod:`edge.physics.footprint`), not over the equal-area disk.
    sensor_offset_m : (float, float)
        Offset (x, y) of the rectangle's centre from the heater's axis (nominal 0; a calibration
        may identify it).
    sensor_depth_m : (float, float)
        Depth range of the flux sensor below the top of the sensing layer.
    thermocouple_r_m : float
        Distance of the thermocouple from the axis (on the interface).
    estimator : str
        The estimator kind that reads this probe's touches (a key of
        :data:`edge.estimation.methods.KINDS`): ``"thick_body"`` for a heater wide against the heat's
        reach (one-dimensional at its sensors), ``"axisym"`` for a small heater whose lateral spreading
        the estimate must model.
    nominal_power_W : float
        Heater power of a standard touch.
    """

    name: str
    heater_radius_m: float
    heater_thickness_m: float = 20e-6
    sensing_thickness_m: float = 0.4e-3
    sensing: Solid = field(default=PROBE_MATERIAL)
    heater_material: Solid = field(default=PROBE_MATERIAL)
    substrate: Solid | None = field(default=PU_FOAM)
    substrate_thickness_m: float = 0.030
    probe_radius_m: float = 0.040
    sensor_radius_m: float = math.sqrt(SENSOR_SIDE_m ** 2 / math.pi)
    sensor_depth_m: tuple[float, float] = (0.0, 0.4e-3)
    sensor_square_m: tuple[float, float] | None = None
    sensor_offset_m: tuple[float, float] = (0.0, 0.0)
    thermocouple_r_m: float = 0.0
    nominal_power_W: float = PAPER_POWER_W
    estimator: str = "thick_body"

    def __post_init__(self) -> None:
        for n in ("heater_radius_m", "heater_thickness_m", "sensing_thickness_m", "substrate_thickness_m",
                  "probe_radius_m", "sensor_radius_m", "nominal_power_W"):
            finite_positive(n, getattr(self, n))
        finite_nonnegative("thermocouple_r_m", self.thermocouple_r_m)
        d0, d1 = (float(x) for x in self.sensor_depth_m)
        if not 0.0 <= d0 < d1 <= self.sensing_thickness_m * (1 + 1e-12):
            raise ValueError("sensor_depth_m must be an increasing range inside the sensing layer")
        if self.sensor_square_m is not None:
            for v in self.sensor_square_m:
                finite_positive("sensor_square_m", v)
        for v in self.sensor_offset_m:
            if not math.isfinite(v):
                raise ValueError("sensor_offset_m must be finite")
        if self.probe_radius_m < self.heater_radius_m * (1 - 1e-12):
            raise ValueError("the probe must be at least as wide as its heater")

    @classmethod
    def with_rectangular_heater(cls, name: str, width_m: float, length_m: float, **kw) -> "ProbeGeometry":
        """A probe whose rectangular heater is represented by the disk of equal area."""
        a = math.sqrt(finite_positive("width_m", width_m) * finite_positive("length_m", length_m) / math.pi)
        kw.setdefault("probe_radius_m", a)
        return cls(name=name, heater_radius_m=a, **kw)

    @property
    def heater_area_m2(self) -> float:
        return math.pi * self.heater_radius_m ** 2

    @property
    def heater_volume_m3(self) -> float:
        return self.heater_area_m2 * self.heater_thickness_m

    @property
    def sensor_area_m2(self) -> float:
        return math.pi * self.sensor_radius_m ** 2

    @property
    def sensor_reach_m(self) -> float:
        """Farthest point of the flux sensor from the axis (its disk's radius, or the rectangle's far corner)."""
        if self.sensor_square_m is None:
            return self.sensor_radius_m
        (sx, sy), (ox, oy) = self.sensor_square_m, self.sensor_offset_m
        return math.hypot(abs(ox) + 0.5 * sx, abs(oy) + 0.5 * sy)

    @property
    def nominal_areal_power_W_m2(self) -> float:
        return self.nominal_power_W / self.heater_area_m2

    def with_heater_radius(self, radius_m: float, *, same_areal_power: bool = True) -> "ProbeGeometry":
        """This probe with another heater radius (same areal power by default: the heater's
        temperature limit, not its total power, is what a design must respect)."""
        r = finite_positive("radius_m", radius_m)
        p = self.nominal_areal_power_W_m2 * math.pi * r * r if same_areal_power else self.nominal_power_W
        return replace(self, name=f"{self.name}@{r * 1e3:g}mm", heater_radius_m=r,
                       probe_radius_m=max(self.probe_radius_m, r), nominal_power_W=p)


#: The paper's probe: 55 x 60 mm heater (equal-area disk, r = 32.4 mm) at 5 W, on PU foam.
PAPER = ProbeGeometry.with_rectangular_heater("paper", 0.055, 0.060, nominal_power_W=PAPER_POWER_W)

#: The issue's small-heater probe: a 5 mm-radius heater disk at the paper's areal power, same
#: sensing layer, 30 mm PU foam, probe radius 40 mm, 10 x 10 mm flux sensor centred under it -- read
#: over its real square (its edge lies on the heater's edge, where the flux changes fastest: the
#: equal-area disk put k -38 % and alpha -59 % off on glass, issue #34).
SMALL_HEATER = ProbeGeometry(
    name="small-heater", heater_radius_m=5.0e-3, probe_radius_m=0.040,
    sensor_square_m=(SENSOR_SIDE_m, SENSOR_SIDE_m),
    nominal_power_W=PAPER_POWER_W / _PAPER_HEATER_AREA_m2 * math.pi * 5.0e-3 ** 2, estimator="axisym")

PROBES: dict[str, ProbeGeometry] = {"paper": PAPER, "small-heater": SMALL_HEATER}


def get_probe(name: str) -> ProbeGeometry:
    """A shipped probe by name (KeyError naming the choices otherwise)."""
    try:
        return PROBES[name]
    except KeyError:
        raise KeyError(f"unknown probe {name!r}; shipped: {sorted(PROBES)}") from None
