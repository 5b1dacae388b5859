"""Signal conditioning of one measurement's raw series: pure functions, no hardware, no state.

* :func:`resample_uniform` puts the heating phase on the uniform time grid
  the estimator expects (cubic spline, :mod:`edge.estimation.spline`).
* :func:`quality_flags` judges the baseline and the heating flux against the
  ``[measurement]`` thresholds.
* :func:`heat_while_off` and :func:`no_heat_while_on` tell whether the heater
  follows its command (``heater.fault_flux_W_m2``, ``heater.fault_rise_K``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from edge.estimation.spline import resample
from edge.physics.probe import HEATER_AREA_m2
from edge.status import Flag

__all__ = ["MIN_HEAT_s", "MIN_HEAT_SAMPLES", "min_contact_time_s", "resample_uniform", "quality_flags", "contact_effusivity", "temperature_rise_K", "heat_while_off",
           "no_heat_while_on", "AIR_EFFUSIVITY_W_s05_m2K"]

#: Still air near 300 K: sqrt(0.0263 W/(m K) * 1.16 kg/m^3 * 1007 J/(kg K)) (Incropera 7e, Table A.4).
AIR_EFFUSIVITY_W_s05_m2K = 5.5


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
    (:func:`edge.estimation.running.duhamel_m`). So ``e`` of the contact is
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
    from edge.estimation.running import duhamel_m  # noqa: PLC0415 (edge.estimation imports this module's peers)

    t = np.asarray(t_s, float)
    dT, q = np.asarray(dT_K, float), np.asarray(q_W_m2, float)
    keep = t > 0
    t, dT, q = t[keep], dT[keep], q[keep]
    tT = t - T_age_s
    ok = tT > 0
    if not ok.any():
        return None
    m = np.array([duhamel_m(x, t, q) for x in tT[ok]])
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


def temperature_rise_K(t_s: np.ndarray, T_C: np.ndarray) -> float:
    """Temperature change over a window from its straight-line fit (K); 0 for fewer than 3 samples.

    The fit, not the end points, so that one quantisation step or one noisy
    reading at either end does not count as a rise.
    """
    t, T = np.asarray(t_s, float), np.asarray(T_C, float)
    if t.size < 3 or not t[-1] > t[0]:
        return 0.0
    x = t - t[0]
    return float(np.polyfit(x, T, 1)[0] * x[-1])


def heat_while_off(t_s: np.ndarray, T_C: np.ndarray, q_W_m2: np.ndarray, limits: Any) -> str | None:
    """Why a window with the heater commanded off shows heat from the heater, or None.

    The junction warming by more than ``limits.fault_rise_K`` while no heat
    flows in from the object (mean flux not below ``-limits.fault_flux_W_m2 / 4``;
    positive flux is heat leaving the probe) means a heat source inside the
    probe: the heater. In contact a stuck heater pushes its flux into the
    object as the temperature climbs; in air (between touches) the flux is
    near zero and the probe heats itself. What this is not fooled by: a
    probe warmer than the object (the junction cools), an object warmer than
    the probe (it warms the junction, but the flux is reversed), and a
    healthy cool-down (the temperature falls).

    Parameters
    ----------
    t_s, T_C, q_W_m2 : ndarray
        The window's times (s), thermocouple (°C) and flux (W/m^2, no offset removed).
    limits : namespace
        With ``fault_flux_W_m2`` and ``fault_rise_K`` (the ``[heater]`` section).
    """
    q = np.asarray(q_W_m2, float)
    if q.size < 3:
        return None
    q_mean, rise = float(np.mean(q)), temperature_rise_K(t_s, T_C)
    # Heat flows in from the object when the mean flux is negative beyond the noise of a mean
    # (a quarter of fault_flux_W_m2: ~37 W/m^2, above the ~22 W/m^2 3-sigma bound of a baseline
    # mean). A warm PMMA object 1 K above the probe, touched before heating, draws ~100 W/m^2 into
    # the probe and lifts the junction 0.5 K in a second; a stuck heater pushes flux out of it.
    inflow_W_m2 = limits.fault_flux_W_m2 / 4
    if rise > limits.fault_rise_K and q_mean > -inflow_W_m2:
        span = float(t_s[-1] - t_s[0])
        return (f"heat with the heater off: the temperature rose {rise:.2f} K (> {limits.fault_rise_K:g}) "
                f"in {span:.2f} s with {q_mean:.0f} W/m^2 leaving the probe (> -{inflow_W_m2:g})")
    return None


#: The shortest heating a touch may ask for, s, and the fewest samples it must give. Shorter, the
#: flux has not crossed the sensor's own layer and converter (the simulated paper probe shows
#: 19-65 W/m^2 of a 1500-W/m^2 step at 0.26-0.3 s), so "no heat while on" would be judged on a
#: sensor that has not answered yet and latch a heater fault on a healthy heater (ISSUE #35 §3),
#: and the estimators need at least 4 grid points after heater-on.
MIN_HEAT_s = 0.5
MIN_HEAT_SAMPLES = 5


def min_contact_time_s(sample_rate_Hz: float) -> float:
    """The shortest contact (heating) time a touch at ``sample_rate_Hz`` may ask for, s."""
    return max(MIN_HEAT_s, MIN_HEAT_SAMPLES / float(sample_rate_Hz))


def no_heat_while_on(heat_T_C: np.ndarray, heat_q_W_m2: np.ndarray, T0_C: float, power_W: float,
                     limits: Any) -> str | None:
    """Why a heating phase shows no heat from the heater, or None.

    A working heater either pushes its flux through the sensor into the
    object (in contact) or, in air, heats the probe itself. Into a poor
    conductor only part of ``P/A`` crosses the sensor (the rest warms the
    probe; PMMA at 1.3 W: ~110 of 390 W/m^2, a 0.4 K rise), so "no heat"
    means both within noise of zero: a mean flux step (offset removed)
    below half ``limits.fault_flux_W_m2`` and a rise below half
    ``limits.fault_rise_K`` (75 W/m^2 is > 3 sigma of the noisiest
    accepted baseline's mean; 0.25 K is just over one 0.197 K step, which
    quantisation alone can give). Judged only when the commanded flux
    ``P/A`` is at least twice ``fault_flux_W_m2`` (a lower power could not
    be told from no power).

    Parameters
    ----------
    heat_T_C, heat_q_W_m2 : ndarray
        Heating-phase thermocouple (°C) and flux with the baseline offset removed (W/m^2).
    T0_C : float
        Baseline temperature (°C).
    power_W : float
        Commanded power (W).
    limits : namespace
        With ``fault_flux_W_m2`` and ``fault_rise_K``.
    """
    T, q = np.asarray(heat_T_C, float), np.asarray(heat_q_W_m2, float)
    if q.size < 3 or power_W / HEATER_AREA_m2 < 2 * limits.fault_flux_W_m2:
        return None
    q_mean, rise = float(np.mean(q)), float(np.max(T) - T0_C)
    q_lim, rise_lim = limits.fault_flux_W_m2 / 2, limits.fault_rise_K / 2
    if q_mean < q_lim and rise < rise_lim:
        return (f"no heat with the heater on at {power_W:g} W: {q_mean:.0f} W/m^2 (< {q_lim:g}) "
                f"and a {rise:.2f} K rise (< {rise_lim:g})")
    return None
