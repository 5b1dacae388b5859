"""A touch's conditioning before any estimator: baseline, quality flags, the uniform grid.

Pure functions on a raw record (no hardware, no state), used by the one
estimate path (:func:`edge.estimation.seam.estimate_touch`) -- so the device
and ``thermotouch estimate`` on an exported record condition a touch alike --
and by the running decisions:

* :func:`baseline` -- which samples are the pre-contact baseline, T0 and the flux offset;
* :func:`contact_effusivity` -- the effusivity of whatever the face touched (``no_contact``);
* :func:`quality_flags` -- ``no_contact``, ``saturated``, ``noisy``, ``unstable_baseline``;
* :func:`resample_uniform` -- the heating phase on the estimator's uniform grid.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from edge.estimation.spline import resample
from edge.status import Flag

__all__ = ["baseline_mask", "resample_uniform", "quality_flags", "contact_effusivity", "duhamel_m"]

_TWO_OVER_SQRT_PI = 2.0 / math.sqrt(math.pi)


def duhamel_m(t_eval: float, t_q: np.ndarray, q: np.ndarray) -> float:
    """``m(t_eval)`` for a flux that is 0 before t = 0 and piecewise constant between its samples.

    Over ``(t_q[j-1], t_q[j]]`` the flux is the mean of the two samples (the
    first interval, from heater-on at 0, takes ``q[0]``: the flux jumps at
    switch-on); past the last sample it holds ``q[-1]``. Samples after
    ``t_eval`` are ignored and the interval that contains it is cut there.
    """
    if t_eval <= 0 or t_q.size == 0:
        return 0.0
    b = np.asarray(t_q, float)
    q = np.asarray(q, float)
    q_last = q[-1]
    q = np.concatenate((q[:1], 0.5 * (q[1:] + q[:-1])))
    a = np.concatenate(([0.0], b[:-1]))
    a = np.minimum(a, t_eval)
    b = np.minimum(b, t_eval)
    # The last sample's value also holds up to t_eval when t_eval is past it.
    if t_eval > b[-1]:
        a = np.append(a, b[-1])
        b = np.append(b, t_eval)
        q = np.append(q, q_last)
    return float(_TWO_OVER_SQRT_PI * np.sum(q * (np.sqrt(t_eval - a) - np.sqrt(t_eval - b))))


#: Rows x columns of one block of :func:`_duhamel_m_at` (bounds its memory on a long record: ~2 MB).
_BLOCK_ELEMENTS = 1 << 18


def _duhamel_m_at(t_eval: np.ndarray, t_q: np.ndarray, q: np.ndarray) -> np.ndarray:
    """:func:`duhamel_m` at each of ``t_eval`` (all > 0 and none past ``t_q[-1]``), the same numbers.

    One row of intervals per time, a block of rows at a time: the same element-wise terms, and each
    row's sum is NumPy's pairwise sum over the same values, as the 1-D call's (a Python loop of
    :func:`duhamel_m` calls was most of :func:`contact_effusivity`'s cost, twice per touch).
    """
    b = np.asarray(t_q, float)
    q = np.asarray(q, float)
    q = np.concatenate((q[:1], 0.5 * (q[1:] + q[:-1])))
    a = np.concatenate(([0.0], b[:-1]))
    out = np.empty(t_eval.size)
    step = max(1, _BLOCK_ELEMENTS // max(1, b.size))
    for i in range(0, t_eval.size, step):
        x = t_eval[i:i + step, None]
        out[i:i + step] = np.sum(q * (np.sqrt(x - np.minimum(a, x)) - np.sqrt(x - np.minimum(b, x))), axis=1)
    return _TWO_OVER_SQRT_PI * out


def baseline_mask(t_s: np.ndarray, heated: bool, arm_s: float, baseline_s: float) -> np.ndarray:
    """The samples that make the baseline: before heater-on (all when the heater never went on).

    Armed runs (``arm_s > 0``): only the last ``baseline_s`` before heating -- the earlier samples are
    the probe in air and the contact's transient (the sensor chain uses them all).
    """
    t = np.asarray(t_s, float)
    base = t < 0 if heated else np.ones(t.shape, bool)
    if arm_s > 0 and heated:
        base = base & (t >= -baseline_s)
    return base


def resample_uniform(t_s: np.ndarray, T_C: np.ndarray, q_W_m2: np.ndarray, T0_C: float, q_offset_W_m2: float,
                     rate_Hz: float, t_end_s: float, T_age_s: float = 0.0, *, T_dt_s: np.ndarray | None = None,
                     q_dt_s: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heating-phase series on the grid ``k / rate_Hz``, k = 1 .. floor(t_end * rate).

    ``t_s`` is time since heater-on; samples with ``t_s < 0`` (baseline) are
    ignored. The temperature rise is anchored at ``(0, 0)`` (temperature is
    continuous at switch-on; flux is not, so it is not anchored).  Temperature
    readings are placed ``T_age_s`` before they were read (the converter's
    sampling lag), which would otherwise bias e upwards by several percent.

    Parameters
    ----------
    t_s, T_C, q_W_m2 : ndarray
        The raw series: time since heater-on (s), thermocouple (°C), flux (W/m^2).
    T0_C, q_offset_W_m2 : float
        Baseline temperature and flux offset, subtracted.
    rate_Hz : float
        Grid rate.
    t_end_s : float
        Heating duration (s); the grid never runs past it nor past the data.
    T_age_s : float
        Mean age of a temperature reading when read (s).
    T_dt_s, q_dt_s : ndarray, optional
        Each sample's thermocouple and flux read time relative to ``t_s`` (s;
        :attr:`edge.measure.sensors.Reading.T_dt_s`): the sensors are read one
        after the other, and the small-heater probe's fit turns a 1.5-ms skew
        between the two records into several per cent on k and alpha.  The
        grid still starts at heater-on (``t_s = 0``).

    Returns
    -------
    t_s, dT_K, q_W_m2 : ndarray
        The grid and the series on it, flux offset removed.
    """
    t_s = np.asarray(t_s, float)
    heat = t_s >= 0
    th, Th, qh = t_s[heat], np.asarray(T_C, float)[heat], np.asarray(q_W_m2, float)[heat]
    if th.size < 2:
        raise ValueError(f"need at least 2 heating samples to resample, got {th.size}")
    tT = th - T_age_s
    if T_dt_s is not None:
        tT = tT + np.asarray(T_dt_s, float)[heat]
    if q_dt_s is not None:
        th = th + np.asarray(q_dt_s, float)[heat]
    dT = Th - T0_C
    keep = tT > 0  # a reading taken before heater-on belongs to the baseline
    tT, dT = tT[keep], dT[keep]
    if tT.size < 1:
        raise ValueError("no temperature reading taken after heater-on")
    tT, dT = np.concatenate(([0.0], tT)), np.concatenate(([0.0], dT))
    n = int(math.floor(t_end_s * rate_Hz + 1e-9))
    grid = np.arange(1, n + 1) / rate_Hz
    grid = grid[grid <= min(th[-1], tT[-1]) + 1e-9]  # interpolate, never extrapolate
    if grid.size < 2:
        raise ValueError("heating phase too short for the sample rate")
    dT_grid = resample(tT, dT, grid)
    q_grid = resample(th, qh - q_offset_W_m2, np.maximum(grid, th[0]))
    return grid, dT_grid, q_grid


