"""Cubic-spline resampling in NumPy (paper section 4.2).

Instruments sample at their own rate; the estimators want the model's time
step.  :class:`CubicSpline` is the not-a-knot interpolating cubic (scipy's
default boundary condition), solved for the knot slopes by vectorised cyclic
reduction of the tridiagonal system, so it needs neither scipy nor a Python
loop per point.  :func:`resample` keeps the (linear) resampling operator of
small time bases (the daemon's grid) for the ones it meets again.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict

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


#: Systems up to this size are solved densely; larger ones are first halved by cyclic reduction.
_DENSE_MAX = 63


def _tridiagonal_solve(lower: np.ndarray, diag: np.ndarray, upper: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve a diagonally dominant tridiagonal system for (n, m) right-hand sides, without a loop per row.

    Row i reads ``lower[i] x[i-1] + diag[i] x[i] + upper[i] x[i+1] = rhs[i]``
    (``lower[0]`` and ``upper[-1]`` are ignored).  Cyclic reduction: each
    level eliminates the even rows from the odd ones with whole-array
    operations (log2(n) Python steps, O(n) work) until at most
    :data:`_DENSE_MAX` rows are left, which LAPACK solves densely.
    """
    n = diag.size
    size = n if n <= _DENSE_MAX else (1 << n.bit_length()) - 1  # 2^k - 1 halves to 2^(k-1) - 1
    # Negated off-diagonals; padding rows are decoupled (x = 0).
    A = np.zeros(size)
    B = np.ones(size)
    C = np.zeros(size)
    d = np.zeros((size, rhs.shape[1]))
    A[1:n] = -lower[1:n]
    B[:n] = diag
    C[:n - 1] = -upper[:n - 1]
    d[:n] = rhs
    levels = []
    while size > _DENSE_MAX:
        Ae, Ce, de = A[0::2], C[0::2], d[0::2]
        ib = 1.0 / B[0::2]
        fl = A[1::2] * ib[:-1]
        fr = C[1::2] * ib[1:]
        levels.append((Ae, Ce, de, ib))
        B = B[1::2] - fl * Ce[:-1] - fr * Ae[1:]
        d = d[1::2] + fl[:, None] * de[:-1] + fr[:, None] * de[1:]
        A = fl * Ae[:-1]
        C = fr * Ce[1:]
        size = B.size
    M = np.diag(B)
    i = np.arange(size - 1)
    M[i + 1, i] = -A[1:]
    M[i, i + 1] = -C[:-1]
    x = np.linalg.solve(M, d)
    for Ae, Ce, de, ib in reversed(levels):
        xe = de.copy()
        xe[1:] += Ae[1:, None] * x
        xe[:-1] += Ce[:-1, None] * x
        xe *= ib[:, None]
        full = np.empty((xe.shape[0] + x.shape[0], x.shape[1]))
        full[0::2] = xe
        full[1::2] = x
        x = full
    return x[:n]


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
    # The not-a-knot rows are not diagonally dominant: subtract them from their
    # neighbours (row 0's coefficients equal row 1's first two: dx[1] and
    # upper[0] = d0 = dx[0] + dx[1]; likewise at the end), solve the dominant
    # system for slopes 1 .. n-2, then recover the two end slopes.
    lo, di, up = lower[:-1].copy(), diag[1:-1].copy(), upper[1:].copy()  # rows 1 .. n-2
    r = rhs[1:-1].copy()
    di[0] -= upper[0]
    r[0] -= rhs[0]
    di[-1] -= lower[-1]
    r[-1] -= rhs[-1]
    # row i (1-based in the full system) couples to i-1 through lower[i-1].
    inner = _tridiagonal_solve(np.concatenate(([0.0], lo[1:])), di, np.concatenate((up[:-1], [0.0])), r)
    s = np.empty((n, y.shape[1]))
    s[1:-1] = inner
    s[0] = (rhs[0] - upper[0] * inner[0]) / diag[0]
    s[-1] = (rhs[-1] - lower[-1] * inner[-1]) / diag[-1]
    return s


#: Largest resampling operator kept, in entries (targets x knots): 2^17 doubles = 1 MiB.
_OPERATOR_MAX = 1 << 17
#: Most knots of a resampling operator: up to here building W costs about one direct solve (more
#: knots would make every new time base -- a jittered record, each calibration touch -- pay n^2).
_OPERATOR_KNOTS = 64
#: Resampling operators kept (least recently used dropped).
_OPERATORS_KEPT = 8
_operators: OrderedDict = OrderedDict()
_cache_lock = threading.Lock()


def _operator_key(x: np.ndarray, xi: np.ndarray) -> tuple:
    h = hashlib.blake2b(digest_size=16)
    h.update(x.tobytes())
    h.update(xi.tobytes())
    return x.size, xi.size, h.digest()


def resampling_operator(t_s, t_new_s) -> np.ndarray:
    """The matrix W with ``resample(t_s, y, t_new_s) == W @ y`` for every y (the spline is linear in y)."""
    x = np.asarray(t_s, dtype=np.float64)
    return CubicSpline(x, np.eye(x.size))(np.asarray(t_new_s, dtype=np.float64))


def resample(t_s, series, t_new_s) -> np.ndarray:
    """Resample ``series`` ((n,) or (n, m)) from times ``t_s`` to ``t_new_s`` by cubic spline.

    For fixed knots and targets resampling is a linear operator W.  Where W
    costs about one direct solve to build (at most :data:`_OPERATOR_KNOTS`
    knots and :data:`_OPERATOR_MAX` entries: the daemon's measurement grid,
    an instrument's fixed sample times) a series is always resampled as
    ``W @ y``, W kept for the time bases met most recently; otherwise always
    directly.  Which of the two is decided by the sizes alone, never by what
    the cache holds: the two round differently in the last bits, and one record
    must give the same answer bit for bit in a warm daemon and in a fresh
    ``thermotouch estimate``.
    """
    x = np.asarray(t_s, dtype=np.float64)
    xi = np.asarray(t_new_s, dtype=np.float64)
    y = np.asarray(series, dtype=np.float64)
    if not (x.ndim == 1 and xi.ndim == 1 and y.ndim in (1, 2) and 2 <= x.size <= _OPERATOR_KNOTS
            and x.size * xi.size <= _OPERATOR_MAX):
        return CubicSpline(x, y)(xi)
    key = _operator_key(x, xi)
    with _cache_lock:
        W = _operators.get(key)
        if W is not None:
            _operators.move_to_end(key)
    if W is None:
        W = resampling_operator(x, xi)  # validates x
        W.flags.writeable = False
        with _cache_lock:
            _operators[key] = W
            while len(_operators) > _OPERATORS_KEPT:
                _operators.popitem(last=False)
    if y.shape[0] != x.size:
        raise ValueError(f"y has {y.shape[0]} rows but x has {x.size} points")
    if not np.all(np.isfinite(y)):
        raise ValueError("y contains NaN or inf")
    return W @ y
