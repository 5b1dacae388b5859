"""Bessel functions J0 and J1 of real argument, NumPy only (the device has no SciPy).

Used by the axisymmetric model's Hankel read-outs (:mod:`edge.physics.axisym`) and the sensor
footprint's weights (:mod:`edge.physics.footprint`).
"""

from __future__ import annotations

import numpy as np

from edge.physics.memo import BoundedMemo

__all__ = ["bessel_j", "trapezoid_points"]

#: Values already computed, by order and the arguments' exact bytes.  The same arguments come back: every
#: axisymmetric model on a probe's Hankel nodes (a calibration's finite differences build dozens, one per
#: sensing layer) asks for its heater disk's and thermocouple's J_n(zeta a) on the same nodes.
_MEMO = BoundedMemo(64)
#: Arguments larger than this are not kept (a footprint's (nodes x rings) table: computed once per footprint).
_MEMO_MAX_SIZE = 8192


def trapezoid_points(x_max: float) -> int:
    """Trapezoid points over a period for ``exp(i x sin tau)``-type integrands up to bandwidth ``x_max``.

    ``x_max + 10 x_max^(1/3) + 48``: past the Airy transition of the aliased ``J_m(x)``, so the rule is
    good to round-off (~1e-15).  Shared by :func:`bessel_j` and :func:`edge.physics.footprint.rectangle_weights`.
    """
    return int(x_max + 10.0 * x_max ** (1.0 / 3.0)) + 48


def bessel_j(n: int, x: np.ndarray) -> np.ndarray:
    """Bessel function J_n(x), n = 0 or 1, for real x (NumPy only).

    From ``J_n(x) = (1/2pi) int_0^2pi cos(n tau - x sin tau) d tau`` with the
    trapezoid rule, which converges geometrically for a periodic integrand once
    the number of points m exceeds |x| + n by a margin (here |x| + 10 |x|^(1/3) + 48,
    past the Airy transition of the aliased J_m(x)): errors ~1e-15.

    The rule's nodes are the midpoints ``tau_j = 2 pi (j + 1/2) / m`` with m = 4 K: the
    integrand's symmetries under ``tau -> pi - tau`` and ``tau -> tau + pi`` fold the m
    points onto the K in the first quadrant (J0: ``cos(x sin tau)``; J1: its odd part
    ``sin(tau) sin(x sin tau)``, the ``cos(tau) cos(x sin tau)`` part cancels in pairs), the
    same sum at a quarter of the cost.  The x are taken in blocks by increasing |x|, each
    with the m its own largest |x| needs: a model's set-up evaluates thousands of
    arguments from 0 to ~1e3, and most need far fewer points than the largest.
    """
    if n not in (0, 1):
        raise ValueError(f"n must be 0 or 1, got {n}")
    x = np.asarray(x, dtype=float)
    if x.size > _MEMO_MAX_SIZE:
        return _bessel_j(n, x)
    hit = _MEMO((n, x.shape, x.tobytes()), lambda: _bessel_j(n, x))
    return hit.copy()


def _bessel_j(n: int, x: np.ndarray) -> np.ndarray:
    """:func:`bessel_j`, computed (``x`` a float array)."""
    flat = x.reshape(-1)
    order = np.argsort(np.abs(flat), kind="stable")
    xs = flat[order]
    res = np.empty(flat.size)
    block = 256  # keeps the (x, tau) table at most ~2e5 entries for |x| ~ 3e3
    for i in range(0, xs.size, block):
        xb = xs[i:i + block]
        xm = float(np.max(np.abs(xb)))
        m = trapezoid_points(xm)
        k = -(-m // 4)  # quadrant points; 4 k >= m
        sin_tau = np.sin(0.5 * np.pi * (np.arange(k) + 0.5) / k)
        arg = xb[:, None] * sin_tau[None, :]
        if n == 0:
            res[i:i + block] = np.mean(np.cos(arg), axis=1)
        else:
            res[i:i + block] = np.mean(sin_tau[None, :] * np.sin(arg), axis=1)
    out = np.empty(flat.size)
    out[order] = res
    return out.reshape(x.shape)
