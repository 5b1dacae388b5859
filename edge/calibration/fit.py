"""Calibrating the sensor chain on touches of reference materials (ISSUE #10 §4).

Model.  Every reference touch j of material m obeys the sensor chain of
:mod:`edge.estimation.sensor_chain` from its contact on, with its own object
temperature and contact resistance (nuisances, solved linearly by variable
projection) and the material's effusivity e_m.  The probe's parameters
theta = (ln flux_scale, ln sensing depth, bead lag, ln sensing-layer k) are shared by all
touches.  Unknowns: theta and ln e_m.  Priors: ln e_m around the library's
value with the reference's stated uncertainty (:data:`REFERENCE_U_REL`), and
theta around the datasheet with the as-delivered spreads
(:meth:`ProbeCalibration.nominal`): a parameter the references cannot
resolve keeps its datasheet spread instead of wandering.

Contact instant.  A touch's contact lies anywhere within the sample interval after its last sample
in air; the chain runs on a refined grid that places it (:func:`edge.estimation.chain_estimate.contact_fraction`,
what the estimator does on every touch).  Each reference touch's instant is found with the datasheet
chain, the fit made, the instants found again with the fitted chain and the fit repeated from there
(:data:`FIT_CONTACT_INSTANT`).  Fitted with the contact at the interval's start instead, the
walk-through's hand touches (object +-3 K, 10 Hz) pulled the layer's depth 4-12 % and its k 9-22 %
below the drawn probes' true values on 8 of 8 probes, and the calibrated probe read woods 15-58 %
high (bench/asbuilt_calibrated_bench.py --attribute: with the true chain they read within 2 %).

Weights.  Each touch's residuals are scaled by its own residual level: the
rms residual of an unconstrained chain fit on it, inflated for the
residuals' lag-1 autocorrelation (as in the estimator).

Solution.  Levenberg-Marquardt on the stacked, weighted residuals, Jacobian
by forward differences (4 + M columns, each a few sub-millisecond fits).
Covariance of theta: the theta block of (J^T J)^-1 at the solution.

Noise bias.  The thermocouple's noise enters both the fitted temperature and
the storage term through which the sensing layer is fitted (errors in
variables): the fitted depth comes out low, by about 3 % with the precision
board's noise and 8 % with the reference board's.  :func:`_noise_bias`
measures that shift on noise-free copies of the touches made by the fitted
chain itself, refitted with antithetic pairs of noise of each record's own
measured level, and the solution is moved back by it; the estimate's own
scatter is added to the covariance.

Transfer floor.  The calibrated chain then re-measures every reference
touch with e free; the mean square of its relative errors against the
reference values the fit settled on (the library's, moved within their
stated uncertainty -- that part is in theta's covariance already) less
what each touch's stated noise explains, scaled by
n / (n - p) for the p = 4 parameters the same touches fixed, is stored as
``u_rel_floor``: the part of the real probe the chain does not describe,
added to every later measurement.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from datetime import datetime, timezone

import numpy as np

from edge.calibration.model import N_PARAMETERS as NP, CalibrationError, ProbeCalibration, ReferenceFit
from edge.estimation.chain_estimate import contact_fraction
from edge.estimation.contact import find_contact
from edge.estimation.sensor_chain import chain_design, fit_sensor_chain, simulate_chain
from edge.physics.memo import BoundedMemo

__all__ = ["DEFAULT_REFERENCES", "REFERENCE_U_REL", "ReferenceTouch", "check_reference", "clear_fit_memo",
           "fit_calibration"]

#: The references a user is walked through by default (one polymer, one ceramic, one metal).
DEFAULT_REFERENCES = ("pmma", "pyroceram", "aisi_304")
#: Relative standard uncertainty of a reference's effusivity.  Pyroceram 9606 and AISI 304 are
#: certified thermal-conductivity references (about 2 %); PMMA is a well-characterised polymer whose
#: grades differ by a few per cent.  Any other library material: a handbook value (5 %).
REFERENCE_U_REL = {"pmma": 0.03, "pyroceram": 0.02, "aisi_304": 0.02}
OTHER_REFERENCE_U_REL = 0.05
#: Swapped-reference bound (:func:`check_reference`): the datasheet probe's e within this factor of the
#: reference's, widened by SWAP_SIGMAS of the touch's own stated u.
SWAP_RATIO = 2.0
SWAP_SIGMAS = 3.0
FIT_START_s = 0.3
#: How fast the storage term's smoothing widens after contact and heater-on in the calibration's fit
#: (samples per sample of half-width; the estimator's is sensor_chain.SMOOTH_GROWTH = 6).  The
#: thermocouple's noise, shared by the fitted temperature and the storage term, biased the fitted
#: sensing layer (the depth 3.9 % low on average against a stated 2.4 %) and with it the contact
#: resistances measured through it: their 95 % intervals held the truth on 80 % of touches
#: (``python bench/calibration_bench.py --geometry 1d --cal-smooth-growth 6``).  Widening sooner
#: averages that noise away where the layer is decided, at the price of bending the curved theta_b a
#: little.  Growth 6 / 4 / 3 / 2 / 1 held R_c in its interval on 82-80 / 96-86 / 98-89 / 98-93 /
#: 48-27 % of the bench's 1-D touches (R_c below / above 3e-5) with e unchanged (median error 1.2 %):
#: 3 keeps a margin from where bending takes over.
CAL_SMOOTH_GROWTH = 3
_STEPS = (1e-4, 1e-4, 1e-3, 1e-4)
#: Antithetic pairs of noise realisations of the calibration's noise-bias correction (:func:`_noise_bias`)
#: and their seed.  Off by default (ISSUE #34 item 6): its synthetic copies come from
#: :func:`simulate_chain`, which has no storage term for the contact step of an object at another
#: temperature than the probe, so on hand-touched references (object +-1..3 K) the copies are not
#: records the chain can fit and the "bias" it measured was that mismatch, not the noise's: on
#: noise-free faithful-world references (1-D limit, objects +-1 K) it moved the fitted sensing depth
#: by +0.3 to +1.1 % away from the as-built value on 3 of 3 probes (without it: +1.2 to +1.7 %).  On
#: records the chain does describe (object at the probe's temperature) it is unbiased -- noise-free
#: records come back within 1e-4 in every parameter with or without it
#: (tests/edge/calibration/test_fit.py) -- and still undoes the depth pull of a noisy (0.03 K)
#: thermocouple when asked for (``noise_bias_draws=3``).
NOISE_BIAS_DRAWS = 0
NOISE_BIAS_SEED = 20261123
#: Least noise assumed where a record has no samples in air to measure it on (K; W/m^2): the
#: precision board's converters (see edge.estimation.chain_estimate.NOISE_FLOOR_K).
NOISE_FLOOR_T_K = 2e-3
NOISE_FLOOR_q_W_m2 = 0.1
_MAX_ITER = 30
#: Fit each reference touch's contact instant within its first sample interval (module docstring).
FIT_CONTACT_INSTANT = True


@dataclass(frozen=True)
class ReferenceTouch:
    """One touch of a reference material, on the device's clock (0 at heater-on).

    ``T_C`` is the absolute thermocouple temperature, ``q_W_m2`` the flux-sensor voltage over its
    nominal sensitivity.  The record should start with the probe in air (see
    :func:`edge.estimation.contact.find_contact`).
    """

    name: str
    e_W_s05_m2K: float
    t_s: np.ndarray
    T_C: np.ndarray
    q_W_m2: np.ndarray

    @property
    def u_rel_e(self) -> float:
        return REFERENCE_U_REL.get(self.name, OTHER_REFERENCE_U_REL)


def _from_contact(touch: ReferenceTouch):
    """(t from contact, T, q, breaks, noise_T, noise_q): the record from its contact on, where the heater
    switched on, and the noise of T and q measured in air before contact.

    Raises :class:`CalibrationError` for a record that does not start in air: the chain's fit starts
    at contact, and a record without its pre-contact phase (an export cut at heater-on, another probe
    head's record) has no contact to start from.
    """
    t, T, q = (np.asarray(x, dtype=np.float64) for x in (touch.t_s, touch.T_C, touch.q_W_m2))
    try:
        c = find_contact(t, T, q)
    except ValueError as exc:
        raise CalibrationError(f"reference {touch.name}: {exc}") from None
    if not c.recorded_in_air:
        raise CalibrationError(f"reference {touch.name}: the record does not start in air before contact (the "
                               "chain's fit needs the pre-contact phase: record from before the touch)")
    i = c.index
    return (t[i:] - t[i], T[i:], q[i:], ((-float(t[i]),) if t[i] < 0 else ()),
            _measured(c.noise_T_K, NOISE_FLOOR_T_K), _measured(c.noise_q_W_m2, NOISE_FLOOR_q_W_m2))


def _measured(x: float, floor: float) -> float:
    """A noise measured in air, or ``floor`` where the record has none (or it reads as quieter)."""
    return max(float(x), floor) if math.isfinite(x) else floor



def _residual_fn(arrays, idx, prior: ProbeCalibration, th0, u_th0, ln_e0, u_ln_e):
    """Stacked weighted residuals of p = (theta, ln e_m) over the touches (nuisances by variable projection).

    The touches' designs depend on theta only: they are kept for the last few theta, so the
    Jacobian's ln e_m columns (theta unchanged) reuse the base point's instead of rebuilding
    every touch's chain -- the same arrays, so the same residuals to the bit.
    """
    designs: dict[bytes, list] = {}

    def design(th: np.ndarray) -> list:
        key = th.tobytes()
        d = designs.pop(key, None)
        if d is None:
            chain = prior.chain_at(th)
            d = [chain_design(tt, TT, qq, chain, fit_start_s=FIT_START_s, breaks_s=br,
                              smooth_growth=CAL_SMOOTH_GROWTH, contact_frac=fr) for tt, TT, qq, _, br, fr in arrays]
        designs[key] = d                   # most recent last
        while len(designs) > NP + 2:       # the base point, its NP theta steps and a trial step
            del designs[next(iter(designs))]
        return d

    def residuals(p: np.ndarray) -> np.ndarray:
        th, ln_e = p[:NP], p[NP:]
        out = []
        for (X, y), (_, _, _, w, _, _), m in zip(design(th), arrays, idx):
            y2 = y - X[:, 2] * math.exp(-ln_e[m])
            beta = np.linalg.lstsq(X[:, :2], y2, rcond=None)[0]
            out.append(w * (y2 - X[:, :2] @ beta))
        out.append((th - th0) / u_th0)
        out.append((ln_e - ln_e0) / u_ln_e)
        return np.concatenate(out)
    return residuals


def _solve(arrays, idx, prior, th0, u_th0, ln_e0, u_ln_e, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg-Marquardt from ``p``: the solution and its Jacobian (forward differences)."""
    residuals = _residual_fn(arrays, idx, prior, th0, u_th0, ln_e0, u_ln_e)
    steps = np.array(list(_STEPS) + [1e-4] * (p.size - NP))
    centre, width = np.concatenate([th0, ln_e0]), np.concatenate([u_th0, u_ln_e])
    p = np.array(p, dtype=np.float64)
    r = residuals(p)
    cost = float(r @ r)
    lam = 1e-3

    def jac(p: np.ndarray, r: np.ndarray) -> np.ndarray:
        J = np.empty((r.size, p.size))
        for j in range(p.size):
            pj = p.copy()
            pj[j] += steps[j]
            J[:, j] = (residuals(pj) - r) / steps[j]
        return J

    J = jac(p, r)
    for _ in range(_MAX_ITER):
        A = J.T @ J
        g = J.T @ r
        improved = False
        for _ in range(10):
            delta = np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-12), -g)
            p_new = p + delta
            p_new[2] = max(p_new[2], 0.0)   # a bead cannot lead its junction
            # A trial step that leaves the model's domain is a step too long, not an error: on touches
            # whose contact the record cannot place (an object at the probe's own temperature) the
            # normal equations are nearly singular, and an undamped step once sent ln flux_scale
            # past exp's range ("OverflowError: math range error", ISSUE #34).
            c_new, r_new = (_trial_cost(residuals, p_new) if np.all(np.abs(p_new - centre) <= _MAX_PRIOR_SIGMAS * width)
                            else (math.inf, None))
            if c_new < cost:
                improved = True
                break
            lam *= 10.0
        if not improved:
            break
        done = cost - c_new < 1e-10 * max(cost, 1.0) or _small_step(A, delta)
        p, r, cost = p_new, r_new, c_new
        lam = max(lam / 10.0, 1e-9)
        J = jac(p, r)
        if done:
            break
    return p, J


