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
* the calibration's model-form term: its floor (the scatter left on its references and their
  leave-one-out misses), growing outside the references' span of e at the rate the leave-one-out
  check measured (:meth:`edge.calibration.model.ProbeCalibration.model_form_u_rel`);
* without a contact recorded in air, the change of e between fitting from
  0.3 s and from 1.0 s after the record's start (the probe's state at the
  record's start is not the uniform one the model assumes);
* the lateral loss of a finite heater: the fit is that of a uniform disk
  on a half-space (:func:`edge.estimation.sensor_chain._disk_kernel`) at
  the object's most likely alpha -- profiled over ln(alpha) with the
  library's prior given e (:func:`lateral_profile`) -- and u(e) carries
  alpha's uncertainty and the change of e from the next shorter fit
  window (a finite block departs from a half-space), on the fit window
  that states the least u.  Where the record pins alpha (a metal, whose
  heat reaches the heater's edge within seconds) the touch measures alpha
  and k as well: ``determined`` then lists them.

Flags: ``uncalibrated`` (the datasheet chain), ``contact_not_recorded``,
``contact_lost`` (the probe left the object during heating: no estimate),
``lateral_spread`` (the lateral correction moved e by more than 10 %),
``poor_fit`` (normalised residual above :data:`POOR_FIT`), ``no_contact``
(no flux into anything).
"""

from __future__ import annotations

import copy
import math
import sys
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Callable

import numpy as np

from edge.estimation import sensor_chain
from edge.estimation.contact import find_contact
from edge.estimation.content_keys import calibration_content, library_key, object_key, tunables
from edge.estimation.sensor_chain import (DiskFitter, SensorChainCalibration, chain_point, chain_theta, chain_with_theta,
                                          face_flux, fit_sensor_chain, refine_factor)
from edge.physics.geometry import PROBES
from edge.physics.memo import BoundedMemo
from edge.physics.probe import (FLUX_SENSITIVITY_U_REL, SENSING_K_U_REL, SENSING_THICKNESS_U_REL,
                               THERMOCOUPLE_TAU_U_s)
from edge.status import Flag

__all__ = ["estimate_from_contact", "contact_fraction", "uniform_record", "alpha_prior", "lateral_profile", "LateralProfile", "POOR_FIT",
           "FIT_START_s", "DatasheetChain"]

#: Normalised residual (rms residual / noise measured in air) above which the chain does not describe the record.
POOR_FIT = 5.0
#: Samples this long after contact are modelled but not weighted (the contact's first instants).
FIT_START_s = 0.3
#: A calibration whose model-form floor (relative) reaches this determines no e: the small heater's fit
#: calls a quantity identified below the same 30 % (edge.estimation.axifit's identifiable_u_rel).
E_DETERMINED_U_REL = 0.30
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


#: The lateral loss is profiled over ln(alpha): ALPHA_GRID points across the library prior's mean
#: +- ALPHA_SPAN_SD standard deviations (within ALPHA_BOUNDS_m2_s), then ALPHA_REFINE golden-section
#: steps between the best point's neighbours.  Each point is one linear least-squares fit.
ALPHA_GRID = 9
ALPHA_SPAN_SD = 3.0
ALPHA_REFINE = 10
#: Diffusivities the profile may take (m^2/s): below a foam's, above silver's.
ALPHA_BOUNDS_m2_s = (1e-8, 2e-4)
#: Half-step of ln(alpha) for the profile's curvature and for d ln e / d ln alpha.
ALPHA_STEP_LN = 0.05
#: alpha (and k) count as determined by the touch when the profile leaves less than this share of
#: the prior's standard deviation of ln(alpha).
ALPHA_DETERMINED = 0.5
#: The disk at the prior's alpha moving e less than this (relative) from the 1-D fit: the lateral
#: loss is too small to stand out of the probe's own departures from the model (glass, polymers, foams,
#: stainless steel: there a free profile reads those departures as alpha), and alpha is not profiled.
LATERAL_PROFILE_MIN = 0.03
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


@dataclass(frozen=True)
class DatasheetChain:
    """The uncalibrated probe's chain: datasheet values, the as-delivered spreads as covariance.

    What :meth:`edge.calibration.model.ProbeCalibration.nominal` stores, without the calibration
    file's machinery (this package sits below :mod:`edge.calibration`): the attributes the chain
    estimate reads.  ``sha256`` is None -- no calibration was applied.
    """

    probe: str = "paper"
    chain: SensorChainCalibration = SensorChainCalibration()
    u_rel_floor: float = 0.0
    calibrated: bool = False
    sha256: None = None

    @property
    def covariance(self) -> np.ndarray:
        """Covariance of theta = (ln flux_scale, ln sensing_thickness_m, tc_tau_s, ln sensing_k_W_mK)."""
        return np.diag([FLUX_SENSITIVITY_U_REL**2, SENSING_THICKNESS_U_REL**2, THERMOCOUPLE_TAU_U_s**2,
                        SENSING_K_U_REL**2])

    @property
    def theta(self) -> np.ndarray:
        """(ln flux_scale, ln sensing_thickness_m, tc_tau_s, ln sensing_k_W_mK)."""
        return chain_theta(self.chain)

    def chain_at(self, theta) -> SensorChainCalibration:
        """The chain with parameters ``theta`` (as :meth:`ProbeCalibration.chain_at`)."""
        return chain_with_theta(self.chain, theta)


@lru_cache(maxsize=1)
def _library():
    """The material library from its CSV: the prior for callers that have no model bundle.

    The device and every path through :func:`edge.estimation.seam.estimate_touch` pass the bundle's
    library instead (``library=``), the one prior the default method uses.
    """
    from edge.estimation.estimate import DEFAULT_PRIOR_COEF  # noqa: PLC0415
    from edge.estimation.identification import Library  # noqa: PLC0415
    from edge.physics.materials import load_materials  # noqa: PLC0415

    mats = list(load_materials())
    s = [m.solid for m in mats]
    return Library([x.effusivity_W_s05_m2K for x in s], [x.k_W_mK for x in s], [x.rho_c_J_m3K for x in s],
                   [m.name for m in mats], [m.cls for m in mats], kernel_floor_ln=DEFAULT_PRIOR_COEF[0],
                   rho_c_intrinsic_ln=DEFAULT_PRIOR_COEF[1], material_spread_ln=DEFAULT_PRIOR_COEF[2])


def alpha_prior(e: float, u_ln_e: float = 0.02, library=None) -> tuple[float, float]:
    """ln(alpha) mean and standard deviation of an object of effusivity e (alpha = (e / rho c)^2).

    ``library``: the prior's :class:`~edge.estimation.identification.Library` (default: the CSV's).
    """
    m, sd, _ = (library if library is not None else _library()).prior_rho_c(e, u_ln_e)
    return 2.0 * math.log(e) - 2.0 * m, 2.0 * sd


@dataclass(frozen=True)
class LateralProfile:
    """The disk fit at the diffusivity the touch and the library prior make most likely.

    ``fit`` is the chain's fit with a uniform disk of the heater's radius on a half-space of
    diffusivity ``exp(ln_alpha)``; ``u_ln_alpha`` the standard deviation of ln(alpha) from the
    profile's curvature (the prior's when the record says nothing); ``slope`` d ln e / d ln alpha
    there; ``prior`` the library's (mean, sd) of ln(alpha) given e; ``profiled`` False where the
    lateral loss was negligible and alpha was left at the prior.
    """

    fit: Any
    ln_alpha: float
    u_ln_alpha: float
    slope: float
    prior: tuple[float, float]
    profiled: bool

    @property
    def u_ln_e(self) -> float:
        """The part of u(ln e) that alpha's uncertainty leaves."""
        return abs(self.slope) * self.u_ln_alpha


