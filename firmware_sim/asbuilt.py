"""As-built probes drawn from realistic tolerances: the unknowns the device is never told (issue #34, item 4).

:func:`draw_as_built` draws one probe per ``(head, seed)`` -- every parameter a
real probe does not know -- as an :class:`firmware_sim.rz.configs.AsBuilt`
for the faithful world; :func:`as_built_for_scene` is what a scene's
``[as_built]`` table describes (explicit factors, or ``draw_seed = N`` for a
drawn probe).  Benches draw many probes (``bench/asbuilt_bench.py``).  The
device sees only the nominal values of ``[heater]``, ``[sensors]`` and the
stack, plus whatever its calibration finds: nothing under ``edge/`` or
``host/`` may import this module (``tests/firmware_sim/test_asbuilt.py``).

Tolerances (:data:`TOLERANCES`; U = uniform over the range, N2 = normal whose
2-sigma is the stated range, truncated there)

=============================  ==============  ====================================================
parameter                      draw            source / reasoning
=============================  ==============  ====================================================
flux sensitivity               N2 +-5 %        thermopile calibration uncertainty (Hukseflux FHF05
                                               class: +-5 % at k = 2; the brief's 3-5 %)
sensor side (x and y)          U +-0.2 mm      die / foil cutting tolerance of a 10 x 10 mm sensor
sensor offset (x and y)        U +-0.5 mm      placement of the sensor under the heater by hand/jig
sensitivity map                U +-5 % / axis  thermocouple-pair density across the foil: a linear
                                               edge-to-edge gradient per axis
sensing layer thickness, k     U +-10 % each   laminated polyimide / adhesive layer (bond line)
substrate foam k               U +-20 %        rigid PU foam, density and cell gas vary per batch
substrate foam rho c           U +-15 %        density +-15 % (c of PU ~ constant)
substrate foam thickness       U +-3 %         +-1 mm on a 30 mm sheet
thermocouple radius            U in a 0.5 mm   bead placed on the axis by hand (uniform over the
                               disk            disk of 0.5 mm radius)
thermocouple lag               U +-30 %        bead size and bond; a "0 s" datasheet lag (bead in
                                               the layer) draws from U(0, 13) ms
heater resistance              U +-2 %         film resistance tolerance
heater TCR                     U 0.001-0.004/K film heaters (constantan foil ~0, NiCr / carbon
                                               films 1e-3 .. 4e-3); reference 25 degC
lead resistance                U 0.05-0.3 ohm  2 x 0.5 m AWG 30 leads plus contacts, in series
=============================  ==============  ====================================================

Every drawn probe reads its thermopile through its real square footprint
(:class:`firmware_sim.rz.footprint.SquareSensor`), whatever the head.

Approximations that remain in the world
---------------------------------------
* The paper probe's 55 x 60 mm heater is the equal-area disk (r = 32.4 mm): an
  axisymmetric world cannot hold a rectangle.  Measured at 2 s of heating, same
  power density (``python bench/asbuilt_bench.py --bounds``; bench/results/asbuilt.json,
  ``bounds``): the rectangle lies between its inscribed (27.5 mm) and
  circumscribed (40.7 mm) disks and every read-out is monotone in the heated
  region; on PMMA and glass those two disks read the same to 1e-13 (the edges
  are out of the axis's reach), on copper they differ by 0.07 % in flux and
  5.9 % in the rise (a bound).  By superposition over annuli weighted with the
  rectangle's exact share of each (``rectangle_vs_disk``), the rectangle against
  its equal-area disk on copper: flux +0.005 %, rise -0.45 %, flux / rise
  +0.46 % -- the 1-D effusivity the disk world hands the device is ~0.5 % off
  on a metal at 2 s, nil on insulators.
* The paper probe's nominal scenes still read the equal-area disk (its square
  lies 27 mm inside the heater's edge, in uniform flux): square against disk
  3e-13 (PMMA, glass) and 1.5e-6 (copper); off-centre by 0.5 mm with a 5 %
  gradient 2.5e-6 (same command, ``paper_square_vs_disk``).  Drawn paper probes
  read their square anyway.
* The thermocouple's height above the sensing layer's bottom face is modelled
  (``AsBuilt.thermocouple_height_m``, ``[as_built] thermocouple_height_m``) but
  not drawn: no datasheet states it, and at ``q h / k`` (0.6 K for 50 um under
  2.4 kW/m^2) a guessed range would swamp every other unknown; drawn probes put
  the junction on the face.  The thermopile spans the whole sensing layer's depth.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np

from edge.physics.geometry import PROBES
from edge.physics.probe import DEFAULT_STACK, FLUX_SENSITIVITY_V_per_W_m2
from firmware_sim.rz.configs import SQUARE_SENSOR_PROBES, AsBuilt
from firmware_sim.rz.footprint import SquareSensor
from firmware_sim.scene.model import Scene

__all__ = ["TOLERANCES", "NOMINAL_HEATER_OHM", "Nominal", "draw_factors", "draw_as_built", "as_built_for_scene"]

#: name -> (kind, low, high): "rel" a relative deviation (N2: normal, 2 sigma = high, truncated there;
#: U: uniform in [low, high]), "abs" an absolute value in SI units.
TOLERANCES: dict[str, tuple[str, float, float]] = {
    "flux_sensitivity_rel": ("N2", -0.05, 0.05),
    "sensor_side_x_m": ("U", -0.2e-3, 0.2e-3),
    "sensor_side_y_m": ("U", -0.2e-3, 0.2e-3),
    "sensor_offset_x_m": ("U", -0.5e-3, 0.5e-3),
    "sensor_offset_y_m": ("U", -0.5e-3, 0.5e-3),
    "sensor_gradient_x": ("U", -0.05, 0.05),
    "sensor_gradient_y": ("U", -0.05, 0.05),
    "sensing_thickness_rel": ("U", -0.10, 0.10),
    "sensing_k_rel": ("U", -0.10, 0.10),
    "substrate_k_rel": ("U", -0.20, 0.20),
    "substrate_rho_c_rel": ("U", -0.15, 0.15),
    "substrate_thickness_rel": ("U", -0.03, 0.03),
    "thermocouple_r_m": ("disk", 0.0, 0.5e-3),
    "thermocouple_tau_rel": ("U", -0.30, 0.30),
    "heater_resistance_rel": ("U", -0.02, 0.02),
    "heater_tcr_per_K": ("U", 0.001, 0.004),
    "heater_lead_resistance_ohm": ("U", 0.05, 0.3),
}
#: Bead lag drawn when the datasheet states 0 s (a bead laminated in the layer): U(0, this) s.
ZERO_LAG_DRAW_s = 0.013
#: Nominal film resistance per head when no scene says (the paper's 50 ohm; the small heater's at the
#: same areal power: 50 ohm x (55 x 60 mm) / (pi 5^2 mm^2)).
NOMINAL_HEATER_OHM = {"paper": 50.0, "small-heater": 50.0 * 0.055 * 0.060 / (math.pi * 5.0e-3 ** 2)}


@dataclass(frozen=True)
class Nominal:
    """What the device is told: the nominal values the draws deviate from."""

    sensing_thickness_m: float
    sensing_k_W_mK: float
    flux_sensitivity_V_per_W_m2: float
    heater_resistance_ohm: float
    thermocouple_time_constant_s: float

    @classmethod
    def of(cls, head: str, scene: Scene | None = None) -> "Nominal":
        """The scene's nominal values (its stack, ``[sensors]``, ``[heater]``), or the head's defaults."""
        if scene is not None:
            st = scene.stack
            return cls(st.sensing_thickness_m, st.material.k_W_mK, scene.sensors.flux_sensitivity_V_per_W_m2,
                       scene.heater.resistance_ohm, scene.sensors.thermocouple_time_constant_s)
        return cls(DEFAULT_STACK.sensing_thickness_m, DEFAULT_STACK.material.k_W_mK, FLUX_SENSITIVITY_V_per_W_m2,
                   NOMINAL_HEATER_OHM[head], 0.0)


def _rng(head: str, seed: int) -> np.random.Generator:
    if head not in PROBES:
        raise KeyError(f"unknown probe head {head!r}; shipped: {sorted(PROBES)}")
    if not (isinstance(seed, (int, np.integer)) and seed >= 0):
        raise ValueError(f"seed must be an int >= 0, got {seed!r}")
    # One stream per (head, seed): the same seed on two heads draws two independent probes.
    return np.random.default_rng(np.random.SeedSequence([int(seed), zlib.crc32(head.encode())]))


def draw_factors(head: str, seed: int) -> dict[str, float]:
    """The raw draws of one probe (keys of :data:`TOLERANCES`), reproducible per ``(head, seed)``."""
    rng = _rng(head, seed)
    out = {}
    for name, (kind, lo, hi) in TOLERANCES.items():   # a fixed order: a draw never depends on another's
        if kind == "U":
            out[name] = float(rng.uniform(lo, hi))
        elif kind == "N2":
            while True:
                x = float(rng.normal(0.0, 0.5 * hi))
                if lo <= x <= hi:
                    break
            out[name] = x
        elif kind == "disk":
            out[name] = float(hi * math.sqrt(rng.uniform(0.0, 1.0)))
        else:  # pragma: no cover - the table is static
            raise AssertionError(kind)
    out["zero_lag_s"] = float(rng.uniform(0.0, ZERO_LAG_DRAW_s))
    return out


def draw_as_built(head: str, seed: int, scene: Scene | None = None) -> AsBuilt:
    """One probe of ``head`` drawn from :data:`TOLERANCES` (seeded: one probe per seed).

    ``scene`` supplies the nominal values the draws deviate from (default: the head's,
    :meth:`Nominal.of`).
    """
    d = draw_factors(head, seed)
    nom = Nominal.of(head, scene)
    sub = PROBES[head].substrate
    tau = (nom.thermocouple_time_constant_s * (1.0 + d["thermocouple_tau_rel"])
           if nom.thermocouple_time_constant_s > 0 else d["zero_lag_s"])
    sensor = SquareSensor(side_x_m=SquareSensor().side_x_m + d["sensor_side_x_m"],
                          side_y_m=SquareSensor().side_y_m + d["sensor_side_y_m"],
                          offset_x_m=d["sensor_offset_x_m"], offset_y_m=d["sensor_offset_y_m"],
                          gradient_x=d["sensor_gradient_x"], gradient_y=d["sensor_gradient_y"])
    return AsBuilt(
        sensing_thickness_m=nom.sensing_thickness_m * (1.0 + d["sensing_thickness_rel"]),
        sensing_k_W_mK=nom.sensing_k_W_mK * (1.0 + d["sensing_k_rel"]),
        flux_sensitivity_V_per_W_m2=nom.flux_sensitivity_V_per_W_m2 * (1.0 + d["flux_sensitivity_rel"]),
        thermocouple_time_constant_s=tau,
        heater_resistance_ohm=nom.heater_resistance_ohm * (1.0 + d["heater_resistance_rel"]),
        heater_tcr_per_K=d["heater_tcr_per_K"], heater_reference_C=25.0,
        heater_lead_resistance_ohm=d["heater_lead_resistance_ohm"],
        substrate_k_W_mK=None if sub is None else sub.k_W_mK * (1.0 + d["substrate_k_rel"]),
        substrate_rho_c_J_m3K=None if sub is None else sub.rho_kg_m3 * sub.c_J_kgK * (1.0 + d["substrate_rho_c_rel"]),
        substrate_thickness_m=None if sub is None else PROBES[head].substrate_thickness_m * (
            1.0 + d["substrate_thickness_rel"]),
        sensor=sensor, thermocouple_r_m=d["thermocouple_r_m"])


def as_built_for_scene(scene: Scene) -> AsBuilt:
    """The :class:`AsBuilt` a scene's ``[as_built]`` table describes (nominal when it has none).

    ``draw_seed``: the probe :func:`draw_as_built` draws for the scene's head.  Otherwise factors
    multiply the scene's nominal values (the stack's sensing layer, the ``[sensors]`` flux
    sensitivity, the ``[heater]`` resistance, the head's substrate); a factor of 1 and a zero
    position leave the world's nominal construction untouched.
    """
    a = scene.as_built
    if a is None:
        return AsBuilt()
    head = scene.board.probe
    if a.draw_seed is not None:
        return draw_as_built(head, a.draw_seed, scene)
    st, sens = scene.stack, scene.sensors
    p = PROBES[head]
    sub = p.substrate
    wants_square = a.sensor_square or a.sensor_offset_x_m != 0.0 or a.sensor_offset_y_m != 0.0
    if wants_square and head not in SQUARE_SENSOR_PROBES and not a.sensor_square:
        raise ValueError("a sensor offset needs sensor_square = true on this probe")
    return AsBuilt(
        sensing_thickness_m=st.sensing_thickness_m * a.sensing_thickness_factor,
        sensing_k_W_mK=st.material.k_W_mK * a.sensing_k_factor,
        flux_sensitivity_V_per_W_m2=sens.flux_sensitivity_V_per_W_m2 * a.flux_sensitivity_factor,
        thermocouple_time_constant_s=a.thermocouple_time_constant_s,
        heater_resistance_ohm=scene.heater.resistance_ohm * a.heater_resistance_factor,
        heater_tcr_per_K=a.heater_tcr_per_K,
        heater_reference_C=a.heater_reference_C,
        heater_lead_resistance_ohm=a.heater_lead_resistance_ohm,
        substrate_k_W_mK=None if sub is None or a.substrate_k_factor == 1.0 else sub.k_W_mK * a.substrate_k_factor,
        substrate_rho_c_J_m3K=None if sub is None or a.substrate_rho_c_factor == 1.0
        else sub.rho_kg_m3 * sub.c_J_kgK * a.substrate_rho_c_factor,
        substrate_thickness_m=None if sub is None or a.substrate_thickness_factor == 1.0
        else p.substrate_thickness_m * a.substrate_thickness_factor,
        sensor=SquareSensor(offset_x_m=a.sensor_offset_x_m, offset_y_m=a.sensor_offset_y_m) if wants_square else None,
        thermocouple_r_m=a.thermocouple_r_m if a.thermocouple_r_m > 0 else None,
        thermocouple_height_m=a.thermocouple_height_m if a.thermocouple_height_m > 0 else None)
