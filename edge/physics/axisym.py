"""Axisymmetric forward model of a probe with a heater disk: Laplace-Hankel thermal quadrupoles.

What it computes
----------------
For a :class:`~edge.physics.geometry.ProbeGeometry` on an object (k, alpha;
semi-infinite or of known thickness; contact resistance R_c between the
sensing layer and the object), the unit-step responses per watt of heater
power of

* the thermocouple: temperature at ``r = thermocouple_r_m`` on the
  sensing-layer/object interface (probe side of R_c), K/W;
* the flux sensor: the axial (downward) flux averaged over its depth range
  in the sensing layer and over its disk, (W/m^2)/W.

The layers are laterally infinite slabs (the probe's rim is far from a
5 mm heater: the lateral diffusion length in the sensing layer and the
foam over 5 s is ~1 mm); only the heater's source is finite.

How
---
Hankel transform of order 0 in r (``F(zeta) = int f J0(zeta r) r dr``) and
Laplace in t turn the conduction equation of each layer into
``theta'' = gamma^2 theta`` with ``gamma^2 = p / alpha + zeta^2``: a layer
is a 2x2 quadrupole ``[[cosh, sinh / (k gamma)], [k gamma sinh, cosh]]``
per (p, zeta), a contact resistance a series element, a substrate with an
insulated top an admittance ``k gamma tanh(gamma L)``.  The heater film
carries the disk source ``q_v a J1(zeta a) / zeta / p`` (particular
solution ``S / (k gamma^2)``) and is solved exactly between the admittance
above it and the one below it (sensing layer + R_c + object).  Only
``tanh``, ``sech`` and ratios ``cosh(gamma u) / cosh(gamma L)`` with
``u <= L`` are formed, so nothing overflows at large |gamma L|.

Hankel inversion: fixed Gauss-Legendre panels on ``[0, Z]``, chosen from
the geometry once per probe: panels of half an oscillation of the fastest
Bessel product in the integrands (width ``pi / (a + max(b, r_tc))``), a
geometric refinement towards zeta = 0 (where a long-time, high-diffusivity
object varies on scales ``sqrt(p / alpha)`` far below ``1/a``) and the end
``Z = c / L_s``, where the depth decay ``exp(-zeta L_s)`` of everything
the sensors see has removed the integrand; a raised-cosine taper over the
last part of the range makes the truncation of the oscillating tail smooth
(a sharp cut leaves an error of the size of the tail's last half-period).

Time inversion: ONE fixed hyperbolic contour for the whole record
(Weideman & Trefethen 2007, Math. Comp. 76, 1341, section on an interval
``[t0, Lambda t0]``; midpoint rule, conjugate symmetry).  Why not
fixed Talbot (as :mod:`edge.physics.laplace`): its contour scales with
each t, so every sample needs its own M transform evaluations; Stehfest
needs only real p but extended precision beyond ~14 terms and its own
nodes per t too.  The hyperbola serves every t in ``[t_min, t_max]`` of a
record from ~32 values of p, so the probe's part of the kernel can be
precomputed once on the (p, zeta) grid and an object costs one complex
square root and a few operations per node, then two matrix products.

Precomputation (:class:`AxisymModel`): everything that depends only on the
probe and the time window -- the nodes, the heater's source, the substrate
and heater admittances, the sensing layer's hyperbolic ratios at the
sensor depths, the Bessel weights, the inversion matrix.  Per object
(:meth:`AxisymModel.responses`): about 15 complex array operations on
the (p, zeta) grid.  Edge code: NumPy only (the Bessel functions here are
computed from their integral representation).
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from dataclasses import dataclass, replace

import numpy as np

from edge.checks import finite_array, finite_nonnegative, finite_positive, one_of
from edge.physics.bessel import bessel_j
from edge.physics.footprint import rectangle_weights
from edge.physics.geometry import ProbeGeometry
from edge.physics.memo import BoundedMemo
from edge.physics.solids import Solid

__all__ = ["bessel_j", "HyperbolicInversion", "hankel_nodes", "sensor_weights", "AxisymModel", "Responses"]

BACKS = ("infinite", "insulated", "fixed")
#: Contour angle of the hyperbola (W&T 2007 use values near 1.1; this one with N = 32 gives
#: < 1e-6 relative on the layered transforms over Lambda = 250).
_PHI = 1.09


# ----------------------------------------------------------------------------------------------
# Time inversion


@dataclass(frozen=True)
class HyperbolicInversion:
    """Fixed hyperbolic Bromwich contour for times in ``[t_min, t_max]`` (W&T 2007).

    ``s_k = mu (1 - sin(phi) cosh(u_k)) + i mu cos(phi) sinh(u_k)``, ``u_k = (k + 1/2) h``,
    ``k = 0..n-1``; ``f(t) = (h / pi) Im sum_k F(s_k) s'_k exp(s_k t)`` for real f.

    Attributes
    ----------
    s : ndarray, complex (n,)
        Contour nodes (the upper half; conjugate symmetry supplies the rest).
    matrix : ndarray, complex (n_t, n)
        ``(h / pi) s'_k exp(s_k t_j)``: ``f = Im(matrix @ F(s))``; rows for t <= 0 are 0.
    """

    t_s: np.ndarray
    s: np.ndarray
    matrix: np.ndarray

    @classmethod
    def build(cls, t_s: np.ndarray, n: int = 32, *, t_min_s: float | None = None,
              t_max_s: float | None = None) -> "HyperbolicInversion":
        """Contour for the positive times of ``t_s`` (or for ``[t_min_s, t_max_s]``)."""
        t = finite_array("t_s", t_s)
        pos = t[t > 0]
        if pos.size == 0:
            raise ValueError("t_s needs at least one positive time")
        t0 = float(pos.min()) if t_min_s is None else float(t_min_s)
        t1 = float(pos.max()) if t_max_s is None else float(t_max_s)
        lam = max(t1 / t0, 1.0 + 1e-9)
        phi = _PHI
        # W&T 2007 (eqs. for the hyperbola on [t0, Lambda t0]): the strip half-width A and the
        # scale mu balance discretisation and truncation errors over the whole interval.
        A = math.acosh(((math.pi - 2 * phi) * lam + 4 * phi - math.pi) / ((4 * phi - math.pi) * math.sin(phi)))
        mu = (4 * math.pi * phi - math.pi ** 2) * n / t1 / A
        h = A / n
        u = (np.arange(n) + 0.5) * h
        s = mu + 1j * mu * np.sinh(u + 1j * phi)
        ds = 1j * mu * np.cosh(u + 1j * phi)
        tt = np.where(t > 0, t, 0.0)
        mat = (h / math.pi) * ds[None, :] * np.exp(s[None, :] * tt[:, None])
        mat[t <= 0] = 0.0
        return cls(t_s=t, s=s, matrix=mat)

    def invert(self, F: np.ndarray) -> np.ndarray:
        """f(t) from transform values ``F`` at :attr:`s` (last axis)."""
        return np.imag(np.asarray(F) @ self.matrix.T)


# ----------------------------------------------------------------------------------------------
# Hankel quadrature


def hankel_nodes(geometry: ProbeGeometry, *, per_panel: int = 4, depth_decades: float = 10.0,
                 taper: float = 0.25, low_levels: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights (zeta in 1/m) for ``int_0^inf f(zeta) d zeta`` on this probe.

    Parameters
    ----------
    per_panel : int
        Gauss-Legendre points per panel (a panel is half a period of the fastest
        oscillation, ``pi / (a + max(b, r_tc))``).
    depth_decades : float
        End of the range in units of ``1 / L_s`` (the thinnest depth between the
        heater and a sensor): the integrands have decayed by ~exp(-depth_decades).
    taper : float
        Fraction of the range over which the weights are tapered to 0 (raised cosine).
    low_levels : int
        Panels halving towards zeta = 0 inside the first oscillation panel.
    """
    a = geometry.heater_radius_m
    reach = max(geometry.sensor_reach_m, geometry.thermocouple_r_m)
    w = math.pi / (a + reach)
    Z = depth_decades / geometry.sensing_thickness_m
    n_osc = max(1, int(math.ceil(Z / w)))
    breaks = np.concatenate([[0.0], w * 0.5 ** np.arange(low_levels, 0, -1), w * np.arange(1, n_osc + 1)])
    x, wt = np.polynomial.legendre.leggauss(per_panel)
    lo, hi = breaks[:-1, None], breaks[1:, None]
    z = (0.5 * (hi - lo) * x[None, :] + 0.5 * (hi + lo)).ravel()
    wz = (0.5 * (hi - lo) * wt[None, :]).ravel()
    Zend = breaks[-1]
    z0 = (1.0 - taper) * Zend
    ramp = np.clip((z - z0) / (Zend - z0), 0.0, 1.0)
    wz = wz * 0.5 * (1.0 + np.cos(np.pi * ramp))
    return z, wz