def lateral_profile(fit_disk: Callable[[float], Any], e_1d: float, noise_T_K: float,
                    point: Callable[[float], Any] | None = None, library=None) -> LateralProfile | None:
    """Profile the chain's disk fit over ln(alpha), with the library's prior on alpha given e.

    The heated disk loses heat sideways into the object at a rate set by its alpha, which the
    centre's temperature history carries once sqrt(alpha t) nears the heater's radius (a metal
    within seconds).  The objective is the fit's residual sum of squares over its variance plus the
    prior's ((ln alpha - m) / sd)^2 (m, sd the library's given the point's e), minimised on a grid
    and by golden section; the residual's curvature there gives u(ln alpha) (Laplace), never more
    than the prior's.  The residual variance is the larger of
    the noise measured in air and the best fit's own, times its lag-1 inflation: a smooth model error
    (a finite block is not a half-space) must not pass for information on alpha.

    Parameters
    ----------
    fit_disk : callable
        alpha (m^2/s) -> the chain's fit with the disk at that alpha.
    e_1d : float
        The 1-D fit's e (the prior's first guess).
    noise_T_K : float
        Thermocouple noise (K).
    point : callable, optional
        alpha -> e and the residual only (:meth:`edge.estimation.sensor_chain.DiskFitter.point`),
        for the profile's inner loop; ``fit_disk`` then makes only the answer's full fit.
    library : Library, optional
        The prior's library (default: the CSV's; the seam passes the model bundle's).

    Returns
    -------
    LateralProfile or None
        None when no fit over the range is usable.
    """
    def ok(r) -> bool:
        return math.isfinite(r.e_W_s05_m2K) and r.e_W_s05_m2K > 0 and r.n_fitted > 3

    lo_b, hi_b = (math.log(x) for x in ALPHA_BOUNDS_m2_s)
    m0, sd0 = alpha_prior(e_1d, library=library)
    lo, hi = max(lo_b, m0 - ALPHA_SPAN_SD * sd0), min(hi_b, m0 + ALPHA_SPAN_SD * sd0)
    if not lo < hi:
        lo, hi = lo_b, hi_b
    fits: dict[float, Any] = {}

    inner = fit_disk if point is None else point

    def at(la: float):
        if la not in fits:
            fits[la] = inner(math.exp(la))
        return fits[la]

    # A lateral loss (at the prior's alpha) too small to stand out of the probe's own departures from
    # the model: alpha stays at the prior, which the record cannot improve on.
    r_hi, r_m = at(min(hi, m0 + 2.0 * sd0)), at(m0)
    if not (ok(r_hi) and ok(r_m)):
        return None
    if abs(math.log(r_m.e_W_s05_m2K / e_1d)) < LATERAL_PROFILE_MIN:
        m, sd = alpha_prior(r_m.e_W_s05_m2K, library=library)
        slope = math.log(r_hi.e_W_s05_m2K / r_m.e_W_s05_m2K) / (min(hi, m0 + 2.0 * sd0) - m0)
        full = r_m if point is None else fit_disk(math.exp(m0))
        return LateralProfile(full, m0, sd, slope, (m, sd), profiled=False) if ok(full) else None
    grid = np.linspace(lo, hi, ALPHA_GRID)
    good = [at(x) for x in grid if ok(at(x))]
    if not good:
        return None
    best = min(good, key=lambda r: r.rms_residual_K)
    s2 = max(best.rms_residual_K ** 2 * best.n_fitted / max(1, best.n_fitted - 3), noise_T_K ** 2) \
        * best.residual_inflation
    # The prior at each point's own e.  Fixed at the e of the record's best grid point it followed the
    # noise: on the reference board's 0.0625-K steps an aluminium touch's best point can sit at any
    # alpha (the calibration bench's reference board, at commit 654a9b8); fixed at the e of the disk
    # fit at the 1-D fit's prior alpha it let copper's alpha run low.
    def D(la: float) -> float:       # the data's part: residual sum of squares over its variance
        r = at(la)
        return r.rms_residual_K ** 2 * r.n_fitted / s2 if ok(r) else math.inf

    def J(la: float) -> float:       # ... and the prior's
        r = at(la)
        if not ok(r):
            return math.inf
        m, sd = alpha_prior(r.e_W_s05_m2K, library=library)
        return D(la) + ((la - m) / sd) ** 2

    j = int(np.argmin([J(x) for x in grid]))
    a, b = grid[max(0, j - 1)], grid[min(grid.size - 1, j + 1)]
    g = (math.sqrt(5.0) - 1.0) / 2.0
    c, d = b - g * (b - a), a + g * (b - a)
    for _ in range(ALPHA_REFINE):
        if J(c) < J(d):
            b, d = d, c
            c = b - g * (b - a)
        else:
            a, c = c, d
            d = a + g * (b - a)
    la = min((grid[j], c, d), key=J)
    r = fit_disk(math.exp(la)) if point is not None else at(la)
    if not ok(r):
        return None
    m, sd = alpha_prior(r.e_W_s05_m2K, library=library)
    h = ALPHA_STEP_LN
    rp, rm = at(la + h), at(la - h)
    slope = (math.log(rp.e_W_s05_m2K / rm.e_W_s05_m2K) / (2.0 * h)) if ok(rp) and ok(rm) else 0.0
    # u(ln alpha): what the record alone pins (its curvature), or the prior's sd where the record
    # pins less.  Not the posterior's: through rho c's prior given e, a low e raises the prior's alpha,
    # which lowers e -- on a noise-limited copper touch that loop made the posterior over-confident.
    curv = (D(la + h) - 2.0 * D(la) + D(la - h)) / (h * h)
    u_data = math.sqrt(2.0 / curv) if curv > 0 and math.isfinite(curv) else math.inf
    return LateralProfile(r, la, min(u_data, sd), slope, (m, sd), profiled=True)


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


