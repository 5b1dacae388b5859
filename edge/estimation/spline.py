"""Cubic-spline resampling in NumPy (paper section 4.2).

Instruments sample at their own rate; the estimators want the model's time
step.  :class:`CubicSpline` is the not-a-knot interpolating cubic (scipy's
default boundary condition), solved for the knot slopes with a tridiagonal
(Thomas) sweep, so it needs neither scipy nor a dense solve.
"""

from __future__ import annotations

import numpy as np

from edge.checks import finite_array, strictly_increasing


class CubicSpline:
    """Not-a-knot cubic spline through (x, y); ``y`` may be (n,) or (n, m).

    Parameters
    ----------
    x : (n,) strictly increasing abscissae, n >= 2.
    y : (n,) or (n, m) ordinates (several series share one spline solve).
    """

    def __init__(self, x, y) -> None:
        x = finite_array("x", x, min_len=2)
        strictly_increasing("x", x)
        y = np.asarray(y, dtype=np.float64)
        if y.shape[0] != x.size:
            raise ValueError(f"y has {y.shape[0]} rows but x has {x.size} points")
        if not np.all(np.isfinite(y)):
            raise ValueError("y contains NaN or inf")
        self._1d = y.ndim == 1
        y2 = y.reshape(x.size, -1)
        self.x, self.y = x, y2
        self.slopes = _not_a_knot_slopes(x, y2)

    def __call__(self, xi) -> np.ndarray:
        """Spline values at ``xi`` (extrapolates with the end polynomials)."""
        xi = np.asarray(xi, dtype=np.float64)
        x, y, s = self.x, self.y, self.slopes
        i = np.clip(np.searchsorted(x, xi, side="right") - 1, 0, x.size - 2)
        h = (x[i + 1] - x[i])[..., None]
        t = ((xi - x[i])[..., None]) / h
        y0, y1, s0, s1 = y[i], y[i + 1], s[i], s[i + 1]
        # Cubic Hermite basis on [x_i, x_{i+1}] with the solved slopes.
        t2, t3 = t * t, t * t * t
        out = (2 * t3 - 3 * t2 + 1) * y0 + (t3 - 2 * t2 + t) * h * s0 + (-2 * t3 + 3 * t2) * y1 + (t3 - t2) * h * s1
        return out[..., 0] if self._1d else out


def _thomas(lower: np.ndarray, diag: np.ndarray, upper: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve a tridiagonal system (lower[i] couples row i+1 to i) for (n, m) right-hand sides."""
    n = diag.size
    c = np.zeros(n)
    d = np.zeros_like(rhs)
    c[0] = upper[0] / diag[0] if n > 1 else 0.0
    d[0] = rhs[0] / diag[0]
    for i in range(1, n):
        m = diag[i] - lower[i - 1] * c[i - 1]
        if i < n - 1:
            c[i] = upper[i] / m
        d[i] = (rhs[i] - lower[i - 1] * d[i - 1]) / m
    for i in range(n - 2, -1, -1):
        d[i] -= c[i] * d[i + 1]
    return d


def _not_a_knot_slopes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    n = x.size
    dx = np.diff(x)
    slope = np.diff(y, axis=0) / dx[:, None]
    if n == 2:
        return np.vstack([slope[0], slope[0]])
    if n == 3:
        # Not-a-knot with three points is the interpolating parabola.
        a = (slope[1] - slope[0]) / (x[2] - x[0])
        b = slope[0] - a * (x[0] + x[1])
        return 2 * a * x[:, None] + b
    diag = np.empty(n)
    upper = np.empty(n - 1)
    lower = np.empty(n - 1)
    rhs = np.empty((n, y.shape[1]))
    diag[1:-1] = 2.0 * (dx[:-1] + dx[1:])
    upper[1:] = dx[:-1]
    lower[:-1] = dx[1:]
    rhs[1:-1] = 3.0 * (dx[1:, None] * slope[:-1] + dx[:-1, None] * slope[1:])
    # Not-a-knot: third derivative continuous at x[1] and x[-2].
    d0 = x[2] - x[0]
    diag[0] = dx[1]
    upper[0] = d0
    rhs[0] = ((dx[0] + 2 * d0) * dx[1] * slope[0] + dx[0] ** 2 * slope[1]) / d0
    dn = x[-1] - x[-3]
    diag[-1] = dx[-2]
    lower[-1] = dn
    rhs[-1] = (dx[-1] ** 2 * slope[-2] + (2 * dn + dx[-1]) * dx[-2] * slope[-1]) / dn
    return _thomas(lower, diag, upper, rhs)


def resample(t_s, series, t_new_s) -> np.ndarray:
    """Resample ``series`` ((n,) or (n, m)) from times ``t_s`` to ``t_new_s`` by cubic spline."""
    return CubicSpline(t_s, series)(t_new_s)