_WEIGHTS: dict = {}
#: Footprints' weights kept (a few floats per node each): 8 were evicted within one small-heater calibration,
#: whose sensing-layer trials each bring their own nodes, and each cost ~0.3 s of Bessel tables.
_WEIGHTS_MAX = 64


def sensor_weights(geometry: ProbeGeometry, zeta: np.ndarray) -> np.ndarray:
    """The flux sensor's read-out ``W(zeta)`` (area mean of ``J0(zeta |x|)`` over its footprint).

    The rectangle's are cached per footprint and nodes (their set-up is most of a model's): a calibration
    builds many models that share both.
    """
    if geometry.sensor_square_m is None:
        b = geometry.sensor_radius_m
        return 2.0 * bessel_j(1, zeta * b) / (zeta * b)
    (sx, sy), (ox, oy) = geometry.sensor_square_m, geometry.sensor_offset_m
    key = (float(sx), float(sy), float(ox), float(oy), zeta.tobytes())
    w = _WEIGHTS.get(key)
    if w is None:
        if len(_WEIGHTS) >= _WEIGHTS_MAX:
            _WEIGHTS.pop(next(iter(_WEIGHTS)))
        w = _WEIGHTS[key] = rectangle_weights(zeta, sx, sy, ox, oy)
        w.flags.writeable = False
    return w


