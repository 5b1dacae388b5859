"""The flux sensor's real footprint as radial weights of the axisymmetric field.

In an axisymmetric field ``q(r)`` the flux a sensor of footprint ``S`` and
relative sensitivity ``s(x, y)`` reports is exactly

    q_read = (1 / A) * integral_0^inf q(r) w(r) dr,
    w(r) = integral over the part of the circle of radius r inside S of s r dtheta,

with ``A`` the footprint's area (``s`` has mean 1 over it).  On the
finite-volume grid ``q`` is one value per annulus, so the read-out needs the
ring integrals ``W_i = integral_{r_i}^{r_{i+1}} w(r) dr`` -- the
sensitivity-weighted area of ``S`` inside the annulus.  :class:`SquareSensor`
computes them in closed form for an axis-aligned rectangle offset from the
heater's axis with a linear sensitivity map: the area and first moments of
(disk of radius r) ∩ (rectangle) follow from the quadrant integrals
``int_0^X min(Y, sqrt(r^2 - x^2)) dx`` and their moments, signed by quadrant.
:func:`centred_square_weight` is the brief's closed form of ``w(r)`` for a
centred square and :meth:`SquareSensor.circle_weight` the azimuthal integral
by exact arcs (both used by the tests, which also check a 2-D brute-force sum).

The equal-area disk (``sensor_radius_m``) is what the ESTIMATOR assumes
(:mod:`edge.physics.geometry`); the world reads the square for any head that
has one by default (the small-heater probe, whose square's edge lies on the
heater's edge) and for every drawn probe (:mod:`firmware_sim.asbuilt`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from edge.physics.geometry import SENSOR_SIDE_m

__all__ = ["SquareSensor", "centred_square_weight", "centred_square_area_in_disk", "off_axis_weights", "depth_weights"]


def centred_square_weight(r_m: np.ndarray, side_m: float) -> np.ndarray:
    """Arc length of the circle of radius ``r`` inside a centred square of side ``side_m`` (m).

    ``2 pi r`` for ``r <= a/2``, ``8 r (pi/4 - arccos(a / (2 r)))`` for ``a/2 < r <= a/sqrt(2)``, 0 beyond.
    """
    r = np.asarray(r_m, dtype=float)
    h = 0.5 * side_m
    out = np.where(r <= h, 2.0 * np.pi * r, 0.0)
    mid = (r > h) & (r <= h * math.sqrt(2.0))
    rm = np.where(mid, r, 1.0)
    return np.where(mid, 8.0 * rm * (np.pi / 4.0 - np.arccos(np.clip(h / rm, -1.0, 1.0))), out)


def centred_square_area_in_disk(r_m: np.ndarray, side_m: float) -> np.ndarray:
    """Area (m^2) of a centred square of side ``side_m`` inside the disk of radius ``r``."""
    r = np.asarray(r_m, dtype=float)
    h = 0.5 * side_m
    rr = np.maximum(r, h)
    seg = rr * rr * np.arccos(np.clip(h / rr, -1.0, 1.0)) - h * np.sqrt(np.maximum(rr * rr - h * h, 0.0))
    a = np.where(r <= h, np.pi * r * r, np.pi * rr * rr - 4.0 * seg)
    return np.where(r >= h * math.sqrt(2.0), side_m * side_m, a)   # the four segments overlap beyond the corners


def _pow(x: np.ndarray, p: float) -> np.ndarray:
    """``x ** p`` per element through the C library's ``pow``, as NumPy's float64 *scalars* compute it.

    These weights were first computed one radius at a time (NumPy scalars, whose ``**`` calls
    ``pow``); NumPy's array loop for ``**`` may use another implementation (a SIMD one) that
    differs in the last bit.  Computing the powers this way keeps the vectorised weights, and
    every world read-out built on them, bit for bit what they were.
    """
    flat = np.ravel(x)
    return np.fromiter((math.pow(v, p) for v in flat.tolist()), float, flat.size).reshape(np.shape(x))


def _quadrant(X: float, Y: float, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Area and first moments (int x dA, int y dA) of {0<=x<=X, 0<=y<=Y, x^2+y^2<=r^2}, X, Y >= 0, per radius r > 0."""
    xm = np.minimum(X, r)
    xc = np.sqrt(np.maximum(r * r - Y * Y, 0.0))   # sqrt(r^2 - x^2) >= Y for x <= xc
    xa = np.minimum(xm, xc)

    def G(x):   # int sqrt(r^2 - x^2) dx
        return 0.5 * (x * np.sqrt(np.maximum(r * r - x * x, 0.0)) + r * r * np.arcsin(np.clip(x / r, -1.0, 1.0)))

    def H(x):   # -int x sqrt(r^2 - x^2) dx
        return _pow(np.maximum(r * r - x * x, 0.0), 1.5) / 3.0

    area = Y * xa + G(xm) - G(xa)
    mx = 0.5 * Y * xa * xa + H(xa) - H(xm)
    my = 0.5 * (Y * Y * xa + r * r * (xm - xa) - (_pow(xm, 3.0) - _pow(xa, 3.0)) / 3.0)
    return area, mx, my


