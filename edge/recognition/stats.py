"""Small statistics of the open-set test: chi-square tails and normal quantiles (NumPy has no erf).

One definition for the device's test (:meth:`edge.recognition.object_set.ObjectSet.classify`)
and for fitting ``z_crit`` on the host (host/recognition.py).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["tail_p", "chi2_sf", "z_of_p", "open_set_z", "p_crit_of"]

_ERFC = np.frompyfunc(math.erfc, 1, 1)


def tail_p(d2, dof) -> np.ndarray:
    """P(χ²_dof > d2), element-wise, for dof 1, 2 or 3 (arrays broadcast)."""
    d2 = np.maximum(np.asarray(d2, float), 0.0)
    dof = np.broadcast_to(np.asarray(dof, int), d2.shape)
    lo, hi = (int(dof.min()), int(dof.max())) if dof.size else (1, 1)   # the methods: np.any's wrapper cost a touch 10 us
    if lo < 1 or hi > 3:
        raise ValueError(f"dof must be 1, 2 or 3, got {np.unique(dof).tolist()}")
    # math.erfc element by element on Python floats: the values _ERFC gives, without its object array.
    p1 = np.array([math.erfc(v) for v in np.sqrt(d2 / 2.0).ravel().tolist()], float).reshape(d2.shape)
    if hi == 1:   # e alone (most touches): the other tails would be selected away
        return p1
    p3 = p1 + np.sqrt(2.0 * d2 / math.pi) * np.exp(-d2 / 2.0)
    return np.where(dof == 1, p1, np.where(dof == 2, np.exp(-d2 / 2.0), p3))


def chi2_sf(x: float, dof: int) -> float:
    """P(χ²_dof > x) for dof 1, 2 or 3 (the scalar :func:`tail_p`)."""
    return float(tail_p(x, dof))


def z_of_p(p) -> np.ndarray:
    """Element-wise |z| of a standard normal with two-sided tail probability ``p`` (bisection, to 1e-12)."""
    p = np.asarray(p, float)
    if p.ndim == 0:
        # One touch (classify): the same bisection on Python floats, the same values to the bit --
        # 60 rounds of NumPy calls on 0-d arrays were most of a classification's time.
        pv, lo_s, hi_s, r2 = float(p), 0.0, 40.0, math.sqrt(2.0)
        for _ in range(60):
            mid = 0.5 * (lo_s + hi_s)
            if math.erfc(mid / r2) > pv:
                lo_s = mid
            else:
                hi_s = mid
        return np.float64(0.5 * (lo_s + hi_s))
    lo, hi = np.zeros(p.shape), np.full(p.shape, 40.0)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        above = np.asarray(_ERFC(mid / math.sqrt(2.0)), float) > p
        lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
    return 0.5 * (lo + hi)


def open_set_z(d2, dof) -> np.ndarray:
    """The open-set test's statistic per touch: the 1-dof-equivalent |z| of the best-fitting object.

    ``d2`` (..., n) tempered squared distances and ``dof`` (..., n) from
    :meth:`~edge.recognition.object_set.ObjectSet.log_terms`: the largest chi-square p-value over the
    objects, as the |z| with that two-sided tail (``sqrt(d2)`` when the best
    object has e alone). One definition for the test (:meth:`~edge.recognition.object_set.ObjectSet.classify`)
    and for fitting ``z_crit`` on the host (a touch with α has two degrees of
    freedom: its distance is not compared with the 1-dof critical value).
    """
    p = tail_p(d2, dof).max(axis=-1)
    return z_of_p(p)


def p_crit_of(z_crit: float) -> float:
    """Two-sided tail probability of a standard normal beyond ``z_crit``."""
    return math.erfc(z_crit / math.sqrt(2.0))
