"""Signal conditioning of one measurement's raw series: pure functions, no hardware, no state.

* :func:`resample_uniform`, :func:`quality_flags` and :func:`contact_effusivity` live in
  :mod:`edge.estimation.conditioning` (the estimate path conditions a touch itself) and are
  re-exported here for the running decisions and the sequence.
* :func:`heat_while_off` and :func:`no_heat_while_on` tell whether the heater
  follows its command (``heater.fault_flux_W_m2``, ``heater.fault_rise_K``).
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np

from edge.estimation.conditioning import contact_effusivity, quality_flags, resample_uniform
from edge.physics.probe import HEATER_AREA_m2

__all__ = ["MIN_HEAT_s", "MIN_HEAT_SAMPLES", "HEAT_RELAX_s", "min_contact_time_s", "resample_uniform", "quality_flags",
           "contact_effusivity", "temperature_rise_K", "heat_while_off", "no_heat_while_on", "AIR_EFFUSIVITY_W_s05_m2K"]

#: Still air near 300 K: sqrt(0.0263 W/(m K) * 1.16 kg/m^3 * 1007 J/(kg K)) (Incropera 7e, Table A.4).
AIR_EFFUSIVITY_W_s05_m2K = 5.5


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


def heat_while_off(t_s: np.ndarray, T_C: np.ndarray, q_W_m2: np.ndarray, limits: Any, *,
                   since_off_s: float | None = None) -> str | None:
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
    since_off_s : float, optional
        How long before the window the heater was last switched off (None: not since start-up).
        Within :data:`HEAT_RELAX_s` the probe is still relaxing: only a heater's own flux (at least
        ``fault_flux_W_m2``) or twice the rise is evidence of heat.
    """
    q = np.asarray(q_W_m2, float)
    if q.size < 3:
        return None
    q_mean, rise = float(np.mean(q)), temperature_rise_K(t_s, T_C)
    if since_off_s is not None and since_off_s < HEAT_RELAX_s and q_mean < limits.fault_flux_W_m2:
        limits = SimpleNamespace(fault_flux_W_m2=limits.fault_flux_W_m2, fault_rise_K=2 * limits.fault_rise_K)
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
#: How long after a heater-off the probe's own layers keep redistributing their stored heat, s: the
#: heater, sensor and adhesive films (~0.4 mm of polymer, alpha ~1e-7 m^2/s) relax with L^2/alpha ~1.6 s,
#: so within ~3 of those the junction can still warm with no heat source (0.6 K in 0.4 s seen right after
#: a touch with cooldown_s = 0, with 14 W/m^2 leaving the probe). Within that time "heat while off" needs
#: the evidence relaxation cannot give -- the flux a heater pushes (>= fault_flux_W_m2) or twice the
#: rise -- or it latched a healthy heater (ISSUE #35 §3); later windows are judged as before.
HEAT_RELAX_s = 5.0


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
