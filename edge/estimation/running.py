"""A cheap effusivity estimate that grows sample by sample, and the sequential decision on it.

While the heater runs the device wants an answer *now* (which object is
this?), not only at the end of the touch. On a thick body the surface
temperature rise is Duhamel's integral of the flux into it over its
effusivity (exactly, whatever the flux history; :mod:`edge.physics.fluxmodel`)::

    dT(t) = m(t) / e + c,   m(t) = (1 / sqrt(pi)) * integral_0^t q(s) / sqrt(t - s) ds

so ``1/e`` is the slope of a straight-line fit of dT on m, with a free
offset ``c`` (baseline error) -- the default estimator's model
(:meth:`edge.estimation.estimate.Estimator._default`), without its spline
resampling. :class:`RunningEffusivity` keeps that fit up to date in O(n)
work per new sample: ``m`` at the new sample's time is one sum over the
flux samples so far (flux piecewise constant between samples, each
interval integrated exactly: ``2/sqrt(pi) * q * (sqrt(t - a) - sqrt(t - b))``)
and ``m`` at earlier times never changes (causality), so the regression's
running sums are simply extended. Its uncertainty has the same three
terms as the full estimate's: the residual scatter, the thermometer's
rounding (few independent samples per step crossed) and the flux
calibration.

:class:`SequentialDecision` feeds each running estimate into an
:class:`~edge.recognition.ObjectSet` and says when the answer is
decided: the top answer's posterior (an object, or "unknown") at least
``threshold`` after at least ``min_time_s`` of heating. The full estimate
at the end of the touch is still made from the whole record.

NumPy only (edge runtime).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from edge.estimation.estimate import FLUX_CALIBRATION_U_REL, MIN_SNR, QUANTISATION_SAMPLES_PER_STEP

__all__ = ["duhamel_m", "RunningEffusivity", "RunningAnswer", "SequentialDecision", "RefitCadence",
           "RefitDecision", "REFIT_MAX_SHARE"]

_TWO_OVER_SQRT_PI = 2.0 / math.sqrt(math.pi)


def duhamel_m(t_eval: float, t_q: np.ndarray, q: np.ndarray) -> float:
    """``m(t_eval)`` for a flux that is 0 before t = 0 and piecewise constant between its samples.

    Over ``(t_q[j-1], t_q[j]]`` the flux is the mean of the two samples (the
    first interval, from heater-on at 0, takes ``q[0]``: the flux jumps at
    switch-on); past the last sample it holds ``q[-1]``. Samples after
    ``t_eval`` are ignored and the interval that contains it is cut there.
    """
    if t_eval <= 0 or t_q.size == 0:
        return 0.0
    b = np.asarray(t_q, float)
    q = np.asarray(q, float)
    q_last = q[-1]
    q = np.concatenate((q[:1], 0.5 * (q[1:] + q[:-1])))
    a = np.concatenate(([0.0], b[:-1]))
    a = np.minimum(a, t_eval)
    b = np.minimum(b, t_eval)
    # The last sample's value also holds up to t_eval when t_eval is past it.
    if t_eval > b[-1]:
        a = np.append(a, b[-1])
        b = np.append(b, t_eval)
        q = np.append(q, q_last)
    return float(_TWO_OVER_SQRT_PI * np.sum(q * (np.sqrt(t_eval - a) - np.sqrt(t_eval - b))))


class RunningEffusivity:
    """Running fit of ``dT = m / e + c`` over the heating samples seen so far.

    Parameters
    ----------
    T_age_s : float
        Mean age of a temperature reading when read (the converter's lag): a
        reading at time t is placed at ``t - T_age_s``.
    T_resolution_K : float
        The thermometer's step (its rounding enters u(e)); 0: none known.
    """

    def __init__(self, T_age_s: float = 0.0, T_resolution_K: float = 0.0) -> None:
        self.T_age_s = float(T_age_s)
        self.lsb_K = float(T_resolution_K)
        self._tq: list[float] = []
        self._q: list[float] = []
        self._m: list[float] = []
        self._T: list[float] = []

    @property
    def n(self) -> int:
        """Temperature samples in the fit."""
        return len(self._T)

    def add(self, t_s: float, dT_K: float, q_W_m2: float) -> None:
        """One heating sample: time since heater-on (s), rise over the baseline (K), flux (offset removed)."""
        if not t_s > 0:
            return
        self._tq.append(float(t_s))
        self._q.append(float(q_W_m2))
        tT = t_s - self.T_age_s
        if tT <= 0:
            return  # read before the heat reached it: a baseline reading
        self._m.append(duhamel_m(tT, np.asarray(self._tq), np.asarray(self._q)))
        self._T.append(float(dT_K))

    def estimate(self) -> tuple[float, float] | None:
        """``(e, u_ln_e)`` from the samples so far, or None while the rise is not yet above noise."""
        if self.n < 4:
            return None
        m = np.asarray(self._m)
        T = np.asarray(self._T)
        # The fit includes the anchor (0, 0): the rise is continuous at heater-on.
        m = np.concatenate(([0.0], m))
        T = np.concatenate(([0.0], T))
        mc = m - m.mean()
        smm = float(mc @ mc)
        if not smm > 0:
            return None
        a = float(mc @ (T - T.mean())) / smm
        resid = T - T.mean() - a * mc
        sigma2 = float(resid @ resid) / max(1, T.size - 2)
        u_a = math.sqrt(sigma2 / smm)
        if self.lsb_K > 0:
            rise = float(T.max() - T.min())
            n_ind = min(float(T.size), max(1.0, QUANTISATION_SAMPLES_PER_STEP * rise / self.lsb_K))
            u_a = math.hypot(u_a, (self.lsb_K / math.sqrt(12.0)) * math.sqrt(T.size / n_ind / smm))
        if not a > MIN_SNR * u_a:
            return None
        return 1.0 / a, math.hypot(u_a / a, FLUX_CALIBRATION_U_REL)


@dataclass
class RunningAnswer:
    """The running best answer during a touch (``decision`` in STATUS and in the record's result)."""

    object: str
    posterior: float
    elapsed_s: float
    effusivity_W_s05_m2K: float
    u_ln_e: float
    n: int
    decided: bool = False
    cls: str | None = None
    #: The running estimate it rests on: the thick-body fit of the raw reading or the calibrated sensor chain.
    source: str = "thick_body"

    def to_dict(self) -> dict[str, Any]:
        return {"object": self.object, "posterior": round(float(self.posterior), 6),
                "elapsed_s": round(float(self.elapsed_s), 4), "class": self.cls,
                "effusivity_W_s05_m2K": float(self.effusivity_W_s05_m2K), "u_ln_e": float(self.u_ln_e),
                "samples": int(self.n), "decided": bool(self.decided), "source": self.source}


class SequentialDecision:
    """Posterior over an object set updated on each heating sample; decided at ``threshold``.

    Parameters
    ----------
    object_set : ObjectSet
        The objects (``classify(e, u_ln_e)``).
    threshold : float
        Posterior of the top answer that decides (``measurement.decide_posterior``).
    min_time_s : float
        No decision before this much heating (``measurement.decide_min_s``).
    T_age_s, T_resolution_K : float
        As for :class:`RunningEffusivity`.
    """

    def __init__(self, object_set: Any, threshold: float, min_time_s: float, *, T_age_s: float = 0.0,
                 T_resolution_K: float = 0.0) -> None:
        if not 0.0 < threshold <= 1.0:
            raise ValueError(f"threshold must be in (0, 1], got {threshold!r}")
        self.objects = object_set
        self.threshold = float(threshold)
        self.min_time_s = float(min_time_s)
        self.running = RunningEffusivity(T_age_s, T_resolution_K)
        #: The latest answer (None until the rise is above noise).
        self.answer: RunningAnswer | None = None
        #: The answer that decided (None while undecided).
        self.decided: RunningAnswer | None = None

    def update(self, t_s: float, dT_K: float, q_W_m2: float) -> RunningAnswer | None:
        """Add one heating sample; return the (new) running answer, ``decided`` set once it is."""
        self.running.add(t_s, dT_K, q_W_m2)
        est = self.running.estimate()
        if est is None:
            return self.answer
        return self._answer(t_s, *est, self.running.n)

    #: ``RunningAnswer.source`` of this decision's answers.
    source = "thick_body"

    def _answer(self, t_s: float, e: float, u: float, n: int) -> RunningAnswer:
        """Name the object for a running (e, u_ln_e) at ``t_s``; decide at the threshold."""
        rec = self.objects.classify(e, u)
        return self._settle(RunningAnswer(rec.object, rec.object_posterior, t_s, e, u, n, cls=rec.cls,
                                          source=self.source))

    def _settle(self, ans: RunningAnswer) -> RunningAnswer:
        """Make ``ans`` the running answer; it decides when the threshold is reached after ``min_time_s``."""
        if self.decided is None and ans.elapsed_s >= self.min_time_s and ans.posterior >= self.threshold:
            ans.decided = True
            self.decided = ans
        self.answer = ans
        return ans


#: Most of the heating time a running decision's refits may take.  They run in the sampling loop:
#: a refit taking longer than its share stretches the interval to the next one, so a slower CPU
#: (a Pi-class one runs them several times slower than the bench machine) refits less often
#: instead of delaying the samples.
REFIT_MAX_SHARE = 0.2


class RefitCadence:
    """When the next refit of a running decision is due.

    Every ``every_s`` of heating from ``min_time_s`` on, and never sooner after a refit than the
    refits' cost over ``max_share``.  The cost is the shorter of the last two refits after the
    first: the first pays one-time costs (imports, caches: a few times a warm refit in a fresh
    ``thermotouch measure --sim``), and one slow refit (a cold start, a collector pause) must not
    end the running answer for the rest of the touch -- it once stretched the next refit past the
    end of a 2-s touch.

    Parameters
    ----------
    every_s : float
        Heating time between refits when they are fast.
    min_time_s : float
        No refit before this much heating.
    max_share : float
        Largest share of the time the refits may take (:data:`REFIT_MAX_SHARE`).
    timer : callable
        Wall-clock seconds (``time.perf_counter``; a test passes its own).
    """

    def __init__(self, every_s: float, min_time_s: float = 0.0, *, max_share: float = REFIT_MAX_SHARE,
                 timer: Callable[[], float] = time.perf_counter) -> None:
        if not (math.isfinite(every_s) and every_s > 0):
            raise ValueError(f"every_s must be finite and > 0, got {every_s!r}")
        if not 0.0 < max_share <= 1.0:
            raise ValueError(f"max_share must be in (0, 1], got {max_share!r}")
        self.every_s, self.min_time_s, self.max_share = float(every_s), float(min_time_s), float(max_share)
        self.timer = timer
        self.next_s = 0.0
        #: Wall time of each refit (s).
        self.spent_s: list[float] = []

    def due(self, t_s: float) -> bool:
        """True when a refit is due at heating time ``t_s``."""
        return t_s >= max(self.next_s, self.min_time_s)

    def run(self, t_s: float, fit: Callable[[], Any]) -> Any:
        """Run ``fit()`` at heating time ``t_s`` and schedule the next refit from its duration."""
        start = self.timer()
        try:
            return fit()
        finally:
            self.spent_s.append(max(self.timer() - start, 0.0))
            recent = self.spent_s[1:][-2:]
            cost = min(recent) if recent else 0.0
            self.next_s = t_s + max(self.every_s, cost / self.max_share)


class RefitDecision(SequentialDecision):
    """A sequential decision that refits the record so far, on a :class:`RefitCadence`.

    The base of the decisions that need more than the heating samples
    (:class:`edge.estimation.chain_decision.ChainDecision`,
    :class:`edge.measure.estimator_decision.EstimatorDecision`): the sequence hands them its
    record lists (``attach_record``, which stores them in ``_record``), and :meth:`update` calls
    ``_refit(t_s)`` whenever the cadence says a refit is due.

    Parameters
    ----------
    object_set, threshold, min_time_s
        As for :class:`SequentialDecision`.
    every_s : float
        Heating time between refits when they are fast.
    timer : callable
        Wall-clock seconds for the cadence (tests pass their own).
    """

    def __init__(self, object_set: Any, threshold: float, min_time_s: float, *, every_s: float,
                 timer: Callable[[], float] = time.perf_counter) -> None:
        super().__init__(object_set, threshold, min_time_s)
        self.cadence = RefitCadence(every_s, min_time_s, timer=timer)
        self._record: tuple | None = None

    @property
    def fits(self) -> int:
        """Refits made (one per ``every_s`` of heating at most)."""
        return len(self.cadence.spent_s)

    def update(self, t_s: float, dT_K: float, q_W_m2: float) -> RunningAnswer | None:
        """One heating sample at ``t_s`` from heater-on (the record itself comes from ``attach_record``)."""
        if self._record is None or not self.cadence.due(t_s):
            return self.answer
        return self.cadence.run(t_s, lambda: self._refit(t_s))

    def _refit(self, t_s: float) -> RunningAnswer | None:
        raise NotImplementedError

    @staticmethod
    def u_ln_e(e: Any, u: Any) -> float | None:
        """u(e)/e of a refit's estimate, or None where it decides nothing: no e, or no finite u (STATUS is JSON)."""
        if e is None or u is None:
            return None
        e, u = float(e), float(u)
        if not (math.isfinite(e) and e > 0 and math.isfinite(u) and u > 0):
            return None
        return u / e
