"""From a touch's signals to effusivity, conductivity, diffusivity and a material name.

Two methods, side by side on the same data:

``"paper"`` (Ma & Zhang 2024, sections 3 and 5)
    Features u1-u8 -> ln -> normalisation -> PCA (2 components) -> MLP -> k;
    then alpha by scanning the flux-driven model (eqs. 12-13) with that k
    over the paper's alpha ranges and step, keeping the least squared error
    against the measured temperature.  e = k / sqrt(alpha).

``"default"``
    e straight from (q_f, T_f): on a thick object T_f = (D q_f) / e exactly
    (Duhamel), so 1/e is a linear least-squares coefficient (with a free
    temperature offset that absorbs baseline error); no network, no scan.
    With a known finite thickness the flux model also depends on alpha
    through thickness^2/alpha, and a 1-D scan over alpha (e still linear)
    recovers both.  Otherwise k and alpha come from e and a prior learned
    from the material library: the library's ln(rho c) averaged with
    weights from how well each material's effusivity matches the
    measurement (a kernel regression whose width is the measurement's
    uncertainty plus a floor), with its spread carried into the
    uncertainties: k = e^2/(rho c), alpha = e^2/(rho c)^2.

Uncertainties are standard uncertainties (1 sigma).  On a thick body one
touch determines e only; the k and alpha uncertainties of the default method
are dominated by the prior's spread of rho c - that is identifiability, not
noise, and the numbers say so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from edge.checks import finite_array, one_of, strictly_increasing
from edge.estimation.identification import Library
from edge.estimation.features import FEATURE_VERSION, log_features, paper_features
from edge.estimation.mlp import MLP
from edge.estimation.spline import resample
from edge.model.bundle import Bundle, max_relative_error
from edge.physics.fluxmodel import duhamel_apply, surface_temperature, surface_temperature_scan
from edge.physics.probe import volumetric_heat_W_m3
from edge.physics.solids import Solid
from edge.status import Flag

METHODS = ("default", "paper")
MODEL_DT_s = 0.01
#: prior_coef entries, in order (all in natural-log units).
PRIOR_COEF_NAMES = ("kernel_floor_ln", "rho_c_intrinsic_ln", "material_spread_ln", "paper_u_ln_k")
DEFAULT_PRIOR_COEF = (0.06, 0.10, 0.05, 0.10)  # kernel floor chosen by leave-one-out (bench)
#: Relative standard uncertainty of the flux-sensor sensitivity (FHF05 calibration).
FLUX_CALIBRATION_U_REL = 0.02
#: Independent samples per thermometer step crossed (calibrated on simulated touches,
#: see _quantisation_u_a; 1 is the most pessimistic reading).
QUANTISATION_SAMPLES_PER_STEP = 8.0
#: Smallest signal-to-noise ratio of 1/e for which an estimate is reported.
MIN_SNR = 3.0
#: Relative accuracy of the flux model behind the thickness scan (largest error over a record relative
#: to its peak; README forward-bench table: 1e-4..1e-3): residual differences below it are not information.
MODEL_REL_ERROR = 1e-3

# The paper's alpha scans (section 5), chosen there per sample; here by the network's k.
PAPER_ALPHA_SCANS = (
    (0.5, (1e-8, 5e-7, 0.05e-7)),  # PMMA-like
    (10.0, (1e-7, 1e-6, 0.1e-7)),  # glass-like
    (math.inf, (1e-5, 1e-4, 0.1e-5)),  # aluminium-like
)


@dataclass
class MethodEstimate:
    """One 1-D method's own result (SI units; ``*_u`` are standard uncertainties).

    The method step of the estimate path (:class:`edge.estimation.methods.ThickBodyMethod` turns it into
    the dict the seam reads); the answer to a touch is :class:`edge.estimation.result.Estimate`.
    """

    effusivity_W_s05_m2K: float | None
    effusivity_W_s05_m2K_u: float | None
    k_W_mK: float | None
    k_W_mK_u: float | None
    alpha_m2_s: float | None
    alpha_m2_s_u: float | None
    material: str | None
    material_confidence: float
    method: str
    model_sha256: str
    flags: list[str] = field(default_factory=list)
    candidates: list[tuple[str, float]] = field(default_factory=list)
    fit_T_K: np.ndarray | None = None
    t_model_s: np.ndarray | None = None
    #: Extra JSON keys (e.g. ``prior_reason``); present in :meth:`to_dict` only when set.
    notes: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-able dict with the documented keys."""
        def num(x):
            return None if x is None or not math.isfinite(x) else float(x)

        return {
            "effusivity_W_s05_m2K": num(self.effusivity_W_s05_m2K),
            "effusivity_W_s05_m2K_u": num(self.effusivity_W_s05_m2K_u),
            "k_W_mK": num(self.k_W_mK),
            "k_W_mK_u": num(self.k_W_mK_u),
            "alpha_m2_s": num(self.alpha_m2_s),
            "alpha_m2_s_u": num(self.alpha_m2_s_u),
            "material": self.material,
            "material_confidence": float(self.material_confidence),
            "method": self.method,
            "model_sha256": self.model_sha256,
            "flags": list(self.flags),
            "candidates": [[n, float(c)] for n, c in self.candidates],
            **self.notes,
        }