def contact_fraction(tt, TT, qq, chain, breaks, noise_T: float) -> tuple[float, float]:
    """Where, within its first interval, the contact happened, and u(ln e) from not knowing it better.

    :func:`find_contact` names the last sample in air; the contact lies anywhere in the interval that
    follows (ISSUE #34 item 5).  On the device's 10-Hz hand touches it lay 90 ms after that sample, and
    with the object 1 K off the probe the chain, starting the object's response there, read macor
    -8 % and Ti-6Al-4V -8.5 % at 1 s of heating (-3 % at 2 s).  On a record the chain runs refined
    (:data:`edge.estimation.sensor_chain.REFINE_DT_s`) each candidate instant is fitted
    (1-D, one pass) and the one the record fits best is taken; the change of ln e to its neighbours,
    for an instant uniform between them, is its standard uncertainty.  Records sampled finely enough
    are not refined (:func:`edge.estimation.sensor_chain.refine_factor`): the contact is then taken at 0.
    Every fine point of the interval is tried (k / m, k = 0 .. m - 1: at 50 Hz on the 5-ms grid 0, 5,
    10, 15 ms after the sample).
    """
    m = refine_factor(float(tt[1] - tt[0]))
    if m == 1:
        return 0.0, 0.0
    got = []
    for f in (k / m for k in range(m)):
        try:
            # e and the residual only: the candidates are compared on nothing else (chain_point).
            r = chain_point(tt, TT, qq, calibration=chain, fit_start_s=FIT_START_s, breaks_s=breaks, contact_frac=f)
        except ValueError:
            continue
        if r.e_W_s05_m2K > 0 and math.isfinite(r.e_W_s05_m2K) and math.isfinite(r.rms_residual_K):
            got.append((f, r.e_W_s05_m2K, r.rms_residual_K))
    if not got:
        return 0.0, 0.0
    best = min(range(len(got)), key=lambda i: got[i][2])
    e = got[best][1]
    near = [got[i][1] for i in (best - 1, best + 1) if 0 <= i < len(got)]
    u = max((abs(math.log(x / e)) for x in near), default=0.0) / math.sqrt(3.0)
    return got[best][0], u


