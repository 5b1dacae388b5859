"""One touch, from the moment of contact, through a calibrated sensor chain (ISSUE #10 §2-§3).

:func:`estimate_from_contact` takes a record on the device's clock (0 at
heater-on, samples before it, ideally from before contact), finds the
contact (:mod:`edge.estimation.contact`), fits e, the contact resistance and
the object's initial temperature from that instant on
(:func:`edge.estimation.sensor_chain.fit_sensor_chain`), and states u(e) as
the quadrature sum of

* the fit's own (noise and residual) part;
* the calibration's part: the covariance of theta (flux scale, sensing
  depth, bead lag, layer conductivity) pushed through the fit by finite
  differences (four more fits; the perturbed kernels are cached) -- for R_c and T_obj0 too;
* the calibration's transfer floor (the scatter left on its references);
* without a contact recorded in air, the change of e between fitting from
  0.3 s and from 1.0 s after the record's start (the probe's state at the
  record's start is not the uniform one the model assumes);
* the lateral loss of a finite heater, bracketed: e between the 1-D fit
  and the fit of a uniform disk on a half-space
  (:func:`edge.estimation.sensor_chain._disk_kernel`, the object's alpha
  from the library's prior given e), half their log-distance as u, on the
  fit window that states the least u.

Flags: ``uncalibrated`` (the datasheet chain), ``contact_not_recorded``,
``contact_lost`` (the probe left the object during heating: no estimate),
``lateral_spread`` (the lateral correction moved e by more than 10 %),
``poor_fit`` (normalised residual above :data:`POOR_FIT`), ``no_contact``
(no flux into anything).
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Any

import numpy as np

from edge.calibration.model import ProbeCalibration
from edge.estimation.contact import find_contact
from edge.estimation.sensor_chain import face_flux, fit_sensor_chain
from edge.physics.geometry import PROBES

__all__ = ["estimate_from_contact", "uniform_record", "alpha_prior", "POOR_FIT", "FIT_START_s"]

#: Normalised residual (rms residual / noise measured in air) above which the chain does not describe the record.
POOR_FIT = 5.0
#: Samples this long after contact are modelled but not weighted (the contact's first instants).
FIT_START_s = 0.3
#: A contact resistance whose standard uncertainty exceeds this (m^2K/W) was not determined by the
#: touch: it spans the whole range of a dry contact.  Typical of low-effusivity objects, where R_c q is
#: far below the noise and R_c only soaks up what the chain does not describe.
R_C_RESOLVED_m2K_W = 3e-5
#: Least thermocouple noise the goodness of fit assumes (K): the precision board's 24-bit converter
#: reads a type-K junction to ~4 mK rms; nothing real is quieter than half that.
NOISE_FLOOR_K = 2e-3
#: Stated thermocouple noise when the record has no samples in air to measure it on (precision board).
DEFAULT_NOISE_T_K = 0.01
#: Finite-difference steps of theta = (ln flux_scale, ln depth, tau, ln layer k) for the calibration's part of u(e).
_STEPS = (1e-3, 1e-3, 2e-3, 1e-3)


#: Most passes of the lateral-loss correction (e -> alpha from the prior -> e), stopping once e moves
#: less than DISK_TOL (relative).  Glass converges in two; a metal, whose correction is tens of per
#: cent, needs three or four (two passes left copper +30..58 % on the FaithfulWorld paper probe).
DISK_PASSES = 6
DISK_TOL = 1e-3
#: A lateral correction of e beyond this (relative) is flagged ``lateral_spread``.
LATERAL_FLAG = 0.10
#: Contact is lost when, during heating, the face flux falls below this share of its largest value so
#: far and stays there for LOSS_HOLD_s (a lifted probe: the face flux drops to about nothing within
#: a few samples while the heater runs; on an object it only ever eases).
LOSS_FRACTION = 0.25
LOSS_HOLD_s = 0.3
#: ... and only once that largest value stands clear of the flux noise (W/m^2): on foam the face flux
#: is tens of W/m^2 and its noise would otherwise look like a lift.
LOSS_MIN_FLUX_W_m2 = 50.0
#: ... and above this many times the face flux's sample-to-sample noise.
LOSS_NOISE_FACTOR = 8.0
#: Candidate fit windows after heater-on (s) for a finite heater (see estimate_from_contact).
LATERAL_WINDOWS_s = (1.0, 2.0, 4.0, 8.0, math.inf)


@lru_cache(maxsize=1)
def _library():
    """The material library as a prior on rho c given e (the same prior the default estimator uses)."""
    from edge.estimation.estimate import DEFAULT_PRIOR_COEF  # noqa: PLC0415
    from edge.estimation.identification import Library  # noqa: PLC0415
    from edge.physics.materials import load_materials  # noqa: PLC0415

    mats = list(load_materials())
    s = [m.solid for m in mats]
    return Library([x.effusivity_W_s05_m2K for x in s], [x.k_W_mK for x in s], [x.rho_c_J_m3K for x in s],
                   [m.name for m in mats], [m.cls for m in mats], kernel_floor_ln=DEFAULT_PRIOR_COEF[0],
                   rho_c_intrinsic_ln=DEFAULT_PRIOR_COEF[1], material_spread_ln=DEFAULT_PRIOR_COEF[2])


def alpha_prior(e: float, u_ln_e: float = 0.02) -> tuple[float, float]:
    """ln(alpha) mean and standard deviation of an object of effusivity e (alpha = (e / rho c)^2)."""
    m, sd, _ = _library().prior_rho_c(e, u_ln_e)
    return 2.0 * math.log(e) - 2.0 * m, 2.0 * sd


def uniform_record(t_s, *columns) -> tuple[np.ndarray, ...]:
    """The columns on a uniform grid of the record's median step (linear interpolation).

    The chain's kernels need a uniform grid; a device's samples jitter by a few ms.  A gap (a step
    above 1.5 times the median) is refused rather than bridged.

    Raises
    ------
    ValueError
        Fewer than 8 samples, times not increasing, non-finite values, or a gap.
    """
    t = np.asarray(t_s, dtype=np.float64)
    cols = [np.asarray(c, dtype=np.float64) for c in columns]
    if t.ndim != 1 or t.size < 8 or any(c.shape != t.shape for c in cols):
        raise ValueError("the record needs at least 8 samples, every column as long as t_s")
    if not (np.all(np.isfinite(t)) and all(np.all(np.isfinite(c)) for c in cols)):
        raise ValueError("the record has non-finite values")
    d = np.diff(t)
    if np.any(d <= 0):
        raise ValueError(f"times must increase (t_s = {t[int(np.argmax(d <= 0)) + 1]:.6g})")
    dt = float(np.median(d))
    if np.any(d > 1.5 * dt):
        i = int(np.argmax(d > 1.5 * dt))
        raise ValueError(f"a gap of {d[i]:.3g} s after t_s = {t[i]:.6g} (the step is {dt:.3g} s)")
    if np.allclose(d, dt, rtol=1e-6, atol=1e-9):
        return (t, *cols)
    n = int(math.floor((t[-1] - t[0]) / dt + 1e-9)) + 1
    tu = t[0] + dt * np.arange(n)
    return (tu, *(np.interp(tu, t, c) for c in cols))


def contact_lost_at(t_from_contact: np.ndarray, phi_W_m2: np.ndarray, t_heat_s: float) -> float | None:
    """Time from contact at which the probe left the object during heating (None: it stayed).

    The face flux, averaged over LOSS_HOLD_s, falls below :data:`LOSS_FRACTION` of its largest value
    since heater-on and stays there for LOSS_HOLD_s -- and that largest value stands clear of the face
    flux's own noise (LOSS_NOISE_FACTOR times it, and LOSS_MIN_FLUX_W_m2): on a coarse thermometer
    (the MCP9600's 0.0625 K steps) the storage term makes the inferred face flux swing by hundreds of
    W/m^2 from sample to sample, and a swing is not a lift.
    """
    t, phi = np.asarray(t_from_contact), np.asarray(phi_W_m2)
    on = np.nonzero(t >= t_heat_s)[0]
    if on.size < 6:
        return None
    dt = float(t[1] - t[0])
    hold = max(2, int(round(LOSS_HOLD_s / dt)))
    seg = phi[on]
    noise = 1.4826 * float(np.median(np.abs(np.diff(seg) - np.median(np.diff(seg))))) / math.sqrt(2.0)
    w = min(hold, seg.size)
    smooth = np.convolve(seg, np.ones(w) / w, mode="valid")      # smooth[j] averages seg[j:j + w]
    peak = np.maximum.accumulate(smooth)
    low = (smooth < LOSS_FRACTION * peak) & (peak > max(LOSS_MIN_FLUX_W_m2, LOSS_NOISE_FACTOR * noise))
    run = np.convolve(low.astype(int), np.ones(hold, dtype=int), mode="valid")
    hit = np.nonzero(run == hold)[0]
    return None if hit.size == 0 else float(t[on[hit[0]]])


def estimate_from_contact(t_s, T_C, q_W_m2, calibration: ProbeCalibration | None = None, *,
                          heater_radius_m: float | None = None) -> dict[str, Any]:
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
    heater_radius_m : float, optional
        Radius of the heated disk (default: the calibration's probe's); ``math.inf`` for 1-D.  The
        object loses heat sideways from a finite disk, by an amount that depends on its alpha and
        size, which one touch does not give: e is bracketed between the 1-D fit and a disk on a
        half-space (alpha from the library's prior given e), half the bracket going into u(e)
        (``u_e_parts["lateral"]``).

    Returns
    -------
    dict
        ``effusivity_W_s05_m2K`` and ``..._u`` (k = 1) with its parts ``u_e_parts`` (fit,
        calibration, floor, contact, lateral), ``contact_resistance_m2K_W`` (+ ``_u``),
        ``object_temperature0`` (+ ``_u``), ``probe_temperature0``, ``contact_t_s``,
        ``normalised_residual``, ``flags``, ``determined``, ``calibration_sha256``.
    """
    cal = ProbeCalibration.nominal() if calibration is None else calibration
    t, T, q = uniform_record(t_s, T_C, q_W_m2)
    c = find_contact(t, T, q)
    flags: list[str] = [] if cal.calibrated else ["uncalibrated"]
    i0 = c.index
    tt, TT, qq = t[i0:] - t[i0], T[i0:], q[i0:]
    if tt.size < 8 or tt[-1] < FIT_START_s + 0.2:
        raise ValueError(f"record too short after contact ({tt[-1]:.2f} s from t = {t[i0]:.2f} s)")
    noise_T = c.noise_T_K if math.isfinite(c.noise_T_K) and c.noise_T_K > 0 else DEFAULT_NOISE_T_K
    # Air samples that hardly move (a quiet simulator, a converter sitting on one code) measure ~0:
    # the goodness of fit is judged against at least NOISE_FLOOR_K.
    noise_T = max(noise_T, NOISE_FLOOR_K)
    # The heater switched on at t = 0 of the record's clock: theta_b's slope jumps there.
    breaks = (-float(t[i0]),) if t[i0] < 0 else ()
    a = PROBES[cal.probe].heater_radius_m if heater_radius_m is None else float(heater_radius_m)

    def fit(chain, disk, start=FIT_START_s):
        return fit_sensor_chain(tt, TT, qq, calibration=chain, fit_start_s=start, noise_T_K=noise_T,
                                breaks_s=breaks, disk=disk)

    def bad(x) -> bool:
        return not (math.isfinite(x.e_W_s05_m2K) and x.e_W_s05_m2K > 0)

    t_lost = contact_lost_at(tt, face_flux(tt, TT, qq, cal.chain, breaks_s=breaks), breaks[0] if breaks else 0.0)
    if t_lost is not None:
        # A lifted probe: what follows is the probe in air, not the object.  Refused, not fitted
        # (fitting up to the lift would pass off a shorter, unplanned touch as the measurement).
        return {"flags": flags + ["contact_lost"], "effusivity_W_s05_m2K": None, "effusivity_W_s05_m2K_u": None,
                "contact_t_s": float(t[i0]), "contact_lost_t_s": float(t[i0] + t_lost),
                "normalised_residual": None, "determined": [], "calibration_sha256": cal.sha256,
                "probe": cal.probe}

    r1d = r = fit(cal.chain, None)
    disk = None
    u_lat = 0.0
    e_lat = None
    if not bad(r) and math.isfinite(a):
        # Lateral loss lies between two bounds: 1-D (none: e too high) and a uniform disk on a
        # half-space (all of it: e too low on a finite block, whose sides stop the spread; -20..-50 %
        # on metals after 10 s on the FaithfulWorld).  The estimate is their geometric mean, with half
        # their log-distance as its standard uncertainty; the fit window (heater-on + 1, 2, 4, 8 s or
        # the whole record) is the one whose stated u -- noise and bracket together -- is least.
        full = (tt, TT, qq)
        t_heat = -float(t[i0]) if t[i0] < 0 else 0.0
        best = None
        for extra in LATERAL_WINDOWS_s:
            n_keep = int(np.searchsorted(full[0], t_heat + extra, side="right"))
            if n_keep < 16 or (best is not None and n_keep >= full[0].size and extra != math.inf):
                continue
            tt, TT, qq = (x[:n_keep] for x in full)
            c1 = fit(cal.chain, None)
            cd = c1
            for _ in range(DISK_PASSES):
                if bad(cd):
                    break
                ln_a, _sd = alpha_prior(cd.e_W_s05_m2K)
                dk = (a, math.exp(ln_a))
                prev, cd = cd, fit(cal.chain, dk)
                if not bad(cd) and prev is not c1 and abs(math.log(cd.e_W_s05_m2K / prev.e_W_s05_m2K)) < DISK_TOL:
                    break
            if bad(c1) or bad(cd):
                continue
            span = abs(math.log(c1.e_W_s05_m2K / cd.e_W_s05_m2K)) / 2.0
            u_tot = math.hypot(cd.u_e_W_s05_m2K / cd.e_W_s05_m2K, span)
            if best is None or u_tot < best[0]:
                best = (u_tot, n_keep, c1, cd, dk, span)
        if best is not None:
            _, n_keep, r1d, r, disk, u_lat = best
            tt, TT, qq = (x[:n_keep] for x in full)
            e_lat = math.sqrt(r1d.e_W_s05_m2K * r.e_W_s05_m2K)
        else:
            tt, TT, qq = full
    if bad(r):
        return {"flags": flags + ["no_fit"], "effusivity_W_s05_m2K": None, "effusivity_W_s05_m2K_u": None,
                "contact_t_s": float(t[i0]), "normalised_residual": r.normalised_residual,
                "determined": [], "calibration_sha256": cal.sha256, "probe": cal.probe}
    e = r.e_W_s05_m2K if e_lat is None else e_lat
    if 2.0 * u_lat > LATERAL_FLAG:
        flags.append("lateral_spread")
    # Calibration's part: d ln e / d theta by finite differences, through the covariance.
    # The same for R_c and T_obj0: an error in the sensing depth trades directly with R_c (dL / k).
    th0 = cal.theta
    G = np.zeros((3, th0.size))   # rows: ln e, R_c, T_obj0; columns: theta
    for j, h in enumerate(_STEPS):
        th = th0.copy()
        th[j] += h
        rj = fit(cal.chain_at(th), disk)
        if rj.e_W_s05_m2K > 0 and math.isfinite(rj.e_W_s05_m2K):
            G[0, j] = (math.log(rj.e_W_s05_m2K) - math.log(r.e_W_s05_m2K)) / h
        G[1, j] = (rj.R_c_m2K_W - r.R_c_m2K_W) / h
        G[2, j] = (rj.T_obj0_C - r.T_obj0_C) / h
    var_cal = np.maximum(np.diag(G @ cal.covariance @ G.T), 0.0)
    u_cal = math.sqrt(float(var_cal[0]))
    u_fit = r.u_e_W_s05_m2K / r.e_W_s05_m2K
    u_contact = 0.0
    if not c.recorded_in_air:
        flags.append("contact_not_recorded")
        r_late = fit(cal.chain, disk, 1.0)
        if r_late.e_W_s05_m2K > 0 and math.isfinite(r_late.e_W_s05_m2K):
            u_contact = abs(math.log(r_late.e_W_s05_m2K / r.e_W_s05_m2K))
    u_rel = math.sqrt(u_fit**2 + u_cal**2 + cal.u_rel_floor**2 + u_contact**2 + u_lat**2)
    # R_c leans on the first second after contact, where the smoothing of theta_b (a bias-variance
    # choice) bends the storage term most: the change of R_c without it is part of R_c's uncertainty.
    r_raw = fit_sensor_chain(tt, TT, qq, calibration=cal.chain, fit_start_s=FIT_START_s, noise_T_K=noise_T,
                             breaks_s=breaks, disk=disk, smooth_s=0.0)
    u_Rc_method = abs(r_raw.R_c_m2K_W - r.R_c_m2K_W) if math.isfinite(r_raw.R_c_m2K_W) else 0.0
    u_Rc = math.sqrt(r.u_R_c_m2K_W**2 + float(var_cal[1]) + u_Rc_method**2)
    if r.normalised_residual > POOR_FIT:
        flags.append("poor_fit")
    return {
        "effusivity_W_s05_m2K": e,
        "effusivity_W_s05_m2K_u": e * u_rel,
        "u_e_parts": {"fit": u_fit, "calibration": u_cal, "floor": cal.u_rel_floor, "contact": u_contact,
                      "lateral": u_lat},
        "lateral_correction": (e / r1d.e_W_s05_m2K - 1.0) if disk is not None else 0.0,
        "fit_end_t_s": float(t[i0] + tt[-1]),
        "contact_resistance_m2K_W": r.R_c_m2K_W,
        "contact_resistance_m2K_W_u": u_Rc,
        "object_temperature0": r.T_obj0_C,
        "object_temperature0_u": math.sqrt(r.u_T_obj0_C**2 + float(var_cal[2])),
        "probe_temperature0": float(TT[0]),
        "contact_t_s": float(t[i0]), "contact_detected": c.detected,
        "normalised_residual": r.normalised_residual, "noise_T_K": noise_T,
        "flags": flags,
        "determined": ["e", "T_obj0"] + (["R_c"] if u_Rc <= R_C_RESOLVED_m2K_W else []),
        "calibration_sha256": cal.sha256, "probe": cal.probe,
    }
