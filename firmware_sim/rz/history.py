"""Read-outs of the faithful world's step history at arbitrary times (:class:`~firmware_sim.rz.probe_world.FaithfulWorld`).

The world records its outputs at every step end; a read-out between two records is the linear
interpolation of each quantity, and the thermocouple's bead lag ``tau y' + y = T`` is solved
exactly on that piecewise-linear temperature.  A chip converts one sample at a time, so the
one-time read-out (:func:`_interpolate_one`) works on scalars: the same IEEE operations on the
same numbers as the array path (:func:`interpolate`, which the series and truth read-outs use),
so the same bits, for a tenth of the cost of small-array calls.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["interpolate"]


def interpolate(h: dict[str, np.ndarray], n: int, ts: np.ndarray, names: Sequence[str],
                tau_s: float) -> dict[str, np.ndarray]:
    """Quantities ``names`` and the lagged thermocouple ``"y"`` at times ``ts`` (s) from ``n`` records.

    Parameters
    ----------
    h : dict of ndarray
        The history: ``"t"`` (record times, non-decreasing), ``"T_tc"``, ``"y"`` and every
        quantity of ``names``, of which the first ``n`` entries are valid.
    n : int
        Number of records (>= 1).
    ts : ndarray
        Read-out times (s, >= 0).
    names : sequence of str
        Quantities interpolated linearly.
    tau_s : float
        The thermocouple bead's time constant (<= 0: no lag).

    Returns
    -------
    dict of ndarray
        One array the shape of ``ts`` per name, and ``"y"``.
    """
    if ts.size == 1:
        return _interpolate_one(h, n, ts, names, tau_s)
    t = h["t"][:n]
    i = np.clip(np.searchsorted(t, ts, side="right") - 1, 0, n - 1)
    j = np.minimum(i + 1, n - 1)
    span = t[j] - t[i]
    w = np.where(span > 0, (ts - t[i]) / np.where(span > 0, span, 1.0), 0.0)
    out = {name: h[name][:n][i] + w * (h[name][:n][j] - h[name][:n][i]) for name in names}
    # The lag, exactly on the piecewise-linear temperature.
    T0, T1 = h["T_tc"][:n][i], h["T_tc"][:n][j]
    y0 = h["y"][:n][i]
    if tau_s > 0:
        dt = ts - t[i]
        m = np.where(span > 0, (T1 - T0) / np.where(span > 0, span, 1.0), 0.0)
        Tt = T0 + m * dt
        out["y"] = Tt - m * tau_s + (y0 - T0 + m * tau_s) * np.exp(-dt / tau_s)
    else:
        out["y"] = T0 + w * (T1 - T0)
    return out


def _interpolate_one(h: dict[str, np.ndarray], n: int, ts: np.ndarray, names: Sequence[str],
                     tau_s: float) -> dict[str, np.ndarray]:
    """:func:`interpolate` at one time, on float64 scalars (each step as the array path's)."""
    shape = ts.shape
    x = ts.reshape(-1)[0]
    t = h["t"]
    i = min(max(int(t[:n].searchsorted(x, side="right")) - 1, 0), n - 1)
    j = min(i + 1, n - 1)
    ti = t[i]
    span = t[j] - ti
    pos = span > 0
    w = (x - ti) / span if pos else np.float64(0.0)
    out = {}
    for name in names:
        a = h[name]
        vi = a[i]
        out[name] = np.full(shape, vi + w * (a[j] - vi))
    T_tc = h["T_tc"]
    T0, T1 = T_tc[i], T_tc[j]
    if tau_s > 0:
        dt = x - ti
        m = (T1 - T0) / span if pos else np.float64(0.0)
        Tt = T0 + m * dt
        # np.exp on an array, as the array path calls it (the same loop, the same bits).
        decay = np.exp(np.full(shape, -dt / tau_s))
        out["y"] = Tt - m * tau_s + (h["y"][i] - T0 + m * tau_s) * decay
    else:
        out["y"] = np.full(shape, T0 + w * (T1 - T0))
    return out