#: Whole answers of :func:`estimate_from_contact` by their exact inputs.  A touch is estimated more than once
#: on the same numbers: the device's answer repeats the running decision's last refit when that refit saw the
#: whole record, and ``thermotouch estimate`` of an exported touch (in the same process: the CLI's tests, the
#: demo) repeats the device's.  Kept per record bytes, the calibration's and the library's content and this
#: module's tunables; a hit returns a copy, the same numbers a recomputation gives.
_ESTIMATES = BoundedMemo(32)


def _calibration_key(cal: Any) -> tuple | None:
    """The calibration's content as a key (None: no content key known -- the estimate is not kept)."""
    if cal is None or type(cal) is DatasheetChain:
        return ("datasheet", cal)                       # frozen, compared by its fields
    return object_key(cal, calibration_content)


def _tunables() -> tuple:
    """This module's and the sensor chain's constants as they are now (a test may change one)."""
    return tunables(sys.modules[__name__], sensor_chain)


def _estimate_key(t_s, T_C, q_W_m2, calibration: Any, heater_radius_m: float | None, library: Any,
                  T_resolution_K: float = 0.0) -> tuple | None:
    cal_key, lib_key = _calibration_key(calibration), library_key(library)
    if cal_key is None or lib_key is None:
        return None
    arrays = [np.asarray(x, dtype=np.float64) for x in (t_s, T_C, q_W_m2)]
    return (*((a.shape, a.tobytes()) for a in arrays), cal_key, lib_key,
            None if heater_radius_m is None else float(heater_radius_m), float(T_resolution_K), _tunables())


