"""One touch, from the moment of contact, through a calibrated sensor chain (ISSUE #10 §2-§3).

:func:`estimate_from_contact` takes a record on the device's clock (0 at
heater-on, samples before it, ideally from before contact), finds the
contact (:mod:`edge.estimation.contact`), fits e, the contact resistance and
the object's initial temperature from that instant on
(:func:`edge.estimation.sensor_chain.fit_sensor_chain`), and states u(e) as
the quadrature sum of

* the fit's own (noise and residual) part;
* the calibration's part: the covariance of theta (flux scale, sensing
  depth, bead lag) pushed through the fit by finite differences (three
  more fits; the perturbed kernels are cached) -- for R_c and T_obj0 too;
* the calibration's transfer floor (the scatter left on its references);
* without a contact recorded in air, the change of e between fitting from
  0.3 s and from 1.0 s after the record's start (the probe's state at the
  record's start is not the uniform one the model assumes).

Flags: ``uncalibrated`` (the datasheet chain), ``contact_not_recorded``,
``poor_fit`` (normalised residual above :data:`POOR_FIT`), ``no_contact``
(no flux into anything).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from edge.calibration.model import ProbeCalibration
from edge.estimation.contact import find_contact
from edge.estimation.sensor_chain import fit_sensor_chain

__all__ = ["estimate_from_contact", "POOR_FIT", "FIT_START_s"]

#: Normalised residual (rms residual / noise measured in air) above which the chain does not describe the record.
POOR_FIT = 5.0
#: Samples this long after contact are modelled but not weighted (the contact's first instants).
FIT_START_s = 0.3
#: Stated thermocouple noise when the record has no samples in air to measure it on (precision board).
DEFAULT_NOISE_T_K = 0.01
#: Finite-difference steps of theta = (ln flux_scale, ln depth, tau) for the calibration's part of u(e).
_STEPS = (1e-3, 1e-3, 2e-3)


def estimate_from_contact(t_s, T_C, q_W_m2, calibration: ProbeCalibration | None = None) -> dict[str, Any]:
    """e, R_c and T_obj0 of one touch, with their uncertainties, flags and the fit's quality.

    Parameters
    ----------
    t_s : array (n,)
        Uniform times, s, 0 at heater-on (negative before: from before contact if possible).
    T_C : array (n,)
        Absolute thermocouple temperature (degC or K; T_obj0 is returned on the same scale).
    q_W_m2 : array (n,)
        Flux-sensor voltage over its nominal sensitivity, W/m^2.
    calibration : ProbeCalibration, optional
        Default: the uncalibrated datasheet probe (flagged).

    Returns
    -------
    dict
        ``effusivity_W_s05_m2K`` and ``..._u`` (k = 1) with its parts ``u_e_parts`` (fit,
        calibration, floor, contact), ``contact_resistance_m2K_W`` (+ ``_u``),
        ``object_temperature0`` (+ ``_u``), ``probe_temperature0``, ``contact_t_s``,
        ``normalised_residual``, ``flags``, ``determined``, ``calibration_sha256``.
    """
    cal = ProbeCalibration.nominal() if calibration is None else calibration
    t = np.asarray(t_s, dtype=np.float64)
    T = np.asarray(T_C, dtype=np.float64)
    q = np.asarray(q_W_m2, dtype=np.float64)
    c = find_contact(t, T, q)
    flags: list[str] = [] if cal.calibrated else ["uncalibrated"]
    i0 = c.index
    tt, TT, qq = t[i0:] - t[i0], T[i0:], q[i0:]
    if tt.size < 8 or tt[-1] < FIT_START_s + 0.2:
        raise ValueError(f"record too short after contact ({tt[-1]:.2f} s from t = {t[i0]:.2f} s)")
    noise_T = c.noise_T_K if math.isfinite(c.noise_T_K) and c.noise_T_K > 0 else DEFAULT_NOISE_T_K
    noise_T = max(noise_T, 1e-4)   # a converter's step is never below 0.1 mK: keep the ratio finite
    r = fit_sensor_chain(tt, TT, qq, calibration=cal.chain, fit_start_s=FIT_START_s, noise_T_K=noise_T)
    if not (math.isfinite(r.e_W_s05_m2K) and r.e_W_s05_m2K > 0):
        return {"flags": flags + ["no_fit"], "effusivity_W_s05_m2K": None, "effusivity_W_s05_m2K_u": None,
                "contact_t_s": float(t[i0]), "normalised_residual": r.normalised_residual,
                "determined": [], "calibration_sha256": cal.sha256}
    e = r.e_W_s05_m2K
    # Calibration's part: d ln e / d theta by finite differences, through the covariance.
    # The same for R_c and T_obj0: an error in the sensing depth trades directly with R_c (dL / k).
    th0 = cal.theta
    G = np.zeros((3, 3))   # rows: ln e, R_c, T_obj0; columns: theta
    for j, h in enumerate(_STEPS):
        th = th0.copy()
        th[j] += h
        rj = fit_sensor_chain(tt, TT, qq, calibration=cal.chain_at(th), fit_start_s=FIT_START_s, noise_T_K=noise_T)
        if rj.e_W_s05_m2K > 0 and math.isfinite(rj.e_W_s05_m2K):
            G[0, j] = (math.log(rj.e_W_s05_m2K) - math.log(e)) / h
        G[1, j] = (rj.R_c_m2K_W - r.R_c_m2K_W) / h
        G[2, j] = (rj.T_obj0_C - r.T_obj0_C) / h
    var_cal = np.maximum(np.diag(G @ cal.covariance @ G.T), 0.0)
    u_cal = math.sqrt(float(var_cal[0]))
    u_fit = r.u_e_W_s05_m2K / e
    u_contact = 0.0
    if not c.recorded_in_air:
        flags.append("contact_not_recorded")
        r_late = fit_sensor_chain(tt, TT, qq, calibration=cal.chain, fit_start_s=1.0, noise_T_K=noise_T)
        if r_late.e_W_s05_m2K > 0 and math.isfinite(r_late.e_W_s05_m2K):
            u_contact = abs(math.log(r_late.e_W_s05_m2K / e))
    u_rel = math.sqrt(u_fit**2 + u_cal**2 + cal.u_rel_floor**2 + u_contact**2)
    if r.normalised_residual > POOR_FIT:
        flags.append("poor_fit")
    return {
        "effusivity_W_s05_m2K": e,
        "effusivity_W_s05_m2K_u": e * u_rel,
        "u_e_parts": {"fit": u_fit, "calibration": u_cal, "floor": cal.u_rel_floor, "contact": u_contact},
        "contact_resistance_m2K_W": r.R_c_m2K_W,
        "contact_resistance_m2K_W_u": math.sqrt(r.u_R_c_m2K_W**2 + float(var_cal[1])),
        "object_temperature0": r.T_obj0_C,
        "object_temperature0_u": math.sqrt(r.u_T_obj0_C**2 + float(var_cal[2])),
        "probe_temperature0": float(TT[0]),
        "contact_t_s": float(t[i0]), "contact_detected": c.detected,
        "normalised_residual": r.normalised_residual, "noise_T_K": noise_T,
        "flags": flags,
        "determined": ["e", "R_c", "T_obj0"],
        "calibration_sha256": cal.sha256, "probe": cal.probe,
    }
