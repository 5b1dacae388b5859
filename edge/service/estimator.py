"""The daemon's default estimator: the estimation pipeline on the model store's active bundle.

It lives in the service layer because it joins two peers that know nothing
of each other -- the model store (:mod:`edge.model.store`) and the estimator
(:mod:`edge.estimation.estimate`) -- into the ``EstimatorFn`` the
measurement sequence calls (:data:`edge.measure.sequence.EstimatorFn`).

It dispatches on the probe head (``board.probe``): ``"paper"`` takes the 1-D
path exactly as before; ``"small-heater"`` the axisymmetric fit
(:class:`edge.estimation.probe_estimate.AxiEstimator`), whose result also says
what the touch determined and what came from the library prior.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from edge.estimation.estimate import Estimator
from edge.model.store import ModelStore, ModelStoreError
from edge.physics.geometry import PROBES, get_probe
from edge.physics.probe import HEATER_VOLUME_m3

__all__ = ["ModelEstimator"]


class ModelEstimator:
    """:class:`edge.estimation.estimate.Estimator` on the store's active bundle.

    Rebuilt when the active bundle changes (after an upload or rollback).

    Parameters
    ----------
    store : ModelStore
    T_resolution_K : float
        The thermometer's resolution (K), which the estimator carries into u(e).
    probe : str
        The probe head (a name in :data:`edge.physics.geometry.PROBES`, ``board.probe``).
    """

    def __init__(self, store: ModelStore, T_resolution_K: float = 0.0, probe: str = "paper",
                 calibration=None) -> None:
        if probe not in PROBES:
            raise ValueError(f"unknown probe {probe!r}; shipped: {sorted(PROBES)}")
        self.store = store
        #: The probe head whose geometry decides the estimator.
        self.probe = probe
        self._axi = None
        #: ``calibration()`` -> the installed ProbeCalibration or None: the small heater's flux scale
        #: (the paper probe's chain is applied after the estimate, edge.service.calibration).
        self.calibration = calibration
        #: The thermometer's resolution (K), which the estimator carries into u(e).
        self.T_resolution_K = float(T_resolution_K)
        self._sha: str | None = None
        self._est: Estimator | None = None
        self._lock = threading.Lock()

    def model_sha256(self) -> str | None:
        """SHA-256 of the active bundle, or None when the store has no usable model."""
        try:
            return self.store.current().sha256
        except ModelStoreError:
            return None

    def _refresh(self) -> Estimator:
        """The active bundle's :class:`Estimator`, rebuilt when the bundle changed (call under the lock)."""
        bundle = self.store.current()
        if self._sha != bundle.sha256:
            self._est, self._sha = Estimator.from_bundle(bundle), bundle.sha256
            self._axi = None
        return self._est

    def estimator(self) -> Estimator:
        """The :class:`Estimator` of the active bundle (built when the bundle changed)."""
        with self._lock:
            return self._refresh()

    def _axi_estimator(self) -> Any:
        """The small heater's estimator on the active bundle (call under the lock)."""
        est = self._refresh()
        if self._axi is None:
            from edge.estimation.probe_estimate import AxiEstimator  # noqa: PLC0415

            self._axi = AxiEstimator(est, get_probe(self.probe))
        return self._axi

    def prepare(self, t_s: np.ndarray) -> None:
        """Get ready to estimate on grid ``t_s`` and its prefixes (the small heater's model; else nothing)."""
        if self.probe == "paper":
            return
        with self._lock:
            axi = self._axi_estimator()
        axi.prepare(t_s)

    def __call__(self, t_s: np.ndarray, dT_K: np.ndarray, q_W_m2: np.ndarray, q_v_W_m3: float,
                 method: str) -> dict:
        """Estimate from the resampled series (see :data:`edge.measure.sequence.EstimatorFn`)."""
        with self._lock:
            est = self._refresh()
            axi = self._axi_estimator() if self.probe != "paper" else None
        if self.probe != "paper":
            # The sequence reports the heater's power density on the paper's heater volume (the
            # 1-D model's convention); the power itself is what the axisymmetric fit starts from.
            cal = self.calibration() if self.calibration is not None else None
            flux = {} if cal is None or cal.probe != self.probe else {
                "flux_scale": cal.chain.flux_scale, "flux_u_rel": float(cal.u_theta[0])}
            d = axi.estimate(t_s, dT_K, q_W_m2, power_W=q_v_W_m3 * HEATER_VOLUME_m3 if q_v_W_m3 else None,
                             T_resolution_K=self.T_resolution_K, **flux)
            if flux:
                d["calibration_sha256"] = cal.sha256
            return d
        return est.estimate(t_s, dT_K, q_W_m2, method=method, q_v_W_m3=q_v_W_m3,
                            T_resolution_K=self.T_resolution_K).to_dict()