def _uniform_grid(t_end: float, dt: float) -> np.ndarray:
    n = int(math.floor(t_end / dt + 1e-9)) + 1
    return np.arange(n) * dt


def _lstsq_with_offset(m: np.ndarray, T: np.ndarray, n_eff: int):
    """Fit T = a m + c; return a, c, u_a, rss, fitted.

    The residuals of a resampled series are correlated over the spline's
    support, so the variance is scaled from the grid's point count to the
    ``n_eff`` raw samples behind it.
    """
    X = np.column_stack([m, np.ones_like(m)])
    coef, *_ = np.linalg.lstsq(X, T, rcond=None)
    fit = X @ coef
    rss = float(np.sum((T - fit) ** 2))
    sigma2 = rss / max(1, T.size - 2) * (T.size / max(n_eff, 3))
    try:
        u_a = math.sqrt(max(float(sigma2 * np.linalg.inv(X.T @ X)[0, 0]), 0.0))
    except np.linalg.LinAlgError:
        u_a = math.inf
    return float(coef[0]), float(coef[1]), u_a, rss, fit


def _slopes_and_rss(models: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Slope a and residual sum of squares of T = a m + c for every row m of ``models`` at once."""
    mc = models - models.mean(axis=1, keepdims=True)
    Tc = T - T.mean()
    smm = np.einsum("ij,ij->i", mc, mc)
    smT = mc @ Tc
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(smm > 0, smT / smm, 0.0)
    resid = Tc[None, :] - a[:, None] * mc
    return a, np.einsum("ij,ij->i", resid, resid)


def _quantisation_u_a(m: np.ndarray, Tg: np.ndarray, grid: np.ndarray, lsb_K: float) -> float:
    """Standard uncertainty of the slope a in T = a m + c from the thermometer's resolution.

    Rounding to steps of ``lsb_K`` is an error of lsb/sqrt(12) that stays
    correlated while the temperature crosses a step, so only a few samples
    per step crossed are independent; white-noise statistics of the
    residuals would understate it (their z-scores spread 1.6x too wide on
    simulated MCP9600 touches).  :data:`QUANTISATION_SAMPLES_PER_STEP`
    independent samples per step crossed brings that spread to 0.9.
    """
    if not lsb_K > 0 or grid.size < 3:
        return 0.0
    span = float(grid[-1] - grid[0])
    rise = float(np.max(Tg) - np.min(Tg))
    n_ind = min(float(grid.size), max(1.0, QUANTISATION_SAMPLES_PER_STEP * rise / lsb_K))
    s_mm = float(np.sum((m - m.mean()) ** 2))
    if s_mm <= 0 or span <= 0:
        return math.inf
    return (lsb_K / math.sqrt(12.0)) * math.sqrt(grid.size / n_ind / s_mm)


class Estimator:
    """Estimates e, k, alpha and the material from a model bundle's arrays.

    Parameters
    ----------
    arrays : mapping of name -> ndarray
        A bundle's arrays (see edge/model/schema.py).
    model_sha256 : str
        Identity of the bundle, reported with every estimate.
    paper_scan_scheme : {"duhamel", "paper"}
        Flux model used by the paper method's alpha scan: the paper's explicit
        FTCS (faithful, slow on metals) or Duhamel's integral (same answer on
        thick objects, fast).
    """

    def __init__(self, arrays: Mapping[str, np.ndarray], model_sha256: str = "", *,
                 paper_scan_scheme: str = "duhamel") -> None:
        one_of("paper_scan_scheme", paper_scan_scheme, ("duhamel", "paper"))
        self.sha256 = model_sha256
        self.paper_scan_scheme = paper_scan_scheme
        a = arrays
        self.has_paper = "mlp_n_layers" in a
        if self.has_paper:
            if int(a["feature_version"]) != FEATURE_VERSION:
                raise ValueError(
                    f"bundle feature_version {int(a['feature_version'])} != edge's {FEATURE_VERSION}"
                )
            self.x_floor = np.asarray(a["x_log_offset"], float)
            self.x_mean = np.asarray(a["x_mean"], float)
            self.x_scale = np.asarray(a["x_scale"], float)
            self.pca_mean = np.asarray(a["pca_mean"], float)
            self.pca_components = np.asarray(a["pca_components"], float)
            self.y_transform = int(a["y_transform"])
            self.mlp = MLP.from_arrays(a)
            self.p_min = np.asarray(a["pca_score_min"], float) if "pca_score_min" in a else None
            self.p_max = np.asarray(a["pca_score_max"], float) if "pca_score_max" in a else None
        coef = np.asarray(a["prior_coef"], float) if "prior_coef" in a else np.array(DEFAULT_PRIOR_COEF)
        kernel_floor, rho_c_intrinsic, material_spread, self.paper_u_ln_k = (
            list(coef) + list(DEFAULT_PRIOR_COEF[len(coef):]))[:4]
        self.library = Library.from_arrays(a, kernel_floor_ln=kernel_floor, rho_c_intrinsic_ln=rho_c_intrinsic,
                                           material_spread_ln=material_spread)

    @classmethod
    def from_bundle(cls, bundle, **kwargs) -> "Estimator":
        """An estimator for a loaded :class:`edge.model.bundle.Bundle`."""
        return cls(bundle.arrays, bundle.sha256, **kwargs)

    # -- the paper's network -------------------------------------------------
    def paper_k(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """k (W/m/K) from raw features (..., 8); also the PCA scores and clip mask."""
        if not self.has_paper:
            raise ValueError("this bundle has no paper network (mlp_*)")
        x, clipped = log_features(np.atleast_2d(u), self.x_floor)
        z = (x - self.x_mean) / self.x_scale
        p = (z - self.pca_mean) @ self.pca_components.T
        y = self.mlp.predict(p)
        k = np.exp(y) if self.y_transform == 1 else y
        return k, p, clipped

    # -- entry point ------------------------------------------------------------
    def estimate(self, t_s, dT_K, q_W_m2, *, t_q_s=None, method: str = "default", thickness_m: float | None = None,
                 back: str = "infinite", q_v_W_m3: float | None = None, n_raw: int | None = None,
                 T_resolution_K: float = 0.0, power_W: float | None = None) -> MethodEstimate:
        """Estimate from a record that starts at heater-on (this method's own result).

        Parameters
        ----------
        t_s : (n,) temperature sample times (s), increasing, heater on at t = 0.
        dT_K : (n,) excess temperature over the baseline (K).
        q_W_m2 : flux into the object (W/m^2), sampled at ``t_q_s`` (default ``t_s``).
        method : ``"default"`` or ``"paper"``.
        thickness_m, back : a known finite object (``"insulated"`` or
            ``"fixed"`` back) lets the default method separate k and alpha.
        q_v_W_m3 : heater power density, only used to flag powers outside
            the paper network's training range.
        power_W : the heater's power (W): the same flag, through the paper heater's
            volume (the network's training convention; ``q_v_W_m3`` wins when both are given).
        T_resolution_K : the thermometer's resolution (ADC step in K); its
            rounding error enters the uncertainty of e (0: none known).
        """
        one_of("method", method, METHODS)
        if q_v_W_m3 is None and power_W is not None:
            q_v_W_m3 = volumetric_heat_W_m3(power_W)
        tT = finite_array("t_s", t_s, min_len=4)
        strictly_increasing("t_s", tT)
        T = finite_array("dT_K", dT_K)
        if T.size != tT.size:
            raise ValueError(f"dT_K has {T.size} samples but t_s has {tT.size}")
        tq = tT if t_q_s is None else strictly_increasing("t_q_s", finite_array("t_q_s", t_q_s, min_len=4))
        q = finite_array("q_W_m2", q_W_m2)
        if q.size != tq.size:
            raise ValueError(f"q_W_m2 has {q.size} samples but its times have {tq.size}")
        # At heater-on (t = 0) the excess temperature and the flux are zero by
        # definition; a record that starts later gets that point, so the
        # resampling grid never extrapolates backwards.
        if tT[0] > 0:
            tT, T = np.concatenate(([0.0], tT)), np.concatenate(([0.0], T))
        if tq[0] > 0:
            tq, q = np.concatenate(([0.0], tq)), np.concatenate(([0.0], q))
        t_end = min(tT[-1], tq[-1])
        if t_end < 10 * MODEL_DT_s:
            raise ValueError(f"record too short: {t_end:.3g} s")
        grid = _uniform_grid(t_end, MODEL_DT_s)
        if tq is tT or (tq.size == tT.size and np.array_equal(tq, tT)):
            Tg, qg = resample(tT, np.column_stack((T, q)), grid).T  # one spline solve for both
        else:
            Tg = resample(tT, T, grid)
            qg = resample(tq, q, grid)
        n_eff = n_raw or int(min(tT.size, np.count_nonzero(tT <= t_end)))
        flags: list[Flag] = []
        if float(np.mean(qg[grid.size // 2:])) < 20.0 or float(np.max(Tg)) <= 0.0:
            flags.append(Flag.NO_SIGNAL)
            return MethodEstimate(None, None, None, None, None, None, None, 0.0, method, self.sha256, flags)
        if method == "paper":
            return self._paper(grid, Tg, qg, n_eff, flags, q_v_W_m3, T_resolution_K)
        return self._default(grid, Tg, qg, n_eff, flags, thickness_m, back, T_resolution_K)

    def _finish(self, e, u_ln_e, k, u_ln_k, alpha, u_ln_alpha, method, flags, fit, grid) -> MethodEstimate:
        cands = self.library.identify(e, u_ln_e)
        return MethodEstimate(
            effusivity_W_s05_m2K=e, effusivity_W_s05_m2K_u=e * u_ln_e,
            k_W_mK=k, k_W_mK_u=k * u_ln_k, alpha_m2_s=alpha, alpha_m2_s_u=alpha * u_ln_alpha,
            material=cands[0][0], material_confidence=cands[0][1], method=method, model_sha256=self.sha256,
            flags=flags, candidates=cands, fit_T_K=fit, t_model_s=grid,
        )

    def _default(self, grid, Tg, qg, n_eff, flags, thickness_m, back, lsb_K) -> MethodEstimate:
        if thickness_m is not None and back != "infinite":
            return self._default_finite(grid, Tg, qg, n_eff, flags, thickness_m, back, lsb_K)
        m = duhamel_apply(qg, MODEL_DT_s)
        a, c, u_a, _, fit = _lstsq_with_offset(m, Tg, n_eff)
        u_a = math.hypot(u_a, _quantisation_u_a(m, Tg, grid, lsb_K))
        if not a > MIN_SNR * u_a:
            # The temperature rise is lost in noise or quantisation: an e from it would be a guess.
            flags.append(Flag.INSUFFICIENT_SIGNAL)
            return MethodEstimate(None, None, None, None, None, None, None, 0.0, "default", self.sha256, flags)
        e = 1.0 / a
        u_ln_e = math.hypot(u_a / a, FLUX_CALIBRATION_U_REL)
        return self.from_effusivity(e, u_ln_e, flags=flags, fit=fit, grid=grid)

    def from_effusivity(self, e: float, u_ln_e: float, *, method: str = "default", flags: list | None = None,
                        fit=None, grid=None) -> MethodEstimate:
        """The estimate a thick body's effusivity alone gives: k and α from the library prior given e.

        ``k = e^2 / rho c``, ``alpha = k / rho c`` with ln rho c and its spread
        from the library (:meth:`Library.prior_rho_c`), the material named by
        :meth:`Library.identify`. The default method's last step, and the one
        definition the device uses for an e measured another way (the sensor
        chain's, :func:`edge.estimation.seam.chain_answer`).
        """
        flags = [] if flags is None else flags
        k, u_ln_k, alpha, u_ln_alpha, outside = self.library.k_alpha_given_e(e, u_ln_e)
        if outside:
            flags.append(Flag.OUTSIDE_TRAINING_RANGE)
        return self._finish(e, u_ln_e, k, u_ln_k, alpha, u_ln_alpha, method, flags, fit, grid)

    def _default_finite(self, grid, Tg, qg, n_eff, flags, thickness_m, back, lsb_K) -> MethodEstimate:
        # For fixed alpha the flux model is linear in 1/e: scan alpha, solve e.
        alphas = np.geomspace(1e-8, 3e-4, 61)
        units = [Solid(math.sqrt(al), 1.0 / math.sqrt(al), 1.0) for al in alphas]  # e = 1
        models = surface_temperature_scan(grid, qg, units, thickness_m=thickness_m, back=back)
        a_all, rss_all = _slopes_and_rss(models, Tg)
        rss_all = np.where(a_all > 0, rss_all, np.inf)
        best = None
        if np.any(a_all > 0):
            i = int(np.argmin(rss_all))
            m = models[i]
            a, c, u_a, rss, fit = _lstsq_with_offset(m, Tg, n_eff)
            u_a = math.hypot(u_a, _quantisation_u_a(m, Tg, grid, lsb_K))
            rss_all[i] = rss
            best = (rss, float(alphas[i]), a, u_a, fit)
        if best is None or not best[2] > MIN_SNR * best[3]:
            flags.append(Flag.INSUFFICIENT_SIGNAL)
            return MethodEstimate(None, None, None, None, None, None, None, 0.0, "default", self.sha256, flags)
        rss, alpha, a, u_a, fit = best
        e = 1.0 / a
        u_ln_e = math.hypot(u_a / a, FLUX_CALIBRATION_U_REL)
        # alpha's uncertainty from the RSS profile (delta chi^2 = 1 with sigma^2 from the best fit).  The
        # noise floor is the model's own accuracy and the thermometer's rounding: on a noise-free record
        # the residual alone would turn differences of 1e-6 between equivalent models into "information".
        rss_all = np.asarray(rss_all)
        sigma2 = rss / max(1, n_eff - 3) * (Tg.size / max(n_eff, 3)) if rss > 0 else 1e-30
        sigma2 = max(sigma2, (MODEL_REL_ERROR * float(np.max(np.abs(Tg)))) ** 2 + lsb_K ** 2 / 12.0)
        ok = (rss_all - rss) / max(sigma2 * Tg.size / max(n_eff, 3), 1e-300) <= 1.0
        if ok[0]:
            # The smallest scanned alpha (whose heat stays far from the back over the record: a
            # semi-infinite object) fits as well as the best one: the record does not show the
            # thickness, so it says nothing about alpha beyond an upper bound.  A k and alpha from
            # the scan would be a noise-picked point on a flat profile stated to a few percent (a
            # 20-mm PMMA slab gave k 1.73 +- 0.08, true 0.185); the library prior answers instead.
            fl = len(flags)
            res = self._default(grid, Tg, qg, n_eff, flags, None, "infinite", lsb_K)
            new = [f for f in (Flag.THICKNESS_UNRESOLVED, Flag.K_ALPHA_FROM_PRIOR) if f not in res.flags[fl:]]
            res.flags.extend(new)
            reach_m = math.sqrt(float(alphas[ok].max()) * float(grid[-1]))
            res.notes["prior_reason"] = (
                f"thickness {thickness_m:g} m does not show in the record (the record is as well fitted by a "
                f"semi-infinite object; the heat's reach sqrt(alpha t) would have to exceed {reach_m:.2g} m)")
            return res
        la = np.log(alphas[ok])
        u_ln_alpha = max(float(la.max() - la.min()) / 2.0, math.log(alphas[1] / alphas[0]) / 2.0)
        if alpha <= alphas[0] * 1.01 or alpha >= alphas[-1] / 1.01:
            flags.append(Flag.ALPHA_AT_SCAN_EDGE)
        k = e * math.sqrt(alpha)
        u_ln_k = math.hypot(u_ln_e, 0.5 * u_ln_alpha)
        return self._finish(e, u_ln_e, k, u_ln_k, alpha, u_ln_alpha, "default", flags, fit, grid)

    def _paper(self, grid, Tg, qg, n_eff, flags, q_v_W_m3, lsb_K) -> MethodEstimate:
        u = paper_features(grid, qg, Tg)
        k_arr, p, clipped = self.paper_k(u)
        k = float(k_arr[0])
        if clipped.any():
            flags.append(Flag.FEATURE_CLIPPED)
        if self.p_min is not None and (np.any(p < self.p_min) or np.any(p > self.p_max)):
            flags.append(Flag.OUTSIDE_TRAINING_RANGE)
        if q_v_W_m3 is not None and not (4.0e7 * 0.999 <= q_v_W_m3 <= 1.4e8 * 1.001):
            flags.append(Flag.POWER_OUTSIDE_TRAINING_RANGE)
        if not (k > 0 and math.isfinite(k)):
            flags.append(Flag.NO_SIGNAL)
            return MethodEstimate(None, None, None, None, None, None, None, 0.0, "paper", self.sha256, flags)
        lo, hi, step = next(rng for kmax, rng in PAPER_ALPHA_SCANS if k < kmax)
        alphas = np.arange(lo, hi + step / 2, step)
        m = duhamel_apply(qg, MODEL_DT_s)
        if self.paper_scan_scheme == "duhamel":
            # T_model = m sqrt(alpha) / k for every alpha at once.
            models = np.outer(np.sqrt(alphas) / k, m)
        else:
            models = np.array([
                surface_temperature(grid, qg, Solid(k, k / al, 1.0), scheme="paper") for al in alphas
            ])
        sse = np.sum((models - Tg) ** 2, axis=1)
        i = int(np.argmin(sse))
        alpha = float(alphas[i])
        if i == 0 or i == alphas.size - 1:
            flags.append(Flag.ALPHA_AT_SCAN_EDGE)
        e = k / math.sqrt(alpha)
        u_ln_k = self.paper_u_ln_k
        # The scan fits the data through e = k/sqrt(alpha): e carries the fit's
        # noise (and the scan step), alpha ~ (k/e)^2 carries k's uncertainty twice.
        a, _, u_a, _, _ = _lstsq_with_offset(m, Tg, n_eff)
        u_a = math.hypot(u_a, _quantisation_u_a(m, Tg, grid, lsb_K))
        u_ln_e_fit = u_a / a if a > 0 else 0.0
        u_ln_e = math.hypot(math.hypot(u_ln_e_fit, FLUX_CALIBRATION_U_REL), 0.5 * step / alpha / math.sqrt(3))
        u_ln_alpha = math.hypot(2 * u_ln_k, 2 * u_ln_e)
        return self._finish(e, u_ln_e, k, u_ln_k, alpha, u_ln_alpha, "paper", flags, models[i], grid)


def mlp_golden_check(bundle: Bundle, golden: Mapping[str, np.ndarray]) -> float:
    """Golden check of the network alone: the bundle's MLP maps ``mlp_inputs`` to ``mlp_outputs``."""
    return max_relative_error(MLP.from_arrays(bundle.arrays).predict(golden["mlp_inputs"]), golden["mlp_outputs"])


def pipeline_golden_check(bundle: Bundle, golden: Mapping[str, np.ndarray]) -> float:
    """Golden check of a whole bundle: the MLP vectors and, if present, features -> k."""
    err = mlp_golden_check(bundle, golden)
    if "pipeline_features" in golden:
        k, _, _ = Estimator(bundle.arrays, "").paper_k(np.asarray(golden["pipeline_features"]))
        err = max(err, max_relative_error(k, np.asarray(golden["pipeline_k"])))
    return err