# ----------------------------------------------------------------------------------------------
# Stable hyperbolic helpers (Re z >= 0)


def _tanh(z):
    e = np.exp(-2.0 * z)
    return (1.0 - e) / (1.0 + e)


def _sech(z):
    e = np.exp(-z)
    return 2.0 * e / (1.0 + e * e)


def insulated_layer_admittance(k_W_mK: float, gamma, thickness_m: float):
    """Admittance ``k gamma tanh(gamma d)`` of a layer with an insulated far side (the substrate above the heater)."""
    return k_W_mK * gamma * _tanh(gamma * thickness_m)


def series_contact(Y, contact_resistance_m2K_W: float):
    """The admittance ``Y / (1 + R_c Y)`` an object of admittance ``Y`` presents through a contact resistance."""
    R = contact_resistance_m2K_W
    return Y / (1.0 + R * Y) if R != 0.0 else Y


def _ch_sh_ratios(g, u, L, den=None):
    """(cosh(g u) / cosh(g L), sinh(g u) / cosh(g L)) for 0 <= u <= L.

    Both from the same two exponentials over the same denominator ``1 + exp(-2 g L)`` (pass ``den`` to
    share it between depths): a model's set-up forms them on every (p, zeta) node.
    """
    if den is None:
        den = 1.0 + np.exp(-2.0 * g * L)
    a, b = np.exp(g * (u - L)), np.exp(-g * (u + L))
    return (a + b) / den, (a - b) / den


# ----------------------------------------------------------------------------------------------
# The model


#: Probe parts of the last few models built (everything a model's set-up computes), by geometry,
#: times and quadrature: a new estimator, a design table, a restarted daemon on the same probe and
#: grid take them instead of recomputing the same arrays (the set-up is most of a cold fit's cost).
#: No model writes into these arrays (its variants -- :meth:`AxisymModel.with_substrate`,
#: :meth:`AxisymModel.head` -- replace attributes, never modify them in place).
_PARTS: OrderedDict = OrderedDict()
_PARTS_MAX = 4
_PARTS_LOCK = threading.Lock()


def _parts_key(geometry: ProbeGeometry, t_s, quadrature: tuple, nodes) -> tuple | None:
    """The key of a model's probe parts, or None where it has none (unhashable or invalid inputs:
    the set-up then builds, and reports, as ever)."""
    try:
        t = np.asarray(t_s, dtype=float)
        nd = None if nodes is None else tuple(np.asarray(a, dtype=float).tobytes() for a in nodes)
        key = (geometry, t.shape, t.tobytes(), quadrature, nd)
        hash(key)
    except (TypeError, ValueError):
        return None
    return key


def _cached_parts(key: tuple | None) -> dict | None:
    if key is None:
        return None
    with _PARTS_LOCK:
        parts = _PARTS.get(key)
        if parts is not None:
            _PARTS.move_to_end(key)
        return parts


