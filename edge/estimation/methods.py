"""The probe heads' estimators behind one interface, chosen by the kind the probe head names.

A probe head (:class:`edge.physics.geometry.ProbeGeometry`) names its
estimator kind (``geometry.estimator``); :data:`KINDS` maps the kind to a
class.  Every class follows one small contract (as scikit-learn's
estimators do):

* built from the model bundle's :class:`~edge.estimation.estimate.Estimator`
  (its library is the one prior, its sha256 the model's id) and the probe
  head: ``cls(estimator, geometry, T_resolution_K=...)``;
* ``prepare(t_s)`` -- get ready for a grid and its prefixes (may do nothing);
* ``__call__(t_s, dT_K, q_W_m2, power_W, method, *, calibration=None,
  thickness_m=None, back="infinite") -> dict`` on the uniform grid from
  heater-on (:func:`edge.estimation.conditioning.resample_uniform`): the keys
  of an estimate (``effusivity_W_s05_m2K`` and its ``_u``, k, α, ``flags``,
  ``method``, ``model_sha256``, ``material``...) plus ``determined`` and
  ``from_prior`` (lists of ``"e"``, ``"k"``, ``"alpha"``), when it applied
  one ``calibration_sha256``, and optionally ``series`` (arrays: ``t_model_s``,
  ``fit_T_K``, the model on its grid; not part of the JSON).

Class attributes say what else the seam does for the kind:

* ``sensor_chain`` -- the calibrated sensor chain (:mod:`edge.estimation.chain_estimate`)
  runs on the raw record and its e becomes the answer when calibrated and trusted;
* ``running`` -- the running decision it takes: ``"thick_body"`` (the 1-D early-time
  model, or the chain once calibrated) or ``"refit"`` (this estimator on the record so far);
* ``measures_alpha`` -- whether a touch can measure α (a heater small against the heat's reach):
  object sets are then calibrated on touches that carry it;
* ``kind`` -- its key in :data:`KINDS`; a 1-D (``"thick_body"``) probe head is the one the
  simulator's ideal 1-D world can model.

Adding a probe head with a new estimator: write the class, add it here, name
its kind in the probe head.  Nothing else dispatches on probe names.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from edge.estimation.estimate import Estimator
from edge.physics.geometry import ProbeGeometry, get_probe

__all__ = ["KINDS", "ThickBodyMethod", "AxiMethod", "method_class", "kind_of"]


class _Method:
    """What every head's estimator holds: the bundle's estimator, the head, the thermocouple's resolution."""

    def __init__(self, estimator: Estimator, geometry: ProbeGeometry, *, T_resolution_K: float = 0.0) -> None:
        self.estimator = estimator
        self.geometry = geometry
        self.T_resolution_K = float(T_resolution_K)


class ThickBodyMethod(_Method):
    """The 1-D estimator (``"default"`` and ``"paper"`` methods) of a heater wide against the heat's reach."""

    kind = "thick_body"
    sensor_chain = True
    running = "thick_body"
    measures_alpha = False

    def prepare(self, t_s: np.ndarray) -> None:
        """Nothing to build: the 1-D model is cheap on any grid."""

    def __call__(self, t_s, dT_K, q_W_m2, power_W: float | None, method: str = "default", *,
                 calibration: Any = None, thickness_m: float | None = None, back: str = "infinite") -> dict:
        r = self.estimator.estimate(t_s, dT_K, q_W_m2, method=method, thickness_m=thickness_m, back=back,
                                    power_W=power_W, T_resolution_K=self.T_resolution_K)
        d = r.to_dict()
        d["probe"] = self.geometry.name
        if r.fit_T_K is not None:
            # The model on its own grid (arrays: not part of the JSON; the seam keeps them in Estimate.series).
            d["series"] = {"t_model_s": r.t_model_s, "fit_T_K": r.fit_T_K}
        if r.effusivity_W_s05_m2K is None:
            d["determined"], d["from_prior"] = [], []
        elif method == "paper":
            # The network's k and the scan's alpha: both from the record.
            d["determined"], d["from_prior"] = ["e", "k", "alpha"], []
        elif thickness_m is not None and back != "infinite" and "k_alpha_from_prior" not in d["flags"]:
            d["determined"], d["from_prior"] = ["e", "k", "alpha"], []
            d["thickness_determined"] = ["k", "alpha"]
        else:
            d["determined"], d["from_prior"] = ["e"], ["k", "alpha"]
        return d