#: Converged when an accepted step moved every parameter by less than this fraction of its standard
#: uncertainty.  The forward-difference Jacobian (steps 1e-4) cannot polish further: the iterations past
#: this point zig-zagged for cost changes of 1e-8 relative, and stopping here moved the fitted chain by
#: under 0.01 of its sigma (0.02 % in depth and k, 0.08 % in the bead lag) at half the fit's CPU time.
_STEP_TOL_SIGMA = 1e-2


def _small_step(A: np.ndarray, delta: np.ndarray) -> bool:
    """Whether ``delta`` is within :data:`_STEP_TOL_SIGMA` sd of every parameter (sd from ``A = J^T J``)."""
    try:
        sd = np.sqrt(np.abs(np.diag(np.linalg.inv(A))))
    except np.linalg.LinAlgError:
        return False
    return bool(np.all(np.abs(delta) <= _STEP_TOL_SIGMA * sd))


#: A trial step further than this many prior standard deviations from the prior is not evaluated (a step
#: too long: the plausibility bounds refuse far less, and the chain's design turns NaN out there).
_MAX_PRIOR_SIGMAS = 30.0


def _trial_cost(residuals, p: np.ndarray) -> tuple[float, np.ndarray | None]:
    """Sum of squares at ``p`` and the residuals; infinite (None) where the model cannot be evaluated."""
    try:
        r = residuals(p)
    except (OverflowError, ValueError, np.linalg.LinAlgError):
        return math.inf, None
    c = float(r @ r)
    return (c, r) if math.isfinite(c) else (math.inf, None)