#: One fit window's 1-D fit and lateral profile (:func:`_window_profile`) by their exact inputs.  A running
#: decision refits the growing record every ``CHAIN_EVERY_s``: the windows that end before the record does
#: (heater-on + 1 s, + 2 s, ...) hold the same samples at every later refit (59 of 91 windows of a replayed
#: round trip's refits were repeats).
_WINDOWS = BoundedMemo(64)


def _window_profile(tt: np.ndarray, TT: np.ndarray, qq: np.ndarray, chain: SensorChainCalibration, noise_T: float,
                    breaks: tuple, frac: float, a: float, library: Any) -> tuple[Any, LateralProfile | None]:
    """The 1-D disk-free fit of one window and its lateral profile (None when that fit is unusable), kept."""
    lib_key = library_key(library)
    key = None if lib_key is None else (tt.tobytes(), TT.tobytes(), qq.tobytes(), chain, float(noise_T), breaks,
                                        float(frac), float(a), lib_key, _tunables())
    hit = None if key is None else _WINDOWS.get(key)
    if hit is not None:
        return hit
    F = DiskFitter(tt, TT, qq, calibration=chain, fit_start_s=FIT_START_s, noise_T_K=noise_T, breaks_s=breaks,
                   contact_frac=frac)
    c1 = F(None)
    p = None
    if math.isfinite(c1.e_W_s05_m2K) and c1.e_W_s05_m2K > 0:
        p = lateral_profile(lambda al: F((a, al)), c1.e_W_s05_m2K, noise_T, point=lambda al: F.point((a, al)),
                            library=library)
    if key is not None:
        for res in (c1, None if p is None else p.fit):   # shared from here on: read-only
            if res is not None:
                res.correlation.flags.writeable = False
        _WINDOWS.put(key, (c1, p))
    return c1, p


