"""The faithful world's probe as built and its grid configurations (one per air / contact phase kind).

:class:`AsBuilt` (how the probe was really built; the device is never told), :class:`Geometry`
(the probe's and object's real dimensions and surroundings), their constructors from a probe
name and a scene, and :func:`build_config`: the (r, z) grid of one configuration -- the probe in
air, or on one touch's object through its contact resistance -- with its step solvers and
read-out weights (:class:`GridConfig`).  Used by :class:`firmware_sim.rz.probe_world.FaithfulWorld`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from edge.physics.geometry import PROBES, ProbeGeometry
from edge.physics.solids import Solid
from firmware_sim.rz.footprint import SquareSensor
from firmware_sim.rz.grid import ADIABATIC, PU_FOAM, SENSOR_AREA_m2, Boundary, Grid, Layer, Mesh
from firmware_sim.rz.solver import Solver, axis_weights
from firmware_sim.scene.model import Scene

__all__ = ["AsBuilt", "Geometry", "GridConfig", "SQUARE_SENSOR_PROBES", "geometry_for_probe", "build_config"]

#: Heads whose world reads the square thermopile by default.  The small-heater probe's square has its
#: edge on the heater's edge, where the flux changes fastest: the equal-area disk is the estimator's
#: approximation and the world must not share it.  The paper probe's square lies 27 mm inside its
#: heater's edge, where the flux is uniform: square and disk read the same to 3e-13 (PMMA, glass) and
#: 2.5e-6 (copper, 0.5 mm off centre, 5 % gradient) after 2 s (python bench/asbuilt_bench.py --bounds),
#: so its nominal scenes keep the disk and stay byte-identical.  A head's variants (``name@<r>mm``,
#: :meth:`ProbeGeometry.with_heater_radius`) carry the same sensor.
SQUARE_SENSOR_PROBES = frozenset({"small-heater"})


@dataclass(frozen=True)
class AsBuilt:
    """How this probe was really built; the device is never told.

    ``None`` means "as the scene/stack says" (nominal).  Defaults are the
    ideal probe.

    Attributes
    ----------
    sensing_thickness_m, sensing_k_W_mK : float or None
        Sensing layer thickness and conductivity (rho c as the stack's).
    flux_sensitivity_V_per_W_m2 : float or None
        True thermopile sensitivity (default the scene's nominal value).
    thermocouple_time_constant_s : float or None
        True bead lag (default the scene's).
    heater_resistance_ohm : float or None
        Film resistance at ``heater_reference_C`` (default the scene's).
    heater_tcr_per_K : float
        Temperature coefficient of the film's resistance (1/K).
    heater_reference_C : float
        Temperature at which the film has ``heater_resistance_ohm``.
    heater_lead_resistance_ohm : float
        Leads and contacts in series with the film: they take part of the supply's power
        (``P_film = d V^2 R / (R + R_lead)^2``; the device computes ``d V^2 / R_nominal``).
    substrate_k_W_mK, substrate_rho_c_J_m3K, substrate_thickness_m : float or None
        The backing foam as built (default the probe geometry's substrate).
    sensor : SquareSensor or None
        The thermopile's real footprint (side, offset from the heater's axis, sensitivity map);
        default the geometry's (the small-heater probe's centred 10 x 10 mm square, the paper
        probe's equal-area disk).
    thermocouple_r_m : float or None
        The thermocouple's distance from the heater's axis (default the geometry's, 0).
    thermocouple_height_m : float or None
        The junction's height above the sensing layer's bottom face (default the geometry's, 0).
    """

    sensing_thickness_m: float | None = None
    sensing_k_W_mK: float | None = None
    flux_sensitivity_V_per_W_m2: float | None = None
    thermocouple_time_constant_s: float | None = None
    heater_resistance_ohm: float | None = None
    heater_tcr_per_K: float = 0.0
    heater_reference_C: float = 25.0
    heater_lead_resistance_ohm: float = 0.0
    substrate_k_W_mK: float | None = None
    substrate_rho_c_J_m3K: float | None = None
    substrate_thickness_m: float | None = None
    sensor: SquareSensor | None = None
    thermocouple_r_m: float | None = None
    thermocouple_height_m: float | None = None

    def __post_init__(self) -> None:
        for name in ("sensing_thickness_m", "sensing_k_W_mK", "flux_sensitivity_V_per_W_m2",
                     "heater_resistance_ohm", "substrate_k_W_mK", "substrate_rho_c_J_m3K", "substrate_thickness_m"):
            v = getattr(self, name)
            if v is not None and not (v > 0 and math.isfinite(v)):
                raise ValueError(f"{name} must be finite and > 0, got {v!r}")
        tau = self.thermocouple_time_constant_s
        if tau is not None and not (tau >= 0 and math.isfinite(tau)):
            raise ValueError(f"thermocouple_time_constant_s must be finite and >= 0, got {tau!r}")
        if not math.isfinite(self.heater_tcr_per_K):
            raise ValueError("heater_tcr_per_K must be finite")
        for name in ("heater_lead_resistance_ohm", "thermocouple_r_m", "thermocouple_height_m"):
            v = getattr(self, name)
            if v is not None and not (v >= 0 and math.isfinite(v)):
                raise ValueError(f"{name} must be finite and >= 0, got {v!r}")

    def apply_to(self, geometry: "Geometry") -> "Geometry":
        """``geometry`` with this probe's substrate, sensor footprint and thermocouple position."""
        geo = geometry
        if geo.substrate is not None and (self.substrate_k_W_mK is not None or self.substrate_rho_c_J_m3K is not None):
            sub = geo.substrate
            k = sub.k_W_mK if self.substrate_k_W_mK is None else self.substrate_k_W_mK
            rho_c = sub.rho_kg_m3 * sub.c_J_kgK if self.substrate_rho_c_J_m3K is None else self.substrate_rho_c_J_m3K
            geo = replace(geo, substrate=Solid(k_W_mK=k, rho_kg_m3=sub.rho_kg_m3, c_J_kgK=rho_c / sub.rho_kg_m3))
        if geo.substrate is not None and self.substrate_thickness_m is not None:
            geo = replace(geo, substrate_thickness_m=self.substrate_thickness_m)
        if self.sensor is not None:
            geo = replace(geo, sensor_square=self.sensor)
        if self.thermocouple_r_m is not None:
            geo = replace(geo, thermocouple_r_m=self.thermocouple_r_m)
        if self.thermocouple_height_m is not None:
            geo = replace(geo, thermocouple_height_m=self.thermocouple_height_m)
        return geo


@dataclass(frozen=True)
class Geometry:
    """The probe's and object's real geometry and surroundings (not as-built deviations).

    ``substrate=None`` with ``h_air_W_m2K=0`` and a large ``heater_radius_m``
    is the 1-D limit (the estimator's insulated-top stack).
    """

    substrate: Solid | None = PU_FOAM
    substrate_thickness_m: float = 0.030
    heater_radius_m: float | None = None     # default: equal-area disk of the heater
    probe_radius_m: float | None = None      # default: the heater radius
    object_radius_m: float = 0.05
    infinite_thickness_m: float = 0.10       # object thickness for back = "infinite"
    h_air_W_m2K: float = 5.0                 # natural convection on every exposed face
    mesh: Mesh = field(default_factory=Mesh)
    #: The film's real area, which turns electrical power into q_v (default: the stack's, 55 x 60 mm).
    #: A heater disk wider than this (the 1-D limit) is a larger film at the same power density.
    heater_area_m2: float | None = None
    sensor_radius_m: float | None = None     # default: the 10 x 10 mm thermopile's equal-area disk
    #: The thermopile's real footprint; when given it replaces the disk in the read-out (the disk is
    #: only what the estimator assumes).
    sensor_square: SquareSensor | None = None
    thermocouple_r_m: float = 0.0            # the thermocouple's distance from the axis
    thermocouple_height_m: float = 0.0       # its height above the sensing layer's bottom face

    def __post_init__(self) -> None:
        if not self.h_air_W_m2K >= 0 or math.isinf(self.h_air_W_m2K):
            raise ValueError("h_air_W_m2K must be finite and >= 0")
        for name in ("heater_area_m2", "sensor_radius_m"):
            v = getattr(self, name)
            if v is not None and not (v > 0 and math.isfinite(v)):
                raise ValueError(f"{name} must be finite and > 0, got {v!r}")
        for name in ("thermocouple_r_m", "thermocouple_height_m"):
            if not (getattr(self, name) >= 0 and math.isfinite(getattr(self, name))):
                raise ValueError(f"{name} must be finite and >= 0")


def geometry_for_probe(probe: ProbeGeometry | str, **overrides) -> Geometry:
    """The world's :class:`Geometry` for a probe of :data:`edge.physics.geometry.PROBES` (or its name).

    Only the probe's dimensions are taken (heater disk and its area, probe
    radius, substrate, flux-sensor disk, thermocouple radius): the layer stack
    (heater film and sensing layer) stays the scene's, as built.  The probes
    of :data:`SQUARE_SENSOR_PROBES` read their thermopile through its real
    10 x 10 mm square (:class:`SquareSensor`), not the estimator's disk.
    ``overrides`` replace any other :class:`Geometry` field (object radius,
    convection, mesh, ...).
    """
    p = PROBES[probe] if isinstance(probe, str) else probe
    kw = dict(substrate=p.substrate, substrate_thickness_m=p.substrate_thickness_m,
              heater_radius_m=p.heater_radius_m, probe_radius_m=p.probe_radius_m,
              heater_area_m2=p.heater_area_m2, sensor_radius_m=p.sensor_radius_m,
              thermocouple_r_m=p.thermocouple_r_m)
    if p.name.split("@")[0] in SQUARE_SENSOR_PROBES:
        kw["sensor_square"] = SquareSensor()
    kw.update(overrides)
    return Geometry(**kw)


class GridConfig:
    """One grid configuration: its grid, step solvers and read-out weights."""

    def __init__(self, grid: Grid, n_probe_rows: int, tcr_weights: np.ndarray) -> None:
        self.grid = grid
        self.n_probe_rows = n_probe_rows
        self.solvers: dict[float, Solver] = {}
        self.main_dt = None
        self.src = None
        self.heater_w = tcr_weights
        self.has_object = grid.nz > n_probe_rows
        if self.has_object:
            self.obj_rows = slice(n_probe_rows, grid.nz)
            self.k_obj = float(grid.k_cell_W_mK[n_probe_rows, 0])
            #: What the object-side face temperature reads of the grid (FaithfulWorld._record, every
            #: record): the axial conductances and areas of the first two rings across the interface,
            #: the object's top cell height and the axis weights (grid properties rebuilt per call).
            self.face_terms = (grid.g_z_W_K[n_probe_rows - 1, :2], grid.ring_area_m2[:2],
                               grid.dz_m[n_probe_rows], axis_weights(grid))

    def solver(self, dt: float, scheme: str = "trbdf2") -> Solver:
        key = (round(dt, 12), scheme)
        s = self.solvers.get(key)
        if s is None:
            if len(self.solvers) >= 8:  # the main step, the start-up sub-steps and a few partial ones
                self.solvers.pop(next(k for k in self.solvers if k != (self.main_dt, "trbdf2")))
            # The read-out weights depend on the grid only: every step's solver shares the first's.
            # Factored at its first solve: a step the process has taken before is recalled, not solved.
            s = Solver(self.grid, dt, scheme, probes=next(iter(self.solvers.values())).probes if self.solvers else None,
                       factor_now=False)
            self.solvers[key] = s
            if self.src is None:
                # Per watt of electrical power: the film's power density q_v = P / (A L) over the heated
                # disk (the equal-area disk by default: exactly 1 W; a larger disk, e.g. for the 1-D
                # limit, is a larger film at the same power density).
                self.src = self.grid.volume_source_W("heater", self.grid.meta["heater_radius_m"], self.q_v_per_W)
                # Read-only: the step memo (firmware_sim.rz.stepmemo) digests it once per solver, not per step.
                self.src.flags.writeable = False
        return s


def build_config(key: tuple, scene: Scene, geometry: Geometry, stack, sensing_material: Solid, T_amb: float,
                 dt_s: float, ref: GridConfig | None = None) -> GridConfig:
    """The grid configuration ``key`` names: ``("air",)`` or ``("contact", R_c, T_object)``.

    ``stack`` is the probe's stack as built, ``sensing_material`` its sensing layer,
    ``T_amb`` the air's temperature (°C), ``dt_s`` the march's main step.  Every
    configuration must share the probe's cells: ``ref`` (any earlier one) is checked.
    """
    geo = geometry
    a_h = math.sqrt(stack.heater_area_m2 / math.pi) if geo.heater_radius_m is None else geo.heater_radius_m
    r_p = a_h if geo.probe_radius_m is None else geo.probe_radius_m
    if r_p < a_h:
        raise ValueError("the probe must be at least as wide as its heater")
    air = Boundary(geo.h_air_W_m2K, T_amb)
    layers = []
    if geo.substrate is not None:
        layers.append(Layer("substrate", geo.substrate_thickness_m, geo.substrate, r_p, fine_m=5e-6,
                            fine_top_m=geo.mesh.max_dz_m))
    layers.append(Layer("heater", stack.heater_thickness_m, stack.material, r_p, fine_m=5e-6))
    n_probe_layers = len(layers) + 1
    if key[0] == "air":
        layers.append(Layer("sensing", stack.sensing_thickness_m, sensing_material, r_p, fine_m=10e-6))
        bottom = air
    else:
        _, rc, T_obj = key
        o = scene.object
        thick = geo.infinite_thickness_m if o.back == "infinite" else o.thickness_m
        layers.append(Layer("sensing", stack.sensing_thickness_m, sensing_material, r_p, fine_m=10e-6,
                            contact_below_m2K_W=rc))
        layers.append(Layer("object", thick, o.solid, geo.object_radius_m, fine_m=10e-6, fine_bottom_m=1e-3))
        bottom = Boundary(math.inf, T_obj) if o.back == "fixed" else ADIABATIC
    mesh = geo.mesh
    R = max(r_p, geo.object_radius_m)   # the same radial faces in every configuration
    sq = geo.sensor_square
    if sq is None:
        r_s = math.sqrt(SENSOR_AREA_m2 / math.pi) if geo.sensor_radius_m is None else geo.sensor_radius_m
        sensor_feats = {r_s: mesh.feature_dr_m}
    else:
        # The square's read-out weights are exact ring integrals on any faces; faces at its inner
        # circle and its farthest corner keep the rings it only partly covers narrow.
        r_s = sq.outer_radius_m
        sensor_feats = {r_s: mesh.feature_dr_m}
        if sq.inner_radius_m > 0:
            sensor_feats[sq.inner_radius_m] = mesh.feature_dr_m
    # The heater's edge wins where it coincides with another feature (it is the sharp 2-D corner).
    feats = {0.0: mesh.axis_dr_m, **sensor_feats, r_p: mesh.edge_dr_m,
             geo.object_radius_m: mesh.feature_dr_m, R: mesh.feature_dr_m, a_h: mesh.edge_dr_m}
    # A sensor wider than the heater (the small-heater probe) reads the heater's edge and beyond.
    if r_s > r_p:
        raise ValueError("the flux sensor must lie within the probe")
    r_breaks = sorted(feats)
    z_sens = sum(l.thickness_m for l in layers[:n_probe_layers - 1])
    g = Grid.build(layers, r_breaks_m=r_breaks, r_fine_m=[feats[r] for r in r_breaks], mesh=mesh,
                   top=air, side=air, bottom=bottom)
    g.meta.update(heater_radius_m=a_h, probe_radius_m=r_p, sensor_radius_m=r_s,
                  sensor_z_m=(z_sens, z_sens + stack.sensing_thickness_m),
                  interface_z_m=z_sens + stack.sensing_thickness_m,
                  heater_volume_m3=float(np.pi * a_h ** 2 * stack.heater_thickness_m))
    if sq is not None:
        g.meta["sensor_ring_weights"] = sq.ring_weights(g.r_faces_m[: g.r_index_below(r_s) + 1])
    if geo.thermocouple_r_m > 0:
        g.meta["thermocouple_r_m"] = geo.thermocouple_r_m
    if geo.thermocouple_height_m > 0:
        if geo.thermocouple_height_m >= stack.sensing_thickness_m:
            raise ValueError("the thermocouple must lie inside the sensing layer")
        g.meta["thermocouple_height_m"] = geo.thermocouple_height_m
    n_probe_rows = int(np.sum(g.layer_of_row < n_probe_layers))
    # Heater film mean temperature (for the TCR): volume weights over the heated disk.
    w = g.volume_source_W("heater", a_h, 1.0)
    w = w / w.sum()
    cfg = GridConfig(g, n_probe_rows, w)
    cfg.main_dt = round(dt_s, 12)
    cfg.q_v_per_W = stack.q_v_from_power(1.0)
    if ref is not None and not (np.array_equal(ref.grid.r_faces_m, g.r_faces_m) and np.array_equal(
            ref.grid.z_faces_m[: n_probe_rows + 1], g.z_faces_m[: n_probe_rows + 1])):
        raise AssertionError("configurations must share the probe's cells")
    return cfg
