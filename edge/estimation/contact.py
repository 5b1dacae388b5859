"""Where a touch begins: the contact instant found in a record that starts with the probe in air.

ISSUE #10 §2.  The flux-driven relation of :mod:`edge.estimation.sensor_chain`
holds from the moment of contact, whatever the probe did before, provided
the probe was settled in air at that moment.  So the record must start in
air and the contact must be found in it.  In air the thermopile reads about
zero: natural convection moves a few W/m^2 per kelvin of excess. The
thermocouple drifts slowly.  At contact with an object at another
temperature both step.  With an object at the probe's temperature nothing
steps, and nothing needs to: the probe and the object are then one uniform
body until the heater starts, so heater-on is as good an origin as the true
contact -- provided the probe was touching when the heater went on.  That is
checked on the heater's response (ISSUE #37): under a touching probe the
flux the heater drives into the object against the rise it makes
(:func:`edge.estimation.conditioning.contact_effusivity`) is a solid's, in
air it is still air's.  Without a step the origin comes, in this order, from
the user's trigger (``trigger_t_s``: a record field, e.g. an armed run's
``contact_detected_s`` on the record's clock), from the heater's response
(origin heater-on), or the contact is refused (``how == "none"``).

The noise is measured on the record itself: the first ``quiet_s`` seconds,
with the median absolute deviation of the first differences (robust to a
slow drift).  Contact is the first sample, before heater-on, where the
flux leaves that baseline, or the temperature jumps from one sample to the
next, by ``n_sigma`` noise widths plus a floor (``q_floor_W_m2``,
``T_floor_K``): the floors keep the convective drift of a probe cooling in
air from counting as a touch.  The
origin is the sample before it.  The true instant lies within one sample
period before the detected sample, and the fit does not weight the first
``fit_start_s`` after the origin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Contact", "find_contact", "HOW"]

#: Flux step (W/m^2) below which a change is not a contact.  Convection from a
#: probe 1 K above the room is ~5 W/m^2; a 0.5 K difference to foam (e ~ 40)
#: gives ~20 W/m^2 after 0.5 s.
Q_FLOOR_W_m2 = 8.0
#: Largest steady flux reading (W/m^2) still taken for a probe in air: a channel offset of a few
#: converter steps plus convection from a probe a kelvin or two off the room.  A record whose first
#: samples read more starts during a contact.
Q_AIR_MAX_W_m2 = 60.0
#: Temperature step (K) below which a change is not a contact, for the same reason.
T_FLOOR_K = 0.03
#: Effusivity of what the heater heats (W s^0.5/(m^2 K)) below which the probe was in air when the
#: heater went on: still air 5.5, the lightest foams ~28 (as the ``no_contact`` quality flag's default).
AIR_E_W_s05_m2K = 12.0
#: How the contact was found: a temperature jump, a flux step, the user's trigger, the heater's
#: response (no step: object at the probe's temperature, origin heater-on), or not at all.
HOW = ("temperature", "flux", "trigger", "heater_response", "none")


@dataclass(frozen=True)
class Contact:
    """Where the fit's clock starts.

    Attributes
    ----------
    index : int
        Sample taken as the contact instant (the last sample in air).
    t_s : float
        Its time on the record's clock (0 at heater-on).
    detected : bool
        A step was seen before heater-on.  False: none was seen, and the origin is the last
        sample at or before heater-on (an object at the probe's temperature) -- or the record
        has no samples in air.
    recorded_in_air : bool
        The record starts with the probe in air (at least ``quiet_s`` of quiet samples).
        False: the touch began before the record, and the fit cannot start at contact.
    noise_T_K, noise_q_W_m2 : float
        Noise measured on the samples in air (NaN without them).
    how : str
        One of :data:`HOW`: what found the origin; ``"none"``: no step, no trigger, and the heater's
        response was not a touching probe's (or could not be judged) -- a clear refusal to name a
        contact, which the caller reports (``no_contact``) instead of fitting from heater-on.
    """

    index: int
    t_s: float
    detected: bool
    recorded_in_air: bool
    noise_T_K: float
    noise_q_W_m2: float
    how: str = "none"


def _noise(x: np.ndarray) -> float:
    """Noise sigma from the first differences (MAD, robust to a drift and to one spike)."""
    d = np.diff(x)
    if d.size < 2:
        return float("nan")
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))


def _lsb(x: np.ndarray) -> float:
    """The smallest step between samples (a converter's LSB when it shows; 0 for continuous noise)."""
    d = np.abs(np.diff(x))
    d = d[d > 1e-12]
    if d.size < 2:
        return 0.0
    step = float(d.min())
    # Continuous noise has small steps too: call it quantised only when most steps are multiples of it.
    ratio = d / step
    return step if float(np.mean(np.abs(ratio - np.round(ratio)) < 0.05)) > 0.9 else 0.0


def _heater_response_touching(t: np.ndarray, T: np.ndarray, q: np.ndarray, i_on: int, T0: float, q0: float,
                              min_rise_K: float) -> bool | None:
    """Did the heater heat a solid (True), air (False), or can the record not tell (None)?"""
    from edge.estimation.conditioning import contact_effusivity  # noqa: PLC0415 - same package, below us

    after = np.arange(i_on, t.size)
    if after.size < 4:
        return None
    e = contact_effusivity(t[after], T[after] - T0, q[after] - q0, min_rise_K=min_rise_K)
    return None if e is None else bool(e >= AIR_E_W_s05_m2K)


def find_contact(t_s, T_C, q_W_m2, *, quiet_s: float = 0.3, n_sigma: float = 6.0,
                 q_floor_W_m2: float = Q_FLOOR_W_m2, T_floor_K: float = T_FLOOR_K,
                 trigger_t_s: float | None = None) -> Contact:
    """Find the contact instant of a record whose clock has heater-on at 0.

    Parameters
    ----------
    t_s : array (n,)
        Increasing times, s (0 at heater-on; negative before).
    T_C : array (n,)
        Thermocouple, degC (or K: only differences are used).
    q_W_m2 : array (n,)
        Flux-sensor reading, W/m^2.
    quiet_s : float
        Length of the baseline at the start of the record that must be in air, s.
    n_sigma : float
        Detection threshold in noise widths (above the floors).
    trigger_t_s : float, optional
        The user's trigger on the record's clock (s, at or before heater-on): the origin when no
        step is seen.  Ignored when it lies after heater-on or outside the record.

    Returns
    -------
    Contact
    """
    t = np.asarray(t_s, dtype=np.float64)
    T = np.asarray(T_C, dtype=np.float64)
    q = np.asarray(q_W_m2, dtype=np.float64)
    if t.ndim != 1 or T.shape != t.shape or q.shape != t.shape or t.size < 2:
        raise ValueError("t_s, T_C and q_W_m2 must be 1-D of one length >= 2")
    pre = np.nonzero(t <= 0.0)[0]
    i_on = int(pre[-1]) if pre.size else 0
    # The baseline: the first quiet_s, and at least 4 samples (a 10-Hz record has 3 in 0.3 s).
    base = np.arange(max(4, int(np.count_nonzero(t <= t[0] + quiet_s + 1e-9))))
    if pre.size < 4 or base.size < 4 or base[-1] >= i_on:
        # Nothing (or too little) before heater-on to call "air": the record starts in contact or at heater-on.
        return Contact(i_on, float(t[i_on]), False, False, float("nan"), float("nan"), "none")
    T0, q0 = float(np.median(T[base])), float(np.median(q[base]))

    # A coarse converter (the MCP9600's 0.0625 K, the ADS1115's 14 W/m^2) flips an LSB now and then
    # while its noise measures ~0 by MAD: two steps are added to the floors.
    lsb_T, lsb_q = _lsb(T[:i_on + 1]), _lsb(q[:i_on + 1])
    T_floor_K = T_floor_K + 2.0 * lsb_T
    q_floor_W_m2 = q_floor_W_m2 + 2.0 * lsb_q

    def detect(sT: float, sq: float):
        thr_T, thr_q = n_sigma * sT + T_floor_K, n_sigma * sq + q_floor_W_m2
        # Temperature: a jump between consecutive samples, not a distance from the baseline (a probe
        # cooling in air after the last touch drifts by more than the floor in a few seconds).
        jump = np.abs(np.diff(T[:i_on + 1], prepend=T[0])) > math.sqrt(2.0) * n_sigma * sT + T_floor_K
        out = (np.abs(q[:i_on + 1] - q0) > thr_q) | jump
        # In air the thermopile reads its channel's offset and a little convection: |q0| is bounded
        # by Q_AIR_MAX_W_m2, not by the noise (a slowly decaying contact transient is quiet but not small).
        quiet = bool(np.all(np.abs(q[base] - q0) <= thr_q) and abs(q0) <= max(thr_q, Q_AIR_MAX_W_m2)
                     and np.all(np.abs(T[base] - T0) <= thr_T))
        return np.nonzero(out)[0], quiet

    # Noise first on everything before heater-on (MAD: robust to most of a contact transient), then
    # again on the samples in air only, and the contact found again with it.
    sT, sq = _noise(T[:i_on + 1]), _noise(q[:i_on + 1])
    hit, in_air = detect(sT, sq)
    if hit.size and hit[0] >= 4:
        sT, sq = _noise(T[:hit[0]]), _noise(q[:hit[0]])
        hit, in_air = detect(sT, sq)
    # The baseline itself must be quiet: a record that starts during a contact transient is not in air.
    if not in_air:
        return Contact(0, float(t[0]), False, False, sT, sq, "none")
    if hit.size == 0:
        # No step: the object is at the probe's temperature (or the touch is too light to show).
        if trigger_t_s is not None and math.isfinite(trigger_t_s) and t[0] <= trigger_t_s <= t[i_on]:
            i = int(np.nonzero(t <= trigger_t_s + 1e-9)[0][-1])
            return Contact(i, float(t[i]), True, True, sT, sq, "trigger")
        touching = _heater_response_touching(t, T, q, i_on, T0, q0, 2.0 * lsb_T)
        return Contact(i_on, float(t[i_on]), False, True, sT, sq, "heater_response" if touching else "none")
    i = max(int(hit[0]) - 1, 0)
    i_hit = int(hit[0])
    stepped_T = abs(T[i_hit] - T[i_hit - 1]) > math.sqrt(2.0) * n_sigma * sT + T_floor_K if i_hit else False
    return Contact(i, float(t[i]), True, True, sT, sq, "temperature" if stepped_T else "flux")
