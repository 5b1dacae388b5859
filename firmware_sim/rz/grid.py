"""Axisymmetric (r, z) finite-volume grid of the probe on an object.

The world is a stack of horizontal layers, top (z = 0) to bottom, each a
disk of its own radius: for the probe, the PU-foam substrate, the heater film,
the sensing layer, then the object (or air, or nothing).  Cells are annuli
``r_i < r < r_{i+1}``, ``z_j < z < z_{j+1}`` on one tensor grid; a cell whose
centre lies outside its layer's radius is *inactive* (not part of the body:
no capacity, no conduction) and the faces of active cells that touch it are
outer surfaces.

Cell-centred finite volumes with exact annular volumes ``pi (r_o^2 - r_i^2) dz``
and face areas (``2 pi r dz`` radially, ``pi (r_o^2 - r_i^2)`` axially); the
conductance between neighbours is the series of their half-cell resistances
plus, on the faces of a layer interface, that interface's contact resistance
(m^2 K/W).  Outer surfaces lose heat to an ambient through a film coefficient
``h`` (W/m^2/K) in series with the half cell: ``h = 0`` is adiabatic,
``h = inf`` a fixed temperature.

Cell sizes are graded (:func:`graded_faces`): small at the features that
carry steep gradients (layer interfaces, the heater edge, the sensor edge),
growing geometrically away from them, with every feature on a face.  Refining
by an integer factor subdivides each segment's smooth size map, so a refined
grid keeps the coarse grid's faces and the sequence is fit for Richardson
estimates.

Units are SI throughout; temperatures may be K or degC (only differences
enter the linear model, as long as one scale is used).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from edge.physics.probe import DEFAULT_STACK, ProbeStack
from edge.physics.solids import Solid

__all__ = ["AIR", "PU_FOAM", "Layer", "Boundary", "Mesh", "Grid", "graded_faces", "probe_grid",
           "half_space_grid", "heater_disk_radius_m", "SENSOR_AREA_m2"]

#: Still air near 300 K (Incropera 7e, Table A.4); pure conduction.
AIR = Solid(k_W_mK=0.0263, rho_kg_m3=1.1614, c_J_kgK=1007.0)
#: Rigid PU foam substrate above the heater (issue: k ~ 0.03, rho ~ 40, c ~ 1400).
PU_FOAM = Solid(k_W_mK=0.03, rho_kg_m3=40.0, c_J_kgK=1400.0)
#: Sensitive area of the 10 x 10 mm thermopile heat-flux sensor.
SENSOR_AREA_m2 = 0.010 * 0.010


def heater_disk_radius_m(stack: ProbeStack = DEFAULT_STACK) -> float:
    """Radius of the disk with the heater's area (55 x 60 mm -> 32.4 mm)."""
    return math.sqrt(stack.heater_area_m2 / math.pi)


# ----------------------------------------------------------------------------------------------
# 1-D grading