def _keep_parts(key: tuple | None, model: "AxisymModel") -> None:
    if key is None:
        return
    parts = dict(model.__dict__)
    # The times as the key has them: the caller keeps its own array (and may reuse it).
    inv = model.inversion
    t = inv.t_s.copy()
    parts["inversion"] = HyperbolicInversion(t_s=t, s=inv.s, matrix=inv.matrix)
    parts["t_s"] = t
    with _PARTS_LOCK:
        _PARTS[key] = parts
        while len(_PARTS) > _PARTS_MAX:
            _PARTS.popitem(last=False)


#: The model's arrays one object's transforms are computed from (see :meth:`AxisymModel.transforms`).
_TRANSFORM_PARTS = ("_p", "_z2", "_kgs", "_Ts", "_Ss", "_kgsTs", "_Ts_kgs", "_dYdn_num", "_num", "_B", "_C",
                    "_qa", "_qb", "_w_T", "_w_q")
#: Transforms already computed, by the very arrays of the model and the object's exact numbers.  A
#: record is estimated more than once with the same model parts -- the device's answer, then
#: ``thermotouch estimate`` on its export, a calibration's re-measurement, a running answer's refits
#: from the same start -- and two of three calls of a suite's fits repeat one already made.  An
#: entry holds the arrays it was computed from, so their ids in its key cannot be reused while it
#: lives (no model writes into them, see :data:`_PARTS`); a hit returns copies, the same bits.
_TRANSFORMS: OrderedDict = OrderedDict()
_TRANSFORMS_MAX = 512


def _transforms_key(model: "AxisymModel", args: tuple) -> tuple:
    """(key, the model's arrays); key None where an argument is unhashable (an array: no memo)."""
    parts = tuple(getattr(model, name) for name in _TRANSFORM_PARTS)
    key = tuple(map(id, parts)) + args
    try:
        hash(key)
    except TypeError:
        return None, parts
    return key, parts


def _cached_transforms(key: tuple | None, parts: tuple):
    if key is None:
        return None
    with _PARTS_LOCK:
        hit = _TRANSFORMS.get(key)
        if hit is None or any(a is not b for a, b in zip(hit[0], parts)):
            return None
        _TRANSFORMS.move_to_end(key)
    return tuple(x.copy() for x in hit[1])


def _keep_transforms(key: tuple | None, parts: tuple, out: tuple) -> None:
    if key is None:
        return
    with _PARTS_LOCK:
        _TRANSFORMS[key] = (parts, tuple(x.copy() for x in out))
        while len(_TRANSFORMS) > _TRANSFORMS_MAX:
            _TRANSFORMS.popitem(last=False)


#: Terms of the (p, zeta) grid by its numbers and one material's (read-only, the same bits): an object's or
#: the sensing layer's gamma (its complex square root is most of a transform), a substrate's admittance, the
#: heater film's terms.  A calibration's
#: finite-difference columns of the probe's own parameters and of a reference's k or contact build other
#: models on the same grid for the same objects: 55 % of the small-heater tests' transforms and 70 % of
#: their substrate set-ups were of a grid and material seen before.  ~0.2 MB an entry on the small heater
#: (the film's four terms 0.9 MB); at most 8 MB in all (a calibration's iteration uses about 15 entries).
_GRID_TERMS = BoundedMemo(48, max_bytes=8 * 2**20)

#: Substrate variants kept per model (:meth:`AxisymModel.with_substrate`): the point and its two substrate
#: columns and a trial; ~0.65 MB each on the small-heater probe.
_VARIANTS_MAX = 4


@dataclass(frozen=True)
class Responses:
    """Unit-step responses per watt of heater power on the model's time grid."""

    t_s: np.ndarray
    T_tc_K_per_W: np.ndarray
    q_sensor_W_m2_per_W: np.ndarray


