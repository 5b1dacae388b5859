"""The running decision on the device's own estimator (the small-heater probe's ``--until-decided``).

The paper probe's running answer fits the 1-D thick-body model to the heating
samples (:mod:`edge.estimation.running`).  The small-heater probe has no such
early-time model: its 10 x 10 mm flux sensor sees the 5-mm heater's edge
from the first samples.  :class:`EstimatorDecision` refits the estimator the
result will come from -- the device's, with the installed flux calibration --
on the record so far, resampled as the result will be
(:func:`edge.measure.signal.resample_uniform`), every ``every_s`` of heating,
and names the object from that estimate with e and, where the touch measured
it, alpha (:meth:`edge.recognition.ObjectSet.classify_estimate`).
The running answer and the result are then one estimate at two lengths.

Cost.  When heating starts the estimator builds its model for the touch's
whole grid (``estimate_fn.prepare``); each refit works on that model's head,
so it costs the fit alone (``python bench/decision_bench.py --world faithful --probe small-heater``
reports it: about 12 ms on this machine).

NumPy only (edge runtime).
"""

from __future__ import annotations

import math
import time
from typing import Any, Callable

import numpy as np

from edge.estimation.conditioning import resample_uniform
from edge.estimation.running import RefitDecision, RunningAnswer
from edge.estimation.seam import BLOCKERS

__all__ = ["EstimatorDecision", "ESTIMATOR_EVERY_s"]

#: Heating time between two refits.  A small-heater fit on a prepared model takes ~12 ms on this
#: machine and a few times that on a Pi-class CPU: one per 0.25 s keeps the sampling loop's budget
#: (its samples are 20 ms apart) and answers within a quarter second of when the record allows.
ESTIMATOR_EVERY_s = 0.25


class EstimatorDecision(RefitDecision):
    """Sequential decision on the device estimator's refit of the record so far.

    Parameters
    ----------
    object_set, threshold, min_time_s
        As for :class:`~edge.estimation.running.SequentialDecision`.
    estimate_fn : callable
        The device's estimator, ``(t_s, dT_K, q_W_m2, power_W, method) -> dict`` on a uniform
        grid from heater-on (:class:`edge.service.estimator.ModelEstimator`); its optional
        ``prepare(t_s)`` is called with the touch's whole grid when heating starts.
    rate_Hz : float
        The grid's rate (the profile's sample rate, as for the result).
    heat_s : float
        Planned heating time (the whole grid).
    power_W : float
        Heater power (the estimator's starting scale).
    method : str
        Passed to ``estimate_fn``.
    T_age_s : float
        Age of a thermocouple reading when read (as for the result's resampling).
    every_s : float
        Heating time between refits (:data:`ESTIMATOR_EVERY_s`), stretched where a refit takes more
        than its share (:class:`~edge.estimation.running.RefitCadence`).
    timer : callable
        Wall-clock seconds for the cadence (tests pass their own).
    """

    source = "device_estimate"

    def __init__(self, object_set: Any, threshold: float, min_time_s: float, *,
                 estimate_fn: Callable[..., dict], rate_Hz: float, heat_s: float, power_W: float,
                 method: str = "default", T_age_s: float = 0.0, every_s: float = ESTIMATOR_EVERY_s,
                 timer: Callable[[], float] = time.perf_counter) -> None:
        super().__init__(object_set, threshold, min_time_s, every_s=every_s, timer=timer)
        for name, v in (("rate_Hz", rate_Hz), ("heat_s", heat_s)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0, got {v!r}")
        self.estimate_fn = estimate_fn
        self.rate_Hz, self.heat_s = float(rate_Hz), float(heat_s)
        self.power_W = float(power_W)
        self.method = method
        self.T_age_s = float(T_age_s)

    def attach_record(self, t_s: list, T_C: list, q_W_m2: list, t_on_s: float, *, T0_C: float | None = None,
                      q0_W_m2: float | None = None, dts: list | None = None) -> None:
        """The sequence's record lists (appended in place; absolute clock times), heater-on time and baseline.

        ``T0_C`` and ``q0_W_m2``: the baseline the heating is measured from; ``dts``: each sample's
        read-time skews (see :func:`~edge.measure.signal.resample_uniform`).
        """
        if T0_C is None or q0_W_m2 is None:
            raise ValueError("EstimatorDecision needs the baseline (T0_C, q0_W_m2)")
        self._record = (t_s, T_C, q_W_m2, float(t_on_s), float(T0_C), float(q0_W_m2), dts)
        prepare = getattr(self.estimate_fn, "prepare", None)
        if prepare is not None:
            n = int(math.floor(self.heat_s * self.rate_Hz + 1e-9))
            if n >= 4:
                prepare(np.arange(1, n + 1) / self.rate_Hz)

    def _refit(self, t_s: float) -> RunningAnswer | None:
        ts, Ts, qs, t_on, T0, q0, dts = self._record
        n = min(len(ts), len(Ts), len(qs))
        t = np.asarray(ts[:n], float) - t_on
        skew = np.asarray(dts[:n], float).reshape(-1, 2) if dts is not None and len(dts) >= n else None
        try:
            g_t, g_dT, g_q = resample_uniform(t, np.asarray(Ts[:n], float), np.asarray(qs[:n], float), T0, q0,
                                              self.rate_Hz, t_s, self.T_age_s,
                                              T_dt_s=None if skew is None else skew[:, 0],
                                              q_dt_s=None if skew is None else skew[:, 1])
            if g_t.size < 4:
                return self.answer
            d = self.estimate_fn(g_t, g_dT, g_q, self.power_W, self.method)
        except ValueError:   # a prefix the estimator cannot fit yet
            return self.answer
        if BLOCKERS & set(d.get("flags") or ()):   # the one blocker table (edge.estimation.seam)
            return self.answer
        u_ln_e = self.u_ln_e(d.get("effusivity_W_s05_m2K"), d.get("effusivity_W_s05_m2K_u"))
        rec = self.objects.classify_estimate(d) if u_ln_e is not None else None
        if rec is None:
            return self.answer
        return self._settle(RunningAnswer(rec.object, rec.object_posterior, t_s, float(d["effusivity_W_s05_m2K"]),
                                          u_ln_e, int(g_t.size), cls=rec.cls, source=self.source))