def estimate_from_contact(t_s, T_C, q_W_m2, calibration: Any = None, *,
                          heater_radius_m: float | None = None, library=None,
                          T_resolution_K: float = 0.0) -> dict[str, Any]:
    """e, R_c and T_obj0 of one touch, with their uncertainties, flags and the fit's quality.

    Parameters
    ----------
    t_s : array (n,)
        Uniform times, s, 0 at heater-on (negative before: from before contact if possible).
    T_C : array (n,)
        Absolute thermocouple temperature (degC or K; T_obj0 is returned on the same scale).
    q_W_m2 : array (n,)
        Flux-sensor voltage over its nominal sensitivity, W/m^2.
    calibration : edge.calibration.model.ProbeCalibration, optional
        Default: the uncalibrated datasheet probe (:class:`DatasheetChain`, flagged).
    heater_radius_m : float, optional
        Radius of the heated disk (default: the calibration's probe's); ``math.inf`` for 1-D.  The
        object loses heat sideways from a finite disk at a rate set by its alpha: e is the disk
        fit's at the alpha the record and the library prior make most likely, alpha's uncertainty
        and the fit's change between windows going into u(e) (``u_e_parts["lateral"]``).
    library : Library, optional
        The prior on alpha given e (default: the CSV's; the seam passes the model bundle's).
    T_resolution_K : float, optional
        The thermometer's step (K; the record's ``T_resolution_K``).  A heating ramp read through it
        errs by step / sqrt 12 per sample, which samples in air sitting on one code do not show: the
        goodness of fit is judged against at least that (the reference board's 16-bit MCP9600, 0.197 K,
        0.057 K; on the precision board's converter it is far below the noise and changes nothing).

    Returns
    -------
    dict
        ``effusivity_W_s05_m2K`` and ``..._u`` (k = 1) with its parts ``u_e_parts`` (fit,
        calibration, floor, contact, lateral), ``contact_resistance_m2K_W`` (+ ``_u``),
        ``object_temperature0`` (+ ``_u``), ``probe_temperature0``, ``contact_t_s``,
        ``normalised_residual``, ``flags``, ``determined``, ``calibration_sha256``; with a finite
        heater also ``alpha_m2_s``, ``k_W_mK`` (+ ``_u``; measured when ``determined`` lists them,
        otherwise the prior's) and ``alpha_prior_ln`` (mean, sd of ln alpha).  Flags are
        :class:`edge.status.Flag` words.  The same inputs give the same answer, kept (:data:`_ESTIMATES`).
    """
    T_resolution_K = float(T_resolution_K)
    if not (math.isfinite(T_resolution_K) and T_resolution_K >= 0.0):
        raise ValueError(f"T_resolution_K must be a non-negative finite number, got {T_resolution_K!r}")
    key = _estimate_key(t_s, T_C, q_W_m2, calibration, heater_radius_m, library, T_resolution_K)
    hit = None if key is None else _ESTIMATES.get(key)
    if hit is not None:
        return copy.deepcopy(hit)
    d = _estimate_from_contact(t_s, T_C, q_W_m2, calibration, heater_radius_m=heater_radius_m, library=library,
                               T_resolution_K=T_resolution_K)
    if key is not None:
        _ESTIMATES.put(key, copy.deepcopy(d))
    return d


