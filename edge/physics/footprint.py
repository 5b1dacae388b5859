"""The flux sensor's real footprint in the Hankel read-out: a rectangle, offset from the heater's axis.

Under an axisymmetric field ``q(r) = int_0^inf Q(zeta) J0(zeta r) zeta d zeta`` a sensor of
footprint ``S`` (area ``A``, uniform sensitivity) reads the area mean

    q_read = int_0^inf Q(zeta) W(zeta) zeta d zeta,    W(zeta) = (1/A) int_S J0(zeta |x|) dA.

For the equal-area disk of radius b centred on the axis ``W = 2 J1(zeta b) / (zeta b)``
(:class:`edge.physics.axisym.AxisymModel`'s former read-out).  For the real rectangle
(half-sides ``hx``, ``hy``, centre ``(cx, cy)``) the plane-wave form of J0,
``J0(zeta |x|) = (1/2pi) int_0^2pi exp(i zeta (x cos th + y sin th)) d th``, makes the area
integral separable, each side's in closed form:

    W(zeta) = (1/2pi) int_0^2pi cos(zeta (cx cos th + cy sin th)) sinc(zeta hx cos th) sinc(zeta hy sin th) d th

(``sinc u = sin u / u``; the sine part cancels between th and th + pi).  The integrand is periodic and
entire in th, so the trapezoid rule converges geometrically once its points exceed the
integrand's bandwidth ``zeta R`` (R: the farthest corner's distance from the axis) by the margin :func:`edge.physics.bessel.bessel_j`
uses: ~1e-16 (it was a Gauss-Legendre sum over r of J1(zeta r) times the area ``A(r)`` inside the
disk of radius r, good to ~1e-10 and 30 times slower: a drawn probe's every footprint, and each of
a calibration's model-form trials, builds one).  :func:`area_in_disk` (that ``A(r)``, exact) stays
for the tests.  The world computes its read-out independently (``firmware_sim.rz.footprint``: the
quadrant decomposition on its finite-volume rings); a test compares the two.

Why it matters: the small heater's 10 x 10 mm square has its edge on the heater's edge (5 mm),
where the flux changes fastest; its equal-area disk (5.64 mm) moves the read-out by per cents
and k and alpha by tens of per cent (issue #34).  NumPy only.
"""

from __future__ import annotations

import math

import numpy as np

from edge.physics.bessel import trapezoid_points

__all__ = ["area_in_disk", "rectangle_weights"]


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


#: Hankel variables per block of :func:`rectangle_weights` (each block takes the points its largest needs).
_BLOCK = 64


def rectangle_weights(zeta, side_x_m: float, side_y_m: float, offset_x_m: float = 0.0,
                      offset_y_m: float = 0.0) -> np.ndarray:
    """``W(zeta)``: the area mean of ``J0(zeta |x|)`` over the rectangle (see the module docstring).

    Parameters
    ----------
    zeta : array_like
        Hankel variables (1/m), >= 0.
    side_x_m, side_y_m : float
        The rectangle's sides (m).
    offset_x_m, offset_y_m : float
        Its centre's offset from the heater's axis (m).

    Notes
    -----
    The zeta are taken in blocks by increasing ``|zeta|``, each with the trapezoid points its own
    largest needs (:func:`edge.physics.bessel.trapezoid_points` of ``X = |zeta| R``, R the farthest
    corner's distance): within 1e-15 (round-off) of the rule with 200 more points
    (``tests/edge/physics/test_footprint.py``).
    """
    z = np.asarray(zeta, dtype=float)
    if not (side_x_m > 0 and side_y_m > 0):
        raise ValueError("sides must be > 0")
    hx, hy = 0.5 * float(side_x_m), 0.5 * float(side_y_m)
    cx, cy = float(offset_x_m), float(offset_y_m)
    # The integrand's bandwidth in th, per unit zeta: the farthest corner's distance R (a point at distance rho
    # contributes the harmonics J_n(zeta rho) exp(i n th), negligible beyond n ~ zeta rho).
    reach = math.hypot(abs(cx) + hx, abs(cy) + hy)
    flat = z.reshape(-1)
    order = np.argsort(np.abs(flat), kind="stable")
    zs = flat[order]
    res = np.empty(flat.size)
    for i in range(0, zs.size, _BLOCK):
        zb = zs[i:i + _BLOCK, None]
        x = float(np.max(np.abs(zb))) * reach
        m = trapezoid_points(x)
        th = 2.0 * np.pi * (np.arange(m) + 0.5) / m
        kx, ky = zb * np.cos(th), zb * np.sin(th)
        # np.sinc is sin(pi u) / (pi u), finite at 0.
        f = np.cos(kx * cx + ky * cy) * np.sinc(kx * (hx / np.pi)) * np.sinc(ky * (hy / np.pi))
        res[i:i + _BLOCK] = np.mean(f, axis=1)
    out = np.empty(flat.size)
    out[order] = res
    return out.reshape(z.shape)
