"""Calibration of the small-heater probe: its flux sensor's scale, from touches of reference materials.

The small heater's axisymmetric fit (:mod:`edge.estimation.probe_estimate`) frees the heater power
and takes the flux sensor's reading as calibrated; its one calibration parameter is that sensor's
scale ``f`` (true flux per unit of the reading).  A scale error does not move k and alpha one to one:
with the power free, T and q then disagree and the fit reads it as lateral spreading (on PMMA at
5 s, d ln alpha / d ln f ~ -16) -- which is also what makes references with known k *and* alpha
pin ``f`` down well.

Method: Gauss-Newton on ``x = ln f``.  Per touch of a reference the fit's own k and alpha at the
current ``f`` and their sensitivities to it (``fit.flux_scale_sensitivity``) give two residuals,
``ln k_fit - ln k_ref`` and ``ln alpha_fit - ln alpha_ref``, weighted by the fit's uncertainty and
the reference's (k from its certificate, alpha twice as uncertain: it also carries rho c); the
datasheet's spread of the sensor (:data:`edge.physics.probe.FLUX_SENSITIVITY_U_REL`) is the
prior.  Touches that did not determine k and alpha (a short touch of a metal) weigh nothing in
the fit; their e still appears among the references' re-measured errors.  The result is a :class:`~edge.calibration.model.ProbeCalibration` for probe
``small-heater`` whose ``chain.flux_scale`` and first covariance entry are the fit; the paper
probe's layer parameters keep their datasheet values (the small heater's model has its layers
from its geometry).

Edge code: NumPy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone

import numpy as np

from edge.calibration.fit import check_reference
from edge.calibration.model import CalibrationError, ProbeCalibration, ReferenceFit
from edge.physics.probe import FLUX_SENSITIVITY_U_REL

__all__ = ["AxiReferenceTouch", "fit_flux_scale", "ITERATIONS"]

#: Gauss-Newton steps on ln f (the model is nearly linear in it over a few per cent).
ITERATIONS = 3


@dataclass(frozen=True)
class AxiReferenceTouch:
    """One touch of a reference by the small-heater probe: its record from heater-on and its k, alpha.

    ``u_rel_k`` is the reference's stated relative standard uncertainty of k; alpha's is taken
    twice that.
    """

    name: str
    k_W_mK: float
    alpha_m2_s: float
    u_rel_k: float
    t_s: np.ndarray
    dT_K: np.ndarray
    q_W_m2: np.ndarray


def _touch_rows(estimator, touch: AxiReferenceTouch, scale: float) -> tuple[list, list, dict]:
    d = estimator.estimate(touch.t_s, touch.dT_K, touch.q_W_m2, flux_scale=scale, flux_u_rel=0.0)
    fit = d.get("fit") or {}
    ok = {"k", "alpha"} <= set(d.get("determined") or [])
    if not ok or fit.get("flux_scale_sensitivity") is None:
        return [], [], d
    sens = fit["flux_scale_sensitivity"]
    rows, res = [], []
    for q, ref, u_ref in (("k", touch.k_W_mK, touch.u_rel_k), ("alpha", touch.alpha_m2_s, 2.0 * touch.u_rel_k)):
        val = fit["k_W_mK"] if q == "k" else fit["alpha_m2_s"]
        u = math.hypot(fit["u_rel_k"] if q == "k" else fit["u_rel_alpha"], u_ref)
        rows.append(sens[q] / u)
        res.append((math.log(val) - math.log(ref)) / u)
    return rows, res, d


def fit_flux_scale(estimator, touches: list[AxiReferenceTouch], *, min_references: int = 2) -> ProbeCalibration:
    """Fit the small-heater probe's flux scale to reference touches (see the module docstring).

    Parameters
    ----------
    estimator : edge.estimation.probe_estimate.AxiEstimator
        The small-heater estimator (its geometry is the probe's).
    touches : list of AxiReferenceTouch
        At least two different references.

    ``min_references``: fewest different references (the leave-one-out self-check fits on one less).
    The model-form floor (``u_rel_floor``) is 0 here: it is the self-check's, from the references
    re-measured without themselves (:mod:`edge.calibration.selfcheck`).

    Raises
    ------
    CalibrationError
        Fewer than two references, a touch whose e contradicts its reference
        (:func:`edge.calibration.fit.check_reference`), or none of the touches determined k and alpha.
    """
    if len({t.name for t in touches}) < min_references:
        raise CalibrationError("calibration needs touches of at least two different references")
    x = 0.0
    for it in range(ITERATIONS):
        J, r = [1.0 / FLUX_SENSITIVITY_U_REL], [x / FLUX_SENSITIVITY_U_REL]
        used = 0
        for tc in touches:
            rows, res, d = _touch_rows(estimator, tc, math.exp(x))
            if it == 0:
                # The datasheet scale's e against the declared reference: swapped names are refused
                # before they are fitted (the same bound as the paper probe's).
                check_reference(tc.name, tc.k_W_mK / math.sqrt(tc.alpha_m2_s), d.get("effusivity_W_s05_m2K"),
                                d.get("effusivity_W_s05_m2K_u"))
            J += rows
            r += res
            used += bool(rows)
        if used == 0:
            raise CalibrationError("no reference touch determined k and alpha: touch longer (5 s) or use "
                                   "references the probe resolves (pmma, pyroceram)")
        J, r = np.asarray(J), np.asarray(r)
        # r(x + dx) ~ r + J dx (the prior row's own derivative is 1 / u); least squares in dx.
        x -= float(J @ r) / float(J @ J)
    u_x = 1.0 / math.sqrt(float(J @ J))
    scale = math.exp(x)
    refs: dict[str, list] = {}
    for tc in touches:
        d = estimator.estimate(tc.t_s, tc.dT_K, tc.q_W_m2, flux_scale=scale, flux_u_rel=u_x)
        e_ref = tc.k_W_mK / math.sqrt(tc.alpha_m2_s)
        e = d.get("effusivity_W_s05_m2K")
        errs = refs.setdefault(tc.name, [e_ref, tc.u_rel_k, []])[2]
        if e is not None and math.isfinite(e):
            errs.append(e / e_ref - 1.0)
    nominal = ProbeCalibration.nominal("small-heater")
    cov = np.array(nominal.covariance)
    cov[0, :] = cov[:, 0] = 0.0
    cov[0, 0] = u_x * u_x
    return ProbeCalibration(
        probe="small-heater", chain=nominal.chain_at([x, *nominal.theta[1:]]), covariance=cov,
        u_rel_floor=0.0, calibrated=True, created_utc=datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        references=tuple(ReferenceFit(n, v[0], v[1], len(v[2]), tuple(float(a) for a in v[2]))
                         for n, v in sorted(refs.items()) if v[2]))
