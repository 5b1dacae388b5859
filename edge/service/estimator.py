"""The daemon's model: the store's active bundle as the estimate path's context.

It lives in the service layer because it joins two peers that know nothing
of each other -- the model store (:mod:`edge.model.store`) and the estimate
path (:mod:`edge.estimation.seam`).  It keeps the active bundle's
:class:`~edge.estimation.estimate.Estimator` (rebuilt when the bundle
changes) and the probe head's estimators built on it (the small heater's
model is built once per time grid), and hands them out two ways:

* :meth:`ModelEstimator.context` -- a :class:`~edge.estimation.seam.SeamContext`
  for :func:`~edge.estimation.seam.estimate_touch` (the daemon's answer to a touch);
* calling it -- the probe head's estimator on a uniform grid,
  ``(t_s, dT_K, q_W_m2, power_W, method) -> dict`` with the installed calibration,
  for the running decision that refits the record so far
  (:class:`edge.estimation.running.EstimatorDecision`).

Which estimator a probe head takes is data: its ``estimator`` kind
(:data:`edge.estimation.methods.KINDS`), not its name.
"""

from __future__ import annotations

import threading
from typing import Any, Callable

import numpy as np

from edge.estimation.estimate import Estimator
from edge.estimation.seam import SeamContext
from edge.model.store import ModelStore, ModelStoreError
from edge.physics.geometry import PROBES

__all__ = ["ModelEstimator"]


class ModelEstimator:
    """The store's active bundle as an estimator and as the estimate path's context.

    Parameters
    ----------
    store : ModelStore
    T_resolution_K : float
        The thermometer's resolution (K), which the estimator carries into u(e).
    probe : str
        The probe head (a name in :data:`edge.physics.geometry.PROBES`, ``board.probe``).
    calibration : callable () -> ProbeCalibration or None, optional
        The installed calibration (applied when it is this probe head's).
    """

    def __init__(self, store: ModelStore, T_resolution_K: float = 0.0, probe: str = "paper",
                 calibration: Callable[[], Any] | None = None) -> None:
        if probe not in PROBES:
            raise ValueError(f"unknown probe {probe!r}; shipped: {sorted(PROBES)}")
        self.store = store
        #: The probe head whose estimator kind decides the estimator.
        self.probe = probe
        self.calibration = calibration
        #: The thermometer's resolution (K), which the estimator carries into u(e).
        self.T_resolution_K = float(T_resolution_K)
        self._sha: str | None = None
        self._est: Estimator | None = None
        #: The probe heads' estimators on the active bundle (shared with every context made here).
        self.methods: dict = {}
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
            self.methods.clear()
        return self._est

    def estimator(self) -> Estimator:
        """The :class:`Estimator` of the active bundle (built when the bundle changed)."""
        with self._lock:
            return self._refresh()

    def context(self, **kw: Any) -> SeamContext:
        """A :class:`SeamContext` on the active bundle (``kw``: the other fields), sharing the estimators.

        Raises ModelStoreError when the store has no usable model.
        """
        return SeamContext(estimator=self.estimator(), methods=self.methods, **kw)

    def _method(self) -> Any:
        with self._lock:
            self._refresh()
        return SeamContext(estimator=self._est, methods=self.methods).method_for(self.probe, self.T_resolution_K)

    def prepare(self, t_s: np.ndarray) -> None:
        """Get ready to estimate on grid ``t_s`` and its prefixes (the small heater builds its model)."""
        self._method().prepare(t_s)

    def __call__(self, t_s: np.ndarray, dT_K: np.ndarray, q_W_m2: np.ndarray, power_W: float | None,
                 method: str) -> dict:
        """The probe head's estimate on a uniform grid from heater-on, with the installed calibration."""
        cal = self.calibration() if self.calibration is not None else None
        return self._method()(t_s, dT_K, q_W_m2, power_W, method, calibration=cal)
