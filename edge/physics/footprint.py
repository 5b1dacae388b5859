"""The flux sensor's real footprint in the Hankel read-out: a rectangle, offset from the heater's axis.

Under an axisymmetric field ``q(r) = int_0^inf Q(zeta) J0(zeta r) zeta d zeta`` a sensor of
footprint ``S`` (area ``A``, uniform sensitivity) reads the area mean

    q_read = int_0^inf Q(zeta) W(zeta) zeta d zeta,    W(zeta) = (1/A) int_S J0(zeta |x|) dA.

For the equal-area disk of radius b centred on the axis ``W = 2 J1(zeta b) / (zeta b)``
(:class:`edge.physics.axisym.AxisymModel`'s former read-out).  For the real square it is computed
here from the area ``A(r)`` of the footprint inside the disk of radius r about the axis:
``int_S J0(zeta |x|) dA = int_0^R J0(zeta r) A'(r) dr``, integrated by parts (J0' = -J1)

    W(zeta) = J0(zeta R) + (zeta / A) int_0^R J1(zeta r) A(r) dr,

R the footprint's farthest corner.  ``A(r)`` is exact (:func:`area_in_disk`: per r, the
footprint's chord lengths integrated in x between the points where the circle crosses the
rectangle's sides, with the closed form of ``int sqrt(r^2 - x^2) dx``); ``A`` is C1 in r, so
Gauss-Legendre panels between its breakpoints (the distances to the sides and to the corners) with
a cosine clustering at both ends of each panel (``A''`` has inverse-square-root spikes where the
circle touches a side) converge fast.  The world computes its read-out independently
(``firmware_sim.rz.footprint``: the quadrant decomposition on its finite-volume rings); a test
compares the two.

Why it matters: the small heater's 10 x 10 mm square has its edge on the heater's edge (5 mm),
where the flux changes fastest; its equal-area disk (5.64 mm) moves the read-out by per cents
and k and alpha by tens of per cent (issue #34).  NumPy only.
"""

from __future__ import annotations

import math

import numpy as np

from edge.physics.bessel import bessel_j

__all__ = ["area_in_disk", "rectangle_weights", "breakpoints"]


def _chord_integral(r: float, a: float, b: float) -> float:
    """``int_a^b sqrt(r^2 - x^2) dx`` for -r <= a <= b <= r."""
    def G(x: float) -> float:
        x = min(max(x, -r), r)
        return 0.5 * (x * math.sqrt(max(r * r - x * x, 0.0)) + r * r * math.asin(x / r))
    return G(b) - G(a)


def area_in_disk(r_m, bounds_m: tuple[float, float, float, float]) -> np.ndarray:
    """Area (m^2) of the rectangle ``(x0, x1, y0, y1)`` inside the disk of radius ``r`` about the origin.

    Per r: ``int_{x0}^{x1} |[y0, y1] ∩ [-s(x), s(x)]| dx`` with ``s = sqrt(r^2 - x^2)``; between
    consecutive crossing abscissae the clipped chord is one of ``0``, ``y1 - y0``, ``y1 + s``,
    ``s - y0`` or ``2 s``, each integrated in closed form.
    """
    x0, x1, y0, y1 = (float(v) for v in bounds_m)
    rr = np.atleast_1d(np.asarray(r_m, dtype=float))
    out = np.zeros(rr.shape)
    for n, r in enumerate(rr):
        if r <= 0:
            continue
        lo, hi = max(x0, -r), min(x1, r)
        if hi <= lo:
            continue
        cuts = {lo, hi}
        for y in (y0, y1):
            if abs(y) < r:
                c = math.sqrt(r * r - y * y)
                cuts.update(v for v in (-c, c) if lo < v < hi)
        xs = sorted(cuts)
        tot = 0.0
        for a, b in zip(xs[:-1], xs[1:]):
            m = 0.5 * (a + b)
            s = math.sqrt(max(r * r - m * m, 0.0))
            top_is_circle, bot_is_circle = s < y1, -s > y0
            if min(y1, s) <= max(y0, -s):
                continue                            # the chord misses [y0, y1] on this piece
            # chord = min(y1, s) - max(y0, -s), the s-parts integrated exactly
            n_s = int(top_is_circle) + int(bot_is_circle)
            const = (0.0 if top_is_circle else y1) - (0.0 if bot_is_circle else y0)
            tot += const * (b - a) + n_s * _chord_integral(r, a, b)
        out[n] = tot
    return out


def breakpoints(bounds_m: tuple[float, float, float, float]) -> list[float]:
    """Radii where ``A(r)`` changes form: the distances to the sides (where the axis projects onto them)
    and to the corners."""
    x0, x1, y0, y1 = bounds_m
    pts = {0.0}
    for x in (x0, x1):
        if y0 <= 0.0 <= y1:
            pts.add(abs(x))
        for y in (y0, y1):
            pts.add(math.hypot(x, y))
    for y in (y0, y1):
        if x0 <= 0.0 <= x1:
            pts.add(abs(y))
    return sorted(p for p in pts if p >= 0.0)


def rectangle_weights(zeta, side_x_m: float, side_y_m: float, offset_x_m: float = 0.0,
                      offset_y_m: float = 0.0, *, per_panel: int | None = None) -> np.ndarray:
    """``W(zeta)``: the area mean of ``J0(zeta |x|)`` over the rectangle (see the module docstring).

    Parameters
    ----------
    zeta : array_like
        Hankel variables (1/m), >= 0.
    side_x_m, side_y_m : float
        The rectangle's sides (m).
    offset_x_m, offset_y_m : float
        Its centre's offset from the heater's axis (m).
    per_panel : int, optional
        Gauss-Legendre points per panel (default: enough for the fastest ``zeta`` given, ~8 per
        half-period of J1 and at least 24).
    """
    z = np.asarray(zeta, dtype=float)
    if not (side_x_m > 0 and side_y_m > 0):
        raise ValueError("sides must be > 0")
    hx, hy = 0.5 * side_x_m, 0.5 * side_y_m
    bounds = (offset_x_m - hx, offset_x_m + hx, offset_y_m - hy, offset_y_m + hy)
    A = side_x_m * side_y_m
    br = breakpoints(bounds)
    R = br[-1]
    zmax = float(np.max(np.abs(z))) if z.size else 0.0
    u, wu = np.polynomial.legendre.leggauss(8)
    r_nodes, r_w = [], []
    for a, b in zip(br[:-1], br[1:]):
        if b - a <= 1e-15:
            continue
        # Sub-panels of at most half a period of J1(zeta_max r), each with a cosine map clustering
        # its nodes at both ends (the tangent points' square-root behaviour of A'').
        n_sub = max(3, int(math.ceil(zmax * (b - a) / math.pi)) + 1) if per_panel is None else per_panel
        edges = a + (b - a) * 0.5 * (1.0 - np.cos(np.pi * np.arange(n_sub + 1) / n_sub))
        lo, hi = edges[:-1, None], edges[1:, None]
        r_nodes.append((0.5 * (hi - lo) * u[None, :] + 0.5 * (hi + lo)).ravel())
        r_w.append((0.5 * (hi - lo) * wu[None, :]).ravel())
    r = np.concatenate(r_nodes)
    w = np.concatenate(r_w)
    Ar = area_in_disk(r, bounds)
    J1 = bessel_j(1, z[:, None] * r[None, :])
    return bessel_j(0, z * R) + z / A * (J1 @ (w * Ar))