def _noise_bias(arrays, idx, noise, prior, th0, u_th0, ln_e0, u_ln_e, p: np.ndarray,
                draws: int) -> tuple[np.ndarray, np.ndarray]:
    """The bias the records' noise puts into the fitted p, measured on the chain's own records.

    The thermocouple's noise enters both the fitted temperature and the storage term the layer is
    fitted through (errors in variables): the fitted depth comes out low by about the square of the
    noise over the signal -- 3 % on the precision board, 8 % on the reference board's MCP9600.  Each
    touch is re-made noise-free by the fitted chain (:func:`simulate_chain`, driven by the touch's own
    thermopile record, with the touch's fitted object temperature and contact resistance), fitted
    once as it is and with ``draws`` antithetic pairs of fresh noise of the level measured in air
    before its contact (thermocouple and thermopile); the mean shift of p is the bias.  A difference
    of fits of the same model: the chain need not reproduce the real record for it to hold.  Seeded:
    a calibration is reproducible.

    Returns the bias of p and the covariance of its estimate.
    """
    chain = prior.chain_at(p[:NP])
    clean = []
    for (tt, TT, qq, w, br, fr), m in zip(arrays, idx):
        e = math.exp(p[NP + m])
        X, y = chain_design(tt, TT, qq, chain, fit_start_s=FIT_START_s, breaks_s=br,
                            smooth_growth=CAL_SMOOTH_GROWTH, contact_frac=fr)
        d_T0, R_c = np.linalg.lstsq(X[:, :2], y - X[:, 2] / e, rcond=None)[0]
        Tp0 = float(TT[0])
        T_syn = simulate_chain(tt, qq, e_W_s05_m2K=e, R_c_m2K_W=float(R_c), T_obj0_C=Tp0 + float(d_T0),
                               T_probe0_C=Tp0, calibration=chain)
        clean.append((tt, T_syn, qq, w, br, fr))
    args = (idx, prior, th0, u_th0, ln_e0, u_ln_e)
    p0, _ = _solve(clean, *args, p)
    rng = np.random.default_rng(NOISE_BIAS_SEED)
    shifts = []
    for _ in range(draws):
        draw = [(s_T * rng.standard_normal(x[1].size), s_q * rng.standard_normal(x[2].size))
                for x, (s_T, s_q) in zip(clean, noise)]
        # Antithetic pairs: the noise and its negative.  The shift of p linear in the noise (the
        # fit's own scatter, as large as its stated u) cancels in the pair's mean; what is left is
        # the even part, the bias -- so a few pairs estimate it without adding the scatter to the
        # calibration.  A full refit per draw: one Gauss-Newton step from the clean solution missed
        # most of the shift (the reference board's depth bias is not linear in the noise).
        pair = []
        for sign in (1.0, -1.0):
            noisy = [(tt, T_syn + sign * nT, qq + sign * nq, w, br, fr)
                     for (tt, T_syn, qq, w, br, fr), (nT, nq) in zip(clean, draw)]
            pair.append(_solve(noisy, *args, p0)[0])
        shifts.append(0.5 * (pair[0] + pair[1]) - p0)
    shifts = np.asarray(shifts)
    # The bias and the covariance of its estimate (the draws' scatter over their number).
    cov = np.cov(shifts.T, ddof=1) / draws if draws > 1 else np.zeros((p.size, p.size))
    return shifts.mean(axis=0), np.atleast_2d(cov)