def _segment_faces(a: float, b: float, h_a: float, h_b: float, growth: float, h_max: float,
                   refine: int) -> np.ndarray:
    """Faces on [a, b]: sizes ~ min(h_max, h_a + m (x - a), h_b + m (b - x)), m = growth - 1.

    The size function s(x) defines the stretching Phi(x) = int_a^x dx / s; the
    segment gets n = ceil(Phi(b)) * refine cells equally spaced in Phi.
    Phi is piecewise analytic (log on the growing parts, linear on the flat
    part) and inverted exactly, so the faces are a smooth map of a uniform
    grid -- the property that keeps cell-centred FV second order and makes a
    refined grid a subdivision of the coarse one.
    """
    m = growth - 1.0
    h_a = min(h_a, h_max, b - a)
    h_b = min(h_b, h_max, b - a)
    x_l = min(max(a + (h_max - h_a) / m, a), b)  # end of the growing part from a
    x_r = min(max(b - (h_max - h_b) / m, a), b)  # start of the shrinking part to b
    if x_l > x_r:  # the two ramps meet before reaching h_max
        x_l = x_r = min(max((h_b - h_a + m * (a + b)) / (2.0 * m), a), b)
    # Pieces: [a, x_l] size h_a + m (x - a); [x_l, x_r] size h_max; [x_r, b] size h_b + m (b - x).
    s_l = h_a + m * (x_l - a)
    s_r = h_b + m * (b - x_r)
    phi_1 = math.log(s_l / h_a) / m
    phi_2 = phi_1 + (x_r - x_l) / h_max
    phi_3 = phi_2 + math.log(s_r / h_b) / m
    n = max(1, math.ceil(phi_3 - 1e-9)) * refine
    p = np.linspace(0.0, phi_3, n + 1)
    x = np.empty_like(p)
    i1 = p <= phi_1
    i3 = p >= phi_2
    i2 = ~(i1 | i3)
    x[i1] = a + h_a * np.expm1(m * p[i1]) / m
    x[i2] = x_l + (p[i2] - phi_1) * h_max
    # On the shrinking part, s(x) = h_b + m (b - x) and phi_3 - Phi(x) = ln(s(x) / h_b) / m.
    x[i3] = b - h_b * np.expm1(m * (phi_3 - p[i3])) / m
    x[0], x[-1] = a, b
    return x


def graded_faces(breaks_m: Sequence[float], fine_m: Sequence[float], *, growth: float = 1.25,
                 max_m: float = np.inf, refine: int = 1) -> np.ndarray:
    """Face coordinates (m) of a 1-D grid graded towards the break points.

    Parameters
    ----------
    breaks_m : sequence of float
        Increasing coordinates that must be faces (layer interfaces, edges).
    fine_m : sequence of float
        Cell size wanted at each break (same length as ``breaks_m``).
    growth : float
        Ratio of neighbouring cell sizes away from a break (> 1).
    max_m : float
        Largest cell size.
    refine : int
        Subdivision factor (1, 2, 4, ...): each segment gets ``refine`` times
        the cells of the base grid, on the same smooth stretching.
    """
    x = np.asarray(breaks_m, dtype=float)
    h = np.asarray(fine_m, dtype=float)
    if x.ndim != 1 or x.size < 2 or h.shape != x.shape or np.any(np.diff(x) <= 0) or np.any(h <= 0):
        raise ValueError("breaks_m must increase (>= 2 points) and fine_m be positive, same length")
    if not growth > 1.0 or int(refine) != refine or refine < 1:
        raise ValueError("growth must be > 1 and refine a positive integer")
    parts = [_segment_faces(x[i], x[i + 1], h[i], h[i + 1], growth, max_m, int(refine))
             for i in range(x.size - 1)]
    return np.concatenate([parts[0]] + [p[1:] for p in parts[1:]])


# ----------------------------------------------------------------------------------------------
# Geometry description


@dataclass(frozen=True)
class Layer:
    """One horizontal layer: a disk of ``radius_m`` (None: the whole domain).

    ``contact_below_m2K_W`` is a thermal contact resistance on the interface
    with the next layer down (in series on those faces).  ``fine_m`` is the
    cell size wanted at both faces of the layer.
    """

    name: str
    thickness_m: float
    material: Solid
    radius_m: float | None = None
    fine_m: float = 10e-6
    contact_below_m2K_W: float = 0.0
    fine_top_m: float | None = None      # override at the top face (None: fine_m)
    fine_bottom_m: float | None = None   # override at the bottom face (None: fine_m)

    def __post_init__(self) -> None:
        if not (self.thickness_m > 0 and math.isfinite(self.thickness_m)):
            raise ValueError(f"layer {self.name!r}: thickness_m must be finite and > 0")
        if self.radius_m is not None and not self.radius_m > 0:
            raise ValueError(f"layer {self.name!r}: radius_m must be > 0")
        if not self.contact_below_m2K_W >= 0:
            raise ValueError(f"layer {self.name!r}: contact_below_m2K_W must be >= 0")


