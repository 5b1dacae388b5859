"""The probe's daemon: request handlers for one board, one method per protocol command.

Construction order matters: the heater is driven OFF (enable line inactive,
PWM duty 0) before anything else -- runtime overrides, history, model store,
sensors. Then :meth:`Daemon.serve` answers protocol requests
(:mod:`edge.protocol.messages`) on a serial port until the stop event is set
(SIGTERM/SIGINT in :mod:`edge.service.main`): a running measurement is cut
(heater off at once through the watchdog), the loop ends, and
:meth:`Daemon.close` closes the heater driver and the history database.

A measurement (MEASURE, or a press of the trigger button when
``measurement.trigger_button`` is set) runs in a worker thread
(:mod:`edge.service.worker`) while the serve loop keeps reading the port:
STATUS (``state = "measuring"``, its ``phase`` and ``measurement_elapsed_s``
on the board clock) and PING are answered, every other request gets ERROR
``BUSY``, and the MEASURE reply is sent with its request's id when the
measurement ends. Only the worker switches the heater on; the serve loop
waits for it before it switches the heater off on its way out.

Commands
--------
PING, INFO (firmware/model versions, model sha256, board), STATUS,
MEASURE (optional ``power_W`` or ``voltage_V``, ``contact_time_s``),
RESULT (by id or latest), HISTORY (paged, newest first), SERIES (a stored
measurement's raw or resampled series, paged to fit one reply), CONFIG_GET,
CONFIG_SET (runtime keys only, validated, persisted atomically),
MODEL_BEGIN/CHUNK/COMMIT/ABORT (verified atomic install through
:class:`edge.model.store.ModelStore`, :mod:`edge.service.upload`),
OBJECTS_BEGIN/CHUNK/COMMIT/ABORT/LIST/REMOVE/SELECT (the user's object sets,
:mod:`edge.service.objects`; every measurement result names its object among
the active set, the built-in library when none is chosen).
Argument policy and reply sizing are in :mod:`edge.service.requests`.

ABORT (answered while measuring too) cuts a running measurement: the heater
goes off at once, the sequence ends with ``status = "aborted"``, ``reason =
"host_abort"``, the record is stored and ABORT replies with its id.

Degraded start
--------------
A state directory that is read-only or full, a corrupt history database, a
model store that cannot be used: the daemon still starts, keeps the heater
off, answers STATUS and INFO with a ``faults`` list saying what is wrong, and
refuses MEASURE with BAD_STATE naming the faults. Faults are re-checked
(at most every :data:`FAULT_RECHECK_s` on requests, and at once before each
MEASURE), so the daemon measures again as soon as the cause is gone. A
record the history cannot take is kept in memory (up to
:data:`MAX_UNSAVED_RECORDS`) and stored on a later re-check; STATUS reports
``unsaved_records``.

MEASURE replies with the stored record (``measurement_id``, ``status``,
``flags``, ``result`` ...). Every measurement is committed to the history
before the reply. A sensor fault or open thermocouple answers ERROR
``SENSOR_FAULT`` and a crashed estimation ERROR ``INTERNAL``, each naming the
stored measurement id; safety cuts (over-temperature, on-time) give a record
with ``status = "aborted"`` and ``reason``.

Modules
-------
This module holds the daemon's construction, its measurement path and its shutdown; the rest
is mixed in by concern: :mod:`edge.service.faults` (degraded start, faults, unsaved records),
:mod:`edge.service.status_commands` (PING, INFO, STATUS, the :class:`State`),
:mod:`edge.service.history_commands` (RESULT, HISTORY, SERIES),
:mod:`edge.service.update_commands` (CONFIG_*, MODEL_*, OBJECTS_*, CALIBRATION_*) and
:mod:`edge.service.serving` (the serve loop, ABORT, the trigger button).
"""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any, Callable, Mapping