def contact_effusivity(t_s: np.ndarray, dT_K: np.ndarray, q_W_m2: np.ndarray, T_age_s: float = 0.0,
                       min_rise_K: float = 0.0) -> float | None:
    """The effusivity of whatever the probe's face touched, from the heating record alone (W s^0.5/(m^2 K)).

    Whatever lies under the sensor -- a solid, or air -- obeys Duhamel's
    relation between the flux into it and its surface temperature rise,
    ``m(t) = e dT(t)`` with ``m`` the flux's half-integral
    (:func:`duhamel_m`). So ``e`` of the contact is
    the least-squares slope of m on dT (through the origin: both are zero at
    heater-on). In air almost all the heater's power stays in the probe: the
    temperature climbs fastest and the flux is near zero, so this gives
    still air's ~5.5 (or less: noise); on the lightest foam ~28, on
    cardboard ~120, PMMA ~570, metals thousands -- whatever the power and the
    contact time (the ratio does not depend on either), unlike a flux
    threshold on a fraction of P/A, which a poor conductor never reaches in
    a short touch.

    Returns None when the rise (mean over the last third of the record) is
    not above ``min_rise_K`` (pass two thermometer steps): no rise to judge
    by -- a metal at a power below a step, where rounding makes the slope
    anything, or no heat, which :func:`no_heat_while_on` judges. In air the
    rise is the largest any touch gives (all of P/A into the probe's own
    heat capacity), so a probe in air with an unresolved rise would not be
    told from a metal by any record.
    """
    t = np.asarray(t_s, float)
    dT, q = np.asarray(dT_K, float), np.asarray(q_W_m2, float)
    keep = t > 0
    t, dT, q = t[keep], dT[keep], q[keep]
    tT = t - T_age_s
    ok = tT > 0
    if not ok.any():
        return None
    x = tT[ok]
    m = _duhamel_m_at(x, t, q) if float(x.max()) <= float(t[-1]) else np.array([duhamel_m(v, t, q) for v in x])
    d = dT[ok]
    s_dd = float(d @ d)
    if not s_dd > 0 or float(np.mean(d[-max(1, d.size // 3):])) <= min_rise_K:
        return None
    return float(m @ d) / s_dd


def quality_flags(base_t: np.ndarray, base_T: np.ndarray, base_q: np.ndarray, heat_q: np.ndarray,
                  contact_e: float | None, saturated: bool, thresholds: Any) -> list[Flag]:
    """Flags from the baseline and heating series (see the ``[measurement]`` thresholds).

    Parameters
    ----------
    base_t, base_T, base_q : ndarray
        Baseline times (s), thermocouple (°C) and flux (W/m^2).
    heat_q : ndarray
        Heating-phase flux with the baseline offset removed (W/m^2).
    contact_e : float or None
        :func:`contact_effusivity` of the heating record; ``no_contact`` when it is
        below ``thresholds.no_contact_e_W_s05_m2K`` (None: not judged).
    saturated : bool
        Whether any reading clipped.
    thresholds : namespace
        The ``[measurement]`` section.

    Returns
    -------
    list of Flag
        In the order no_contact, saturated, noisy, unstable_baseline.
    """
    flags = []
    if heat_q.size and contact_e is not None and contact_e < thresholds.no_contact_e_W_s05_m2K:
        flags.append(Flag.NO_CONTACT)
    if saturated:
        flags.append(Flag.SATURATED)
    if base_T.size >= 3:
        # Noise is the scatter about the baseline's trend; the trend itself is drift.
        x = base_t - base_t[0]
        span = float(x[-1])
        slope, resid_T = 0.0, base_T - np.mean(base_T)
        if span > 0:
            coef = np.polyfit(x, base_T, 1)
            slope, resid_T = float(coef[0]), base_T - np.polyval(coef, x)
        if float(np.std(resid_T)) > thresholds.noise_T_K or float(np.std(base_q)) > thresholds.noise_q_W_m2:
            flags.append(Flag.NOISY)
        if abs(slope) * span > thresholds.unstable_baseline_K:
            flags.append(Flag.UNSTABLE_BASELINE)
    return flags