def check_reference(name: str, e_ref: float, e_W_s05_m2K: float | None, u_e_W_s05_m2K: float | None) -> None:
    """Refuse a reference touch whose datasheet-probe e contradicts its declared reference (swapped names).

    Bound: ``|ln(e / e_ref)| <= ln SWAP_RATIO + SWAP_SIGMAS * u_rel(e)``.  With the sensor chain's
    datasheet tolerances pushed to 2 sigma (sensitivity +-10 %, sensing layer +-15 %) and hand touches
    (R_c 0-1e-4, object -3/+2 K) the datasheet probe read pmma, pyroceram and aisi_304 at 0.74-1.31 x
    their value (``firmware_sim.rigs.contact_record.record_touch``, those draws, seed 1, 4-s heating); a factor 2 leaves margin.  Where
    the datasheet probe cannot resolve e (a metal: copper read 2.4-6.3 x with a stated u of 16-82 %) the
    touch's own stated u widens it.  Swapping pmma (558) and aisi_304 (7493) is a factor 13, pmma and
    pyroceram (2892) 5: both refused.  Closer swaps are the self-check's to find.

    Raises
    ------
    CalibrationError
        One line naming the reference, the e read and the bound.
    """
    if e_W_s05_m2K is None or not (e_W_s05_m2K > 0 and math.isfinite(e_W_s05_m2K)):
        return   # nothing read, nothing contradicted: whether the touch can be fitted is the fit's to say
    u_rel = (u_e_W_s05_m2K / e_W_s05_m2K) if u_e_W_s05_m2K is not None and math.isfinite(u_e_W_s05_m2K) else 0.0
    bound = math.log(SWAP_RATIO) + SWAP_SIGMAS * u_rel
    if abs(math.log(e_W_s05_m2K / e_ref)) > bound:
        raise CalibrationError(f"reference {name}: the touch reads e {e_W_s05_m2K:.0f} with the datasheet probe, "
                               f"{e_W_s05_m2K / e_ref:.2g} x {name}'s {e_ref:.0f} (at most x {math.exp(bound):.2g} "
                               "from the probe's tolerances): wrong reference name, swapped records, or another "
                               "probe head's record")