class AxiMethod(_Method):
    """The small heater's axisymmetric fit (:class:`edge.estimation.probe_estimate.AxiEstimator`)."""

    kind = "axisym"
    #: The seam passes the raw record and its baseline (``record=``, ``baseline=``): a hand touch's object
    #: offset is fitted on the samples before heater-on too.
    takes_record = True
    sensor_chain = False
    running = "refit"
    measures_alpha = True

    def __init__(self, estimator: Estimator, geometry: ProbeGeometry, *, T_resolution_K: float = 0.0) -> None:
        from edge.estimation.probe_estimate import AxiEstimator  # noqa: PLC0415 - the 1-D device never needs it

        super().__init__(estimator, geometry, T_resolution_K=T_resolution_K)
        self.axi = AxiEstimator(estimator, geometry)

    def prepare(self, t_s: np.ndarray) -> None:
        """Build the fit's model for the touch's whole grid (its prefixes then reuse it)."""
        self.axi.prepare(t_s)

    def __call__(self, t_s, dT_K, q_W_m2, power_W: float | None, method: str = "default", *,
                 calibration: Any = None, thickness_m: float | None = None, back: str = "infinite",
                 record: Any = None, baseline: tuple[float, float] | None = None) -> dict:
        # The installed calibration of this probe head replaces the datasheet's probe (flux scale and its u;
        # when it identified them, the sensing layer and the substrate, edge.calibration.axi), and such
        # answers fit the touch's contact resistance: a hand touch's is unknown, and 1e-5 m^2K/W alone put
        # AISI 304 at -9 % in e on a calibrated drawn probe (3.6 % fitted; bench/asbuilt_small_bench.py).
        from edge.estimation.probe_estimate import calibrated_params  # noqa: PLC0415 - loaded with AxiEstimator

        cal = calibration if calibration is not None and calibration.probe == self.geometry.name else None
        flux = {} if cal is None else {"flux_scale": cal.flux_scale, "flux_u_rel": cal.flux_u_rel,
                                       "u_rel_floor": cal.u_rel_floor}
        probe = calibrated_params(cal)
        if probe is not None:
            # A calibration that identified the probe as built (an older one calibrated the flux scale only,
            # and its answers stay as they were).
            flux.update(calibrated=probe, fit_contact=True)
            # The heater's TCR it identified (its self-heating droop, edge.physics.heater_tcr).
            flux["heater_tcr_per_K"] = float((cal.head_model or {}).get("heater_tcr_per_K") or 0.0)
            flux["heater_tcr_per_K_u"] = float((cal.head_model or {}).get("heater_tcr_per_K_u") or 0.0)
            flux["model_form"] = (cal.head_model or {}).get("model_form")
        pre = None
        if record is not None and baseline is not None and None not in baseline:
            # A hand touch: the object met the probe at another temperature before heating (ISSUE #34: the
            # contact transient of an object up to 3 K off dominated the 5-s errors); its offset is fitted.
            from edge.estimation.object_offset import pre_heating  # noqa: PLC0415
            pre = pre_heating(record, *baseline)
        d = self.axi.estimate(t_s, dT_K, q_W_m2, power_W=power_W, thickness_m=thickness_m, back=back,
                              T_resolution_K=self.T_resolution_K, pre=pre, **flux)
        if cal is not None:
            d["calibration_sha256"] = cal.sha256
        return d


#: Estimator kind -> class.
KINDS: dict[str, type] = {"thick_body": ThickBodyMethod, "axisym": AxiMethod}


def kind_of(probe: ProbeGeometry | str) -> str:
    """The estimator kind a probe head names."""
    geo = get_probe(probe) if isinstance(probe, str) else probe
    return geo.estimator


def method_class(probe: ProbeGeometry | str) -> type:
    """The estimator class of a probe head (KeyError naming the kinds for one that is not registered)."""
    kind = kind_of(probe)
    try:
        return KINDS[kind]
    except KeyError:
        raise KeyError(f"probe {probe!r} names estimator kind {kind!r}; registered: {sorted(KINDS)}") from None