from edge.security.policy import UpdatePolicy
from edge.estimation.methods import method_class
from edge.estimation.record import TouchRecord
from edge.estimation.result import Estimate
from edge.estimation.seam import SeamContext, estimate_touch
from edge.hw.board import Board
from edge.hw.chips import sample_rate_Hz
from edge.hw.drivers.button import Button
from edge.hw.drivers.heater import Heater, HeaterError, HeaterOffError
from edge.hw.faults import SensorFault
from edge.measure.sensors import make_sensors, thermocouple_resolution_K
from edge.estimation.running import SequentialDecision, decision_for
from edge.measure.ready import Readiness
from edge.measure.sequence import MeasurementParams, MeasurementSequence, Phase
from edge.measure.watchdog import HeaterWatchdog, Limits
from edge.model.bundle import limits_for_ram
from edge.model.store import ModelStore, ModelStoreError
from edge.protocol.endpoint import SerialEndpoint
from edge.protocol.frame import DEFAULT_MAX_PAYLOAD
from edge.protocol.commands import Command
from edge.protocol.errors import CommandError, ErrorCode
from edge.protocol.messages import Request
from edge.service.config import Config, RuntimeOverrides
from edge.service.estimator import ModelEstimator
from edge.service.events import EventStream, TappedDecision, TappedSensors
from edge.service.notify import Notifier
from edge.service.calibration import ProbeCalibrations
from edge.service.faults import FAULT_RECHECK_s, MAX_UNSAVED_RECORDS, MIN_FREE_BYTES, FaultKeeping
from edge.service.history_commands import HistoryCommands
from edge.service.objects import ObjectSets
from edge.service.requests import fit_record, measure_params
from edge.service.serving import ABORT_WAIT_s, ANSWERED_WHILE_MEASURING, Serving
from edge.service.status_commands import FIRMWARE_VERSION, State, StatusCommands
from edge.service.update_commands import CalibrationCommands, ConfigCommands, ModelCommands, ObjectSetCommands
from edge.service.upload import MAX_UPLOAD_BYTES, ModelUpload
from edge.service.worker import MeasurementWorker
from edge.status import Reason, Status
from edge.storage.history import History, HistoryError
from edge.storage.identity import IdentityError, load_or_create_device_id

__all__ = ["FIRMWARE_VERSION", "ANSWERED_WHILE_MEASURING", "FAULT_RECHECK_s", "MAX_UNSAVED_RECORDS",
           "MIN_FREE_BYTES", "ABORT_WAIT_s", "State", "Daemon"]

log = logging.getLogger("thermotouch.edge")