def fit_calibration(touches: list[ReferenceTouch], *, probe: str = "paper",
                    created_utc: str | None = None, noise_bias_draws: int = NOISE_BIAS_DRAWS,
                    min_references: int = 2) -> ProbeCalibration:
    """Fit the probe's chain to reference touches; see the module docstring.

    ``noise_bias_draws``: antithetic noise pairs of the bias correction (0: none; see :func:`_noise_bias`).
    ``min_references``: fewest different references (the leave-one-out self-check fits on one less).
    Inputs that cannot be a calibration are refused before fitting: a record without its pre-contact
    phase, a touch whose datasheet e contradicts its reference (:func:`check_reference`).

    Raises
    ------
    CalibrationError
        Fewer than two reference materials, a record too short, or a fit that does not converge.
    """
    if isinstance(noise_bias_draws, bool) or not (isinstance(noise_bias_draws, int) and noise_bias_draws >= 0):
        raise ValueError(f"noise_bias_draws must be an int >= 0, got {noise_bias_draws!r}")
    names = sorted({tc.name for tc in touches})
    if len(names) < min_references:
        raise CalibrationError(f"need touches of at least two reference materials, got {names or 'none'}")
    e_lib = {}
    for tc in touches:
        e_lib.setdefault(tc.name, tc.e_W_s05_m2K)
        if not math.isclose(e_lib[tc.name], tc.e_W_s05_m2K, rel_tol=1e-12):
            raise CalibrationError(f"reference {tc.name}: touches disagree on its effusivity")
    key = _fit_key(touches, probe, noise_bias_draws)
    fitted = _FITS.get(key)
    if fitted is None:
        fitted = _FITS.put(key, _fit(touches, names, e_lib, probe, noise_bias_draws))
    chain, cov, floor, refs = fitted
    stamp = created_utc or datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    return ProbeCalibration(probe=probe, chain=chain, covariance=cov, u_rel_floor=floor,
                            calibrated=True, created_utc=stamp, references=refs)