@dataclass(frozen=True)
class Boundary:
    """Heat loss of an outer surface: ``q = h (T - T_inf)``; h = 0 adiabatic, h = inf fixed T."""

    h_W_m2K: float = 0.0
    T_inf_K: float = 0.0

    def __post_init__(self) -> None:
        if not self.h_W_m2K >= 0:
            raise ValueError("h_W_m2K must be >= 0 (inf for a fixed temperature)")


ADIABATIC = Boundary()


@dataclass(frozen=True)
class Mesh:
    """Grading parameters (see :func:`graded_faces`)."""

    growth: float = 1.15
    max_dz_m: float = 5e-3
    max_dr_m: float = 4e-3
    axis_dr_m: float = 1.0e-3       # cell size at the axis (the field is flat there)
    edge_dr_m: float = 60e-6        # at the heater/probe edge (2-D corner of the field)
    feature_dr_m: float = 0.4e-3    # at other radial features (sensor edge, object edge)
    refine: int = 1


# ----------------------------------------------------------------------------------------------
# The grid


@dataclass
class Grid:
    """Cell-centred (r, z) finite-volume grid of a layer stack.

    Arrays are indexed ``[j, i]`` (z index j top to bottom, r index i from the
    axis).  Built by :meth:`build`; the solver reads only the arrays.

    Attributes
    ----------
    r_faces_m, z_faces_m : ndarray
        Face coordinates (``nr + 1``, ``nz + 1``).
    layer_of_row : ndarray of int
        Layer index of each z row.
    active : ndarray of bool, (nz, nr)
        Cells that belong to a body.
    cap_J_K : ndarray, (nz, nr)
        Heat capacity rho c V of each cell (0 for inactive cells).
    g_r_W_K : ndarray, (nz, nr - 1)
        Conductance between radial neighbours (0 across inactive cells).
    g_z_W_K : ndarray, (nz - 1, nr)
        Conductance between axial neighbours (contact resistance included).
    g_b_W_K, t_b_K : ndarray, (nz, nr)
        Total conductance of each cell to the ambient over its outer faces and
        the conductance-weighted ambient temperature (sum g T_inf / sum g).
    g_bottom_W_K : ndarray, (nr,)
        Part of ``g_b_W_K`` through the bottom face of the domain (for the
        flux leaving through it).
    """

    layers: tuple[Layer, ...]
    r_faces_m: np.ndarray
    z_faces_m: np.ndarray
    layer_of_row: np.ndarray
    active: np.ndarray
    cap_J_K: np.ndarray
    k_cell_W_mK: np.ndarray
    g_r_W_K: np.ndarray
    g_z_W_K: np.ndarray
    g_b_W_K: np.ndarray
    t_b_K: np.ndarray
    g_bottom_W_K: np.ndarray
    boundaries: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)

    # -- geometry views
    @property
    def nr(self) -> int:
        return self.r_faces_m.size - 1

    @property
    def nz(self) -> int:
        return self.z_faces_m.size - 1

    @property
    def shape(self) -> tuple[int, int]:
        return (self.nz, self.nr)

    @property
    def dr_m(self) -> np.ndarray:
        return np.diff(self.r_faces_m)

    @property
    def dz_m(self) -> np.ndarray:
        return np.diff(self.z_faces_m)

    @property
    def r_centres_m(self) -> np.ndarray:
        return 0.5 * (self.r_faces_m[1:] + self.r_faces_m[:-1])

    @property
    def z_centres_m(self) -> np.ndarray:
        return 0.5 * (self.z_faces_m[1:] + self.z_faces_m[:-1])

    @property
    def ring_area_m2(self) -> np.ndarray:
        """Area of each annulus, pi (r_o^2 - r_i^2) (the axial face areas)."""
        r = self.r_faces_m
        return np.pi * (r[1:] ** 2 - r[:-1] ** 2)

    @property
    def volume_m3(self) -> np.ndarray:
        return self.dz_m[:, None] * self.ring_area_m2[None, :]

    def layer_index(self, name: str) -> int:
        for n, layer in enumerate(self.layers):
            if layer.name == name:
                return n
        raise KeyError(f"no layer named {name!r}; layers: {[l.name for l in self.layers]}")

    def rows_of(self, name: str) -> np.ndarray:
        """z-row indices of a layer."""
        return np.flatnonzero(self.layer_of_row == self.layer_index(name))

    def layer_top_m(self, name: str) -> float:
        return float(self.z_faces_m[self.rows_of(name)[0]])

    def r_index_below(self, radius_m: float) -> int:
        """Number of radial cells inside ``radius_m`` (which must be a face, to 1e-9 relative)."""
        i = int(np.argmin(np.abs(self.r_faces_m - radius_m)))
        if abs(self.r_faces_m[i] - radius_m) > 1e-9 * max(radius_m, 1e-12):
            raise ValueError(f"radius {radius_m} m is not a face of the grid")
        return i

    def z_index_of(self, z_m: float) -> int:
        """Index of the z face at ``z_m`` (which must be a face)."""
        j = int(np.argmin(np.abs(self.z_faces_m - z_m)))
        if abs(self.z_faces_m[j] - z_m) > 1e-9 * max(abs(z_m), self.z_faces_m[-1] * 1e-6):
            raise ValueError(f"depth {z_m} m is not a face of the grid")
        return j

    # -- sources
    def volume_source_W(self, layer: str, radius_m: float, q_v_W_m3: float = 1.0) -> np.ndarray:
        """Per-cell power (W) of a uniform ``q_v`` in a layer's cells inside ``radius_m``."""
        out = np.zeros(self.shape)
        n = self.r_index_below(radius_m)
        rows = self.rows_of(layer)
        out[rows, :n] = q_v_W_m3 * self.volume_m3[rows, :n]
        return out * self.active

    def top_flux_source_W(self, radius_m: float, q_W_m2: float = 1.0) -> np.ndarray:
        """Per-cell power (W) of a uniform flux into the top face of the domain inside ``radius_m``."""
        out = np.zeros(self.shape)
        n = self.r_index_below(radius_m)
        out[0, :n] = q_W_m2 * self.ring_area_m2[:n]
        return out * self.active

    # -- construction
    @classmethod
    def build(cls, layers: Sequence[Layer], *, r_breaks_m: Sequence[float], r_fine_m: Sequence[float],
              mesh: Mesh = Mesh(), top: Boundary = ADIABATIC, side: Boundary = ADIABATIC,
              bottom: Boundary = ADIABATIC, z_extra_m: Sequence[float] = ()) -> "Grid":
        """Grid of ``layers`` (top to bottom) on radial breaks ``r_breaks_m`` (0 ... domain radius).

        ``top``, ``bottom``: the domain's top and bottom faces; ``side``: every
        other outer surface (the domain's rim and the faces of active cells
        next to inactive ones, e.g. the probe's rim and the object's free top
        around the probe).  ``z_extra_m`` are further depths that must be faces
        (e.g. the flux sensor's depth range), graded like interfaces.
        """
        layers = tuple(layers)
        if not layers:
            raise ValueError("at least one layer")
        r_b = np.asarray(r_breaks_m, float)
        if r_b[0] != 0.0:
            raise ValueError("r_breaks_m must start at the axis (0)")
        R = float(r_b[-1])
        for layer in layers:
            if layer.radius_m is not None and layer.radius_m > R * (1 + 1e-12):
                raise ValueError(f"layer {layer.name!r} is wider than the domain ({R} m)")
        r_faces = graded_faces(r_b, r_fine_m, growth=mesh.growth, max_m=mesh.max_dr_m, refine=mesh.refine)

        # z: each layer's faces graded towards its two faces (and any extra depths inside it).
        z_parts = []
        row_layer = []
        z0 = 0.0
        extra = np.sort(np.asarray(z_extra_m, float))
        for n, layer in enumerate(layers):
            z1 = z0 + layer.thickness_m
            inner = extra[(extra > z0 + 1e-12) & (extra < z1 - 1e-12)]
            br = np.concatenate([[z0], inner, [z1]])
            # The neighbour's fine size also bounds ours at a shared face: cells on both
            # sides of an interface should be of similar size.
            ft = layer.fine_m if layer.fine_top_m is None else layer.fine_top_m
            fb = layer.fine_m if layer.fine_bottom_m is None else layer.fine_bottom_m
            f_top = min(ft, layers[n - 1].fine_m) if n > 0 else ft
            f_bot = min(fb, layers[n + 1].fine_m) if n + 1 < len(layers) else fb
            fine = np.r_[f_top, np.full(inner.size, layer.fine_m), f_bot]
            zf = graded_faces(br, fine, growth=mesh.growth, max_m=mesh.max_dz_m, refine=mesh.refine)
            z_parts.append(zf if n == 0 else zf[1:])
            row_layer += [n] * (zf.size - 1)
            z0 = z1
        z_faces = np.concatenate(z_parts)
        row_layer = np.asarray(row_layer)

        nz, nr = z_faces.size - 1, r_faces.size - 1
        rc = 0.5 * (r_faces[1:] + r_faces[:-1])
        dr = np.diff(r_faces)
        dz = np.diff(z_faces)
        ring = np.pi * (r_faces[1:] ** 2 - r_faces[:-1] ** 2)
        radius = np.array([R if l.radius_m is None else l.radius_m for l in layers])
        active = rc[None, :] < radius[row_layer][:, None]
        k = np.array([l.material.k_W_mK for l in layers])[row_layer][:, None] * np.ones((1, nr))
        rho_c = np.array([l.material.rho_c_J_m3K for l in layers])[row_layer]
        cap = rho_c[:, None] * dz[:, None] * ring[None, :] * active

        # Radial faces between i and i+1: area 2 pi r_f dz; half-cell resistances (r_f - r_c)/k.
        rf = r_faces[1:-1]
        area_r = 2.0 * np.pi * rf[None, :] * dz[:, None]
        res_r = (rf - rc[:-1])[None, :] / k[:, :-1] + (rc[1:] - rf)[None, :] / k[:, 1:]
        both_r = active[:, :-1] & active[:, 1:]
        g_r = np.where(both_r, area_r / res_r, 0.0)

        # Axial faces between j and j+1: area of the annulus; half cells + contact resistance.
        r_contact = np.array([l.contact_below_m2K_W for l in layers])
        interface = row_layer[:-1] != row_layer[1:]
        rc_face = np.where(interface, r_contact[row_layer[:-1]], 0.0)
        res_z = (0.5 * dz[:-1, None] / k[:-1] + 0.5 * dz[1:, None] / k[1:] + rc_face[:, None])
        both_z = active[:-1] & active[1:]
        g_z = np.where(both_z, ring[None, :] / res_z, 0.0)

        # Outer surfaces: film coefficient in series with the half cell.
        gb = np.zeros((nz, nr))
        gbt = np.zeros((nz, nr))  # sum of g * T_inf

        def add(mask, area, half_m, kk, bnd: Boundary):
            if bnd.h_W_m2K == 0.0:
                return np.zeros_like(area * mask, dtype=float)
            res = half_m / kk + (0.0 if math.isinf(bnd.h_W_m2K) else 1.0 / bnd.h_W_m2K)
            g = np.where(mask, area / res, 0.0)
            gb[...] += g
            gbt[...] += g * bnd.T_inf_K
            return g

        ring2 = np.broadcast_to(ring[None, :], (nz, nr))
        # Upward-facing free faces: domain top, or an active cell under an inactive one.
        up = active.copy()
        up[1:] &= ~active[:-1]
        top_row = np.zeros((nz, nr), bool)
        top_row[0] = True
        half_z = np.broadcast_to(0.5 * dz[:, None], (nz, nr))
        add(up & top_row, ring2, half_z, k, top)
        add(up & ~top_row, ring2, half_z, k, side)
        # Downward-facing free faces: domain bottom, or over an inactive cell.
        down = active.copy()
        down[:-1] &= ~active[1:]
        bot_row = np.zeros((nz, nr), bool)
        bot_row[-1] = True
        g_bottom = add(down & bot_row, ring2, half_z, k, bottom)[-1].copy()
        add(down & ~bot_row, ring2, half_z, k, side)
        # Outward radial free faces: domain rim, or next to an inactive cell.
        out = active.copy()
        out[:, :-1] &= ~active[:, 1:]
        area_out = 2.0 * np.pi * r_faces[None, 1:] * dz[:, None]
        add(out, area_out, np.broadcast_to((r_faces[1:] - rc)[None, :], (nz, nr)), k, side)
        # (Inward radial free faces cannot occur: layers are disks about the axis.)

        t_b = np.divide(gbt, gb, out=np.zeros_like(gb), where=gb > 0)
        return cls(layers=layers, r_faces_m=r_faces, z_faces_m=z_faces, layer_of_row=row_layer,
                   active=active, cap_J_K=cap, k_cell_W_mK=k, g_r_W_K=g_r, g_z_W_K=g_z, g_b_W_K=gb,
                   t_b_K=t_b, g_bottom_W_K=g_bottom,
                   boundaries={"top": top, "side": side, "bottom": bottom})