@dataclass(frozen=True)
class SquareSensor:
    """An axis-aligned rectangular flux sensor, offset from the heater's axis, with a linear sensitivity map.

    The relative sensitivity is ``s = 1 + gradient_x (x - x_c) / side_x + gradient_y (y - y_c) / side_y``
    (mean 1 over the footprint; ``gradient_x`` is the edge-to-edge change along x).

    Attributes
    ----------
    side_x_m, side_y_m : float
        Sides (m); the shipped thermopile is 10 x 10 mm.
    offset_x_m, offset_y_m : float
        Centre's offset from the heater's axis (m).
    gradient_x, gradient_y : float
        Edge-to-edge relative change of the sensitivity along x and y (|g| < 2 keeps s > 0).
    """

    side_x_m: float = SENSOR_SIDE_m
    side_y_m: float = SENSOR_SIDE_m
    offset_x_m: float = 0.0
    offset_y_m: float = 0.0
    gradient_x: float = 0.0
    gradient_y: float = 0.0

    def __post_init__(self) -> None:
        for n in ("side_x_m", "side_y_m"):
            v = getattr(self, n)
            if not (v > 0 and math.isfinite(v)):
                raise ValueError(f"{n} must be finite and > 0, got {v!r}")
        for n in ("offset_x_m", "offset_y_m"):
            if not math.isfinite(getattr(self, n)):
                raise ValueError(f"{n} must be finite")
        if not (abs(self.gradient_x) + abs(self.gradient_y) < 2.0):
            raise ValueError("the sensitivity map must stay positive: |gradient_x| + |gradient_y| < 2")

    # -- geometry
    @property
    def area_m2(self) -> float:
        return self.side_x_m * self.side_y_m

    @property
    def bounds_m(self) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1) of the footprint, the heater's axis at the origin."""
        hx, hy = 0.5 * self.side_x_m, 0.5 * self.side_y_m
        return (self.offset_x_m - hx, self.offset_x_m + hx, self.offset_y_m - hy, self.offset_y_m + hy)

    @property
    def inner_radius_m(self) -> float:
        """Radius of the largest circle about the axis that lies wholly inside (0 if the axis is outside)."""
        x0, x1, y0, y1 = self.bounds_m
        if not (x0 < 0 < x1 and y0 < 0 < y1):
            return 0.0
        return min(-x0, x1, -y0, y1)

    @property
    def outer_radius_m(self) -> float:
        """Distance of the farthest corner from the axis (beyond it the weights vanish)."""
        x0, x1, y0, y1 = self.bounds_m
        return math.hypot(max(abs(x0), abs(x1)), max(abs(y0), abs(y1)))

    def sensitivity(self, x_m, y_m):
        """Relative sensitivity at (x, y) (1 on average over the footprint)."""
        return (1.0 + self.gradient_x * (np.asarray(x_m) - self.offset_x_m) / self.side_x_m
                + self.gradient_y * (np.asarray(y_m) - self.offset_y_m) / self.side_y_m)

    # -- exact weights
    def disk_moments(self, r_m: np.ndarray) -> np.ndarray:
        """Sensitivity-weighted area (m^2) of the footprint inside the disk of radius ``r`` (per r)."""
        x0, x1, y0, y1 = self.bounds_m
        r = np.atleast_1d(np.asarray(r_m, dtype=float))
        out = np.zeros(r.shape)
        c0 = 1.0 - self.gradient_x * self.offset_x_m / self.side_x_m - self.gradient_y * self.offset_y_m / self.side_y_m
        cx, cy = self.gradient_x / self.side_x_m, self.gradient_y / self.side_y_m
        pos = r > 0
        rp = r[pos]
        tot = np.zeros(rp.shape)
        # Signed quadrant decomposition: rect = S(x1,y1) - S(x0,y1) - S(x1,y0) + S(x0,y0).  All radii at once,
        # in the same order of operations as one radius at a time (the same numbers, bit for bit).
        for X, Y, sign in ((x1, y1, 1.0), (x0, y1, -1.0), (x1, y0, -1.0), (x0, y0, 1.0)):
            a, mx, my = _quadrant(abs(X), abs(Y), rp)
            sx, sy = math.copysign(1.0, X), math.copysign(1.0, Y)
            tot += sign * (c0 * sx * sy * a + cx * sy * mx + cy * sx * my)
        out[pos] = tot
        return out

    def ring_weights(self, r_faces_m: np.ndarray) -> np.ndarray:
        """Sensitivity-weighted area (m^2) of the footprint in each annulus between consecutive faces."""
        return np.diff(self.disk_moments(np.asarray(r_faces_m, dtype=float)))

    def circle_weight(self, r_m: float) -> float:
        """``w(r)``: the azimuthal integral of ``s r dtheta`` over the circle's arcs inside the footprint (m)."""
        r = float(r_m)
        if r <= 0:
            return 0.0
        x0, x1, y0, y1 = self.bounds_m
        cuts = [0.0, 2 * math.pi]
        for x in (x0, x1):
            if abs(x) < r:
                a = math.acos(x / r)
                cuts += [a, 2 * math.pi - a]
        for y in (y0, y1):
            if abs(y) < r:
                a = math.asin(y / r)
                cuts += [a % (2 * math.pi), (math.pi - a) % (2 * math.pi)]
        cuts = sorted(cuts)
        c0 = 1.0 - self.gradient_x * self.offset_x_m / self.side_x_m - self.gradient_y * self.offset_y_m / self.side_y_m
        cx, cy = self.gradient_x / self.side_x_m, self.gradient_y / self.side_y_m
        w = 0.0
        for a, b in zip(cuts[:-1], cuts[1:]):
            if b - a <= 0:
                continue
            m = 0.5 * (a + b)
            xm, ym = r * math.cos(m), r * math.sin(m)
            if x0 <= xm <= x1 and y0 <= ym <= y1:
                w += r * (c0 * (b - a) + cx * r * (math.sin(b) - math.sin(a)) - cy * r * (math.cos(b) - math.cos(a)))
        return w