#: Fits already made, by their exact inputs (:func:`_fit_key`): a calibration's leave-one-reference-out
#: self-check refits subsets of its references, and a refused calibration run again with ``--force``, a
#: walk-through's touches refitted from their exports, two calibrations sharing references fit the same
#: touches again (a third of the suite's fits were repeats).  The values hold no array a caller can
#: change (:class:`ProbeCalibration` copies the covariance).
_FITS = BoundedMemo(16)
#: Solutions before the noise-bias correction (:func:`_solve_touches`), by the fit's inputs but its draws: a fit
#: with the correction repeats the one without (the same touches, the same solves) before it corrects.
_SOLVED = BoundedMemo(8)


def clear_fit_memo() -> None:
    """Forget the fits kept (:data:`_FITS`): the next :func:`fit_calibration` of any input computes afresh."""
    _FITS.clear()
    _SOLVED.clear()


def _fit_key(touches, probe: str, noise_bias_draws: int) -> tuple:
    """The exact inputs of a fit: the touches (digest of their records), the probe, the draws, and what
    the fit reads of this module when it runs -- its settings and the functions it calls, so that a
    setting changed or a function replaced (a bench's ``--cal-smooth-growth``, a test's stand-in) is
    another key."""
    h = hashlib.sha256()
    for tc in touches:
        h.update(repr((tc.name, float(tc.e_W_s05_m2K))).encode())
        for x in (tc.t_s, tc.T_C, tc.q_W_m2):
            a = np.ascontiguousarray(x, dtype=np.float64)
            h.update(repr(a.shape).encode())
            h.update(a.tobytes())
    settings = (FIT_START_s, CAL_SMOOTH_GROWTH, tuple(_STEPS), NOISE_BIAS_SEED, NOISE_FLOOR_T_K, NOISE_FLOOR_q_W_m2,
                _MAX_ITER, FIT_CONTACT_INSTANT, _STEP_TOL_SIGMA, _MAX_PRIOR_SIGMAS, SWAP_RATIO, SWAP_SIGMAS,
                tuple(sorted(REFERENCE_U_REL.items())), OTHER_REFERENCE_U_REL)
    # The functions themselves (kept alive by the key, so a replaced one's id cannot come back as another's).
    calls = (fit_sensor_chain, simulate_chain, chain_design, contact_fraction, find_contact, check_reference, _solve,
             _noise_bias, _from_contact)
    return (h.hexdigest(), probe, int(noise_bias_draws), settings, calls, ProbeCalibration.nominal(probe).sha256)


