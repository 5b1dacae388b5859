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

Every running decision of the device lives here (:func:`decision_for` picks
the one a probe head takes, from its estimator kind's ``running``):

* :class:`SequentialDecision` -- the thick-body model above, on the raw
  thermopile reading (the paper probe, uncalibrated);
* :class:`ChainDecision` -- the calibrated sensor chain on the record so far
  (the paper probe once calibrated).  The thick-body model is right for the
  flux at the object's face, wrong for a thermopile inside its sensing layer,
  which for the first second or two reads heat still warming the layer (on
  the faithful world a PMMA touch read as glass); with a calibration the
  answer is the chain's (:func:`edge.estimation.seam.chain_answer`), and the
  running answer is the same estimate, from the contact on, every ``every_s``
  of heating.  It needs the samples since arming: the sequence hands it its
  record lists (``attach_record``);
* :class:`EstimatorDecision` -- the device's own estimator refitted on the
  record so far (the small-heater probe, whose flux sensor sees its heater's
  edge from the first samples: no early-time model), resampled as the result
  will be, naming the object with e and, where the touch measured it, α.
  When heating starts the estimator builds its model for the touch's whole
  grid (``estimate_fn.prepare``); each refit then costs the fit alone
  (``python bench/decision_bench.py --world faithful --probe small-heater``: about 12 ms).

No running answer is made from an estimate raising any of the one blocker
table's flags (:data:`edge.estimation.result.BLOCKERS`).

NumPy only (edge runtime).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from edge.estimation.chain_estimate import estimate_from_contact
from edge.estimation.conditioning import duhamel_m, resample_uniform
from edge.estimation.estimate import FLUX_CALIBRATION_U_REL, MIN_SNR, QUANTISATION_SAMPLES_PER_STEP
from edge.estimation.result import BLOCKERS

__all__ = ["duhamel_m", "RunningEffusivity", "RunningAnswer", "SequentialDecision", "RefitCadence",
           "RefitDecision", "REFIT_MAX_SHARE", "ChainDecision", "CHAIN_EVERY_s", "EstimatorDecision",
           "ESTIMATOR_EVERY_s", "decision_for"]

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

    @property
    def calibrated_from_s(self) -> float:
        """The shortest heating time the set's posteriors are calibrated at (0 without a per-contact table)."""
        table = getattr(self.objects, "contact_calibration", None) or {}
        return float(min(table)) if table else 0.0

    def _answer(self, t_s: float, e: float, u: float, n: int) -> RunningAnswer:
        """Name the object for a running (e, u_ln_e) at ``t_s``; decide at the threshold.

        A set calibrated per contact time names it with its calibration at ``t_s`` of heating
        (``ObjectSet.at_contact``: a 0.6-s running answer is as over-confident as a 0.6-s touch).
        """
        at = getattr(self.objects, "at_contact", None)
        rec = (self.objects if at is None else at(t_s)).classify(e, u)
        return self._settle(RunningAnswer(rec.object, rec.object_posterior, t_s, e, u, n, cls=rec.cls,
                                          source=self.source))

    def _settle(self, ans: RunningAnswer) -> RunningAnswer:
        """Make ``ans`` the running answer; it decides when the threshold is reached after ``min_time_s``.

        Never before the shortest contact time the set's posteriors are calibrated at (its
        ``contact_calibration``): earlier, a posterior of 0.95 has not been shown to mean 95 %.
        """
        if (self.decided is None and ans.elapsed_s >= max(self.min_time_s, self.calibrated_from_s)
                and ans.posterior >= self.threshold):
            ans.decided = True
            self.decided = ans
        self.answer = ans
        return ans


#: Most of the heating time a running decision's refits may take.  They run in the sampling loop:
#: a refit taking longer than its share stretches the interval to the next one, so a slower CPU
#: (a Pi-class one runs them several times slower than the bench machine) refits less often
#: instead of delaying the samples.
REFIT_MAX_SHARE = 0.2


#: Float rounding of sample times against a refit's due time (s).
_DUE_TOLERANCE_s = 1e-6


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
        # To within a microsecond: where the sample period is every_s (10 Hz and 0.1 s), 0.3 + 0.1 lands
        # just past the sample at 0.4 and every other refit was skipped.
        return t_s >= max(self.next_s, self.min_time_s) - _DUE_TOLERANCE_s

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
    (:class:`edge.estimation.running.ChainDecision`,
    :class:`edge.estimation.running.EstimatorDecision`): the sequence hands them its
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


# -- the calibrated sensor chain's running answer ----------------------------------------------------
#: Heating time between two chain fits: about 6 ms each on this machine (bench/daemon_bench.py), so a
#: fit per 0.1 s keeps the sampling loop's budget on a Pi-class CPU.
CHAIN_EVERY_s = 0.1


class ChainDecision(RefitDecision):
    """Sequential decision on the calibrated sensor chain's running estimate.

    Parameters
    ----------
    object_set, threshold, min_time_s
        As for :class:`~edge.estimation.running.SequentialDecision`.
    calibration : ProbeCalibration
        The installed calibration (the chain's parameters and their u).
    library : Library, optional
        The prior on alpha given e: the model bundle's, as for the answer (default: the CSV's).
    every_s : float
        Heating time between fits (:data:`CHAIN_EVERY_s`), stretched where a fit takes more than its
        share (:class:`~edge.estimation.running.RefitCadence`).
    timer : callable
        Wall-clock seconds for the cadence (tests pass their own).
    """

    source = "sensor_chain"

    def __init__(self, object_set: Any, threshold: float, min_time_s: float, *, calibration: Any,
                 library: Any = None, every_s: float = CHAIN_EVERY_s,
                 timer: Callable[[], float] = time.perf_counter, T_resolution_K: float = 0.0) -> None:
        super().__init__(object_set, threshold, min_time_s, every_s=every_s, timer=timer)
        self.calibration = calibration
        self.library = library
        self.T_resolution_K = float(T_resolution_K)   # the thermometer's step: as the final answer (seam) takes it

    def attach_record(self, t_s: list, T_C: list, q_W_m2: list, t_on_s: float, **_baseline: Any) -> None:
        """The sequence's record lists (appended in place; absolute clock times) and the heater-on time.

        The chain fits from the contact on, with the object's temperature free: the baseline the
        sequence also passes (``T0_C``, ``q0_W_m2``, ``dts``) is not used.
        """
        self._record = (t_s, T_C, q_W_m2, float(t_on_s))

    def _refit(self, t_s: float) -> RunningAnswer | None:
        ts, Ts, qs, t_on = self._record
        n = min(len(ts), len(Ts), len(qs))
        try:
            d = estimate_from_contact(np.asarray(ts[:n], float) - t_on, np.asarray(Ts[:n], float),
                                      np.asarray(qs[:n], float), self.calibration, library=self.library,
                                      T_resolution_K=self.T_resolution_K)
        except ValueError:  # a prefix the chain cannot fit yet (too few samples since contact)
            return self.answer
        u_ln_e = self.u_ln_e(d.get("effusivity_W_s05_m2K"), d.get("effusivity_W_s05_m2K_u"))
        if u_ln_e is None or BLOCKERS & set(d.get("flags") or ()):   # the one blocker table
            return self.answer
        return self._answer(t_s, float(d["effusivity_W_s05_m2K"]), u_ln_e, n)


# -- the device estimator's running answer (probe heads without an early-time model) --------------
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
        read-time skews (see :func:`~edge.estimation.conditioning.resample_uniform`).
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
        if BLOCKERS & set(d.get("flags") or ()):   # the one blocker table
            return self.answer
        u_ln_e = self.u_ln_e(d.get("effusivity_W_s05_m2K"), d.get("effusivity_W_s05_m2K_u"))
        rec = self.objects.classify_estimate(d) if u_ln_e is not None else None
        if rec is None:
            return self.answer
        return self._settle(RunningAnswer(rec.object, rec.object_posterior, t_s, float(d["effusivity_W_s05_m2K"]),
                                          u_ln_e, int(g_t.size), cls=rec.cls, source=self.source))


def decision_for(kind: Any, object_set: Any, threshold: float, min_time_s: float, *, calibration: Any = None,
                 estimate_fn: Callable[..., dict] | None = None, params: Any = None, T_age_s: float = 0.0,
                 T_resolution_K: float = 0.0, library: Any = None) -> SequentialDecision:
    """The running decision of a probe head whose estimator class is ``kind`` (:mod:`edge.estimation.methods`).

    ``kind.running == "refit"``: :class:`EstimatorDecision` on ``estimate_fn`` (``params``: the run's
    MeasurementParams); otherwise :class:`ChainDecision` when ``calibration`` (already checked to be this
    probe head's) is given and the kind carries a sensor chain (``library``: the model bundle's prior),
    else :class:`SequentialDecision`.
    """
    if kind.running == "refit":
        return EstimatorDecision(object_set, threshold, min_time_s, estimate_fn=estimate_fn,
                                 rate_Hz=params.sample_rate_Hz, heat_s=params.contact_time_s,
                                 power_W=params.power_W, method=params.method, T_age_s=T_age_s)
    if calibration is not None and kind.sensor_chain:
        # Calibrated: the running answer is the same estimate the result will be (seam.chain_answer).
        return ChainDecision(object_set, threshold, min_time_s, calibration=calibration, library=library,
                             T_resolution_K=T_resolution_K)
    return SequentialDecision(object_set, threshold, min_time_s, T_age_s=T_age_s, T_resolution_K=T_resolution_K)
