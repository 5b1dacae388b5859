"""The measurement sequence: one touch, from baseline to estimate.

One touch runs::

    idle -> [cooldown] -> baseline -> heating -> (heater off) -> estimating -> idle

* **cooldown** (``cooldown_s`` since the last heating, on the board clock).
* **baseline** (``baseline_s``, heater off): T0 is the mean thermocouple
  reading and the flux offset the mean flux reading; their spread and drift
  give the ``noisy`` and ``unstable_baseline`` flags
  (:func:`edge.measure.signal.quality_flags`).
* **heating**: the heater runs at the requested power for the contact time
  while the sensors are sampled at ``sample_rate_Hz`` on the board clock
  (the simulator's virtual clock makes a 2-s touch take milliseconds).
  With a ``decision`` hook each heating sample also updates a running
  answer (:class:`edge.estimation.running.SequentialDecision`: a cheap
  running e and the object set's posterior, :attr:`MeasurementSequence.answer`,
  which STATUS reports); with ``until_decided`` the heating stops as soon as
  that answer is decided, the record is flagged ``decided`` and its result
  carries the ``decision``.
* **heater off**, then the raw record (:class:`~edge.estimation.record.TouchRecord`)
  goes to the estimate path (:func:`edge.estimation.seam.estimate_touch`, through
  the ``estimator`` hook), which conditions it (baseline, quality flags, the
  uniform grid) and estimates; its crash can no longer leave the heater on.
  The sequence judges the baseline itself only for safety (``no_heat_while_on``
  needs a steady baseline) and for the record of a run it does not estimate.

Safety (the heater can burn)
----------------------------
* Every exit from the heating phase -- normal end, exception, sensor fault,
  ``KeyboardInterrupt``/``SystemExit``, the abort event set by SIGTERM/SIGINT
  or a daemon stop -- passes a ``finally`` that switches the heater off.
* The heating time is clamped to ``max_on_time_s`` whatever is requested
  (hard cap on the request), and the sampling loop stops heating before a
  sample whose read could end past the limit (watchdog check in the loop,
  using the slowest read seen so far as the margin).
* :class:`edge.measure.watchdog.HeaterWatchdog` is independent of the loop
  and cuts the heater even while the loop is stuck in a driver call.
* A thermocouple reading above ``over_temperature_C`` or an open
  thermocouple (SensorFault ``open_thermocouple``) cuts the heater at once.
* The heater must follow its command: heat arriving while it is off (in the
  cool-down, which is sampled, or the baseline:
  :func:`edge.measure.signal.heat_while_off`) or no heat while it is on
  (:func:`edge.measure.signal.no_heat_while_on`) is a heater fault: the run
  fails with reason and flag ``heater_fault`` and the heater is disabled
  (:meth:`~edge.hw.drivers.heater.Heater.disable`), which stops the daemon
  measuring until it restarts.
* Each turn of the sampling and waiting loops beats ``beats`` (the systemd
  watchdog, :class:`edge.service.notify.Notifier`), so a loop stuck in a
  driver call stops the watchdog pets.

Nothing here imports the simulator; sensors are reached through the board.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Callable, Mapping

import numpy as np

from edge.estimation.record import RecordError, TouchRecord
from edge.estimation.seam import TooFewSamples, condition
from edge.hw.drivers.heater import Heater, HeaterOffError
from edge.hw.faults import SensorFault
from edge.measure.sensors import Reading
from edge.measure.signal import heat_while_off, no_heat_while_on
from edge.measure.watchdog import HeaterWatchdog, Limits, Trip
from edge.status import Flag, Reason, Status
from edge.storage.history import utc_now

__all__ = [
    "Phase",
    "MeasurementParams",
    "Outcome",
    "MeasurementSequence",
    "EstimatorFn",
]

log = logging.getLogger(__name__)

#: ``estimator(record, decision) -> Estimate``: the one estimate path on a touch record and the running
#: decision's last answer (:func:`edge.estimation.seam.estimate_touch` with the device's context).
EstimatorFn = Callable[[TouchRecord, "Mapping[str, Any] | None"], Any]


class Phase(StrEnum):
    """The step a sequence is in (``phase`` in STATUS while measuring)."""

    IDLE = "idle"
    COOLDOWN = "cooldown"
    BASELINE = "baseline"
    HEATING = "heating"
    #: Not entered any more (resampling is part of the estimate path); kept as a word of the protocol.
    RESAMPLING = "resampling"
    ESTIMATING = "estimating"


@dataclass(frozen=True)
class MeasurementParams:
    """One measurement's settings (from the config, optionally overridden by MEASURE)."""

    power_W: float
    contact_time_s: float
    baseline_s: float
    sample_rate_Hz: float
    cooldown_s: float
    method: str = "default"
    #: Stop heating once the running answer is decided (needs the sequence's ``decision`` hook).
    until_decided: bool = False
    #: Armed: sample in air up to this long waiting for the touch (0: off, the baseline is baseline_s).
    arm_s: float = 0.0
    #: Armed: heat this long after the detected contact.
    settle_s: float = 1.0

    def __post_init__(self) -> None:
        for name in ("power_W", "contact_time_s", "baseline_s", "sample_rate_Hz"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        for name in ("cooldown_s", "arm_s", "settle_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")


@dataclass
class Outcome:
    """What one run produced; :meth:`record` turns it into a history row.

    ``status`` is :attr:`Status.OK`, :attr:`Status.ABORTED` (a safety cut or
    a stop: ``reason`` says which) or :attr:`Status.FAILED` (sensor fault,
    estimator crash, bug).  ``flags`` holds :class:`~edge.status.Flag` members: the
    estimate's (which include the sequence's quality flags) when there is one, else the sequence's.
    ``touch`` is the raw record the estimate was made from, ``estimate`` the typed answer
    (``result`` is its ``to_dict()``).
    """

    status: Status = Status.FAILED
    reason: Reason | None = None
    error: str | None = None
    flags: list[str] = field(default_factory=list)
    result: dict[str, Any] | None = None
    started_utc: str = ""
    power_W: float = 0.0
    contact_time_s: float = 0.0
    heater_on_s: float = 0.0
    T0_C: float | None = None
    q_offset_W_m2: float | None = None
    sample_rate_Hz: float = 0.0
    model_sha256: str | None = None
    raw_t_s: np.ndarray | None = None
    raw_T_C: np.ndarray | None = None
    raw_q_W_m2: np.ndarray | None = None
    grid_t_s: np.ndarray | None = None
    grid_dT_K: np.ndarray | None = None
    grid_q_W_m2: np.ndarray | None = None
    compute_s: float | None = None
    exception: BaseException | None = None
    #: The last running answer (a :class:`~edge.estimation.running.RunningAnswer` dict), if any.
    decision: dict[str, Any] | None = None
    #: Armed runs: when the contact was detected, s after arming (None: not armed, or on something already).
    contact_detected_s: float | None = None
    #: The raw touch as the estimate path reads it (None: too little was recorded to make one).
    touch: TouchRecord | None = None
    #: The typed answer (:class:`edge.estimation.result.Estimate`), when the touch was estimated.
    estimate: Any = None

    def record(self, config_snapshot: Mapping[str, Any]) -> dict[str, Any]:
        """Keyword set for :meth:`edge.storage.history.History.add` (with the touch's header and read times)."""
        keys = ("status", "reason", "error", "flags", "result", "started_utc", "power_W", "contact_time_s",
                "heater_on_s", "T0_C", "q_offset_W_m2", "sample_rate_Hz", "model_sha256", "raw_t_s",
                "raw_T_C", "raw_q_W_m2", "grid_t_s", "grid_dT_K", "grid_q_W_m2")
        rec = {k: getattr(self, k) for k in keys}
        rec["config"] = dict(config_snapshot)
        touch = self.touch
        rec["touch_header"] = None if touch is None else touch.header()
        rec["raw_T_dt_s"] = None if touch is None else touch.T_dt_s
        rec["raw_q_dt_s"] = None if touch is None else touch.q_dt_s
        return rec


#: The reason a run ends with when the watchdog cut the heater under it.
_TRIP_REASONS = {Trip.ABORT: Reason.STOPPED, Trip.MAX_ON_TIME: Reason.MAX_ON_TIME}


class _Stop(Exception):
    """Internal: leave the heating loop for a safety reason."""

    def __init__(self, reason: Reason, detail: str = "") -> None:
        self.reason = reason
        super().__init__(detail or reason)


class MeasurementSequence:
    """Runs measurements on one heater + sensors pair.

    Parameters
    ----------
    heater : Heater
    sensors : object with ``read() -> Reading``
    clock : Clock
        The board clock (virtual in the simulator).
    limits : Limits
    estimator : EstimatorFn
        ``(record, decision) -> Estimate``, called after the heater is off; any exception it raises
        becomes a ``failed`` outcome with the raw data kept (``too_few_samples`` for
        :class:`~edge.estimation.seam.TooFewSamples`).
    thresholds : namespace
        The ``[measurement]`` flag thresholds.
    watchdog : HeaterWatchdog, optional
        Built here (and closed by :meth:`close`) if not given.
    abort_event : threading.Event, optional
        Set to stop a running measurement (heater off within a sample period,
        or at once through the watchdog).
    model_sha256 : callable () -> str or None, optional
        Identity of the model the estimator uses, stored with the record.
    on_state : callable (Phase) -> None, optional
        Told each state change (for STATUS).
    cancel_event : threading.Event, optional
        Set to cut a running measurement on the host's request (ABORT): like
        ``abort_event``, but the record's reason is ``host_abort``. Whoever
        sets it also switches the heater off at once.
    beats : object with ``beat(name)`` and ``done(name)``, optional
        Liveness reports of the sampling loop, as ``"measure"`` (the
        daemon's :class:`edge.service.notify.Notifier`).
    decision : callable (MeasurementParams) -> SequentialDecision or None, optional
        Builds the running decision for one run (the daemon's, on its object
        set); None or a None result: no running answer.
    probe : str
        The probe head (``board.probe``) the touch records name.
    """

    def __init__(self, heater: Heater, sensors: Any, clock: Any, limits: Limits, estimator: EstimatorFn,
                 thresholds: Any, *, watchdog: HeaterWatchdog | None = None,
                 abort_event: threading.Event | None = None,
                 model_sha256: Callable[[], str | None] | None = None,
                 on_state: Callable[[Phase], None] | None = None,
                 cancel_event: threading.Event | None = None, beats: Any = None,
                 decision: Callable[[MeasurementParams], Any] | None = None, probe: str = "paper") -> None:
        self.heater = heater
        self.sensors = sensors
        self.clock = clock
        self.limits = limits
        self.estimator = estimator
        self.thresholds = thresholds
        self.abort_event = abort_event if abort_event is not None else threading.Event()
        self.cancel_event = cancel_event if cancel_event is not None else threading.Event()
        self._own_watchdog = watchdog is None
        self.watchdog = watchdog if watchdog is not None else HeaterWatchdog(
            heater, clock, limits.max_on_time_s, abort_event=self.abort_event)
        self.model_sha256 = model_sha256 or (lambda: None)
        self.on_state = on_state or (lambda s: None)
        self.beats = beats
        self.decision = decision
        #: The probe head (``board.probe``), recorded with every touch.
        self.probe = probe
        #: Identity recorded with every touch (its record's ``meta``: the daemon sets ``device_id`` and the
        #: software version), so a stored record and its export name the instrument that made them.
        self.identity: dict[str, Any] = {}
        #: The running answer of the current (or last) run: a RunningAnswer, or None.
        self.answer: Any = None
        self.state = Phase.IDLE
        self._last_off: float | None = None
        #: (on, off) board-clock times of this sequence's heatings within the duty window.
        self._on_log: list[tuple[float, float]] = []
        #: The slowest sensor read of the touch in progress (s): measured per touch, so one slow read
        #: (a bus that hung once, then recovered) does not stop every later touch (ISSUE #35 §4).
        self._max_read_s = 0.0

    def _set_state(self, s: Phase) -> None:
        self.state = s
        try:
            self.on_state(s)
        except Exception:
            log.exception("on_state callback failed")

    def close(self) -> None:
        """Heater off and the watchdog stopped (if this object built it)."""
        try:
            self.heater.off()
        finally:
            if self._own_watchdog:
                self.watchdog.close()

    # -- sampling ----------------------------------------------------------------------
    def _sample(self, ts: list, Ts: list, qs: list, sat: list, dts: list | None = None) -> Reading:
        self._beat()
        t0 = self.clock.monotonic()
        r = self.sensors.read()
        t1 = self.clock.monotonic()
        self._max_read_s = max(self._max_read_s, t1 - t0)
        ts.append(0.5 * (t0 + t1))  # board-clock time, made relative later
        Ts.append(r.T_C)
        qs.append(r.q_W_m2)
        sat.append(r.saturated)
        if dts is not None:
            # Each sensor's own time within the read (sensors that do not time themselves: 0).
            dts.append((float(getattr(r, "T_dt_s", 0.0)), float(getattr(r, "q_dt_s", 0.0))))
        return r

    def _check_temperature(self, r: Reading) -> None:
        if not math.isfinite(r.T_C):
            raise _Stop(Reason.SENSOR_FAULT, f"thermocouple reading is {r.T_C}")
        if r.T_C > self.limits.over_temperature_C:
            raise _Stop(Reason.OVER_TEMPERATURE,
                        f"thermocouple {r.T_C:.2f} °C above the {self.limits.over_temperature_C} °C limit")

    def _beat(self) -> None:
        if self.beats is not None:
            self.beats.beat("measure")

    def _wait(self, until: float) -> None:
        """Sleep on the board clock until ``until``, in steps, watching the abort event."""
        while True:
            self._beat()
            if self.abort_event.is_set():
                raise _Stop(Reason.STOPPED, "measurement stopped (daemon shutting down)")
            if self.cancel_event.is_set():
                raise _Stop(Reason.HOST_ABORT, "measurement aborted by the host (ABORT)")
            dt = until - self.clock.monotonic()
            if dt <= 0:
                return
            self.clock.sleep(min(dt, 0.05))

    def _check_heat_off(self, t: list, T: list, q: list, where: str) -> None:
        since = None if not t or self._last_off is None else t[0] - self._last_off
        why = heat_while_off(np.array(t), np.array(T), np.array(q), self.limits, since_off_s=since)
        if why is not None:
            raise _Stop(Reason.HEATER_FAULT, f"{where}: {why}")

    def _cool_down(self, until: float, period: float) -> None:
        """Wait until ``until`` sampling the sensors (kept apart from the run's series), then judge them.

        After a heating the probe and the object relax: the temperature
        falls. A heater that keeps heating shows up here first.
        """
        ts: list[float] = []
        Ts: list[float] = []
        qs: list[float] = []
        t0 = self.clock.monotonic()
        k = 0
        while t0 + k * period < until:
            self._wait(t0 + k * period)
            self._check_temperature(self._sample(ts, Ts, qs, []))
            k += 1
        self._wait(until)
        self._check_heat_off(ts, Ts, qs, "cool-down")

    def duty_wait_s(self, heat_s: float, now: float | None = None) -> float:
        """How long to wait before a heating of ``heat_s`` so no window of ``limits.duty_window_s`` holds
        more than ``limits.max_duty`` of heater-on time (0: it may start now).

        The on-time already in the window ending when this heating would end only falls as the start
        moves later, so the earliest admissible start is found by bisection within one window.
        """
        now = self.clock.monotonic() if now is None else now
        w, cap = self.limits.duty_window_s, self.limits.max_duty * self.limits.duty_window_s

        def fits(start: float) -> bool:
            lo = start + heat_s - w
            past = sum(max(0.0, min(off, start) - max(on, lo)) for on, off in self._on_log)
            return past + heat_s <= cap + 1e-9

        if fits(now):
            return 0.0
        a, b = now, now + w  # at now + w every logged heating has left the window
        for _ in range(40):
            mid = 0.5 * (a + b)
            a, b = (a, mid) if fits(mid) else (mid, b)
        return b - now

    def _log_heating(self, t_on: float, t_off: float) -> None:
        self._on_log.append((t_on, t_off))
        horizon = t_off - self.limits.duty_window_s
        self._on_log = [(a, b) for a, b in self._on_log if b > horizon]

    # -- the run ---------------------------------------------------------------------
    def run(self, params: MeasurementParams) -> Outcome:
        """Run one measurement; never returns with the heater on.

        Returns an :class:`Outcome` for everything except BaseExceptions
        (KeyboardInterrupt, SystemExit), which propagate after the heater is
        off. A :class:`~edge.hw.drivers.heater.HeaterOffError` is reported as a
        failed outcome with reason ``heater_fault``.
        """
        out = Outcome(started_utc=utc_now(), power_W=params.power_W,
                      contact_time_s=params.contact_time_s, sample_rate_Hz=params.sample_rate_Hz)
        period = 1.0 / params.sample_rate_Hz
        # Hard cap on the request, below the watchdog's trip point.
        heat_s = min(params.contact_time_s, self.limits.max_on_time_s - 2 * self.watchdog.guard_s)
        if heat_s < params.contact_time_s:
            log.warning("contact_time_s=%g s clamped to %g s by max_on_time_s", params.contact_time_s, heat_s)
        ts: list[float] = []
        Ts: list[float] = []
        qs: list[float] = []
        sat: list[bool] = []
        dts: list[tuple[float, float]] = []
        on_before = self.heater.on_time_s
        t_on = t_off = None
        self._max_read_s = 0.0
        try:
            try:
                if self.abort_event.is_set():
                    raise _Stop(Reason.STOPPED, "measurement stopped before it started")
                if self.heater.disabled is not None:
                    raise _Stop(Reason.HEATER_FAULT, f"heater disabled: {self.heater.disabled}")
                if heat_s > self.limits.max_duty * self.limits.duty_window_s:
                    raise _Stop(Reason.MAX_ON_TIME, f"contact_time_s={heat_s:g} s exceeds the duty limit "
                                f"{self.limits.max_duty:g} x {self.limits.duty_window_s:g} s; the heater stayed off")
                if self._last_off is not None and params.cooldown_s > 0:
                    self._set_state(Phase.COOLDOWN)
                    self._cool_down(self._last_off + params.cooldown_s, period)
                wait = self.duty_wait_s(heat_s)
                if wait > 0:
                    # The duty limit (ISSUE #35 §6): rest as in a cool-down until this touch fits.
                    log.info("duty limit: %.2f s of rest before heating", wait)
                    self._set_state(Phase.COOLDOWN)
                    self._cool_down(self.clock.monotonic() + wait, period)
                # ---- baseline
                self._set_state(Phase.BASELINE)
                if params.arm_s > 0:
                    out.contact_detected_s = self._armed(params, period, ts, Ts, qs, sat, dts)
                else:
                    t_base = self.clock.monotonic()
                    n_base = max(3, int(round(params.baseline_s * params.sample_rate_Hz)))
                    for k in range(n_base):
                        self._wait(t_base + k * period)
                        self._check_temperature(self._sample(ts, Ts, qs, sat, dts))
                    # At least baseline_s even when it is no whole number of periods (12.5 Hz: 6 x 80 ms
                    # would switch the heater on 20 ms early, before a touch timed to the configured baseline).
                    self._wait(t_base + max(n_base * period, params.baseline_s))
                self._check_heat_off(ts, Ts, qs, "baseline")
                decider = self._make_decider(params)
                # The running answer's reference: the last baseline_s before heating (armed, the samples
                # before it are the probe in air and the contact's transient).
                n_ref = max(1, int(round(params.baseline_s * params.sample_rate_Hz)))
                T0_run, q0_run = float(np.mean(Ts[-n_ref:])), float(np.mean(qs[-n_ref:]))
                decided = False
                if self._max_read_s >= self.limits.max_on_time_s - self.watchdog.guard_s:
                    # Reads this slow could not stop the heater in time: say so before it goes on, not
                    # after a pulse of a few milliseconds.
                    raise _Stop(Reason.MAX_ON_TIME, f"sensor reads too slow ({self._max_read_s:.3g} s) to stay "
                                f"within max_on_time_s={self.limits.max_on_time_s} s; the heater stayed off")
                # ---- heating
                self._set_state(Phase.HEATING)
                self.watchdog.arm()
                t_on = self.clock.monotonic()
                self.heater.on_power(params.power_W)
                if decider is not None and hasattr(decider, "attach_record"):
                    # A decider that refits the record (the sensor chain from contact on, the small
                    # heater's estimator) gets the record lists; failing, it ends the running answer only.
                    try:
                        decider.attach_record(ts, Ts, qs, t_on, T0_C=T0_run, q0_W_m2=q0_run, dts=dts)
                    except Exception:
                        log.exception("running decision unavailable; heating goes on without it")
                        decider = None
                guard = self.watchdog.guard_s
                for k in range(int(math.floor(heat_s * params.sample_rate_Hz + 1e-9)) + 1):
                    self._wait(t_on + k * period)
                    if not self.heater.is_on:
                        if self.cancel_event.is_set():
                            raise _Stop(Reason.HOST_ABORT, "measurement aborted by the host (ABORT)")
                        why = _TRIP_REASONS.get(self.watchdog.tripped)
                        raise _Stop(why or Reason.HEATER_CUT, f"heater was cut by the watchdog ({why})")
                    on_s = self.clock.monotonic() - t_on
                    # Watchdog in the loop: no read may end past the limit.
                    if on_s + self._max_read_s >= self.limits.max_on_time_s - guard:
                        if on_s >= heat_s - period:
                            break  # within a sample of the end anyway
                        raise _Stop(Reason.MAX_ON_TIME, "sensor reads too slow to stay within "
                                    f"max_on_time_s={self.limits.max_on_time_s} s")
                    r = self._sample(ts, Ts, qs, sat, dts)
                    if self.clock.monotonic() - t_on > self.limits.max_on_time_s:
                        raise _Stop(Reason.MAX_ON_TIME, "a sensor read ended past max_on_time_s")
                    self._check_temperature(r)
                    if decider is not None and self._decide(decider, ts[-1] - t_on, r, T0_run, q0_run) \
                            and params.until_decided:
                        decided = True
                        break
                if not decided:
                    self._wait(t_on + heat_s)
                self.heater.off()
                t_off = self.clock.monotonic()
                self.watchdog.disarm()
            except _Stop as e:
                out.status = Status.FAILED if e.reason in (Reason.SENSOR_FAULT, Reason.HEATER_FAULT) \
                    else Status.ABORTED
                out.reason, out.error = e.reason, str(e)
                log.warning("measurement %s: %s", out.status, e)
            except SensorFault as e:
                out.status = Status.FAILED
                # SensorFault.reason is the drivers' word; the record gets the sequence's.
                out.reason = Reason.OPEN_THERMOCOUPLE if e.reason == "open_thermocouple" else Reason.SENSOR_FAULT
                out.error, out.exception = str(e), e
                log.error("measurement failed: %s", e)
            except HeaterOffError:
                raise
            except Exception as e:  # a bug or an unexpected driver error: heater off, keep the data
                out.status, out.reason = Status.FAILED, Reason.INTERNAL
                out.error, out.exception = f"{type(e).__name__}: {e}", e
                log.exception("measurement failed")
            finally:
                # Every path, including BaseException, passes here with the heater switched off.
                try:
                    self.heater.off()
                finally:
                    self.watchdog.disarm()
                    if t_on is not None:
                        self._last_off = self.clock.monotonic()
                        if t_off is None:
                            t_off = self._last_off
                        self._log_heating(t_on, self._last_off)
        except HeaterOffError as e:
            out.status, out.reason = Status.FAILED, Reason.HEATER_FAULT
            out.error, out.exception = str(e), e
            log.critical("heater fault: %s", e)
        out.heater_on_s = self.heater.on_time_s - on_before
        t_arr, T_arr, q_arr = np.array(ts, float), np.array(Ts, float), np.array(qs, float)
        # Times relative to heater-on (baseline negative); without heating, to the first sample.
        if t_on is not None:
            t_arr -= t_on
        elif t_arr.size:
            t_arr -= t_arr[-1] + 1.0
        out.raw_t_s, out.raw_T_C, out.raw_q_W_m2 = t_arr, T_arr, q_arr
        if self.answer is not None:
            out.decision = self.answer.to_dict()
            out.decision["stopped_early"] = bool(params.until_decided and self.answer.decided)
        if out.status != Status.FAILED or out.reason != Reason.HEATER_FAULT:
            try:
                self._finish(out, params, t_arr, T_arr, q_arr, any(sat), t_on, t_off,
                             np.array(dts, float).reshape(-1, 2) if len(dts) == t_arr.size else None)
            except Exception as e:
                # Whatever breaks after the heating (a bug in the record or the baseline), the touch
                # heated and its raw data is returned for the record.
                out.status, out.reason = Status.FAILED, Reason.INTERNAL
                out.error, out.exception = f"{type(e).__name__}: {e}", e
                log.exception("post-processing failed (heater was already off)")
        if out.reason == Reason.HEATER_FAULT:
            self._heater_fault(out)
        if self.beats is not None:
            self.beats.done("measure")
        self._set_state(Phase.IDLE)
        return out

    def _armed(self, params: MeasurementParams, period: float, ts: list, Ts: list, qs: list, sat: list,
               dts: list) -> float | None:
        """Sample in air until the touch is found (:func:`edge.estimation.contact.find_contact`), then settle_s.

        Returns the detected contact's time relative to the start of arming (None: the probe was
        already on something when armed -- the record then says ``contact_not_recorded`` -- and the
        settling runs from the start).  Raises ``_Stop(NO_CONTACT)`` after ``arm_s`` without one; the
        heater is never switched on while armed.
        """
        from edge.estimation.contact import find_contact  # noqa: PLC0415

        t0 = self.clock.monotonic()
        n_quiet = max(4, int(math.ceil(0.3 / period)))
        # "Already on something" is judged only on a longer look: a few coarse samples in air can
        # flip an LSB and look unquiet.
        n_judge = max(3 * n_quiet, int(math.ceil(1.0 / period)))
        t_contact: float | None = None
        settle_from: float | None = None
        k = 0
        while True:
            self._wait(t0 + k * period)
            self._check_temperature(self._sample(ts, Ts, qs, sat, dts))
            k += 1
            now = self.clock.monotonic()
            if settle_from is None and k > n_quiet:
                tt = np.asarray(ts)
                # All samples are "before heater-on" here: the last one plays heater-on's part.
                c = find_contact(tt - tt[-1], np.asarray(Ts), np.asarray(qs))
                if not c.recorded_in_air:
                    if k >= n_judge:
                        settle_from = t0
                elif c.detected:
                    t_contact = settle_from = float(tt[c.index])
            if settle_from is None and now - t0 >= params.arm_s:
                raise _Stop(Reason.NO_CONTACT, f"no contact within arm_s = {params.arm_s:g} s (heater never on)")
            if settle_from is not None and now >= settle_from + params.settle_s and k >= 3:
                return None if t_contact is None else t_contact - t0

    def _make_decider(self, params: MeasurementParams) -> Any:
        self.answer = None
        if self.decision is None:
            return None
        try:
            return self.decision(params)
        except Exception:
            log.exception("running decision unavailable; measuring without it")
            return None

    def _decide(self, decider: Any, t_s: float, r: Reading, T0_C: float, q0_W_m2: float) -> bool:
        """Feed one heating sample to the running decision; True once it is decided.

        A failure here is logged and ends the running answer, never the touch.
        """
        try:
            ans = decider.update(t_s, r.T_C - T0_C, r.q_W_m2 - q0_W_m2)
        except Exception:
            log.exception("running decision failed; heating goes on")
            return False
        if ans is not None:
            self.answer = ans
        return bool(ans is not None and ans.decided)

    def _heater_fault(self, out: Outcome) -> None:
        """Flag the record and latch the heater off: no measurement until restart."""
        if Flag.HEATER_FAULT not in out.flags:
            out.flags.append(Flag.HEATER_FAULT)
        log.critical("heater fault: %s", out.error)
        try:
            self.heater.disable(out.error or "heater fault")
        except HeaterOffError:
            pass  # already reported: the run's own off() failed the same way

    def _touch(self, out: Outcome, params: MeasurementParams, t: np.ndarray, T: np.ndarray, q: np.ndarray,
               saturated: bool, t_on: float | None, t_off: float | None, dts: np.ndarray | None) -> TouchRecord | None:
        """The raw record of this run, as the estimate path and an export read it (None: nothing to record)."""
        heated = t_on is not None and t_off is not None
        try:
            return TouchRecord(
                probe=self.probe, t_s=t, T_C=T, q_W_m2=q,
                power_W=params.power_W, heater_on_s=max(t_off - t_on, 0.0) if heated else 0.0,
                sample_rate_Hz=params.sample_rate_Hz, baseline_s=params.baseline_s, method=params.method,
                T_age_s=float(getattr(self.sensors, "T_age_s", 0.0)),
                T_resolution_K=float(getattr(self.sensors, "T_resolution_K", 0.0)), saturated=bool(saturated),
                T_dt_s=None if dts is None else dts[:, 0], q_dt_s=None if dts is None else dts[:, 1],
                arm_s=params.arm_s, contact_detected_s=out.contact_detected_s,
                meta={**self.identity, "started_utc": out.started_utc})
        except RecordError as e:
            log.warning("no touch record: %s", e)
            return None

    def _finish(self, out: Outcome, params: MeasurementParams, t: np.ndarray, T: np.ndarray, q: np.ndarray,
                saturated: bool, t_on: float | None, t_off: float | None, dts: np.ndarray | None = None) -> None:
        """The touch record, the safety check on the heating, and the estimate (heater already off).

        ``dts`` (n, 2): each sample's thermocouple and flux read time relative to ``t`` (s), or None.
        """
        c0 = time.perf_counter()
        touch = out.touch = self._touch(out, params, t, T, q, saturated, t_on, t_off, dts)
        if touch is None:
            if out.status == Status.OK or out.reason is None:
                out.status, out.reason, out.error = Status.FAILED, Reason.TOO_FEW_SAMPLES, "no samples recorded"
            return
        # The baseline and its flags, as the estimate path will find them: the record of a run that is not
        # estimated keeps them, and the heating is judged against a steady baseline only.
        cond = condition(touch, self.thresholds)
        out.T0_C, out.q_offset_W_m2 = cond.T0_C, cond.q_offset_W_m2
        out.flags = list(cond.flags)
        if out.decision is not None and out.decision.get("stopped_early"):
            out.flags.append(Flag.DECIDED)
        if out.status != Status.OK and out.reason is not None:
            # Don't estimate from a cut-short or faulty run; the raw data is kept.
            return
        # "No heat" is measured from the baseline's offset and T0: a baseline that is not steady (a
        # warm probe put back on the object drives a transient flux) is no reference to judge by.
        steady = out.T0_C is not None and Flag.NOISY not in out.flags and Flag.UNSTABLE_BASELINE not in out.flags
        heat = ~cond.base
        why = (no_heat_while_on(T[heat], q[heat] - (out.q_offset_W_m2 or 0.0), out.T0_C, params.power_W,
                                self.limits) if steady else None)
        if why is not None:
            out.status, out.reason, out.error = Status.FAILED, Reason.HEATER_FAULT, why
            return
        out.status = Status.OK
        self._set_state(Phase.ESTIMATING)
        try:
            out.model_sha256 = self.model_sha256()
        except Exception:
            out.model_sha256 = None
        try:
            est = self.estimator(touch, out.decision)
        except TooFewSamples as e:
            out.status, out.reason, out.error = Status.FAILED, Reason.TOO_FEW_SAMPLES, str(e)
            return
        except Exception as e:
            out.status, out.reason = Status.FAILED, Reason.ESTIMATION_FAILED
            out.error, out.exception = f"{type(e).__name__}: {e}", e
            log.exception("estimation failed (heater was already off)")
            return
        finally:
            out.compute_s = time.perf_counter() - c0
        out.estimate = est
        out.result = est.to_dict()
        out.model_sha256 = est.model_sha256 or out.model_sha256
        # The estimate's flags begin with the same conditioning flags; whatever it adds follows.
        # Flags the estimate superseded (the calibrated chain fitted a contact the 1-D check missed) go.
        gone = set((est.details.get("sensor_chain") or {}).get("superseded_flags") or ())
        out.flags = [f for f in dict.fromkeys(out.flags + list(est.flags)) if str(f) not in gone]
        g = est.series
        out.grid_t_s, out.grid_dT_K, out.grid_q_W_m2 = g.get("grid_t_s"), g.get("grid_dT_K"), g.get("grid_q_W_m2")