def _solve_touches(touches: list[ReferenceTouch], names: list[str], e_lib: dict[str, float], prior) -> tuple:
    """The fit's solution before any noise-bias correction: the touches' arrays from contact (copies), their
    noises in air, reference indices, the references' ln e and u, the solution p and its Jacobian."""
    th0 = prior.theta
    u_th0 = prior.u_theta
    segs, noise = [], []
    for tc in touches:
        tt, TT, qq, br, c_T, c_q = _from_contact(tc)
        if tt.size < 16:
            raise CalibrationError(f"reference {tc.name}: record too short after contact ({tt.size} samples)")
        r = fit_sensor_chain(tt, TT, qq, calibration=prior.chain, fit_start_s=FIT_START_s, breaks_s=br)
        check_reference(tc.name, tc.e_W_s05_m2K, r.e_W_s05_m2K, r.u_e_W_s05_m2K)
        X, y = chain_design(tt, TT, qq, prior.chain, fit_start_s=FIT_START_s, breaks_s=br)
        res = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
        rho = float(np.clip((res[1:] @ res[:-1]) / max(float(res @ res), 1e-300), 0.0, 0.95))
        w = 1.0 / max(r.rms_residual_K * math.sqrt((1 + rho) / (1 - rho)), 1e-6)
        frac = contact_fraction(tt, TT, qq, prior.chain, br, c_T)[0] if FIT_CONTACT_INSTANT else 0.0
        segs.append((tc, tt, TT, qq, w, br, frac))
        noise.append((c_T, c_q))
    m_index = {n: i for i, n in enumerate(names)}
    ln_e0 = np.array([math.log(e_lib[n]) for n in names])
    u_ln_e = np.array([next(tc.u_rel_e for tc in touches if tc.name == n) for n in names])
    idx = [m_index[tc.name] for tc, *_ in segs]
    arrays = [(tt, TT, qq, w, br, fr) for _, tt, TT, qq, w, br, fr in segs]
    p_start = np.concatenate([th0, ln_e0])
    p, J = _solve(arrays, idx, prior, th0, u_th0, ln_e0, u_ln_e, p_start)
    if FIT_CONTACT_INSTANT and np.all(np.isfinite(p)):
        # The contact instants again, through the fitted chain, and the fit from there.
        chain1 = prior.chain_at(p[:NP])
        arrays = [(tt, TT, qq, w, br, contact_fraction(tt, TT, qq, chain1, br, c_T)[0])
                  for (tt, TT, qq, w, br, _), (c_T, _) in zip(arrays, noise)]
        p, J = _solve(arrays, idx, prior, th0, u_th0, ln_e0, u_ln_e, p)
    # Copies: a caller's arrays (the records from contact are views of them) may change after the fit is kept.
    arrays = [(np.array(tt), np.array(TT), np.array(qq), w, br, fr) for tt, TT, qq, w, br, fr in arrays]
    return (tuple(arrays), tuple(noise), tuple(idx), ln_e0, u_ln_e, p, J)