def off_axis_weights(r_faces_m: np.ndarray, r_m: float) -> list[tuple[int, float]]:
    """(column, weight) pairs that read a cell-centred radial profile at radius ``r_m`` > 0 (the thermocouple).

    Linear in r^2 between the two columns whose mean r^2 brackets r^2 (the even profile T = a + b r^2
    locally; the first pair extrapolates inside the first cell's mean r^2, as the axis read-out does).
    """
    r = np.asarray(r_faces_m, dtype=float)
    rho = 0.5 * (r[1:] ** 2 + r[:-1] ** 2)
    x = float(r_m) ** 2
    if not 0.0 < x <= rho[-1]:
        raise ValueError(f"radius {r_m} m must be > 0 and inside the grid")
    i = int(min(max(np.searchsorted(rho, x) - 1, 0), rho.size - 2))
    f = (x - rho[i]) / (rho[i + 1] - rho[i])
    return [(i, 1.0 - f), (i + 1, f)]


def depth_weights(z_centres_m: np.ndarray, z_m: float) -> tuple[int, float]:
    """``(j, f)``: a value at depth ``z_m`` is ``(1 - f) v[j] + f v[j + 1]`` between cell centres (clamped)."""
    z = np.asarray(z_centres_m, dtype=float)
    if z.size < 2:
        raise ValueError("the sensing layer needs two rows to place the thermocouple inside it")
    j = int(min(max(np.searchsorted(z, z_m) - 1, 0), z.size - 2))
    return j, float(min(max((z_m - z[j]) / (z[j + 1] - z[j]), 0.0), 1.0))