class Daemon(FaultKeeping, StatusCommands, HistoryCommands, ConfigCommands, ModelCommands, ObjectSetCommands,
             CalibrationCommands, Serving):
    """Request handler and measurement owner for one board.

    Construction switches the heater off first. Use :meth:`serve` to answer
    a serial port and :meth:`close` (or ``with``) to shut down. The request
    handlers of each concern come from the mixins (module docstring); a
    request ``X`` is answered by the method ``_cmd_x`` (:meth:`handle`).

    Parameters
    ----------
    config : Config
        The file configuration; stored runtime overrides are applied on top.
    board : Board
    estimator : callable, optional
        The probe head's estimator on a uniform grid, ``(t_s, dT_K, q_W_m2, power_W, method) -> dict``
        (tests and benches put their own here).  Default: :class:`edge.service.estimator.ModelEstimator`
        on the model store.  Either way the answer is :func:`edge.estimation.seam.estimate_touch`'s.
    stop_event : threading.Event, optional
        Set to stop serving; also aborts a running measurement.
    model_store, history : optional
        Injected instances (default: built from ``[paths]``).
    max_payload : int
        Frame payload bound, bytes (replies are cut to fit).
    max_upload_bytes : int
        Largest model upload accepted (held in memory until commit).
    notifier : Notifier, optional
        systemd notifications and watchdog pets (default: from ``$NOTIFY_SOCKET``; a no-op without).
    object_set : callable () -> ObjectSet, optional
        The objects the running answer chooses among (STATUS ``answer``,
        MEASURE ``until_decided``) and each result names; called at each
        measurement's start. Default: the active set of the object-set
        store (``paths.object_sets``; OBJECTS_* requests), else every
        material of the library
        (:meth:`edge.recognition.ObjectSet.from_library`).
    """

    def __init__(self, config: Config, board: Board, *, estimator: Callable[..., Any] | None = None,
                 stop_event: threading.Event | None = None, model_store: ModelStore | None = None,
                 history: History | None = None, max_payload: int = DEFAULT_MAX_PAYLOAD,
                 max_upload_bytes: int = MAX_UPLOAD_BYTES, notifier: Notifier | None = None,
                 object_set: Callable[[], Any] | None = None) -> None:
        self.board = board
        self.notifier = notifier if notifier is not None else Notifier()
        self.stop_event = stop_event if stop_event is not None else threading.Event()
        self.max_payload = max_payload
        h = config.heater
        # The heater goes OFF before anything else (its constructor drives both channels off).
        self.heater = Heater(board, supply_voltage_V=h.supply_voltage_V, resistance_ohm=h.resistance_ohm,
                             pwm_period_ns=h.pwm_period_ns)
        self.heater.off()
        self.state = State.STARTING
        self.faults: list[str] = []
        #: Active faults by component ("history", "storage", "model", ...): what is wrong now.
        self.component_faults: dict[str, str] = {}
        #: Records the history could not take yet (stored by the next successful re-check).
        self.unsaved: list[dict] = []
        self._last_check = float("-inf")
        self.t_start = time.monotonic()
        try:
            self.base_config = config
            self.overrides = RuntimeOverrides(config.paths.runtime_overrides or None)
            try:
                self.overrides.clean_temporaries()
            except OSError as e:
                log.warning("cannot remove stray temporaries of %s: %s", self.overrides.path, e)
            self.config = self.overrides.load(config)
            for err in self.overrides.errors:
                log.warning("runtime override ignored: %s", err)
            self._apply_logging()
            self.model_limits = limits_for_ram(self.config.limits.ram_bytes)
            self._own_history = history is None
            self.history = history if history is not None else self._open_history()
            self._own_store = model_store is None
            self.store = model_store if model_store is not None else self._open_store()
            try:
                b = self.store.current()
                log.info("model %s (%s) from %s", b.model_version, b.sha256[:12], self.store.source)
            except ModelStoreError as e:
                log.error("no usable model yet: %s", e)
            # Before the estimator: the probe head's estimator applies the installed calibration.
            self.calibration = ProbeCalibrations(self._calibration_root(), self.config.board.probe,
                                                 self._update_policy(),
                                                 device_id=lambda: getattr(self, "device_id", None))
            self._model_est = ModelEstimator(self.store, thermocouple_resolution_K(self.config.sensors),
                                           probe=self.config.board.probe, calibration=self.calibration.current)
            self.estimator = estimator if estimator is not None else self._model_est
            #: Set by ABORT: the running measurement stops with reason host_abort.
            self._cancel = threading.Event()
            self._last_run_id: int | None = None
            self.watchdog = HeaterWatchdog(self.heater, board.clock, h.max_on_time_s,
                                           abort_event=self.stop_event)
            self.sensors: Any = None
            self.sensor_error: str | None = None
            self._init_sensors()
            self.button: Any = None
            if self.config.measurement.trigger_button:
                self._init_button()
            self.sequence: MeasurementSequence | None = None
            self.upload = ModelUpload(self.store, max_upload_bytes)
            self._series_cache: tuple[int, dict] | None = None
            try:
                self.last_id: int | None = self.history.latest_id()
            except HistoryError as e:
                self.last_id = None
                self._set_fault("history", str(e))
            self.measurements = 0
            self.last_timing: dict[str, float | None] = {}
            # Presses while a measurement ran (e.g. the touch that started it) are not new requests.
            self._idle_since = board.clock.monotonic()
            # One measurement at a time; serve() runs it in a worker thread so STATUS stays answered.
            self._measure_lock = threading.Lock()
            self._worker = MeasurementWorker(self.stop_event)
            self.phase: Phase | None = None
            self._measure_t0: float | None = None
            self._object_set_hook = object_set
            #: The running measurement's event stream (a MEASURE with ``stream``), else None.
            self._events: EventStream | None = None
            #: (endpoint, request id) of a streaming MEASURE the serve loop dispatched, for its worker.
            self._event_link: tuple[SerialEndpoint, int] | None = None
            #: Status of the record the last measurement stored (the ``done`` event names it).
            self._last_status: str | None = None
            self.objects = ObjectSets(self._object_sets_root(), policy=self._update_policy())
            #: This device's identity (INFO; every measurement carries it): None if it cannot be read.
            self.device_id = self._load_device_id()
            #: Idle readings of the probe for STATUS ``ready`` (settled probe temperature).
            self.readiness = Readiness()
            #: The link being served (set by :meth:`serve`; its ``replies_dropped`` counts replies a
            #: host did not read in time).
            self.endpoint: SerialEndpoint | None = None
            self._check_faults(force=True)
            self.state = State.IDLE
        except BaseException:
            if history is None and getattr(self, "history", None) is not None:
                self.history.close()
            self.heater.close()
            raise

    # -- set-up helpers --------------------------------------------------------------
    def _object_sets_root(self) -> Path:
        p = self.config.paths
        # '' = beside the model store, so a configuration that predates object sets keeps them on the device.
        return Path(p.object_sets) if p.object_sets else Path(p.model_store).parent / "objects"

    def _load_device_id(self) -> str | None:
        path = Path(self.config.paths.model_store).parent / "device_id"
        try:
            return load_or_create_device_id(path)
        except (IdentityError, OSError) as e:  # a device without its name still measures; INFO says so
            log.error("device identity unavailable: %s", e)
            self._set_fault("identity", f"device identity unavailable: {e}")
            return None

    def _calibration_root(self) -> Path:
        p = self.config.paths
        return Path(p.calibration) if p.calibration else Path(p.model_store).parent / "calibration"

    def _update_policy(self) -> UpdatePolicy:
        """Who may update this device (models and object sets alike): ``[security]``."""
        sec = self.config.security
        return UpdatePolicy(trusted_keys_dir=sec.trusted_keys_dir or None, allow_unsigned=sec.allow_unsigned)

    def _apply_logging(self) -> None:
        for name in ("thermotouch", "edge"):  # the daemon's and the drivers'/sequence's loggers
            logging.getLogger(name).setLevel(self.config.logging.level)

    def _init_sensors(self) -> bool:
        try:
            self.sensors = make_sensors(self.board, self.config.sensors)
            self.sensor_error = None
            return True
        except (SensorFault, ValueError) as e:
            self.sensors, self.sensor_error = None, str(e)
            log.error("sensors not ready: %s", e)
            return False

    def _init_button(self) -> None:
        try:
            self.button = Button(self.board)
        except Exception as e:  # a missing button must not stop the daemon
            log.warning("trigger button unavailable: %s", e)
            self.button = None

    def _get_sequence(self) -> MeasurementSequence:
        if self.sensors is None and not self._init_sensors():
            raise CommandError(ErrorCode.SENSOR_FAULT, f"sensors not ready: {self.sensor_error}")
        h = self.config.heater
        if self.sequence is not None:
            self.sequence.sensors = self.sensors  # re-initialised sensors keep the cool-down record
        else:
            self.sequence = MeasurementSequence(
                self.heater, self.sensors, self.board.clock,
                Limits(h.max_on_time_s, h.over_temperature_C, h.fault_flux_W_m2, h.fault_rise_K, h.max_duty,
                       h.duty_window_s),
                self._estimate, self.config.measurement, watchdog=self.watchdog, abort_event=self.stop_event,
                model_sha256=self._model_sha256, on_state=self._on_state, cancel_event=self._cancel,
                beats=self.notifier, decision=self._make_decision, probe=self.config.board.probe)
        self.sequence.thresholds = self.config.measurement
        self.sequence.identity = {"device_id": self.device_id, "firmware_version": FIRMWARE_VERSION}
        return self.sequence

    def object_set(self) -> Any:
        """The object set of the running answer and of each result: the injected hook's, else the active one."""
        return self._named_object_set()[1]

    def _named_object_set(self) -> tuple[str, Any]:
        if self._object_set_hook is not None:
            objs = self._object_set_hook()
            return getattr(objs, "label", "custom"), objs
        return self.objects.active()

    def _make_decision(self, params: MeasurementParams) -> SequentialDecision | None:
        m = self.config.measurement
        objs = self.object_set()
        if objs is None or not len(objs):
            return None
        probe = self.config.board.probe
        store = getattr(self, "calibration", None)
        cal = store.current() if store is not None else None
        try:   # the answer's prior (the model bundle's library), for the calibrated chain's running answer
            library = self._model_est.estimator().library
        except (ModelStoreError, ValueError):
            library = None
        # The probe head's estimator kind decides (edge.estimation.running.decision_for).
        decision = decision_for(method_class(probe), objs, m.decide_posterior, m.decide_min_s, library=library,
                            calibration=cal if cal is not None and cal.probe == probe else None,
                            estimate_fn=self.estimator, params=params,
                            T_age_s=getattr(self.sensors, "T_age_s", 0.0),
                            T_resolution_K=getattr(self.sensors, "T_resolution_K", 0.0))
        events = self._events
        return decision if events is None or decision is None else TappedDecision(decision, events)

    def _poll_readiness(self) -> None:
        """One idle reading of the probe for STATUS ``ready`` (at most one per sample period, board clock).

        Taken when STATUS is asked (a robot waiting for ``ready`` polls it), not by the serve
        loop: an idle daemon leaves the bus alone.
        """
        if self.sensors is None or self.measuring or self._measure_lock.locked() or self.state != State.IDLE:
            return
        now = self.board.clock.monotonic()
        # At the rate a MEASURE samples (requests.measure_params caps it alike): a faster poll of a
        # slow converter (the reference board's MCP9600, 12.5 Hz) only re-reads its last conversion.
        rate_Hz = sample_rate_Hz(self.config.sensors, self.config.measurement.sample_rate_Hz)
        if now - self.readiness.last_t < 1.0 / rate_Hz:
            return
        try:
            r = self.sensors.read()
        except Exception as e:  # a failing sensor is reported by the next MEASURE; not ready meanwhile
            log.debug("readiness reading failed: %s", e)
            self.readiness.reset()
            return
        self.readiness.add(now, r.T_C)

    def _estimate(self, record: TouchRecord, decision: Mapping[str, Any] | None = None) -> Estimate:
        """The one estimate path on this device's context: model, calibration, object set, thresholds."""
        name, objs = self._named_object_set()
        kw = dict(calibration=self.calibration.current(), object_set=objs if objs is not None and len(objs) else None,
                  object_set_name=name, thresholds=self.config.measurement)
        if self.estimator is self._model_est:
            ctx = self._model_est.context(**kw)
        else:
            # An injected estimator (tests, benches) on the store's model when there is one (the prior).
            try:
                ctx = self._model_est.context(**kw).with_(method=self.estimator)
            except (ModelStoreError, ValueError):   # no model, or one without a library: no prior then
                ctx = SeamContext(method=self.estimator, **kw)
        return estimate_touch(record, ctx, decision=decision)

    def _model_sha256(self) -> str | None:
        return self._model_est.model_sha256()

    def _on_state(self, s: Phase) -> None:
        self.phase = None if s == Phase.IDLE else s
        if self._events is not None:
            self._events.phase(s)

    def _open_events(self, stream: bool, armed: bool) -> EventStream | None:
        """The event stream of a streaming MEASURE the serve loop dispatched (None: no events)."""
        link, self._event_link = self._event_link, None
        if not stream or link is None:
            return None
        endpoint, rid = link
        return EventStream(lambda body, final=False: endpoint.send_event(rid, body, final=final),
                           self.board.clock.monotonic, armed=armed, dropped=lambda: endpoint.events_dropped)

    # -- requests --------------------------------------------------------------------
    def handle(self, req: Request) -> dict[str, Any] | None:
        """Answer one validated request (raises CommandError for ERROR replies)."""
        fn = getattr(self, f"_cmd_{req.command.name.lower()}", None)
        if fn is None:  # pragma: no cover - every command has a handler
            raise CommandError(ErrorCode.UNKNOWN_COMMAND, f"{req.command.name} is not implemented")
        if req.command not in (Command.MEASURE, Command.ABORT):  # MEASURE re-checks itself, ABORT is urgent
            self._check_faults()
        try:
            return fn(req.args)
        except HistoryError as e:
            raise CommandError(ErrorCode.BAD_STATE, f"history unavailable: {e}") from None

    def _cmd_measure(self, args: dict) -> dict:
        return self.measure(power_W=args.get("power_W"), voltage_V=args.get("voltage_V"),
                            contact_time_s=args.get("contact_time_s"), sample_rate_Hz=args.get("sample_rate_Hz"),
                            until_decided=bool(args.get("until_decided") or False), arm_s=args.get("arm_s"),
                            settle_s=args.get("settle_s"), stream=bool(args.get("stream") or False))

    def measure(self, *, power_W: float | None = None, voltage_V: float | None = None,
                contact_time_s: float | None = None, sample_rate_Hz: float | None = None,
                until_decided: bool = False, arm_s: float | None = None, settle_s: float | None = None,
                stream: bool = False) -> dict:
        """Run one measurement, store it, return its summary (CommandError on failure).

        While it runs, :attr:`state` is ``"measuring"`` (``phase`` names the
        sequence step); a second call meanwhile raises BUSY. With ``stream`` (a MEASURE the serve
        loop dispatched), events go to its host as the touch runs (:mod:`edge.service.events`).
        """
        if not self._measure_lock.acquire(blocking=False):
            raise CommandError(ErrorCode.BUSY, "a measurement is already running")
        self._last_status = None
        try:
            return self._measure(power_W, voltage_V, contact_time_s, sample_rate_Hz, until_decided, arm_s, settle_s,
                                 stream)
        finally:
            events, self._events = self._events, None
            if events is not None:  # before the reply: "done" names the stored record
                events.close(self._last_run_id, self._last_status)
            self.readiness.reset()  # the probe was just heated: settle afresh
            self._measure_t0 = None
            self.phase = None
            if self.state == State.MEASURING:
                self.state = State.IDLE
            self._measure_lock.release()

    def _measure(self, power_W: float | None, voltage_V: float | None, contact_time_s: float | None,
                 sample_rate_Hz: float | None = None, until_decided: bool = False, arm_s: float | None = None,
                 settle_s: float | None = None, stream: bool = False) -> dict:
        if self.state == State.FAULT:
            raise CommandError(ErrorCode.BAD_STATE, "heater fault: measurements are disabled until restart; "
                               + "; ".join(self.faults[-1:]))
        if self.stop_event.is_set():
            raise CommandError(ErrorCode.BAD_STATE, "daemon is stopping")
        self._last_run_id = None
        self._check_faults(force=True)
        blockers = self._measure_blockers()
        if blockers:
            raise CommandError(ErrorCode.BAD_STATE, "cannot measure, heater kept off: " + "; ".join(blockers))
        cfg = self.config
        params = measure_params(cfg, self.heater.max_power_W, power_W=power_W, voltage_V=voltage_V,
                                contact_time_s=contact_time_s, sample_rate_Hz=sample_rate_Hz,
                                until_decided=until_decided, arm_s=arm_s, settle_s=settle_s)
        seq = self._get_sequence()
        self._events = self._open_events(stream, params.arm_s > 0)
        if self._events is not None:
            seq.sensors = TappedSensors(seq.sensors, self._events, self.board.clock.monotonic)
        self._measure_t0 = self.board.clock.monotonic()
        self.state = State.MEASURING
        try:
            outcome = seq.run(params)
        finally:
            if self.heater.is_on:  # belt and braces: run() never returns with it on
                try:
                    self.heater.off()
                except HeaterOffError as e:
                    # run() already reported heater_fault; the record must still be stored.
                    log.critical("heater still on after the measurement: %s", e)
        self.measurements += 1
        self._idle_since = self.board.clock.monotonic()
        t_commit = time.perf_counter()
        mid = self._add_record(outcome.record(cfg.to_dict()))
        commit_s = time.perf_counter() - t_commit
        if mid is None:
            log.error("measurement (%s) not stored yet: %s", outcome.status, self.component_faults.get("unsaved"))
            raise CommandError(ErrorCode.INTERNAL, f"measurement ended {outcome.status}"
                               f"{' (' + outcome.reason + ')' if outcome.reason else ''} but the history could "
                               f"not store it: {self.component_faults.get('unsaved')}; it is kept in memory and "
                               "stored once the history works again")
        self._last_run_id, self._last_status = mid, str(outcome.status)
        #: Wall-clock costs of the last measurement after its last sample (for bench/).
        # The sensor chain runs inside the estimate path now: its time is part of compute_s.
        compute_s = outcome.compute_s
        self.last_timing = {"compute_s": compute_s, "sequence_compute_s": outcome.compute_s,
                            "commit_s": commit_s,
                            "compute_and_commit_s": None if compute_s is None else compute_s + commit_s}
        self.last_id = mid
        if compute_s is not None:
            log.debug("measurement %d: compute %.2f ms", mid, compute_s * 1e3)
        log.info("measurement %d: %s%s flags=%s", mid, outcome.status,
                 f" ({outcome.reason})" if outcome.reason else "", [str(f) for f in outcome.flags])
        if outcome.reason == Reason.HEATER_FAULT:
            self.state = State.FAULT
            self.faults.append(outcome.error or "heater fault")
            raise CommandError(ErrorCode.INTERNAL, f"HEATER FAULT ({outcome.error}); measurement {mid} stored")
        if outcome.reason in (Reason.SENSOR_FAULT, Reason.OPEN_THERMOCOUPLE):
            # An open thermocouple is the probe's, not the chips': keep the sensors.
            self.sensors = None if outcome.reason == Reason.SENSOR_FAULT else self.sensors
            self.sensor_error = outcome.error
            raise CommandError(ErrorCode.SENSOR_FAULT, f"{outcome.reason}: {outcome.error}; measurement {mid} stored")
        if outcome.status == Status.FAILED:
            raise CommandError(ErrorCode.INTERNAL, f"{outcome.reason}: {outcome.error}; measurement {mid} stored")
        return fit_record(self.history.get(mid), self.max_payload)

    def close(self) -> None:
        """Heater off and closed, watchdog stopped, history closed (idempotent)."""
        self.stop_event.set()
        errors: list[BaseException] = []
        for fn in (self.heater.close, self.watchdog.close,
                   getattr(self.button, "close", None), self.history.close):
            if fn is None:
                continue
            try:
                fn()
            except Exception as e:
                errors.append(e)
                log.error("shutdown step failed: %s", e)
        self.state = State.STOPPED
        if errors:
            raise HeaterError(f"shutdown incomplete: {errors!r}") from errors[0]

    def __enter__(self) -> Daemon:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