def _fit(touches: list[ReferenceTouch], names: list[str], e_lib: dict[str, float], probe: str,
         noise_bias_draws: int) -> tuple:
    """:func:`fit_calibration`'s fit: (chain, covariance, transfer floor, references)."""
    prior = ProbeCalibration.nominal(probe)
    th0 = prior.theta
    u_th0 = prior.u_theta
    # The solution without the noise-bias correction is the same whatever the draws: a fit with the correction
    # of touches fitted without it (or with other draws) starts from that one (_SOLVED).
    key = _fit_key(touches, probe, 0)
    solved = _SOLVED.get(key)
    if solved is None:
        solved = _SOLVED.put(key, _solve_touches(touches, names, e_lib, prior))
    arrays, noise, idx, ln_e0, u_ln_e, p, J = solved
    p = p.copy()
    segs = [(tc, *a) for tc, a in zip(touches, arrays)]
    m_index = {n: i for i, n in enumerate(names)}
    if not np.all(np.isfinite(p)):
        raise CalibrationError("the fit did not converge (non-finite parameters)")
    cov_bias = np.zeros((NP, NP))
    if noise_bias_draws > 0:
        # One pass: a second, evaluating the bias at the corrected solution, moved it by a small
        # fraction of the correction on the calibration bench's probes (tried, not kept).
        try:
            bias, cov_b = _noise_bias(arrays, idx, noise, prior, th0, u_th0, ln_e0, u_ln_e, p, noise_bias_draws)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:
            raise CalibrationError(f"the noise-bias correction failed on these touches ({exc})") from exc
        p = p - bias
        cov_bias = cov_b[:NP, :NP]
        p[2] = max(p[2], 0.0)   # a bead cannot lead its junction
        if not np.all(np.isfinite(p)):
            raise CalibrationError("the noise-bias correction did not converge (non-finite parameters)")
    # The fit's covariance (at the uncorrected solution: the correction moves p by a few per cent,
    # not J) and the correction's own sampling scatter.
    cov = np.linalg.pinv(J.T @ J)[:NP, :NP] + cov_bias
    cov = 0.5 * (cov + cov.T)
    fitted = ProbeCalibration(probe=probe, chain=prior.chain_at(p[:NP]), covariance=cov, calibrated=True)
    # Transfer floor: re-measure each reference with e free.
    rel: dict[str, list[float]] = {n: [] for n in names}
    excess = []
    e_fit = {n: math.exp(p[NP + m_index[n]]) for n in names}
    for tc, tt, TT, qq, _, br, fr in segs:
        rr = fit_sensor_chain(tt, TT, qq, calibration=fitted.chain, fit_start_s=FIT_START_s, breaks_s=br,
                              contact_frac=fr)
        if not (0.0 < rr.e_W_s05_m2K < math.inf and 0.0 <= rr.u_e_W_s05_m2K < math.inf):
            # A reference the written chain cannot re-measure leaves the floor undefined (it was NaN, and
            # the calibration's own check refused it with no word of why): the calibration cannot check
            # itself on these touches, so it is refused, naming the touch.
            raise CalibrationError(
                f"reference {tc.name}: re-measured with the fitted chain its touch gives no finite e "
                f"(e {rr.e_W_s05_m2K:.4g} +- {rr.u_e_W_s05_m2K:.4g}): too short or too noisy to check the "
                f"calibration on; touch it longer")
        rel[tc.name].append(rr.e_W_s05_m2K / e_lib[tc.name] - 1.0)
        # The floor is what the chain does not describe: the re-measured e against the reference's e
        # as the calibration itself settled it (e_fit: library value moved within its uncertainty, which
        # the covariance of theta already carries), less what the touch's own noise explains.
        d = rr.e_W_s05_m2K / e_fit[tc.name] - 1.0
        excess.append(d * d - (rr.u_e_W_s05_m2K / rr.e_W_s05_m2K) ** 2)
    n = len(excess)
    floor = float(math.sqrt(max(float(np.mean(excess)), 0.0) * n / max(n - NP, 1)))
    refs = tuple(ReferenceFit(nm, e_lib[nm], float(u_ln_e[m_index[nm]]), len(rel[nm]), tuple(rel[nm])) for nm in names)
    return fitted.chain, cov, min(floor, 1.0), refs