class AxisymModel:
    """The forward model of one probe on one time grid, with its probe part precomputed.

    Parameters
    ----------
    geometry : ProbeGeometry
        The probe.
    t_s : array_like
        Output times (s); times <= 0 give 0 (the step starts at t = 0).
    n_laplace : int
        Nodes on the hyperbolic contour.
    per_panel, depth_decades, taper, low_levels :
        Hankel quadrature (see :func:`hankel_nodes`).
    """

    def __init__(self, geometry: ProbeGeometry, t_s, *, n_laplace: int = 32, per_panel: int = 4,
                 depth_decades: float = 10.0, taper: float = 0.25, low_levels: int = 8,
                 nodes: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        g = geometry
        key = _parts_key(g, t_s, (n_laplace, per_panel, depth_decades, taper, low_levels), nodes)
        parts = _cached_parts(key)
        if parts is not None:
            self.__dict__.update(parts)
            return
        self.geometry = g
        self.inversion = HyperbolicInversion.build(t_s, n_laplace)
        self.t_s = self.inversion.t_s
        # ``nodes``: another model's Hankel nodes (:attr:`nodes`) -- a neighbouring probe (a calibration's
        # finite difference) then differs from it only by the physics, not by a shifted quadrature, and
        # shares its read-out weights (cached).
        zeta, wz = nodes if nodes is not None else hankel_nodes(g, per_panel=per_panel, depth_decades=depth_decades,
                                                                taper=taper, low_levels=low_levels)
        self.zeta = zeta
        self.nodes = (zeta, wz)
        p = self.inversion.s[:, None]      # (n_p, 1)
        z2 = (zeta * zeta)[None, :]        # (1, n_z)
        self._p = p
        self._z2 = z2

        # Heater disk source per watt, transformed: q_v a J1(zeta a) / zeta, step 1/p.
        a = g.heater_radius_m
        disk = a * bessel_j(1, zeta * a) / zeta
        q_v = 1.0 / g.heater_volume_m3
        # Output weights of the inverse Hankel transform, zeta d zeta, with the read-outs:
        # thermocouple J0(zeta r_tc), sensor's area mean: over its real rectangle (exact,
        # edge.physics.footprint) or over its equal-area disk, 2 J1(zeta b) / (zeta b).
        self._w_T = wz * zeta * disk * bessel_j(0, zeta * g.thermocouple_r_m)
        self._w_q = wz * zeta * disk * sensor_weights(g, zeta)

        # Heater film (material h): gamma, k gamma, tanh, sech.
        hm = g.heater_material

        def heater() -> tuple[np.ndarray, ...]:
            gh = np.sqrt(p / hm.alpha_m2_s + z2)
            kgh = hm.k_W_mK * gh
            Th = _tanh(gh * g.heater_thickness_m)
            Sh = _sech(gh * g.heater_thickness_m)
            theta_p = q_v / (p * hm.k_W_mK * gh * gh)     # particular solution (per unit source shape)
            return kgh, Th, Sh, theta_p
        # The same film on the same grid for every sensing layer a calibration tries (_GRID_TERMS).
        self._heater = _GRID_TERMS(("heater", *self._grid_key(), hm, float(g.heater_thickness_m), q_v), heater)
        self._set_substrate(g.substrate, g.substrate_thickness_m)

        # Sensing layer (material s), thickness L; sensor depths u = L - z.
        sm = g.sensing
        L = g.sensing_thickness_m
        gs = self._object_gamma_kept(sm.alpha_m2_s)[1]    # sqrt(p / alpha_s + zeta^2), kept by the grid
        self._kgs = sm.k_W_mK * gs
        self._Ts = _tanh(gs * L)
        self._Ss = _sech(gs * L)
        # Per-object terms that depend on the sensing layer only (the same products transforms forms).
        self._kgsTs = self._kgs * self._Ts
        self._dYdn_num = self._kgs * self._kgs * (1.0 - self._Ts * self._Ts)
        self._Ts_kgs = self._Ts / self._kgs
        z0, z1 = g.sensor_depth_m
        u0, u1 = L - z0, L - z1
        dz = z1 - z0
        den = 1.0 + np.exp(-2.0 * gs * L)
        (ch0, sh0), (ch1, sh1) = _ch_sh_ratios(gs, u0, L, den), _ch_sh_ratios(gs, u1, L, den)
        self._qa = sm.k_W_mK * (ch0 - ch1) / dz
        self._qb = (sh0 - sh1) / (gs * dz)
        self.n_nodes = int(self._heater[0].size)
        _keep_parts(key, self)

    def _set_substrate(self, substrate: Solid | None, thickness_m: float) -> None:
        """The heater's terms that the substrate above it sets (an insulated top over ``thickness_m``)."""
        kgh, Th, Sh, theta_p = self._heater
        if substrate is None:
            Yup = np.zeros_like(kgh)
        else:
            def admittance() -> np.ndarray:
                gf = np.sqrt(self._p / substrate.alpha_m2_s + self._z2)
                return insulated_layer_admittance(substrate.k_W_mK, gf, thickness_m)
            Yup = _GRID_TERMS(("substrate", *self._grid_key(), substrate, float(thickness_m)), admittance)
        # theta at the heater's bottom = theta_p * num / (B + C Ydn)  (see module docstring).
        self._num = theta_p * (kgh * Th + Yup * (1.0 - Sh))
        self._B = Yup + kgh * Th
        self._C = 1.0 + Yup * Th / kgh

    def with_substrate(self, substrate: Solid | None, thickness_m: float | None = None) -> "AxisymModel":
        """The same model with another substrate above the heater (its contour, nodes and read-outs shared).

        A calibration identifies the as-built substrate (:mod:`edge.calibration.axi`): only the heater's
        three substrate terms are recomputed, a few array operations instead of a model's set-up.
        """
        th = self.geometry.substrate_thickness_m if thickness_m is None else finite_positive("thickness_m", thickness_m)
        # Kept per model (a few): a calibration asks one sensing layer's model for the same substrate on
        # every touch and finite-difference column, and the same variant's arrays also let the transforms'
        # memo (keyed by their ids) answer a repeated object.
        variants = self.__dict__.setdefault("_variants", BoundedMemo(_VARIANTS_MAX))
        key = (substrate, float(th))
        m = variants.get(key)
        if m is None:
            m = object.__new__(AxisymModel)
            m.__dict__.update(self.__dict__)
            m.__dict__.pop("_variants")          # its own variants are its own
            m.__dict__.pop("_last_hd", None)     # another substrate: another heater
            m.geometry = replace(self.geometry, substrate=substrate, substrate_thickness_m=th)
            m._set_substrate(substrate, th)
            variants.put(key, m)
        return m

    def head(self, n: int) -> "AxisymModel":
        """The same model on its first ``n`` output times (the contour and probe part shared, not copied).

        The contour was built for all of :attr:`t_s`, so it is as accurate on any of them: a record's
        prefix -- a running answer refitting the samples so far -- needs no model of its own.
        """
        n = int(n)
        if not 1 <= n <= self.t_s.size:
            raise ValueError(f"n must be in 1..{self.t_s.size}, got {n}")
        m = object.__new__(AxisymModel)
        m.__dict__.update(self.__dict__)
        m.__dict__.pop("_variants", None)        # variants on the whole grid are not this prefix's
        m.__dict__.pop("_last_hd", None)
        inv = self.inversion
        m.inversion = HyperbolicInversion(t_s=inv.t_s[:n], s=inv.s, matrix=inv.matrix[:n])
        m.t_s = m.inversion.t_s
        return m

    def _grid_key(self) -> tuple[bytes, bytes]:
        """The (p, zeta) grid by value: a neighbouring probe's model (a calibration's finite difference, its
        Hankel nodes shared) has its own arrays of the same numbers."""
        key = self.__dict__.get("_grid_bytes")
        if key is None:
            key = self._grid_bytes = (self._p.tobytes(), self._z2.tobytes())
        return key

    def _object_gamma_kept(self, alpha_m2_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(p / alpha, gamma = sqrt(p / alpha + zeta^2)) of a layer or object of diffusivity ``alpha_m2_s``
        (read-only, kept: :data:`_GRID_TERMS`)."""
        def compute() -> tuple[np.ndarray, np.ndarray]:
            p_a = self._p / alpha_m2_s
            g2 = p_a + self._z2
            return p_a, np.sqrt(g2, out=g2)
        return _GRID_TERMS(("gamma", *self._grid_key(), float(alpha_m2_s)), compute)

    # -- object
    def object_admittance(self, k_W_mK: float, alpha_m2_s: float, thickness_m: float | None = None,
                          back: str = "infinite") -> np.ndarray:
        """Surface admittance q/theta of the object on the (p, zeta) grid."""
        go = self._object_gamma_kept(alpha_m2_s)[1]      # the transforms' gamma (kept): the same numbers
        Y = k_W_mK * go
        if back == "infinite" or thickness_m is None:
            return Y
        t = _tanh(go * thickness_m)
        return Y / t if back == "fixed" else Y * t

    def transforms(self, k_W_mK: float, alpha_m2_s: float, *, thickness_m: float | None = None,
                   back: str = "infinite", contact_resistance_m2K_W: float = 0.0, derivatives: bool = False):
        """Laplace transforms (n_p,) of the thermocouple and flux-sensor step responses per watt.

        With ``derivatives``: also their derivatives (3, n_p) with respect to ln k, ln alpha
        and R_c.  The object enters only through its admittance Y (and R_c through
        ``Y_o = Y / (1 + R_c Y)``), so one derivative of the kernels with respect to ``Y_o``
        serves all three parameters: an exact Jacobian for about half a model evaluation.
        Computed once per model parts and arguments (:data:`_TRANSFORMS`).
        """
        key, parts = _transforms_key(self, (k_W_mK, alpha_m2_s, thickness_m, back, contact_resistance_m2K_W,
                                            bool(derivatives)))
        out = _cached_transforms(key, parts)
        if out is None:
            out = self._transforms(k_W_mK, alpha_m2_s, thickness_m, back, contact_resistance_m2K_W, derivatives)
            _keep_transforms(key, parts, out)
        return out

    def _transforms(self, k_W_mK: float, alpha_m2_s: float, thickness_m: float | None, back: str,
                    contact_resistance_m2K_W: float, derivatives: bool):
        """:meth:`transforms`, computed.

        Each operation of the formulas in the comments, on the same operands in the same order, written into
        a temporary of this call that is no longer needed (``out=``): a touch's running refits make ~7 of
        these per refit on the (p, zeta) grid, and a fresh array for every intermediate was a third of their
        cost.  Operand order is kept to the last bit: NumPy's complex multiply (FMA) is not commutative in
        its rounding, and on grids over 256 KiB NumPy itself evaluates ``x * (temporary)`` as
        ``temporary *= x`` (temporary elision), so products of that form keep their expression form here
        (``dkq``, :meth:`_under_heater`).  tests/edge/physics/test_axisym_inplace.py holds the formulas'
        plain form and checks both grids against it bit for bit.
        """
        p_a, go = self._object_gamma_kept(alpha_m2_s)
        Y = k_W_mK * go
        fin = not (back == "infinite" or thickness_m is None)
        if fin:
            t = _tanh(go * thickness_m)
            Y = Y / t if back == "fixed" else Y * t
        R = contact_resistance_m2K_W
        Yo = series_contact(Y, R)
        kgs = self._kgs
        TsYo, dd, Ydn = self._under_heater(Yo)
        den = np.divide(TsYo, kgs, out=TsYo)            # 1 + Ts Yo / kgs: the sensing layer seen from below
        np.add(1.0, den, out=den)
        hd = np.multiply(self._C, Ydn, out=Ydn)         # B + C Ydn
        np.add(self._B, hd, out=hd)
        # The heater's transform of the same object divides by the same hd: kept for it (the droop's
        # column asks right after, heater_tcr.droop_transforms).
        self._last_hd = ((k_W_mK, alpha_m2_s, thickness_m, back, contact_resistance_m2K_W), hd)
        r = np.multiply(hd, den)                        # heater-bottom temperature / den: num / (hd den)
        np.divide(self._num, r, out=r)
        kT = r * self._Ss
        kq_base = np.multiply(Yo, self._qb)             # qa + Yo qb
        np.add(self._qa, kq_base, out=kq_base)
        T = kT @ self._w_T                              # interface (probe side)
        buf = np.multiply(r, kq_base)
        q = buf @ self._w_q
        if not derivatives:
            return T, q
        # d/dYo of the kernels: dlnr = -(C dYdn / hd + (Ts / kgs) / den), dYdn = dYdn_num / dd^2.
        dlnr = np.multiply(dd, dd, out=dd)
        np.divide(self._dYdn_num, dlnr, out=dlnr)
        np.multiply(self._C, dlnr, out=dlnr)
        np.divide(dlnr, hd, out=dlnr)
        np.add(dlnr, np.divide(self._Ts_kgs, den, out=den), out=dlnr)
        np.negative(dlnr, out=dlnr)
        dkT = np.multiply(kT, dlnr, out=kT)
        dkq = r * (dlnr * kq_base + self._qb)
        # dYo/dtheta for theta = ln k, ln alpha, R_c.
        dYo_dY = 1.0 / (1.0 + R * Y) ** 2 if R != 0.0 else 1.0
        dgo = -0.5 * p_a / go                          # d go / d ln alpha
        if not fin:
            dY_dgo = k_W_mK
        elif back == "fixed":
            dY_dgo = k_W_mK / t - k_W_mK * go * thickness_m * (1.0 - t * t) / (t * t)
        else:
            dY_dgo = k_W_mK * t + k_W_mK * go * thickness_m * (1.0 - t * t)
        d_ln_alpha = np.multiply(dY_dgo, dgo, out=dgo)
        np.multiply(d_ln_alpha, dYo_dY, out=d_ln_alpha)
        d_R = np.negative(Yo, out=dlnr)
        dtheta = (Y * dYo_dY, d_ln_alpha, np.multiply(d_R, Yo, out=d_R))
        dT = np.stack([np.multiply(dkT, d, out=buf) @ self._w_T for d in dtheta])
        dq = np.stack([np.multiply(dkq, d, out=buf) @ self._w_q for d in dtheta])
        return T, q, dT, dq

    def heater_transform(self, k_W_mK: float, alpha_m2_s: float, *, thickness_m: float | None = None,
                         back: str = "infinite", contact_resistance_m2K_W: float = 0.0) -> np.ndarray:
        """Laplace transform (n_p,) of the heater film's mean temperature over its disk per watt (step).

        The film's resistance follows its temperature (its TCR, :mod:`edge.physics.heater_tcr`); the
        film is thin, so its mean is its bottom face's, averaged over the disk (``2 J1(zeta a) / (zeta a)``).
        """
        # Kept with the transforms (:data:`_TRANSFORMS`): a calibration's droop column asks for it at every
        # evaluation of a touch, most of them (another touch's or a global's column) at an object already seen.
        key, parts = _transforms_key(self, ("heater", k_W_mK, alpha_m2_s, thickness_m, back, contact_resistance_m2K_W))
        out = _cached_transforms(key, parts)
        if out is None:
            out = (self._heater_transform(k_W_mK, alpha_m2_s, thickness_m, back, contact_resistance_m2K_W),)
            _keep_transforms(key, parts, out)
        return out[0]

    def _heater_transform(self, k_W_mK: float, alpha_m2_s: float, thickness_m: float | None, back: str,
                          contact_resistance_m2K_W: float) -> np.ndarray:
        """:meth:`heater_transform`, computed."""
        w = getattr(self, "_w_h", None)
        if w is None:
            a = self.geometry.heater_radius_m
            zeta, wz = self.nodes
            disk = a * bessel_j(1, zeta * a) / zeta
            w = self._w_h = wz * zeta * disk * 2.0 * bessel_j(1, zeta * a) / (zeta * a)
        last = getattr(self, "_last_hd", None)
        if last is not None and last[0] == (k_W_mK, alpha_m2_s, thickness_m, back, contact_resistance_m2K_W):
            return (self._num / last[1]) @ w
        Yo = series_contact(self.object_admittance(k_W_mK, alpha_m2_s, thickness_m, back), contact_resistance_m2K_W)
        hd = np.multiply(self._C, self._under_heater(Yo)[2])   # num / (B + C Ydn), in one temporary
        np.add(self._B, hd, out=hd)
        return np.divide(self._num, hd, out=hd) @ w

    def _under_heater(self, Yo):
        """(Ts Yo, kgs + Ts Yo, Ydn): the admittance under the heater through the sensing layer onto ``Yo``."""
        TsYo = self._Ts * Yo
        dd = self._kgs + TsYo
        return TsYo, dd, self._kgs * (self._kgsTs + Yo) / dd

    def responses(self, k_W_mK: float, alpha_m2_s: float, *, thickness_m: float | None = None,
                  back: str = "infinite", contact_resistance_m2K_W: float = 0.0) -> Responses:
        """Thermocouple and flux-sensor step responses per watt at the model's times."""
        one_of("back", back, BACKS)
        finite_positive("k_W_mK", k_W_mK)
        finite_positive("alpha_m2_s", alpha_m2_s)
        if thickness_m is not None:
            finite_positive("thickness_m", thickness_m)
        T, q = self.transforms(k_W_mK, alpha_m2_s, thickness_m=thickness_m, back=back,
                               contact_resistance_m2K_W=contact_resistance_m2K_W)
        out = self.inversion.invert(np.stack([T, q]))
        return Responses(self.t_s, out[0], out[1])

    def solid_responses(self, solid: Solid, **kw) -> Responses:
        """:meth:`responses` for a :class:`Solid`."""
        return self.responses(solid.k_W_mK, solid.alpha_m2_s, **kw)

    def signals(self, k_W_mK: float, alpha_m2_s: float, power_W: float | None = None, **kw):
        """(T_tc in K, q_sensor in W/m^2) for a heater step of ``power_W`` (default: nominal)."""
        P = self.geometry.nominal_power_W if power_W is None else finite_nonnegative("power_W", power_W)
        r = self.responses(k_W_mK, alpha_m2_s, **kw)
        return P * r.T_tc_K_per_W, P * r.q_sensor_W_m2_per_W