def _estimate_from_contact(t_s, T_C, q_W_m2, calibration: Any = None, *,
                           heater_radius_m: float | None = None, library=None,
                           T_resolution_K: float = 0.0) -> dict[str, Any]:
    """:func:`estimate_from_contact`, computed."""
    cal = DatasheetChain() if calibration is None else calibration
    t, T, q = uniform_record(t_s, T_C, q_W_m2)
    c = find_contact(t, T, q)
    flags: list[Flag] = [] if cal.calibrated else [Flag.UNCALIBRATED]
    i0 = c.index
    tt, TT, qq = t[i0:] - t[i0], T[i0:], q[i0:]
    if tt.size < 8 or tt[-1] < FIT_START_s + 0.2:
        raise ValueError(f"record too short after contact ({tt[-1]:.2f} s from t = {t[i0]:.2f} s)")
    noise_T = c.noise_T_K if math.isfinite(c.noise_T_K) and c.noise_T_K > 0 else DEFAULT_NOISE_T_K
    # Air samples that hardly move (a quiet simulator, a converter sitting on one code) measure ~0:
    # the goodness of fit is judged against at least NOISE_FLOOR_K.
    noise_T = max(noise_T, NOISE_FLOOR_K)
    # A coarse thermometer's step errs a ramp by step / sqrt 12 per sample, which air samples sitting on
    # one code do not show (the 16-bit MCP9600: 0.197 K steps, 0.057 K; every reference-board touch was
    # poor_fit without it).  max, not in quadrature: where the air samples dither they carry part of it.
    noise_T = max(noise_T, T_resolution_K / math.sqrt(12.0))
    # The heater switched on at t = 0 of the record's clock: theta_b's slope jumps there.
    breaks = (-float(t[i0]),) if t[i0] < 0 else ()
    a = PROBES[cal.probe].heater_radius_m if heater_radius_m is None else float(heater_radius_m)

    # Where within its first interval the contact happened (a refined grid only; see contact_fraction).
    frac, u_instant = contact_fraction(tt, TT, qq, cal.chain, breaks, noise_T) if c.recorded_in_air else (0.0, 0.0)

    def fit(chain, disk, start=FIT_START_s):
        return fit_sensor_chain(tt, TT, qq, calibration=chain, fit_start_s=start, noise_T_K=noise_T,
                                breaks_s=breaks, disk=disk, contact_frac=frac)

    def bad(x) -> bool:
        return not (math.isfinite(x.e_W_s05_m2K) and x.e_W_s05_m2K > 0)

    t_lost = contact_lost_at(tt, face_flux(tt, TT, qq, cal.chain, breaks_s=breaks), breaks[0] if breaks else 0.0)
    if t_lost is not None:
        # A lifted probe: what follows is the probe in air, not the object.  Refused, not fitted
        # (fitting up to the lift would pass off a shorter, unplanned touch as the measurement).
        return {"flags": flags + [Flag.CONTACT_LOST], "effusivity_W_s05_m2K": None, "effusivity_W_s05_m2K_u": None,
                "contact_t_s": float(t[i0]), "contact_lost_t_s": float(t[i0] + t_lost),
                "normalised_residual": None, "determined": [], "calibration_sha256": cal.sha256,
                "probe": cal.probe}

    r1d = r = fit(cal.chain, None)
    disk = None
    lat: LateralProfile | None = None
    u_lat = 0.0
    if not bad(r) and math.isfinite(a):
        # The finite heater loses heat sideways into the object, at a rate set by the object's alpha
        # (and its size, which one touch does not give).  Per fit window (heater-on + 1, 2, 4, 8 s or
        # the whole record) alpha is profiled with the library's prior (lateral_profile), e taken at
        # the most likely alpha and u(e) widened by alpha's uncertainty and by the change of e from
        # the next shorter window (a finite block departs from a half-space the longer the window:
        # e moves between windows where the disk does not describe the object).  The window is the
        # one whose stated u is least.  On a metal the profile pins alpha to ~10 %: the touch then
        # measures alpha and k too.
        full = (tt, TT, qq)
        t_heat = -float(t[i0]) if t[i0] < 0 else 0.0
        cands = []
        for extra in LATERAL_WINDOWS_s:
            n_keep = int(np.searchsorted(full[0], t_heat + extra, side="right"))
            if n_keep < 16 or (cands and n_keep >= full[0].size and extra != math.inf):
                continue
            tt, TT, qq = (x[:n_keep] for x in full)
            c1, p = _window_profile(tt, TT, qq, cal.chain, noise_T, breaks, frac, a, library)
            if bad(c1) or p is None or bad(p.fit):
                continue
            cands.append([n_keep, c1, p, math.hypot(p.fit.u_e_W_s05_m2K / p.fit.e_W_s05_m2K, p.u_ln_e), 0.0])
        for k, cnd in enumerate(cands):
            # Against the longest window at most 2/3 as long (the whole record may end just after 8 s),
            # for the shortest against the next that is 1.5 times longer.
            shorter = [x for x in cands[:k] if x[0] <= cnd[0] / 1.5]
            longer = [x for x in cands[k + 1:] if x[0] >= cnd[0] * 1.5]
            other = shorter[-1] if shorter else (longer[0] if longer else None)
            if cnd[2].profiled and other is not None:
                cnd[4] = abs(math.log(cnd[2].fit.e_W_s05_m2K / other[2].fit.e_W_s05_m2K))
        if cands:
            n_keep, r1d, lat, _, d_win = min(cands, key=lambda x: math.hypot(x[3], x[4]))
            r = lat.fit
            disk = (a, math.exp(lat.ln_alpha))
            u_lat = math.hypot(lat.u_ln_e, d_win)
            tt, TT, qq = (x[:n_keep] for x in full)
        else:
            tt, TT, qq = full
    if bad(r):
        return {"flags": flags + [Flag.NO_FIT], "effusivity_W_s05_m2K": None, "effusivity_W_s05_m2K_u": None,
                "contact_t_s": float(t[i0]), "normalised_residual": r.normalised_residual,
                "determined": [], "calibration_sha256": cal.sha256, "probe": cal.probe}
    e = r.e_W_s05_m2K
    if disk is not None and abs(math.log(e / r1d.e_W_s05_m2K)) > LATERAL_FLAG:
        flags.append(Flag.LATERAL_SPREAD)
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
        flags.append(Flag.CONTACT_NOT_RECORDED)
        r_late = fit(cal.chain, disk, 1.0)
        if r_late.e_W_s05_m2K > 0 and math.isfinite(r_late.e_W_s05_m2K):
            u_contact = abs(math.log(r_late.e_W_s05_m2K / r.e_W_s05_m2K))
    else:
        u_contact = u_instant
    # The calibration's model-form term at this e: its floor, growing outside the references' span by
    # the rate its leave-one-out check measured (ProbeCalibration.model_form_u_rel; the datasheet chain: 0).
    model_form = getattr(cal, "model_form_u_rel", None)
    u_floor = float(model_form(e)) if model_form is not None else float(cal.u_rel_floor)
    u_rel = math.sqrt(u_fit**2 + u_cal**2 + u_floor**2 + u_contact**2 + u_lat**2)
    # R_c leans on the first second after contact, where the smoothing of theta_b (a bias-variance
    # choice) bends the storage term most: the change of R_c without it is part of R_c's uncertainty.
    r_raw = fit_sensor_chain(tt, TT, qq, calibration=cal.chain, fit_start_s=FIT_START_s, noise_T_K=noise_T,
                             breaks_s=breaks, disk=disk, smooth_s=0.0, contact_frac=frac)
    u_Rc_method = abs(r_raw.R_c_m2K_W - r.R_c_m2K_W) if math.isfinite(r_raw.R_c_m2K_W) else 0.0
    u_Rc = math.sqrt(r.u_R_c_m2K_W**2 + float(var_cal[1]) + u_Rc_method**2)
    if r.normalised_residual > POOR_FIT:
        flags.append(Flag.POOR_FIT)
    # e counts as determined only when it survives the calibration's model-form floor (ISSUE #34): a
    # forced calibration whose references missed by tens of per cent determines nothing, however
    # well the touch itself fitted.  (What the touch's own u does to "determined" is unchanged.)
    e_determined = u_floor < E_DETERMINED_U_REL
    determined = (["e"] if e_determined else []) + ["T_obj0"] + (["R_c"] if u_Rc <= R_C_RESOLVED_m2K_W else [])
    lateral: dict[str, Any] = {}
    if lat is not None:
        # ln k = ln e + ln(alpha) / 2 along the profile: alpha's part enters with slope + 1/2, the
        # rest of u(ln e) as it is.
        alpha = math.exp(lat.ln_alpha)
        u_ln_k = math.sqrt(max(u_rel**2 - lat.u_ln_e**2, 0.0) + ((lat.slope + 0.5) * lat.u_ln_alpha) ** 2)
        k = e * math.sqrt(alpha)
        lateral = {"alpha_m2_s": alpha, "alpha_m2_s_u": alpha * lat.u_ln_alpha, "k_W_mK": k, "k_W_mK_u": k * u_ln_k,
                   "alpha_prior_ln": list(lat.prior)}
        if e_determined and lat.profiled and lat.u_ln_alpha < ALPHA_DETERMINED * lat.prior[1]:
            determined += ["alpha", "k"]
    return {
        "effusivity_W_s05_m2K": e,
        "effusivity_W_s05_m2K_u": e * u_rel,
        "u_e_parts": {"fit": u_fit, "calibration": u_cal, "floor": u_floor, "contact": u_contact,
                      "lateral": u_lat},
        # The fit's part on the stated noise alone, nuisances (T_obj0, R_c) fitted and known: what of
        # u_e_parts["fit"] is noise, nuisance and residual excess (bench/asbuilt_calibrated_bench.py).
        "u_e_fit_noise": r.u_ln_e_noise, "u_e_fit_noise_nuisance_known": r.u_ln_e_noise_nuisance_known,
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
        "determined": determined,
        "calibration_sha256": cal.sha256, "probe": cal.probe,
        **lateral,
    }
