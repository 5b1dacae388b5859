"""One touch of a small-heater probe: e, k, alpha from the axisymmetric fit, the library prior as the fallback.

The paper's probe (a 55 x 60 mm heater) is one-dimensional at its sensors and
measures the effusivity only; :class:`edge.estimation.estimate.Estimator`
handles it.  A probe whose heater is small against the heat's reach
(:data:`edge.physics.geometry.PROBES` ``["small-heater"]``) sees the lateral
spreading, which depends on k and alpha separately; :class:`AxiEstimator`
fits both with :class:`edge.estimation.axifit.AxiFitter` and reports, per
quantity, whether the touch determined it or it came from the prior:

* ``determined``: the quantities (``"e"``, ``"k"``, ``"alpha"``) whose
  relative standard uncertainty from the fit is below
  ``identifiable_u_rel`` (30 %, the fitter's threshold);
* ``from_prior``: k and alpha (together) where the fit alone left either above
  the threshold: the answer then holds the library's prior on ln rho c given e
  (:meth:`~edge.estimation.identification.Library.prior_rho_c`, the one prior of
  the 1-D default method).  On a calibrated probe (``calibrated``) whose fit
  has a covariance the answer is the fit's (ln k, ln alpha) weighted with that prior (:func:`k_alpha_posterior`:
  precision-weighted along ln rho c, the touch's e kept; the fit's own u
  before the prior in ``fit.k_alpha_posterior.u_rel_fit``, the data's share of
  the precision in ``data_share``); otherwise the prior given e alone
  (:meth:`~edge.estimation.identification.Library.k_alpha_given_e`, the
  posterior's limit for a flat fit).  Either way flagged ``k_alpha_from_prior``
  with a ``prior_reason``: never a silent switch, and never called determined
  (``determined`` is the data's alone);
* ``corr_k_alpha``: the fit's correlation of ln k and ln alpha (k and alpha
  are anti-correlated on short touches: the record constrains e = k/sqrt(alpha)
  much better than either).

Nuisances: the heater power is fitted as a free scale (the device's power
setting is only a start); the flux sensor's calibration (2 %,
:data:`~edge.estimation.estimate.FLUX_CALIBRATION_U_REL`) is propagated
through the fit (:attr:`AxiFit.flux_scale_sensitivity`): with the power
free, T and q disagree by a scale error and the fit reads that as lateral
spreading, so on PMMA at 5 s a 2 % error moves k by ~13 % and alpha by ~32 %,
on glass and metals by about one to one (bench/sensitivity_bench.py) -- the stated
u(k), u(alpha), u(e) and
their correlation carry it, and a quantity it leaves above the threshold is
not called determined.  An installed calibration (``flux_scale``, ``flux_u_rel``;
:mod:`edge.calibration.axi`) replaces the datasheet's scale and 2 %; one that identified the probe as
built (``calibrated``: :data:`CALIBRATED` -- the sensing layer's thickness and k, the substrate's k
and rho c, with their covariance) replaces the datasheet's probe in the fit, and its covariance enters
every u through the fit's linear response to each parameter
(:meth:`~edge.estimation.axifit.AxiFitter.model_response`: on glass at 5 s, 1 % of the sensing layer's
thickness is 25 % of k).  The ``method``
argument of the 1-D path does not apply (the paper's network was trained
on the paper's probe); results say ``method: "axisym"``.

Edge code: NumPy only.  The model's probe part (~15 ms) is built once per
time grid and kept (a few grids: the device samples every touch alike).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, replace

import numpy as np

from edge.checks import finite_array, one_of, strictly_increasing
from edge.estimation import object_offset as OO
from edge.estimation.axifit import AxiFitter
from edge.estimation.object_offset import ObjectOffset, PreHeating
from edge.estimation.estimate import FLUX_CALIBRATION_U_REL, MIN_SNR, Estimator
from edge.physics.geometry import ProbeGeometry, get_probe
from edge.physics.solids import Solid
from edge.status import Flag

__all__ = ["AxiEstimator", "QUANTITIES", "CALIBRATED", "geometry_at", "calibrated_params", "MODEL_FORM_TOLERANCES",
           "perturbed_geometry", "k_alpha_posterior"]

#: Names of the quantities in ``determined`` / ``from_prior``.
QUANTITIES = ("e", "k", "alpha")
_BACKS = ("infinite", "insulated", "fixed")
#: Longest span t_max / t_min of the samples fitted: the model's fixed time contour is accurate to
#: ~1e-6 over 250 (edge.physics.axisym) and degrades beyond (2e-5 at 1000, 2e-4 at 5000); the first
#: few milliseconds of a fast-sampled record carry next to nothing on k and alpha.
MAX_TIME_SPAN = 250.0


#: The probe's parameters a calibration identifies (:mod:`edge.calibration.axi`), as ln deviations from the
#: datasheet probe, in this order: the flux scale (true flux per unit reading), the sensing layer's thickness
#: and k (the thermopile spans the layer; its rho c kept), the substrate's k and rho c.
CALIBRATED = ("ln_flux_scale", "ln_sensing_thickness_m", "ln_sensing_k_W_mK", "ln_substrate_k", "ln_substrate_rho_c")
#: Step (in ln) of the finite differences that carry the calibration's covariance into an answer.
_CAL_STEP = 1e-3


#: The drawing's tolerances the fit does not identify, as model-form terms of the calibration's covariance:
#: name -> (ProbeGeometry change, the dimension's size at which its effect is the effect's rms over the
#: tolerance). The calibration (edge.calibration.axi) carries the fit's response to each; an answer carries
#: what is left of it on its own touch (:meth:`AxiEstimator._model_form_variance`). The sides (+-0.2 mm
#: each, uniform) act linearly: a / sqrt 3. The sensor's offset from the heater's axis (+-0.5 mm in x and
#: y, uniform) acts through the read-out's even response, ~ (x^2 + y^2), whose rms over the tolerance is
#: a^2 sqrt(28/45): taken at x = y = a (sqrt(28/45) / 2)^(1/2) = 0.63 a, where x^2 + y^2 is that rms. The
#: thermocouple within 0.5 mm of the axis (uniform over the disk): T(r) is even in r, r^2 uniform on
#: [0, R^2], its rms R^2 / sqrt 3: r = R 3^(-1/4).
MODEL_FORM_TOLERANCES = {
    "sensor_side_x_m": ("side_x", 0.2e-3 / math.sqrt(3.0)),
    "sensor_side_y_m": ("side_y", 0.2e-3 / math.sqrt(3.0)),
    "sensor_offset_m": ("offset", 0.5e-3 * math.sqrt(math.sqrt(28.0 / 45.0) / 2.0)),
    "thermocouple_r_m": ("thermocouple", 0.5e-3 * 3.0 ** -0.25),
}


def perturbed_geometry(geometry, what: str, size_m: float):
    """The probe ``geometry`` with one drawing dimension off by ``size_m`` (:data:`MODEL_FORM_TOLERANCES`).

    None where the dimension is not in the model (an equal-area disk read-out has no square).
    """
    sq = geometry.sensor_square_m
    if what in ("side_x", "side_y", "offset") and sq is None:
        return None    # an equal-area disk read-out: the square's dimensions are not in the model
    if what == "side_x":
        return replace(geometry, sensor_square_m=(sq[0] + size_m, sq[1]))
    if what == "side_y":
        return replace(geometry, sensor_square_m=(sq[0], sq[1] + size_m))
    if what == "offset":
        ox, oy = geometry.sensor_offset_m
        return replace(geometry, sensor_offset_m=(ox + size_m, oy + size_m))
    return replace(geometry, thermocouple_r_m=geometry.thermocouple_r_m + size_m)


def geometry_at(geometry: ProbeGeometry, p) -> ProbeGeometry:
    """The probe with the calibrated parameters ``p`` (:data:`CALIBRATED` order; the flux scale is not geometry)."""
    sm, sub = geometry.sensing, geometry.substrate
    L = geometry.sensing_thickness_m * math.exp(p[1])
    kw = {"sensing": Solid(sm.k_W_mK * math.exp(p[2]), sm.rho_kg_m3, sm.c_J_kgK), "sensing_thickness_m": L,
          "sensor_depth_m": (0.0, L)}
    if sub is not None:
        kw["substrate"] = Solid(sub.k_W_mK * math.exp(p[3]), sub.rho_kg_m3 * math.exp(p[4]), sub.c_J_kgK)
    return replace(geometry, **kw)


def calibrated_params(cal) -> tuple[np.ndarray, np.ndarray] | None:
    """(values, covariance) of :data:`CALIBRATED` a calibration's ``head_model`` carries, or None.

    (:func:`edge.calibration.axi.fit_flux_scale` writes them; an older calibration has none: the datasheet
    probe with its flux scale.)
    """
    hm = None if cal is None else getattr(cal, "head_model", None)
    if not hm or list(hm.get("parameters") or []) != list(CALIBRATED):
        return None
    return np.array(hm["values"], float), np.array(hm["covariance"], float)


def _num(x):
    return None if x is None or not math.isfinite(x) else float(x)


#: Flux (W/m^2, mean over the record's second half) below which the heater's heat did not reach the
#: sensor: the small-heater probe's 0.11 W spreads over the 10 x 10 mm sensor at ~1000 W/m^2 into any
#: solid (PMMA ~700 W/m^2 after 1 s), so 20 W/m^2 is a touch in air or a dead heater, not a material.
NO_SIGNAL_FLUX_W_m2 = 20.0


def _signal_check(T: np.ndarray, q: np.ndarray, T_resolution_K: float) -> Flag | None:
    """``no_signal`` when neither sensor saw the heat, ``insufficient_signal`` when only the flux did.

    On the small-heater probe a metal rises ~0.1 K in 2 s: below one step of a
    16-bit MCP9600 (0.2 K), so the thermometer reads a flat line while the
    flux is plain. That is not "no signal" (the 1-D probe's test, made for a
    paper-sized heater) but a record the fit cannot use: e needs the rise.
    Two thermometer steps are asked of the rise (one step can be rounding).
    """
    flux = float(np.mean(q[q.size // 2:]))
    rise = float(np.max(T))
    if flux < NO_SIGNAL_FLUX_W_m2 and rise <= 2.0 * T_resolution_K:
        return Flag.NO_SIGNAL
    if flux < NO_SIGNAL_FLUX_W_m2 or not rise > max(2.0 * T_resolution_K, 0.0):
        return Flag.INSUFFICIENT_SIGNAL
    return None


#: Fitted object effusivity (W s^0.5/(m^2 K)) below which the probe touched nothing: still air is
#: 5.5, the lightest foams ~28 (the ``[measurement] no_contact_e_W_s05_m2K`` default); the
#: small-heater fit gives 2.4-2.6 for a probe in air on the simulator.
NO_CONTACT_E_W_s05_m2K = 12.0


#: The small heater's k and alpha where the fit alone did not determine them: the fit weighted with the
#: library's prior (:func:`k_alpha_posterior`, True) or the prior given e alone (False, the switch before it;
#: bench/asbuilt_small_bench.py ``--no-posterior`` measures both on one cache).
K_ALPHA_POSTERIOR = True


def k_alpha_posterior(ln_k: float, ln_alpha: float, V, ln_rho_c: float, u_ln_rho_c: float):
    """The fit's (ln k, ln alpha) combined with the library's prior on ln rho c given e: precision-weighted.

    The library's prior given e (:meth:`edge.estimation.identification.Library.prior_rho_c`) states
    ln rho c = ln k - ln alpha; e = k / sqrt(alpha) comes from this very touch, so the prior adds
    precision along ln rho c alone (``H^T H / u^2``, ``H = [1, -1]``) and is flat along e (weighting its
    e in again would count the touch twice). Posterior precision ``V^-1 + H^T H / u^2``, written in its
    update form so that a flat fit (``V`` unbounded along ln rho c) needs no inverse.

    Parameters
    ----------
    ln_k, ln_alpha : float
        The fit's estimate.
    V : array_like, shape (2, 2)
        Its full covariance (fit, calibration, model-form terms, floor).
    ln_rho_c, u_ln_rho_c : float
        The prior's mean and standard deviation of ln rho c given the touch's e.

    Returns
    -------
    x : ndarray, shape (2,)
        Posterior (ln k, ln alpha): the posterior's ln rho c at the fit's ln e.
    V_post : ndarray, shape (2, 2)
        Its covariance.
    data_share : float
        The fit's share of the posterior's precision of ln rho c (1: the data alone, 0: the prior alone);
        above 1/2 the posterior's variance of ln rho c is below half the prior's.
    """
    V = np.asarray(V, dtype=float)
    x = np.array([ln_k, ln_alpha], dtype=float)
    H = np.array([1.0, -1.0])
    VH = V @ H
    s_fit = float(H @ VH)                      # the fit's variance of ln rho c
    s_pri = float(u_ln_rho_c) ** 2
    S = s_fit + s_pri
    if not S > 0:
        return x, V.copy(), 1.0
    K = VH / S
    # The mean's rho c is the posterior's; its e stays the touch's (the answer's e, k and alpha satisfy
    # e = k / sqrt(alpha), as the prior alone did): the update moves along rho c only, e = G x fixed.
    ln_rc_post = float(H @ (x + K * (ln_rho_c - float(H @ x))))
    ln_e = float(x[0] - 0.5 * x[1])
    x_post = np.array([2.0 * ln_e - ln_rc_post, 2.0 * ln_e - 2.0 * ln_rc_post])
    V_post = V - np.outer(K, VH)
    V_post = 0.5 * (V_post + V_post.T)
    return x_post, V_post, s_pri / S


class AxiEstimator:
    """e, k, alpha and the material from one touch of an axisymmetric probe.

    Parameters
    ----------
    estimator : Estimator
        The 1-D estimator of the active bundle: its library supplies the prior
        and names the material, its ``sha256`` identifies the model.
    probe : ProbeGeometry or str
        The probe (a name in :data:`edge.physics.geometry.PROBES`).
    sigma_T_K, sigma_q_W_m2 : float
        Noise of the thermocouple and the flux sensor (1 sigma): they weight
        the two records against each other; the fit's residual scatter then
        scales the covariance (``s^2 = chi^2 / dof``).
    identifiable_u_rel : float
        Relative u below which the touch counts as having determined a quantity.
    max_models : int
        Time grids whose model is kept.
    fit_contact : bool
        Fit the contact resistance too (default: an ideal contact; freeing it costs alpha on most
        touches and four times the fit time, ``bench/decision_bench.py --fit-contact``).
    """

    def __init__(self, estimator: Estimator, probe: ProbeGeometry | str = "small-heater", *,
                 sigma_T_K: float = 0.01, sigma_q_W_m2: float = 0.5, identifiable_u_rel: float = 0.30,
                 max_models: int = 8, fit_contact: bool = False) -> None:
        self.estimator = estimator
        self.geometry = get_probe(probe) if isinstance(probe, str) else probe
        self.sigma_T_K = float(sigma_T_K)
        self.sigma_q_W_m2 = float(sigma_q_W_m2)
        self.identifiable_u_rel = float(identifiable_u_rel)
        self.max_models = int(max_models)
        self.fit_contact = bool(fit_contact)
        self._models: OrderedDict = OrderedDict()

    def _model(self, t: np.ndarray, geometry: ProbeGeometry | None = None, nodes=None):
        """The fitter's model for these times (cached: its setup is most of a fit's cost on a cold grid).

        ``geometry``: a calibrated probe (:func:`calibrated_geometry`); default the datasheet's.
        """
        from edge.physics.axisym import AxisymModel  # noqa: PLC0415 - the 1-D device never needs it

        geo = self.geometry if geometry is None else geometry
        key = (geo, t.tobytes())
        m = self._models.get(key)
        if m is None:
            # A prefix of a grid already modelled (a running answer on the samples so far): its head.
            for k, full in reversed(self._models.items()):
                if k[0] == geo and full.t_s.size > t.size and np.array_equal(full.t_s[:t.size], t):
                    self._models.move_to_end(k)
                    return full.head(t.size)
            m = AxisymModel(geo, t, nodes=nodes)
            self._models[key] = m
            while len(self._models) > self.max_models:
                self._models.popitem(last=False)
        else:
            self._models.move_to_end(key)
        return m

    def _calibration_sensitivity(self, fitter, f, t, calibrated, sens: dict, u_flux: float):
        """(S, C): d(ln k, ln alpha) per calibrated parameter (2 x n) and their covariance (n x n).

        Without a calibrated probe only the flux scale, known to ``u_flux``.
        """
        col0 = np.array([sens["k"], sens["alpha"]])
        if calibrated is None or not f.converged:
            return col0[:, None], np.array([[u_flux ** 2]])
        p, C = calibrated
        S = np.zeros((2, len(CALIBRATED)))
        S[:, 0] = col0
        for i in range(1, len(CALIBRATED)):
            if i >= 3 and self.geometry.substrate is None:
                continue
            dp = np.array(p, float)
            dp[i] += _CAL_STEP
            m = self._model(t, geometry_at(self.geometry, dp), fitter.model.nodes) if i < 3 else \
                fitter.model.with_substrate(geometry_at(self.geometry, dp).substrate)
            # The truth at p + dp read with the model at p: the fit is off by -response.
            S[:, i] = -fitter.model_response(m) / _CAL_STEP
        return S, np.array(C, float)

    def _model_form_variance(self, fitter, t, calibrated, S, C, model_form: dict):
        """(C less the model-form terms, their covariance (2 x 2) of (ln k, ln alpha) on this touch).

        A drawing dimension off by its rms (:data:`MODEL_FORM_TOLERANCES`) moved the calibration by ``-d``
        (``model_form[name]``, the truth's parameters minus the calibrated ones), so this answer is off by
        ``S d`` through the parameters and by ``-model_response`` of the probe with that dimension: the
        calibration's shift partly makes up for the dimension on the touch too (both absorb the same
        misread flux), which ``S d`` alone would state as if it added (on insulators at 5 s that put
        u(k) at ~25 %, the calibration's shift of the sensing layer read through their strong
        sensitivity to it). A term without a geometry change here keeps ``S d`` alone.
        """
        C = np.array(C, float)
        n = len(CALIBRATED)
        base = geometry_at(self.geometry, calibrated[0])
        V = np.zeros((2, 2))
        seen: dict = {}
        for name, d in model_form.items():
            spec = MODEL_FORM_TOLERANCES.get(name)
            d = np.asarray(d, float)[:n]
            if spec is None or d.size != n or not np.all(np.isfinite(d)):
                continue
            C = C - np.outer(d, d)
            g = perturbed_geometry(base, *spec)
            direct = np.zeros(2)
            if g is not None:
                # A square's sides read the same in an axisymmetric field: one model for both.
                key = (None if g.sensor_square_m is None else tuple(sorted(g.sensor_square_m)),
                       tuple(sorted(g.sensor_offset_m)), g.thermocouple_r_m)
                if key not in seen:
                    seen[key] = -fitter.model_response(self._model(t, g, fitter.model.nodes))
                direct = seen[key]
            err = S @ d + direct
            if np.all(np.isfinite(err)):
                V = V + np.outer(err, err)
        return C, V

    def _offset_stack_variance(self, fitter, offset, geometry, calibrated=None) -> np.ndarray:
        """Covariance (2 x 2) of (ln k, ln alpha) from the offset kernel's stack: known to the calibration's
        covariance when it identified the stack, else to :data:`STACK_TOLERANCE`.

        Linearised as :meth:`~edge.estimation.axifit.AxiFitter.response`: the records' change when the
        kernel's stack is off by one tolerance (the fitted offset times the kernel's change, in noise units)
        moves the fit by ``(J^T J)^-1 J^T dy``.
        """
        from edge.physics.contact_offset import ContactKernel  # noqa: PLC0415

        theta = fitter._final[0]
        k, alpha = math.exp(theta[0]), math.exp(theta[1])
        R = fitter._R(theta)
        e = k / math.sqrt(alpha)
        dT = float(fitter.offset_beta[2])
        base = offset._g(e, R)
        kern = offset.kernel
        geo = self.geometry if geometry is None else geometry
        cols = {}
        for i, tol in OO.STACK_TOLERANCE.items():
            if i >= 3 and geo.substrate is None:
                continue
            if calibrated is not None and OO.OFFSET_STACK_FROM_CALIBRATION:
                tol = _CAL_STEP
            dp = np.zeros(len(CALIBRATED))
            dp[i] = tol
            other = ContactKernel(geometry_at(geo, dp), kern.tau_T_s, kern.tau_q_s)
            T1, q1, _ = other.transforms(e, R)
            g1 = other.inversion.invert(np.stack([T1, q1]))
            nT, nq = offset.n_T, offset.n_q
            dy = np.concatenate([dT * (g1[0][:nT] - base[0][:nT]) / fitter.sigma_T,
                                 dT * (g1[1][nT:nT + nq] - base[1][nT:nT + nq]) / fitter.sigma_q])
            cols[i] = fitter.response(dy) / tol
        idx = sorted(cols)
        if not idx:
            return np.zeros((2, 2))
        S = np.stack([cols[i] for i in idx], axis=1)
        if calibrated is not None and OO.OFFSET_STACK_FROM_CALIBRATION:
            C = np.asarray(calibrated[1], float)[np.ix_(idx, idx)]
        else:
            C = np.diag([OO.STACK_TOLERANCE[i] ** 2 for i in idx])
        return S @ C @ S.T

    def prepare(self, t_s) -> None:
        """Build the model for the grid a touch will be estimated on (its prefixes then reuse it)."""
        t = strictly_increasing("t_s", finite_array("t_s", t_s, min_len=4))
        self._model(t[(t > 0) & (t >= t[-1] / MAX_TIME_SPAN)])

    def estimate(self, t_s, dT_K, q_W_m2, *, power_W: float | None = None, thickness_m: float | None = None,
                 back: str = "infinite", T_resolution_K: float = 0.0, flux_scale: float = 1.0,
                 flux_u_rel: float | None = None, u_rel_floor: float = 0.0,
                 calibrated: tuple[np.ndarray, np.ndarray] | None = None, fit_contact: bool | None = None,
                 pre: PreHeating | None = None, heater_tcr_per_K: float = 0.0,
                 heater_tcr_per_K_u: float = 0.0, model_form: dict | None = None) -> dict:
        """Estimate from one record (times from heater-on; thermocouple rise, flux-sensor reading).

        Parameters
        ----------
        t_s : (n,) sample times (s), increasing; samples at t <= 0, and before
            ``t_s[-1] / MAX_TIME_SPAN``, are ignored.
        dT_K : (n,) thermocouple rise over the baseline (K).
        q_W_m2 : (n,) flux-sensor reading (W/m^2).
        power_W : heater power the touch was made at (default: the probe's nominal);
            fitted as a free scale, so only its order matters.
        thickness_m, back : a known finite object (``"insulated"``/``"fixed"`` back).
        T_resolution_K : the thermometer's step, added to its noise (rounding).
        u_rel_floor : the calibration's model-form floor (relative; what its references re-measured
            without themselves missed by, :mod:`edge.calibration.selfcheck`), added to u(e), u(k) and
            u(alpha) -- a quantity is determined only when it survives it.
        flux_scale, flux_u_rel : the flux sensor's calibration -- true flux per unit of the reading
            and its relative standard uncertainty (:func:`edge.calibration.axi.fit_flux_scale`);
            default the datasheet sensor, known to FLUX_CALIBRATION_U_REL.
        calibrated : (values, covariance) of the probe's :data:`CALIBRATED` parameters as its calibration
            identified them (:func:`calibrated_params`): the fit uses that probe (sensing layer,
            substrate) and every answer's u carries the covariance (the flux scale's entry replaces
            ``flux_u_rel``); default the datasheet's probe.
        fit_contact : fit the contact resistance (default: the constructor's choice).
        pre : the touch's samples before heater-on (:func:`pre_heating`): the object's temperature offset
            is then fitted as a linear nuisance (:class:`ObjectOffset`) on them and the heating grid,
            and its covariance enters every u (``fit["object_offset_K"]``); default: none (an object at
            the probe's temperature, as before).
        heater_tcr_per_K : the heater film's TCR (1/K) its calibration identified: the model carries the
            power's droop under the film's own heating (:mod:`edge.physics.heater_tcr`); 0: none.
        heater_tcr_per_K_u : its standard uncertainty (1/K) as the calibration stated it: the fit's response
            to it enters every u, and with ``pre`` it is the offset's TCR cross term's prior (with
            ``heater_tcr_per_K``) instead of the film heaters' datasheet range.
        model_form : the calibration's model-form terms (``head_model["model_form"]``: per
            :data:`MODEL_FORM_TOLERANCES` name, the calibrated parameters' shift it explains), which its
            covariance ``calibrated[1]`` includes: with them the answer's u carries each term's net effect on
            this touch (:meth:`_model_form_variance`) instead of its shift of the parameters alone.

        Returns
        -------
        dict
            The keys of :meth:`edge.estimation.estimate.MethodEstimate.to_dict` plus ``probe``,
            ``determined``, ``from_prior``, ``prior_reason``, ``corr_k_alpha`` and ``fit``
            (the fit's own k, alpha, their relative u, chi^2/dof, iterations, power scale).
        """
        one_of("back", back, _BACKS)
        t = strictly_increasing("t_s", finite_array("t_s", t_s, min_len=4))
        T = finite_array("dT_K", dT_K)
        q = finite_array("q_W_m2", q_W_m2)
        if T.shape != t.shape or q.shape != t.shape:
            raise ValueError(f"t_s, dT_K and q_W_m2 must have equal lengths, got {t.size}, {T.size}, {q.size}")
        if not (math.isfinite(flux_scale) and flux_scale > 0):
            raise ValueError(f"flux_scale must be finite and > 0, got {flux_scale!r}")
        u_flux = FLUX_CALIBRATION_U_REL if flux_u_rel is None else float(flux_u_rel)
        u_tcr = float(heater_tcr_per_K_u)
        if not (math.isfinite(u_tcr) and u_tcr >= 0):
            raise ValueError(f"heater_tcr_per_K_u must be finite and >= 0, got {heater_tcr_per_K_u!r}")
        if not (math.isfinite(u_flux) and u_flux >= 0):
            raise ValueError(f"flux_u_rel must be finite and >= 0, got {flux_u_rel!r}")
        floor = float(u_rel_floor)
        if not (math.isfinite(floor) and 0.0 <= floor <= 1.0):
            raise ValueError(f"u_rel_floor must be in [0, 1], got {u_rel_floor!r}")
        keep = (t > 0) & (t >= t[-1] / MAX_TIME_SPAN)
        t, T, q = t[keep], T[keep], q[keep] * flux_scale
        est = self.estimator
        out = {"effusivity_W_s05_m2K": None, "effusivity_W_s05_m2K_u": None, "k_W_mK": None, "k_W_mK_u": None,
               "alpha_m2_s": None, "alpha_m2_s_u": None, "material": None, "material_confidence": 0.0,
               "method": "axisym", "model_sha256": est.sha256, "flags": [], "candidates": [],
               "probe": self.geometry.name, "determined": [], "from_prior": [], "prior_reason": None,
               "corr_k_alpha": None, "fit": None}
        if t.size < 4:
            raise ValueError(f"need at least 4 samples after heater-on, got {t.size}")
        # With an object offset the heating records carry its contact transient too (a colder object makes
        # the thermocouple fall): the heater's own signal is judged after the fit, on the records less it.
        why = None if pre is not None else _signal_check(T, q, T_resolution_K)
        if why is not None:
            out["flags"].append(str(why))
            return out
        if back == "infinite":
            thickness_m = None
        sigma_T = math.hypot(self.sigma_T_K, T_resolution_K / math.sqrt(12.0))
        # The calibrated probe: a 5-mm heater splits its heat between the substrate and the object (+-14 %
        # in the foam's effusivity moved nickel's e by -63 / +69 %, issue #34), and the sensing layer's
        # thickness and k set what both sensors see (+-10 % of either: chi^2 per point ~1000 on a drawn probe).
        geometry = None if calibrated is None else geometry_at(self.geometry, calibrated[0])
        offset = None
        if pre is not None:
            # A hand touch: the object's temperature offset, the probe's temperature and the flux zero are
            # linear nuisances over the pre-heating samples and the heating grid (the heater's model is 0
            # before heater-on). The first samples of the grid are dropped: the grid's (0, 0) anchor assumes
            # a flat baseline, which a contact transient is not.
            from edge.physics.contact_offset import ContactKernel  # noqa: PLC0415

            late = t >= OO.OFFSET_GRID_START_s
            t, T, q = t[late], T[late], q[late]
            tau = t - pre.contact_t_s
            dt = float(np.min(np.diff(t))) if t.size > 1 else 0.0
            grid_k = np.rint(t / dt).astype(int) if dt > 0 else None
            if grid_k is not None and not (np.allclose(grid_k * dt, t, atol=1e-3 * dt) and grid_k[0] >= 1):
                grid_k = None     # not a uniform grid from heater-on: no TCR column
            tau_h = None if grid_k is None or not OO.OFFSET_TCR else dt * np.arange(grid_k[-1] + 1) - pre.contact_t_s
            kernel = ContactKernel(self.geometry if geometry is None else geometry,
                                   np.concatenate([pre.tau_T_s, tau]), np.concatenate([pre.tau_q_s, tau]), tau_h)
            tcr_prior = (float(heater_tcr_per_K), u_tcr) if heater_tcr_per_K > 0 else None
            offset = ObjectOffset(kernel, pre.t_s.size, None if tau_h is None else grid_k, tcr_prior)
            t = np.concatenate([pre.t_s, t])
            T = np.concatenate([pre.dT_K, T])
            q = np.concatenate([pre.q_W_m2 * flux_scale, q])
        model = self._model(t, geometry)
        fitter = AxiFitter(model.geometry, t, sigma_T_K=sigma_T, sigma_q_W_m2=self.sigma_q_W_m2,
                           thickness_m=thickness_m, back=back if thickness_m is not None else "infinite",
                           identifiable_u_rel=self.identifiable_u_rel,
                           fit_contact=self.fit_contact if fit_contact is None else bool(fit_contact), model=model,
                           offset=offset, heater_tcr_per_K=heater_tcr_per_K)
        f = fitter.fit(T, q, power_W=power_W)
        if offset is not None:
            XT, Xq, _, _ = offset.columns(f.fit_k_W_mK, f.fit_alpha_m2_s, f.contact_resistance_m2K_W, False)
            b, n_pre = fitter.offset_beta[:3], pre.t_s.size
            why = _signal_check((T - b @ XT)[n_pre:], (q - b @ Xq)[n_pre:], T_resolution_K)
            if why is not None:
                out["flags"].append(str(why))
                return out
        # The fit scales its covariance by chi^2/dof. Below 1 (sensors quieter than the noise they are
        # weighted by) that would state k and alpha better than the sensors' specified noise allows, and
        # the residual no longer measures what it cannot see: the record's time stamps and the model's
        # departures from the real probe. On the simulator's precision board (chi^2/dof ~0.2) the
        # shrunk intervals covered alpha on half the 5-s touches (bench/small_probe_bench.py).
        inflate = 1.0 / math.sqrt(f.chi2_reduced) if 0.0 < f.chi2_reduced < 1.0 else 1.0
        u_rel = {key: inflate * v for key, v in f.u_rel.items()}
        u_le_fit = u_rel["effusivity"]
        fit_info = {"k_W_mK": _num(f.fit_k_W_mK), "alpha_m2_s": _num(f.fit_alpha_m2_s),
                    "u_rel_k": _num(f.u_rel["k"]), "u_rel_alpha": _num(f.u_rel["alpha"]),
                    "u_rel_effusivity": _num(u_le_fit), "chi2_reduced": _num(f.chi2_reduced),
                    "iterations": f.iterations, "converged": f.converged, "power_scale": _num(f.scale)}
        if offset is not None:
            b, C = fitter.offset_beta, fitter.offset_cov
            fit_info["object_offset_K"] = _num(float(b[2]))
            fit_info["object_offset_K_u"] = _num(inflate * math.sqrt(max(float(C[2, 2]), 0.0)))
            fit_info["contact_t_s"] = pre.contact_t_s
            if offset.tcr:
                # -alpha_R dT_obj (times the power scale): the heater's TCR as the contact transient moved it.
                fit_info["tcr_offset"] = _num(float(b[-1]))
        out["fit"] = fit_info
        out["corr_k_alpha"] = _num(f.corr_k_alpha)
        flags: list[str] = []
        if not f.converged:
            flags.append(str(Flag.NOT_CONVERGED))
        e_fit = f.effusivity_W_s05_m2K
        if math.isfinite(e_fit) and e_fit < NO_CONTACT_E_W_s05_m2K:
            # Nothing under the probe but air. The sequence's own test (the effusivity the flux and
            # the rise show, edge.measure.signal.contact_effusivity) is made for the 1-D probe: here
            # the flux sensor, wider than the heater, reads the heat spreading through the probe's own
            # sensing layer, ~340 in air against ~850 on PMMA, far above its 12. The fit models that
            # layer, and what it leaves for the object in air is 2-3.
            flags.append(str(Flag.NO_CONTACT))
            out["flags"] = flags
            return out
        if not (u_le_fit < 1.0 / MIN_SNR):
            # The records do not even fix e: a k or alpha from the prior given such an e would be a guess.
            flags.append(str(Flag.INSUFFICIENT_SIGNAL))
            out["flags"] = flags
            return out
        e = f.effusivity_W_s05_m2K
        # The flux sensor's calibration through the fit: with the heater power free, a scale error
        # of q moves k and alpha by many times itself on low-conductivity solids (AxiFit's
        # flux_scale_sensitivity), not one to one. The fit's covariance (inflated as above) and the
        # calibration's part add; so do their k-alpha covariances.
        sens = f.flux_scale_sensitivity
        # The calibration's part: (ln k, ln alpha) of the truth minus the fit's = S delta for the probe's
        # parameters off by delta (the flux scale's column from the data's response, the others from the
        # model's, AxiFitter.model_response), so its covariance is S C S^T.
        S, C = self._calibration_sensitivity(fitter, f, t, calibrated, sens, u_flux)
        V_mf = None
        if model_form and S.shape[1] == len(CALIBRATED):
            C, V_mf = self._model_form_variance(fitter, t, calibrated, S, C, model_form)
        V = S @ C @ S.T
        if V_mf is not None:
            V = V + V_mf
            out["fit"]["u_rel_model_form"] = {"k": _num(math.sqrt(V_mf[0, 0])), "alpha": _num(math.sqrt(V_mf[1, 1]))}
        # The stack's and the TCR's parts are linearised at the fit's last point whether or not it converged:
        # a fit that stopped short still states e, and left without them its u was the noise's alone (3 of the
        # 6 e misses of 39 calibrated 5-s touches at R_c <= 3e-5 were such fits, |z| 2.1-4.5; asbuilt_small_bench).
        if offset is not None:
            # The offset's kernel is the stack the calibration identified; the calibration states that stack's u
            # too small (OO.OFFSET_STACK_FROM_CALIBRATION): its sensing layer and substrate are taken as known to
            # their datasheet tolerances.
            V_off = self._offset_stack_variance(fitter, offset, geometry, calibrated)
            if np.all(np.isfinite(V_off)):
                V = V + V_off
                out["fit"]["u_rel_offset_stack"] = {"k": _num(math.sqrt(V_off[0, 0])),
                                                    "alpha": _num(math.sqrt(V_off[1, 1]))}
        if u_tcr > 0 and heater_tcr_per_K > 0:
            # The calibrated TCR's own u: the fit holds alpha_R fixed, so its error moves k and alpha by the
            # fit's linearised response to the droop it implies (AxiFitter.tcr_response).
            g = fitter.tcr_response(u_tcr)
            if np.all(np.isfinite(g)):
                V = V + np.outer(g, g)
                out["fit"]["u_rel_heater_tcr"] = {"k": _num(abs(float(g[0]))), "alpha": _num(abs(float(g[1])))}
        step = fitter.remaining_step[:2]
        if not f.converged and np.all(np.isfinite(step)):
            # A fit that stopped short is off its optimum by about the step it had still to go, which its
            # covariance (the curvature there) does not state: 2 of the 5 e misses left at 5 s, R_c <= 3e-5.
            V = V + np.outer(step, step)
            out["fit"]["remaining_step"] = {"ln_k": _num(float(step[0])), "ln_alpha": _num(float(step[1]))}
        V_e = V[0, 0] - V[0, 1] + 0.25 * V[1, 1]
        u_le = math.sqrt(u_le_fit ** 2 + V_e)
        u_lk = math.sqrt(u_rel["k"] ** 2 + V[0, 0])
        u_la = math.sqrt(u_rel["alpha"] ** 2 + V[1, 1])
        # The calibration's model-form floor: independent of the fit and of the flux scale, so it adds in
        # quadrature (and, shared by nothing, leaves the k-alpha covariance as it is).
        u_le, u_lk, u_la = (math.hypot(u, floor) for u in (u_le, u_lk, u_la))
        if out["corr_k_alpha"] is not None and u_lk * u_la > 0:
            cov = out["corr_k_alpha"] * u_rel["k"] * u_rel["alpha"] + V[0, 1]
            out["corr_k_alpha"] = _num(max(-1.0, min(1.0, cov / (u_lk * u_la))))
        # What the record measured of (ln e, ln alpha), with the correlation of their errors, whatever is
        # reported below: object recognition uses it where the touch determined alpha
        # (edge.recognition.measured_alpha), jointly with e.
        c_fit = u_rel["alpha"] * (f.corr_k_alpha * u_rel["k"] - 0.5 * u_rel["alpha"])
        c_ea = c_fit + V[0, 1] - 0.5 * V[1, 1]
        if f.converged and u_la > 0 and math.isfinite(u_la) and math.isfinite(c_ea) and u_le > 0:
            out["fit"]["u_ln_alpha"] = _num(u_la)
            out["fit"]["corr_e_alpha"] = _num(max(-0.999, min(0.999, c_ea / (u_le * u_la))))
        out["fit"]["flux_scale_sensitivity"] = {q: _num(v) for q, v in sens.items()}
        out["fit"]["flux_scale"], out["fit"]["flux_u_rel"] = float(flux_scale), u_flux
        out["fit"]["u_rel_floor"] = floor
        thr = self.identifiable_u_rel
        determined = ["e"] if u_le < thr else []
        k, alpha = f.fit_k_W_mK, f.fit_alpha_m2_s
        reasons = []
        if not f.converged:
            reasons.append("the fit did not converge")
        if not u_lk < thr:
            reasons.append(f"u(k) {100 * u_lk:.0f} % >= {100 * thr:.0f} %")
        if not u_la < thr:
            reasons.append(f"u(alpha) {100 * u_la:.0f} % >= {100 * thr:.0f} %")
        corr = out["corr_k_alpha"]
        V_fit = None
        # Only on a calibrated probe: its fit's covariance carries the calibration's and the drawing's terms; the
        # datasheet probe's fit is biased beyond its u (uncalibrated, the posterior's k / alpha intervals held
        # the truth on 76 / 82 % of bench/asbuilt_small_bench.py's 160 5-s touches, the prior's on 92 / 96 %).
        if reasons and K_ALPHA_POSTERIOR and calibrated is not None and corr is not None and all(math.isfinite(v) and v > 0 for v in (k, alpha, u_lk, u_la)):
            V_fit = np.array([[u_lk ** 2, corr * u_lk * u_la], [corr * u_lk * u_la, u_la ** 2]])
        if reasons and V_fit is not None:
            # Informative but not decisive: the fit's (ln k, ln alpha) weighted with the library's ln rho c
            # given e (k_alpha_posterior), instead of the prior alone that threw the fit's k and alpha away.
            ln_rc, u_ln_rc, outside = est.library.prior_rho_c(e, u_le)
            u_fit = {"k": _num(u_lk), "alpha": _num(u_la)}     # the fit's full u before the prior
            x, Vp, share = k_alpha_posterior(math.log(k), math.log(alpha), V_fit, ln_rc, u_ln_rc)
            k, alpha = math.exp(x[0]), math.exp(x[1])
            u_lk, u_la = math.sqrt(max(Vp[0, 0], 0.0)), math.sqrt(max(Vp[1, 1], 0.0))
            if u_lk * u_la > 0:
                out["corr_k_alpha"] = _num(max(-1.0, min(1.0, Vp[0, 1] / (u_lk * u_la))))
            out["fit"]["k_alpha_posterior"] = {"data_share": _num(share), "u_rel_fit": u_fit,
                                               "fit_k_W_mK": _num(f.fit_k_W_mK),
                                               "fit_alpha_m2_s": _num(f.fit_alpha_m2_s)}
            if outside:
                flags.append(str(Flag.OUTSIDE_TRAINING_RANGE))
            # Not determined, however large the data's share: the fit's own u (u_rel_fit) is what the data
            # determined, and it is above the threshold; the prior narrowed the answer, which the flag says.
            flags.append(str(Flag.K_ALPHA_FROM_PRIOR))
            out["from_prior"] = ["k", "alpha"]
            out["prior_reason"] = ("the touch did not resolve k and alpha (" + "; ".join(reasons)
                                   + f"): the fit weighted with the library's prior given e, data share {share:.2f}")
        elif reasons:
            # k and alpha together: one without the other would not satisfy e = k / sqrt(alpha).
            k, u_lk, alpha, u_la, outside = est.library.k_alpha_given_e(e, u_le)
            if outside:
                flags.append(str(Flag.OUTSIDE_TRAINING_RANGE))
            flags.append(str(Flag.K_ALPHA_FROM_PRIOR))
            out["from_prior"] = ["k", "alpha"]
            out["prior_reason"] = "the touch did not resolve k and alpha: " + "; ".join(reasons)
        else:
            determined += ["k", "alpha"]
        cands = est.library.identify(e, u_le)
        out.update({"effusivity_W_s05_m2K": _num(e), "effusivity_W_s05_m2K_u": _num(e * u_le),
                    "k_W_mK": _num(k), "k_W_mK_u": _num(k * u_lk), "alpha_m2_s": _num(alpha),
                    "alpha_m2_s_u": _num(alpha * u_la), "material": cands[0][0],
                    "material_confidence": float(cands[0][1]), "flags": flags,
                    "candidates": [[n, float(c)] for n, c in cands], "determined": determined})
        return out
