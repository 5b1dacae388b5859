"""The daemon's default estimator: the estimation pipeline on the model store's active bundle.

It lives in the service layer because it joins two peers that know nothing
of each other -- the model store (:mod:`edge.model.store`) and the estimator
(:mod:`edge.estimation.estimate`) -- into the ``EstimatorFn`` the
measurement sequence calls (:data:`edge.measure.sequence.EstimatorFn`).
"""

from __future__ import annotations

import threading

import numpy as np

from edge.estimation.estimate import Estimator
from edge.model.store import ModelStore, ModelStoreError

__all__ = ["ModelEstimator"]


class ModelEstimator:
    """:class:`edge.estimation.estimate.Estimator` on the store's active bundle.

    Rebuilt when the active bundle changes (after an upload or rollback).

    Parameters
    ----------
    store : ModelStore
    T_resolution_K : float
        The thermometer's resolution (K), which the estimator carries into u(e).
    """

    def __init__(self, store: ModelStore, T_resolution_K: float = 0.0) -> None:
        self.store = store
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

    def __call__(self, t_s: np.ndarray, dT_K: np.ndarray, q_W_m2: np.ndarray, q_v_W_m3: float,
                 method: str) -> dict:
        """Estimate from the resampled series (see :data:`edge.measure.sequence.EstimatorFn`)."""
        bundle = self.store.current()
        with self._lock:
            if self._sha != bundle.sha256:
                self._est, self._sha = Estimator.from_bundle(bundle), bundle.sha256
            est = self._est
        return est.estimate(t_s, dT_K, q_W_m2, method=method, q_v_W_m3=q_v_W_m3,
                            T_resolution_K=self.T_resolution_K).to_dict()
