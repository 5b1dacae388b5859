"""k and alpha from one touch of a small-heater probe: Levenberg-Marquardt on the axisymmetric model.

On a probe whose heater is small against the heat's reach in a touch
(:data:`edge.physics.geometry.PROBES` ``["small-heater"]``), the
thermocouple and the flux sensor see the lateral spreading, which depends
on k and alpha separately, not only on the effusivity.  This module fits
both to the two records with :class:`~edge.physics.axisym.AxisymModel`:

* parameters: ln k, ln alpha (log space: positive, and the Jacobian's
  columns are relative sensitivities), optionally the contact resistance
  R_c (>= 0, m^2 K/W, clipped at 0), and one linear nuisance scale -- the
  heater power (``nuisance="power"``: both records scale with it) or the
  flux sensor's sensitivity (``"flux_sensitivity"``: only q does, the
  power is known); the scale is eliminated in closed form at every
  evaluation (variable projection), so the iteration runs on 2 or 3
  parameters;
* residuals weighted by the noise levels (K, W/m^2);
* start: a scan of k along alpha = k / (2e6 J/m^3/K) (the middle of the
  solids' rho c), eight model evaluations, then Levenberg-Marquardt with
  the model's exact Jacobian in log space (:meth:`AxisymModel.transforms`
  differentiates the kernels with respect to the object's admittance, so
  the Jacobian costs about half an evaluation instead of one per parameter
  for finite differences);
* uncertainties: ``cov = s^2 (J^T J)^-1`` with the full Jacobian (scale
  column included, so its correlation with k and alpha is carried) and
  ``s^2 = chi^2 / (n - p)`` (the residual's own scatter, which also absorbs
  model error);
* the flux record's scale: :attr:`AxiFit.flux_scale_sensitivity` is the
  linearised shift of ln k, ln alpha and ln e per unit relative error of the
  flux sensor's calibration, ``(J^T J)^-1 J^T dy`` with ``dy`` the weighted
  flux record (the fit's response to a data perturbation).  With the heater
  power free it is far from the naive 1 for k and 0 for alpha: T and q then
  disagree by the scale error, and the fit reads the disagreement as lateral
  spreading (on PMMA at 5 s, d ln alpha / d ln s ~ -16, bench/sensitivity_bench.py).  The
  caller combines it with the calibration's u (the fit cannot know it);
* identifiability: a quantity is ``"measured"`` when its relative standard
  uncertainty is below ``identifiable_u_rel`` (30 %); otherwise k and
  alpha come from a caller-supplied prior on ln(rho c) given the measured
  effusivity (:func:`library_prior` adapts the device library) and are
  reported as ``"prior"``, or as ``"undetermined"`` if there is none.

Edge code: NumPy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from edge.checks import finite_array, finite_positive, one_of
from edge.estimation.design import covariance_ln_k_alpha
from edge.physics.axisym import AxisymModel
from edge.physics.geometry import ProbeGeometry

__all__ = ["AxiFit", "AxiFitter", "library_prior", "NUISANCES"]

NUISANCES = ("power", "flux_sensitivity")
#: A prior: (effusivity, u of its ln) -> (mean of ln rho c, standard deviation of ln rho c).
Prior = Callable[[float, float], tuple[float, float]]
_RHO_C_START = 2.0e6           # J/m^3/K, middle of the solids' volumetric heat capacities
_LN_K_BOUNDS = (math.log(1e-3), math.log(5e3))
_LN_A_BOUNDS = (math.log(1e-9), math.log(1e-2))
_RC_UNIT = 1e-4                # m^2 K/W: R_c is iterated in this unit (order 1 for real contacts)


def library_prior(library) -> Prior:
    """Adapt an :class:`edge.estimation.identification.Library` to the :data:`Prior` signature."""
    def prior(e: float, u_ln_e: float) -> tuple[float, float]:
        mean, sd, _outside = library.prior_rho_c(e, u_ln_e)
        return mean, sd
    return prior


@dataclass
class AxiFit:
    """Result of one fit (SI; ``*_u`` standard uncertainties, 1 sigma).

    ``determined`` says per quantity (``"k"``, ``"alpha"``, ``"effusivity"``) whether the
    touch measured it (``"measured"``), it came from the prior (``"prior"``), or neither
    (``"undetermined"``: no prior supplied; the fit's values are returned as they are).
    ``fit_k_W_mK``/``fit_alpha_m2_s`` are the fit's own values whatever was reported.
    """

    k_W_mK: float
    k_W_mK_u: float
    alpha_m2_s: float
    alpha_m2_s_u: float
    effusivity_W_s05_m2K: float
    effusivity_W_s05_m2K_u: float
    corr_k_alpha: float
    scale: float
    scale_u: float
    contact_resistance_m2K_W: float
    contact_resistance_m2K_W_u: float
    determined: dict
    fit_k_W_mK: float
    fit_alpha_m2_s: float
    u_rel: dict
    chi2_reduced: float
    iterations: int
    evaluations: int
    converged: bool
    flags: list = field(default_factory=list)
    #: d ln(quantity) / d ln(flux scale) for "k", "alpha", "effusivity" (see the module docstring).
    flux_scale_sensitivity: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        def num(x):
            return None if x is None or not math.isfinite(x) else float(x)
        d = {k: (num(v) if isinstance(v, float) else v) for k, v in self.__dict__.items()}
        d["u_rel"] = {k: num(v) for k, v in self.u_rel.items()}
        d["flux_scale_sensitivity"] = {k: num(v) for k, v in self.flux_scale_sensitivity.items()}
        return d


class AxiFitter:
    """Fits k, alpha (and nuisances) to the records of one probe on one time grid.

    Parameters
    ----------
    geometry : ProbeGeometry
        The probe.
    t_s : array_like
        Sample times of the records (s), from the heater's switch-on.
    sigma_T_K, sigma_q_W_m2 : float
        Noise (1 sigma) of the thermocouple and the flux sensor.
    nuisance : {"power", "flux_sensitivity"}
        The unknown linear scale (see the module docstring).
    fit_contact : bool
        Fit the contact resistance too (else it is fixed at ``contact_resistance_m2K_W``).
    contact_resistance_m2K_W : float
        R_c when not fitted, and the start when fitted.
    thickness_m, back :
        The object's thickness (None: semi-infinite) and back condition.
    identifiable_u_rel : float
        Relative u below which a quantity counts as measured.
    model : AxisymModel, optional
        A prebuilt model for these times (its probe part is the costly setup).
    """

    def __init__(self, geometry: ProbeGeometry, t_s, *, sigma_T_K: float = 0.01, sigma_q_W_m2: float = 0.5,
                 nuisance: str = "power", fit_contact: bool = False, contact_resistance_m2K_W: float = 0.0,
                 thickness_m: float | None = None, back: str = "infinite", identifiable_u_rel: float = 0.30,
                 model: AxisymModel | None = None, offset=None, heater_tcr_per_K: float = 0.0) -> None:
        self.geometry = geometry
        #: The heater film's TCR (1/K) the model's power droops with (edge.physics.heater_tcr); 0: none.
        self.heater_tcr_per_K = float(heater_tcr_per_K)
        #: Extra linear nuisance columns (the object's temperature offset, edge.estimation.probe_estimate's
        #: ObjectOffset): ``offset.columns(k, alpha, R_c, jac)`` -> (XT (m, nT), Xq (m, nq), dXT, dXq), per
        #: unit of each nuisance, with d/d(ln k, ln alpha, R_c) (npar, m, n) when ``jac``; None: none.
        self.offset = offset
        self.t_s = finite_array("t_s", t_s)
        self.model = model if model is not None else AxisymModel(geometry, self.t_s)
        if self.model.t_s.shape != self.t_s.shape or not np.allclose(self.model.t_s, self.t_s):
            raise ValueError("model was built for other times")
        self.sigma_T = finite_positive("sigma_T_K", sigma_T_K)
        self.sigma_q = finite_positive("sigma_q_W_m2", sigma_q_W_m2)
        self.nuisance = one_of("nuisance", nuisance, NUISANCES)
        self.fit_contact = bool(fit_contact)
        self.R_c0 = float(contact_resistance_m2K_W)
        self.thickness_m, self.back = thickness_m, back
        self.identifiable_u_rel = float(identifiable_u_rel)
        self.n_evals = 0

    # -- model pieces
    def _R(self, theta: np.ndarray) -> float:
        return max(theta[2], 0.0) * _RC_UNIT if self.fit_contact else self.R_c0

    def _weighted(self, theta: np.ndarray, P0: float, jac: bool):
        """Weighted model columns (mT, mq) per unit scale, and their theta-derivatives (npar, n).

        The last evaluation with derivatives is kept: the summary needs the Jacobian at the
        accepted point, which the iteration has just computed (a Jacobian costs ~4 plain evaluations).
        """
        last = getattr(self, "_last_jac", None)
        if jac and last is not None and last[1] == P0 and np.array_equal(last[0], theta):
            return last[2]
        out = self._weighted_eval(theta, P0, jac)
        if jac:
            self._last_jac = (theta.copy(), P0, out)
        return out

    def _weighted_eval(self, theta: np.ndarray, P0: float, jac: bool):
        self.n_evals += 1
        out = self.model.transforms(math.exp(theta[0]), math.exp(theta[1]), thickness_m=self.thickness_m,
                                    back=self.back, contact_resistance_m2K_W=self._R(theta), derivatives=jac)
        tcr = self.heater_tcr_per_K
        if tcr:
            # The heater's self-heating droop (edge.physics.heater_tcr): its TCR, calibrated, is known. The
            # droop's own theta-derivatives (through H) are second order and left out of the Jacobian.
            from edge.physics.heater_tcr import droop_transforms  # noqa: PLC0415

            xT, xq, pH = droop_transforms(self.model, math.exp(theta[0]), math.exp(theta[1]), out[0], out[1],
                                          thickness_m=self.thickness_m, back=self.back,
                                          contact_resistance_m2K_W=self._R(theta))
            c = tcr * P0
            out = (out[0] - c * xT, out[1] - c * xq) + (
                () if not jac else (out[2] - c * pH * out[2], out[3] - c * pH * out[3]))
        w = np.array([P0 / self.sigma_T, P0 / self.sigma_q])
        inv = self.model.inversion
        m = inv.invert(np.stack(out[:2])) * w[:, None]
        if not jac:
            return m[0], m[1], None, None
        npar = theta.size
        d = inv.invert(np.concatenate([out[2][:npar], out[3][:npar]]))

        dmT, dmq = d[:npar] * w[0], d[npar:] * w[1]
        if npar == 3:  # R_c is iterated in units of _RC_UNIT
            dmT[2] *= _RC_UNIT
            dmq[2] *= _RC_UNIT
        return m[0], m[1], dmT, dmq

    def _residual(self, theta, yT, yq, P0, jac: bool = False):
        """Projected residual, best scale and (with ``jac``) the residual's Jacobian (n, npar).

        Variable projection: the scale s minimises the residual in closed form for every
        theta; its derivative enters the Jacobian exactly (ds from the normal equation).
        """
        mT, mq, dmT, dmq = self._weighted(theta, P0, jac)
        if self.offset is not None:
            return self._residual_offset(theta, yT, yq, mT, mq, dmT, dmq, jac)
        if self.nuisance == "power":
            m, y = np.concatenate([mT, mq]), np.concatenate([yT, yq])
            mm = float(m @ m)
            s = float(m @ y) / mm
            r = y - s * m
            if not jac:
                return r, s, None
            dm = np.concatenate([dmT, dmq], axis=1)
            ds = (dm @ y - 2.0 * s * (dm @ m)) / mm
            return r, s, -(ds[:, None] * m[None, :] + s * dm).T
        mm = float(mq @ mq)
        s = float(mq @ yq) / mm
        r = np.concatenate([yT - mT, yq - s * mq])
        if not jac:
            return r, s, None
        ds = (dmq @ yq - 2.0 * s * (dmq @ mq)) / mm
        return r, s, -np.concatenate([dmT, ds[:, None] * mq[None, :] + s * dmq], axis=1).T

    def _offset_columns(self, theta: np.ndarray, jac: bool):
        """The offset's weighted columns (m, n) and their theta-derivatives (npar, m, n) or None."""
        XT, Xq, dXT, dXq = self.offset.columns(math.exp(theta[0]), math.exp(theta[1]), self._R(theta), jac)
        X = np.concatenate([XT / self.sigma_T, Xq / self.sigma_q], axis=1)
        if not jac:
            return X, None
        dX = np.concatenate([dXT / self.sigma_T, dXq / self.sigma_q], axis=2)[:theta.size]
        if theta.size == 3:
            dX[2] *= _RC_UNIT
        return X, dX

    def _design(self, theta, mT, mq, dmT, dmq, jac: bool):
        """Columns [heater (power scale), offset's ...] (n, 1 + m) and d(columns)/d theta (npar, n, 1 + m)."""
        X, dX = self._offset_columns(theta, jac)
        if getattr(self.offset, "tcr", False):
            # A column made from the heater's own (the heater's TCR under the contact transient).
            x, dx = self.offset.tcr_columns(math.exp(theta[0]), math.exp(theta[1]), self._R(theta), mT, mq,
                                            dmT, dmq, jac)
            X = np.concatenate([X, x[None, :]])
            if jac:
                dX = np.concatenate([dX, dx[:, None, :]], axis=1)
        A = np.concatenate([np.concatenate([mT, mq])[:, None], X.T], axis=1)
        if not jac:
            return A, None
        dm = np.concatenate([dmT, dmq], axis=1)
        return A, np.concatenate([dm[:, :, None], np.transpose(dX, (0, 2, 1))], axis=2)

    def _with_prior(self, A, dA, y):
        """The offset's prior on its nuisances as extra rows (``offset.prior(beta)`` -> rows, targets)."""
        prior = getattr(self.offset, "prior", None)
        if prior is None:
            return A, dA, y
        rows, targets = prior(np.linalg.lstsq(A, y, rcond=None)[0])
        A = np.concatenate([A, rows])
        y = np.concatenate([y, targets])
        if dA is not None:
            dA = np.concatenate([dA, np.zeros((dA.shape[0],) + rows.shape)], axis=1)
        return A, dA, y

    def _residual_offset(self, theta, yT, yq, mT, mq, dmT, dmq, jac: bool):
        """Variable projection with the power scale and the offset's linear nuisances (Kaufman's Jacobian).

        The linear coefficients minimise the residual in closed form at every theta; the Jacobian is
        the projected ``-(I - A A^+) dA beta`` (Kaufman 1975), which converges like the exact one.
        """
        if self.nuisance != "power":
            raise ValueError("the object offset is fitted with the power scale as the nuisance")
        y = np.concatenate([yT, yq])
        A, dA = self._design(theta, mT, mq, dmT, dmq, jac)
        A, dA, y = self._with_prior(A, dA, y)
        Q, _ = np.linalg.qr(A)
        beta = np.linalg.lstsq(A, y, rcond=None)[0]
        r = y - A @ beta
        self._beta = beta
        if not jac:
            return r, float(beta[0]), None
        D = np.einsum("pnm,m->np", dA, beta)          # (n, npar)
        D = D - Q @ (Q.T @ D)
        return r, float(beta[0]), -D

    def _clip(self, theta: np.ndarray) -> np.ndarray:
        th = theta.copy()
        th[0] = min(max(th[0], _LN_K_BOUNDS[0]), _LN_K_BOUNDS[1])
        th[1] = min(max(th[1], _LN_A_BOUNDS[0]), _LN_A_BOUNDS[1])
        if self.fit_contact:
            th[2] = max(th[2], 0.0)
        return th

    # -- the fit's response to a different model (a calibration's parameters)
    def model_response(self, model: AxisymModel) -> np.ndarray:
        """d(ln k, ln alpha) when the records follow ``model`` instead of the fitted one, at the last fit.

        Linearised: the records' change ``dy`` (the other model's signals at the fitted k, alpha, R_c and
        scale, minus the fitted model's, in noise units) moves the fit by ``(J^T J)^-1 J^T dy``.  Divided
        by a parameter step it is the fit's sensitivity to that parameter of the probe.
        """
        return self._response_to("model", model)

    def tcr_response(self, d_tcr_per_K: float) -> np.ndarray:
        """d(ln k, ln alpha) when the heater's TCR is ``d_tcr_per_K`` off the one fitted with, at the last fit.

        Linearised as :meth:`model_response`: the records' change is the droop's (its column times the step,
        ``edge.physics.heater_tcr``), the fit's response ``(J^T J)^-1 J^T dy``.
        """
        return self._response_to("heater_tcr_per_K", self.heater_tcr_per_K + float(d_tcr_per_K))

    def _response_to(self, attribute: str, value) -> np.ndarray:
        """d(ln k, ln alpha) when the records follow this fitter with ``attribute`` set to ``value``, at the last fit."""
        theta, s, P0, _J = self._final
        base = self._weighted_eval(theta, P0, False)
        keep = getattr(self, attribute)
        try:
            setattr(self, attribute, value)
            other = self._weighted_eval(theta, P0, False)
        finally:
            setattr(self, attribute, keep)
        scale_T = s if self.nuisance == "power" else 1.0
        return self.response(np.concatenate([scale_T * (other[0] - base[0]), s * (other[1] - base[1])]))

    def response(self, dy: np.ndarray) -> np.ndarray:
        """d(ln k, ln alpha) of the last fit when its records (in noise units) change by ``dy``: ``(J^T J)^-1 J^T dy``.

        ``dy`` covers the records only; the offset's prior rows, if any, do not change (zeros).
        """
        J = self._final[3]
        dy = np.concatenate([dy, np.zeros(J.shape[0] - dy.size)])
        return (covariance_ln_k_alpha(J.T @ J) @ (J.T @ dy))[:2]

    # -- the fit
    def fit(self, T_K, q_W_m2, *, power_W: float | None = None, prior: Prior | None = None,
            start: tuple[float, float] | None = None, max_iter: int = 30) -> AxiFit:
        """Fit one touch's records (T rise from the start in K, flux sensor in W/m^2).

        ``power_W``: the heater power the record was taken at (the nominal one by default; with
        ``nuisance="power"`` only its order of magnitude matters).  ``start``: (k, alpha) to
        start from instead of the scan.
        """
        self.n_evals = 0
        self._last_jac = None
        t = self.t_s
        T = finite_array("T_K", T_K)
        q = finite_array("q_W_m2", q_W_m2)
        if T.shape != t.shape or q.shape != t.shape:
            raise ValueError("T_K and q_W_m2 must match the fitter's times")
        P0 = self.geometry.nominal_power_W if power_W is None else finite_positive("power_W", power_W)
        yT, yq = T / self.sigma_T, q / self.sigma_q
        npar = 3 if self.fit_contact else 2
        rc0 = self.R_c0 / _RC_UNIT

        if start is None:
            best = None
            for ln_k in np.linspace(math.log(0.05), math.log(500.0), 8):
                th = np.array([ln_k, ln_k - math.log(_RHO_C_START), rc0][:npar])
                c = float(np.sum(self._residual(th, yT, yq, P0)[0] ** 2))
                if best is None or c < best[0]:
                    best = (c, th)
            theta = best[1]
        else:
            theta = np.array([math.log(start[0]), math.log(start[1]), rc0][:npar])

        r, s, J = self._residual(theta, yT, yq, P0, jac=True)
        cost = float(r @ r)
        lam = 1e-3
        converged = False
        it = 0
        for it in range(1, max_iter + 1):
            g = J.T @ r
            A = J.T @ J
            improved = False
            for _ in range(8):
                D = np.diag(np.diag(A)) + 1e-12 * np.eye(npar)
                try:
                    step = -np.linalg.solve(A + lam * D, g)
                except np.linalg.LinAlgError:
                    lam *= 10.0
                    continue
                th_new = self._clip(theta + step)
                r_new, s_new, J_new = self._residual(th_new, yT, yq, P0, jac=True)
                c_new = float(r_new @ r_new)
                if c_new < cost:
                    improved = True
                    # Converged when the step is negligible or chi^2 (cost is in noise units) fell by
                    # less than 1e-3: the point is then within ~0.03 sigma of the optimum, and a
                    # further iteration (a Jacobian, ~4 model evaluations) would change nothing stated.
                    small = (np.max(np.abs(th_new - theta)) < 1e-5
                             or (cost - c_new) < max(1e-9 * cost, 1e-3))
                    theta, r, s, cost, J = th_new, r_new, s_new, c_new, J_new
                    lam = max(lam / 5.0, 1e-9)
                    break
                lam *= 8.0
            if not improved or small:
                converged = True
                break
        return self._summarise(theta, r, s, cost, yT, yq, P0, prior, it, converged)

    def _summarise(self, theta, r, s, cost, yT, yq, P0, prior, iterations, converged) -> AxiFit:
        npar = theta.size
        # Full Jacobian of the weighted model at the solution: ln k, ln alpha (, R_c), scale.
        mT, mq, dmT, dmq = self._weighted(theta, P0, True)
        if self.offset is not None:
            # Full Jacobian: theta's columns through every linear term, then the power scale and the
            # offset's nuisances -- their covariance with ln k and ln alpha enters every u.
            A, dA = self._design(theta, mT, mq, dmT, dmq, True)
            A, dA, y_all = self._with_prior(A, dA, np.concatenate([yT, yq]))
            beta = np.linalg.lstsq(A, y_all, rcond=None)[0]
            s = float(beta[0])
            J = np.concatenate([np.einsum("pnm,m->np", dA, beta), A], axis=1)
            self.offset_beta = beta[1:].copy()
        elif self.nuisance == "power":
            J = np.concatenate([np.concatenate([s * dmT, s * dmq], axis=1).T,
                                np.concatenate([mT, mq])[:, None]], axis=1)
        else:
            J = np.concatenate([np.concatenate([dmT, s * dmq], axis=1).T,
                                np.concatenate([0.0 * mT, mq])[:, None]], axis=1)
        n = r.size
        dof = max(n - J.shape[1], 1)
        chi2_red = cost / dof
        # Vanishing prior on ln k, ln alpha: e stays determined where k and alpha are not.
        cov = covariance_ln_k_alpha(J.T @ J / chi2_red)
        var_lk, var_la = cov[0, 0], cov[1, 1]
        u_lk = math.sqrt(var_lk) if var_lk >= 0 else math.inf
        u_la = math.sqrt(var_la) if var_la >= 0 else math.inf
        g = np.zeros(J.shape[1])
        g[0], g[1] = 1.0, -0.5
        var_le = float(g @ cov @ g)
        u_le = math.sqrt(var_le) if var_le >= 0 else math.inf
        corr = float(cov[0, 1] / (u_lk * u_la)) if math.isfinite(u_lk * u_la) and u_lk * u_la > 0 else math.nan
        # The fit's response to the flux record scaled by (1 + eps): d beta / d eps = (J^T J)^-1 J^T dy,
        # with the same (vanishing) regularisation as the covariance.
        dy = np.concatenate([np.zeros_like(yT), yq])
        dy = np.concatenate([dy, np.zeros(J.shape[0] - dy.size)])   # the offset's prior rows (none: 0)
        self._final = (theta.copy(), float(s), P0, J)
        #: What the fit had still to go (the Gauss-Newton step to the linearised optimum, its ln k, ln alpha
        #: first): ~0 at a converged fit; for one that stopped short, a part of its answers' u.
        inv_JtJ = covariance_ln_k_alpha(J.T @ J)
        self.remaining_step = inv_JtJ @ (J.T @ r) if r.size == J.shape[0] else np.full(J.shape[1], np.nan)
        d_beta = inv_JtJ @ (J.T @ dy)
        sens = {"k": float(d_beta[0]), "alpha": float(d_beta[1]), "effusivity": float(d_beta[0] - 0.5 * d_beta[1])}
        k, a = math.exp(theta[0]), math.exp(theta[1])
        e = k / math.sqrt(a)
        u_scale = math.sqrt(max(cov[npar, npar], 0.0))
        if self.offset is not None:
            self.offset_cov = cov[npar + 1:, npar + 1:].copy()
        R = max(theta[2], 0.0) * _RC_UNIT if self.fit_contact else self.R_c0
        u_R = math.sqrt(max(cov[2, 2], 0.0)) * _RC_UNIT if self.fit_contact else 0.0
        # Relative u of a log-normal quantity ~ u of its ln (exactly so to first order).
        u_rel = {"k": u_lk, "alpha": u_la, "effusivity": u_le}
        thr = self.identifiable_u_rel
        det = {q: ("measured" if u_rel[q] < thr else "undetermined") for q in u_rel}
        flags = [] if converged else ["not_converged"]
        k_out, uk_out, a_out, ua_out = k, k * u_lk, a, a * u_la
        if det["k"] != "measured" or det["alpha"] != "measured":
            if prior is not None and det["effusivity"] == "measured":
                # k = e^2 / (rho c), alpha = e^2 / (rho c)^2 with ln(rho c) from the prior.
                m, sd = prior(e, u_le)
                rc = math.exp(m)
                k_out, a_out = e * e / rc, e * e / (rc * rc)
                uk_out = k_out * math.hypot(2 * u_le, sd)
                ua_out = a_out * math.hypot(2 * u_le, 2 * sd)
                det["k"] = det["alpha"] = "prior"
                flags.append("k_alpha_from_prior")
            else:
                flags.append("k_alpha_undetermined")
        return AxiFit(k_W_mK=k_out, k_W_mK_u=uk_out, alpha_m2_s=a_out, alpha_m2_s_u=ua_out,
                      effusivity_W_s05_m2K=e, effusivity_W_s05_m2K_u=e * u_le, corr_k_alpha=corr,
                      scale=float(s), scale_u=u_scale, contact_resistance_m2K_W=R, contact_resistance_m2K_W_u=u_R,
                      determined=det, fit_k_W_mK=k, fit_alpha_m2_s=a, u_rel=u_rel, chi2_reduced=chi2_red,
                      iterations=iterations, evaluations=self.n_evals, converged=converged, flags=flags,
                      flux_scale_sensitivity=sens)