# ----------------------------------------------------------------------------------------------
# The probe


def probe_grid(obj: Solid | None, *, stack: ProbeStack = DEFAULT_STACK,
               object_thickness_m: float = 0.04, object_radius_m: float = 0.05,
               contact_resistance_m2K_W: float = 0.0,
               substrate: Solid | None = PU_FOAM, substrate_thickness_m: float = 0.030,
               heater_radius_m: float | None = None, probe_radius_m: float | None = None,
               sensor_radius_m: float = math.sqrt(SENSOR_AREA_m2 / math.pi),
               sensor_depth_m: tuple[float, float] | None = None,
               top: Boundary = ADIABATIC, side: Boundary = ADIABATIC, bottom: Boundary = ADIABATIC,
               mesh: Mesh = Mesh()) -> Grid:
    """Grid of the probe (substrate, heater film, sensing layer) on an object.

    Parameters
    ----------
    obj : Solid or None
        The object's material (pass :data:`AIR` for the probe held in air), or
        None for no object: the sensing layer's bottom is then an outer
        surface (``bottom`` applies there, the bottom face of the domain).
    stack : ProbeStack
        Heater and sensing-layer thickness and material.
    object_thickness_m, object_radius_m : float
        Size of the object (a cylinder under the probe, on the axis).  Large
        values with graded cells stand for a semi-infinite body.
    contact_resistance_m2K_W : float
        Contact resistance between sensing layer and object.
    substrate, substrate_thickness_m :
        The foam above the heater; None for none (the heater's top is then
        the domain top, ``top`` applies -- the 1-D model's insulated top).
    heater_radius_m : float, optional
        Radius of the heated disk (default: the equal-area disk of the heater).
    probe_radius_m : float, optional
        Radius of the probe's layers (default: the heater radius).
    sensor_radius_m : float
        Radius of the flux sensor's equal-area disk (a face of the grid).
    sensor_depth_m : (float, float), optional
        Depth range of the flux sensor below the top of the sensing layer
        (default: the whole layer); both are faces of the grid.
    top, side, bottom : Boundary
        Outer-surface conditions (see :meth:`Grid.build`).
    mesh : Mesh
        Grading and refinement.
    """
    a_h = heater_disk_radius_m(stack) if heater_radius_m is None else float(heater_radius_m)
    r_p = a_h if probe_radius_m is None else float(probe_radius_m)
    if r_p < a_h:
        raise ValueError("the probe must be at least as wide as its heater")
    p = stack.material
    L_s = stack.sensing_thickness_m
    layers = []
    if substrate is not None:
        # Fine only at the heater; its top is far from anything that happens in a touch.
        layers.append(Layer("substrate", substrate_thickness_m, substrate, r_p, fine_m=5e-6,
                            fine_top_m=mesh.max_dz_m))
    layers.append(Layer("heater", stack.heater_thickness_m, p, r_p, fine_m=5e-6))
    layers.append(Layer("sensing", L_s, p, r_p, fine_m=10e-6,
                        contact_below_m2K_W=contact_resistance_m2K_W if obj is not None else 0.0))
    if obj is not None:
        layers.append(Layer("object", object_thickness_m, obj, object_radius_m, fine_m=10e-6,
                            fine_bottom_m=1e-3))
    z_sens = sum(l.thickness_m for l in layers if l.name in ("substrate", "heater"))
    d0, d1 = (0.0, L_s) if sensor_depth_m is None else sensor_depth_m
    if not 0.0 <= d0 < d1 <= L_s * (1 + 1e-12):
        raise ValueError("sensor_depth_m must be an increasing range within the sensing layer")

    R = max(r_p, object_radius_m if obj is not None else 0.0)
    feats = {0.0: mesh.axis_dr_m, sensor_radius_m: mesh.feature_dr_m, a_h: mesh.edge_dr_m,
             r_p: mesh.edge_dr_m, R: mesh.feature_dr_m}
    if obj is not None:
        feats[object_radius_m] = min(feats.get(object_radius_m, np.inf), mesh.feature_dr_m)
    if not 0 < sensor_radius_m < R:
        raise ValueError("sensor_radius_m must lie inside the domain")
    r_breaks = sorted(feats)
    r_fine = [feats[r] for r in r_breaks]
    g = Grid.build(layers, r_breaks_m=r_breaks, r_fine_m=r_fine, mesh=mesh, top=top, side=side,
                   bottom=bottom, z_extra_m=[z_sens + d0, z_sens + d1])
    g.meta.update(heater_radius_m=a_h, probe_radius_m=r_p, sensor_radius_m=sensor_radius_m,
                   sensor_z_m=(z_sens + d0, z_sens + d1), interface_z_m=z_sens + L_s,
                   heater_volume_m3=float(np.pi * a_h ** 2 * stack.heater_thickness_m))
    return g


def half_space_grid(solid: Solid, *, radius_m: float, depth_m: float, disk_radius_m: float,
                    fine_m: float, top: Boundary = ADIABATIC, side: Boundary = ADIABATIC,
                    bottom: Boundary = ADIABATIC, mesh: Mesh = Mesh()) -> Grid:
    """One solid cylinder standing for a half-space, graded towards the top face and a disk edge.

    Used for the disk-on-half-space check (uniform flux over a disk of radius
    ``disk_radius_m`` into the top face, see :meth:`Grid.top_flux_source_W`).
    """
    layer = Layer("solid", depth_m, solid, None, fine_m=fine_m, fine_bottom_m=mesh.max_dz_m)
    r_breaks = [0.0, disk_radius_m, radius_m]
    r_fine = [mesh.axis_dr_m, mesh.edge_dr_m, mesh.max_dr_m]
    return Grid.build([layer], r_breaks_m=r_breaks, r_fine_m=r_fine, mesh=mesh, top=top, side=side,
                      bottom=bottom)
