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
"""

from __future__ import annotations

import logging
import math
import os
import sqlite3
import threading
import time
from enum import StrEnum
from pathlib import Path
from typing import Any, Callable, Mapping

import edge
from edge.security.policy import UpdatePolicy
from edge.estimation.estimate import pipeline_golden_check
from edge.estimation.methods import method_class
from edge.estimation.record import TouchRecord
from edge.estimation.result import Estimate
from edge.estimation.seam import SeamContext, estimate_touch
from edge.estimation.selfcheck import semantic_check
from edge.hw.board import Board
from edge.hw.drivers.button import Button
from edge.hw.drivers.heater import Heater, HeaterError, HeaterOffError
from edge.hw.faults import SensorFault
from edge.measure.sensors import make_sensors, thermocouple_resolution_K
from edge.estimation.chain_decision import ChainDecision
from edge.estimation.running import SequentialDecision
from edge.measure.estimator_decision import EstimatorDecision
from edge.measure.ready import Readiness
from edge.measure.sequence import MeasurementParams, MeasurementSequence, Phase
from edge.measure.watchdog import HeaterWatchdog, Limits
from edge.model.bundle import limits_for_ram
from edge.model.store import InstallError, ModelStore, ModelStoreError
from edge.protocol.endpoint import SerialEndpoint
from edge.protocol.frame import DEFAULT_MAX_PAYLOAD, PROTOCOL_VERSION
from edge.protocol.commands import Command
from edge.protocol.errors import CommandError, ErrorCode
from edge.protocol.messages import Request
from edge.service.config import Config, ConfigError, RuntimeOverrides
from edge.service.estimator import ModelEstimator
from edge.service.notify import Notifier
from edge.service.calibration import ProbeCalibrations
from edge.service.objects import ObjectSets
from edge.service.requests import config_reply, fit_record, history_page, measure_params, series_page
from edge.service.upload import MAX_UPLOAD_BYTES, ModelUpload
from edge.service.worker import MeasurementWorker, measurement_budget_s
from edge.status import Reason, Status
from edge.storage import durable
from edge.storage.history import History, HistoryError

__all__ = ["FIRMWARE_VERSION", "ANSWERED_WHILE_MEASURING", "FAULT_RECHECK_s", "MAX_UNSAVED_RECORDS",
           "MIN_FREE_BYTES", "ABORT_WAIT_s", "State", "Daemon"]

log = logging.getLogger("thermotouch.edge")

FIRMWARE_VERSION = edge.__version__
#: Requests answered while a measurement runs (everything else gets BUSY).
ANSWERED_WHILE_MEASURING = frozenset({Command.STATUS, Command.PING, Command.ABORT})
#: Least time between two re-checks of active faults on ordinary requests, s.
FAULT_RECHECK_s = 1.0
#: Most records kept in memory while the history cannot store them (the oldest go first).
MAX_UNSAVED_RECORDS = 16
#: Free bytes the history's file system must have before a measurement (a record with its series
#: is a few hundred kB at most; SQLite needs room for its journal too).
MIN_FREE_BYTES = 4 * 1024 * 1024
#: Longest ABORT waits for the aborted measurement to be stored, s.
ABORT_WAIT_s = 10.0


class State(StrEnum):
    """The daemon's state (``state`` in STATUS)."""

    STARTING = "starting"
    IDLE = "idle"
    MEASURING = "measuring"
    #: The heater could not be switched off: measurements stay disabled until restart.
    FAULT = "fault"
    STOPPED = "stopped"


def _factory_bundle(cfg: Config) -> Path | None:
    if cfg.paths.factory_model:
        return Path(cfg.paths.factory_model)
    try:
        # Function-local on purpose: thermotouch_models is optional package data, not a code
        # dependency (edge must import without it, see tests/test_edge_purity.py).
        from thermotouch_models import DEFAULT_BUNDLE  # noqa: PLC0415
    except ImportError:
        return None
    return DEFAULT_BUNDLE if (DEFAULT_BUNDLE / "manifest.json").exists() else None


class _UnavailableHistory:
    """Stands in for a history database that cannot be opened; every use raises HistoryError."""

    def __init__(self, path: str, error: str) -> None:
        self.path, self.error = path, error

    def __getattr__(self, name: str) -> Any:
        def unavailable(*args: Any, **kw: Any) -> Any:
            raise HistoryError(f"history database {self.path} unavailable: {self.error}")
        return unavailable

    def close(self) -> None:
        pass

    @property
    def closed(self) -> bool:
        return True


class _UnavailableStore:
    """Stands in for a model store that cannot be opened: no model, every install refused."""

    def __init__(self, root: str, error: str, limits: Any) -> None:
        self.root, self.error, self.limits, self.source = root, error, limits, None

    def current(self) -> Any:
        raise ModelStoreError(f"model store {self.root} unavailable: {self.error}")

    def status(self) -> dict:
        return {"source": None, "sha256": None, "model_version": None,
                "error": f"model store {self.root} unavailable: {self.error}"}

    def install(self, *args: Any, **kw: Any) -> Any:
        raise InstallError(f"model store {self.root} unavailable: {self.error}")



def _non_finite_to_none(x: Any, path: str, bad: list[str]) -> Any:
    """``x`` with every non-finite float (NaN, inf) replaced by None, their paths appended to ``bad``."""
    if isinstance(x, float) and not math.isfinite(x):
        bad.append(path)
        return None
    if isinstance(x, Mapping):
        return {k: _non_finite_to_none(v, f"{path}.{k}", bad) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_non_finite_to_none(v, f"{path}[{j}]", bad) for j, v in enumerate(x)]
    return x

class Daemon:
    """Request handler and measurement owner for one board.

    Construction switches the heater off first. Use :meth:`serve` to answer
    a serial port and :meth:`close` (or ``with``) to shut down.

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
                                                 self._update_policy())
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
            self.objects = ObjectSets(self._object_sets_root(), policy=self._update_policy())
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
    def _open_history(self) -> Any:
        path = self.config.paths.history_db
        try:
            h = History(path)
        except (HistoryError, OSError, sqlite3.Error) as e:
            self._set_fault("history", f"cannot open {path}: {e}")
            return _UnavailableHistory(path, str(e))
        self._clear_fault("history")
        return h

    def _object_sets_root(self) -> Path:
        p = self.config.paths
        # '' = beside the model store, so a configuration that predates object sets keeps them on the device.
        return Path(p.object_sets) if p.object_sets else Path(p.model_store).parent / "objects"

    def _calibration_root(self) -> Path:
        p = self.config.paths
        return Path(p.calibration) if p.calibration else Path(p.model_store).parent / "calibration"

    def _update_policy(self) -> UpdatePolicy:
        """Who may update this device (models and object sets alike): ``[security]``."""
        sec = self.config.security
        return UpdatePolicy(trusted_keys_dir=sec.trusted_keys_dir or None, allow_unsigned=sec.allow_unsigned)

    def _open_store(self) -> Any:
        root = self.config.paths.model_store
        try:
            policy = self._update_policy()
            store = ModelStore(root, _factory_bundle(self.config), golden_check=pipeline_golden_check,
                               limits=self.model_limits, semantic_check=semantic_check, policy=policy)
        except (ModelStoreError, OSError) as e:
            self._set_fault("model_store", f"cannot open {root}: {e}")
            return _UnavailableStore(root, str(e), self.model_limits)
        self._clear_fault("model_store")
        return store

    # -- faults ------------------------------------------------------------------------
    def _set_fault(self, component: str, message: str) -> None:
        if self.component_faults.get(component) != message:
            log.error("fault %s: %s", component, message)
        self.component_faults[component] = message

    def _clear_fault(self, component: str) -> None:
        if self.component_faults.pop(component, None) is not None:
            log.warning("fault %s cleared", component)

    def fault_list(self) -> list[str]:
        """What is wrong now: component faults, then the last heater faults (``faults`` in STATUS/INFO)."""
        out = [f"{k}: {v}" for k, v in sorted(self.component_faults.items())]
        return out + [f"heater: {f}" for f in self.faults[-5:]]

    def _check_faults(self, *, force: bool = False) -> None:
        """Re-check every fault that can heal by itself (at most every FAULT_RECHECK_s unless ``force``)."""
        now = time.monotonic()
        if not force and now - self._last_check < FAULT_RECHECK_s:
            return
        self._last_check = now
        if isinstance(self.history, _UnavailableHistory) and self._own_history:
            self.history = self._open_history()
            if not isinstance(self.history, _UnavailableHistory):
                try:
                    self.last_id = self.history.latest_id()
                except HistoryError as e:
                    self._set_fault("history", str(e))
        if isinstance(self.store, _UnavailableStore) and self._own_store:
            self.store = self._open_store()
            self._model_est.store = self.upload.store = self.store
        self._check_storage()
        self._store_unsaved()
        self._check_objects()
        err = self.calibration.error()
        if err:
            self._set_fault("calibration", err)
        else:
            self._clear_fault("calibration")
        if self.estimator is self._model_est:
            try:
                self.store.current()
                self._clear_fault("model")
            except ModelStoreError as e:
                self._set_fault("model", f"{e} (a measurement would end estimation_failed)")

    def _check_objects(self) -> None:
        """The ``objects`` fault: a chosen set that cannot be used (reported, not blocking: the library names)."""
        self.objects.reopen()
        err = self.objects.error
        if err:
            self._set_fault("objects", err)
        else:
            self._clear_fault("objects")

    def _check_storage(self) -> None:
        path = getattr(self.history, "path", ":memory:")
        if path == ":memory:":
            return
        directory = os.path.dirname(os.path.abspath(path))
        try:
            free = durable.free_bytes(directory)
        except OSError:
            return  # cannot tell; the history's own errors will say
        if free < MIN_FREE_BYTES:
            self._set_fault("storage", f"{directory} is full: {free} B free, {MIN_FREE_BYTES} B needed")
        elif not os.access(directory, os.W_OK):
            self._set_fault("storage", f"{directory} is not writable")
        else:
            self._clear_fault("storage")

    def _store_unsaved(self) -> None:
        while self.unsaved:
            try:
                mid = self.history.add(self.unsaved[0])
            except HistoryError as e:
                self._set_fault("unsaved", f"{len(self.unsaved)} record(s) kept in memory: {e}")
                return
            rec = self.unsaved.pop(0)
            self.last_id = mid
            log.warning("measurement %d (%s) stored late", mid, rec.get("status"))
        self._clear_fault("unsaved")

    def _measure_blockers(self) -> list[str]:
        model = ("model", "model_store") if self.estimator is self._model_est else ()
        return [f"{k}: {v}" for k, v in sorted(self.component_faults.items())
                if k in ("history", "storage", "unsaved") + model]

    def _add_record(self, rec: dict) -> int | None:
        """Store ``rec``; on failure keep it in memory (None) -- a touch that heated is never lost."""
        try:
            return self.history.add(rec)
        except HistoryError as e:
            err: Exception = e
        except (ValueError, TypeError) as e:
            # Something in it the database refuses (e.g. a NaN in the estimator's result): keep the
            # measurement and as much of its result as can be stored, say what was dropped.
            bad: list[str] = []
            result = _non_finite_to_none(rec.get("result"), "result", bad)
            flags = [str(f) for f in rec.get("flags") or []]
            err = None
            if bad:
                log.error("record not storable as is (%s); storing it with %s as null", e, ", ".join(bad))
                try:
                    return self.history.add(dict(rec, result=result, flags=flags, error=(
                        f"{rec.get('error') or ''}; not finite, stored as null: {', '.join(bad)}").lstrip("; ")))
                except (HistoryError, ValueError, TypeError) as e2:
                    err = e2
            log.error("record not storable as is (%s); storing it without its result", err or e)
            rec = dict(rec, result=None, flags=flags,
                       error=f"{rec.get('error') or ''}; result not storable: {err or e}".lstrip("; "))
            try:
                return self.history.add(rec)
            except (HistoryError, ValueError, TypeError) as e2:
                err = e2
        if len(self.unsaved) >= MAX_UNSAVED_RECORDS:
            lost = self.unsaved.pop(0)
            log.critical("unsaved record of %s dropped: %d are kept at most", lost.get("started_utc"),
                         MAX_UNSAVED_RECORDS)
        self.unsaved.append(rec)
        self._set_fault("unsaved", f"{len(self.unsaved)} record(s) kept in memory: {err}")
        return None

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
                Limits(h.max_on_time_s, h.over_temperature_C, h.fault_flux_W_m2, h.fault_rise_K),
                self._estimate, self.config.measurement, watchdog=self.watchdog, abort_event=self.stop_event,
                model_sha256=self._model_sha256, on_state=self._on_state, cancel_event=self._cancel,
                beats=self.notifier, decision=self._make_decision, probe=self.config.board.probe)
        self.sequence.thresholds = self.config.measurement
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
        kind = method_class(probe)
        if kind.running == "refit":
            # A probe head with no early-time model (the small heater's sensor sees its heater's edge from
            # the first samples): the running answer is the device's own estimator on the record so far.
            return EstimatorDecision(objs, m.decide_posterior, m.decide_min_s, estimate_fn=self.estimator,
                                     rate_Hz=params.sample_rate_Hz, heat_s=params.contact_time_s,
                                     power_W=params.power_W, method=params.method,
                                     T_age_s=getattr(self.sensors, "T_age_s", 0.0))
        store = getattr(self, "calibration", None)
        cal = store.current() if store is not None else None
        if cal is not None and cal.probe == probe and kind.sensor_chain:
            # Calibrated: the running answer is the same estimate the result will be (seam.chain_answer).
            return ChainDecision(objs, m.decide_posterior, m.decide_min_s, calibration=cal)
        return SequentialDecision(objs, m.decide_posterior, m.decide_min_s,
                                  T_age_s=getattr(self.sensors, "T_age_s", 0.0),
                                  T_resolution_K=getattr(self.sensors, "T_resolution_K", 0.0))

    def _poll_readiness(self) -> None:
        """One idle reading of the probe for STATUS ``ready`` (at most one per sample period, board clock).

        Taken when STATUS is asked (a robot waiting for ``ready`` polls it), not by the serve
        loop: an idle daemon leaves the bus alone.
        """
        if self.sensors is None or self.measuring or self._measure_lock.locked() or self.state != State.IDLE:
            return
        now = self.board.clock.monotonic()
        if now - self.readiness.last_t < 1.0 / self.config.measurement.sample_rate_Hz:
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

    def _cmd_ping(self, args: dict) -> dict:
        return {"echo": args.get("echo")}

    def _cmd_info(self, args: dict) -> dict:
        st = self.store.status()
        return {"protocol_version": PROTOCOL_VERSION, "firmware_version": FIRMWARE_VERSION,
                "model_version": st.get("model_version"), "model_sha256": st.get("sha256"),
                "model_source": st.get("source"), "board": self.board.name, "faults": self.fault_list(),
                "object_set": self._named_object_set()[0], **self.calibration.info()}

    def _cmd_status(self, args: dict) -> dict:
        try:
            total: int | None = self.history.count()
        except HistoryError:
            total = None  # named in faults
        out = {"state": self.state, "heater_on": self.heater.is_on,
               "heater_fault": self.heater.disabled is not None or self.heater.fault is not None,
               "heater_on_time_s": round(self.heater.on_time_s, 6), "measurements": self.measurements,
               "last_measurement_id": self.last_id, "history_total": total,
               "sensor_error": self.sensor_error, "faults": self.fault_list(),
               "unsaved_records": len(self.unsaved), "can_measure": not self._measure_blockers(),
               "replies_dropped": getattr(self.endpoint, "replies_dropped", 0),
               "uptime_s": round(time.monotonic() - self.t_start, 3)}
        upload = self.upload.progress()
        if upload is not None:
            out["upload"] = upload
        t0 = self._measure_t0
        if self.state == State.MEASURING and t0 is not None:
            out["phase"] = self.phase
            out["measurement_elapsed_s"] = round(self.board.clock.monotonic() - t0, 3)  # board clock
            seq = self.sequence
            running = (Phase.HEATING, Phase.RESAMPLING, Phase.ESTIMATING)
            ans = getattr(seq, "answer", None) if self.phase in running else None
            if ans is not None:
                out["answer"] = ans.to_dict()
            out["ready"] = False
        else:
            self._poll_readiness()
            m = self.config.measurement
            out["ready"] = bool(out["can_measure"] and self.state == State.IDLE
                                and self.readiness.settled(m.baseline_s, m.unstable_baseline_K))
        return out

    def _cmd_measure(self, args: dict) -> dict:
        return self.measure(power_W=args.get("power_W"), voltage_V=args.get("voltage_V"),
                            contact_time_s=args.get("contact_time_s"), sample_rate_Hz=args.get("sample_rate_Hz"),
                            until_decided=bool(args.get("until_decided") or False), arm_s=args.get("arm_s"),
                            settle_s=args.get("settle_s"))

    def measure(self, *, power_W: float | None = None, voltage_V: float | None = None,
                contact_time_s: float | None = None, sample_rate_Hz: float | None = None,
                until_decided: bool = False, arm_s: float | None = None, settle_s: float | None = None) -> dict:
        """Run one measurement, store it, return its summary (CommandError on failure).

        While it runs, :attr:`state` is ``"measuring"`` (``phase`` names the
        sequence step); a second call meanwhile raises BUSY.
        """
        if not self._measure_lock.acquire(blocking=False):
            raise CommandError(ErrorCode.BUSY, "a measurement is already running")
        try:
            return self._measure(power_W, voltage_V, contact_time_s, sample_rate_Hz, until_decided, arm_s, settle_s)
        finally:
            self.readiness.reset()  # the probe was just heated: settle afresh
            self._measure_t0 = None
            self.phase = None
            if self.state == State.MEASURING:
                self.state = State.IDLE
            self._measure_lock.release()

    def _measure(self, power_W: float | None, voltage_V: float | None, contact_time_s: float | None,
                 sample_rate_Hz: float | None = None, until_decided: bool = False, arm_s: float | None = None,
                 settle_s: float | None = None) -> dict:
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
        self._last_run_id = mid
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

    def _cmd_result(self, args: dict) -> dict:
        mid = args.get("measurement_id")
        if mid is None:
            mid = self.history.latest_id()
            if mid is None:
                raise CommandError(ErrorCode.NOT_FOUND, "no measurement stored yet", "measurement_id")
        rec = self.history.get(mid)
        if rec is None:
            raise CommandError(ErrorCode.NOT_FOUND, f"no measurement {mid}", "measurement_id")
        return fit_record(rec, self.max_payload)

    def _cmd_history(self, args: dict) -> dict:
        offset, limit = args.get("offset", 0), args.get("limit", 20)
        total, items = self.history.page(offset, limit)
        return history_page(offset, total, items, self.max_payload)

    def _series_record(self, mid: int) -> dict | None:
        # A host pages through one series after another: keep the last record's arrays
        # (stored records never change, and ids are never reused).
        cached = self._series_cache
        if cached is not None and cached[0] == mid:
            return cached[1]
        rec = self.history.get(mid, series=True)
        if rec is not None:
            self._series_cache = (mid, rec)
        return rec

    def _cmd_series(self, args: dict) -> dict:
        mid, which = args["measurement_id"], args.get("which", "raw")
        offset, limit = args.get("offset", 0), args.get("limit")
        rec = self._series_record(mid)
        if rec is None:
            raise CommandError(ErrorCode.NOT_FOUND, f"no measurement {mid}", "measurement_id")
        return series_page(rec, mid, which, offset, limit, self.max_payload)

    def _cmd_config_get(self, args: dict) -> dict:
        keys = args.get("keys")
        try:
            values = self.config.flat(keys)
        except ConfigError as e:
            raise CommandError(ErrorCode.BAD_ARGUMENT, str(e), e.key) from None
        return config_reply(values, self.max_payload)

    def _cmd_config_set(self, args: dict) -> dict:
        values = args["values"]
        if self.state not in (State.IDLE, State.FAULT):
            raise CommandError(ErrorCode.BUSY, f"cannot change the configuration while {self.state}")
        try:
            new = self.config.with_updates(values)
        except ConfigError as e:
            raise CommandError(ErrorCode.BAD_ARGUMENT, str(e), e.key) from None
        self.overrides.save(new, self.base_config)
        self.config = new
        self._apply_logging()
        log.info("configuration changed: %s", {k: new.get(k) for k in values})
        return config_reply(new.flat(), self.max_payload)

    def _cmd_abort(self, args: dict) -> dict:
        if not self.measuring and not self._measure_lock.locked():
            return {"aborted": False, "measurement_id": None}
        self._cancel.set()  # first, so the sequence reads the heater cut below as the host's abort
        try:
            self.heater.off()  # at once, not at the sequence's next sample
        except HeaterError as e:
            log.critical("ABORT: heater did not switch off: %s", e)
        log.warning("ABORT: measurement cut by the host")
        deadline = time.monotonic() + ABORT_WAIT_s
        # The worker stores the record, then releases; wait for that (never past a stop).
        while (self.measuring or self._measure_lock.locked()) and time.monotonic() < deadline \
                and not self.stop_event.is_set():
            time.sleep(0.005)
        done = not (self.measuring or self._measure_lock.locked())
        if done:
            self._cancel.clear()
        return {"aborted": True, "measurement_id": self._last_run_id if done else None}

    def _cmd_objects_begin(self, args: dict) -> dict:
        return self.objects.begin(args["name"], args["size"], args["sha256"], args.get("activate", True),
                                  signature=None if args.get("signature") is None
                                  else args["signature"].encode("utf-8"))

    def _cmd_objects_chunk(self, args: dict) -> dict:
        return self.objects.chunk(args["offset"], args["data"], args["session"])

    def _cmd_objects_commit(self, args: dict) -> dict:
        try:
            return self.objects.commit(args["session"])
        finally:
            self._check_objects()  # the set in use may have changed: say so now, not at the next re-check

    def _cmd_objects_abort(self, args: dict) -> dict:
        return self.objects.abort(args.get("session"))

    def _cmd_objects_list(self, args: dict) -> dict:
        return self.objects.listing()

    def _cmd_objects_remove(self, args: dict) -> dict:
        try:
            return self.objects.remove(args["name"])
        finally:
            self._check_objects()  # the set in use may have changed: say so now, not at the next re-check

    def _cmd_objects_select(self, args: dict) -> dict:
        try:
            return self.objects.select(args["name"])
        finally:
            self._check_objects()  # the set in use may have changed: say so now, not at the next re-check

    def _cmd_calibration_set(self, args: dict) -> dict:
        if self.measuring:
            raise CommandError(ErrorCode.BUSY, "a measurement is running")
        return self.calibration.install(args["calibration"], args.get("signature"))

    def _cmd_calibration_get(self, args: dict) -> dict:
        return self.calibration.get()

    def _cmd_model_begin(self, args: dict) -> dict:
        out = self.upload.begin(args["size"], args["sha256"], args.get("version"), args.get("downgrade"))
        return {**out, "session": self.upload.session}

    def _cmd_model_chunk(self, args: dict) -> dict:
        return self.upload.chunk(args["offset"], args["data"], args.get("session"), require_session=True)

    def _cmd_model_commit(self, args: dict) -> dict:
        return self.upload.commit(args.get("session"), require_session=True)

    def _cmd_model_abort(self, args: dict) -> dict:
        return self.upload.abort(args.get("session"), require_session=True)

    # -- serving ---------------------------------------------------------------------
    @property
    def measuring(self) -> bool:
        """Whether serve() has a measurement running (its worker may still be sending the reply)."""
        return self._worker.busy

    def _handle_measure(self, req: Request) -> dict[str, Any] | None:
        try:
            return self.handle(req)
        finally:
            self._worker.release()  # before the reply goes out

    def _join_worker(self, *, abort: bool) -> None:
        m, h = self.config.measurement, self.config.heater
        self._worker.join(abort=abort, timeout_s=measurement_budget_s(m, h))

    def _dispatch(self, endpoint: SerialEndpoint, req: Request) -> None:
        if self.measuring:
            if req.command in ANSWERED_WHILE_MEASURING:
                endpoint.handle(req, self.handle)
            else:
                endpoint.send_error(req.request_id, ErrorCode.BUSY,
                                    f"{req.command.name} refused: a measurement is running (STATUS answers)")
            return
        if req.command == Command.MEASURE:
            # The reply, addressed to this request id, is sent by the worker when the measurement ends.
            self._cancel.clear()
            self._worker.start(lambda: endpoint.handle(req, self._handle_measure), "measure")
            return
        endpoint.handle(req, self.handle)

    def _button_measure(self) -> None:
        try:
            self.measure()
        except CommandError as e:
            log.warning("button measurement: %s", e)

    def _poll_button(self) -> None:
        if self.button is None or self.state != State.IDLE or self.measuring:
            return
        try:
            ev = self.button.wait_for_event(0.0)
        except Exception as e:
            log.warning("trigger button failed, disabled: %s", e)
            self.button = None
            return
        if ev is not None and ev.pressed and ev.t_s >= self._idle_since:
            log.info("trigger button pressed: measuring")
            self._cancel.clear()
            self._worker.start(self._button_measure, "button-measure")

    def serve(self, ser: Any, stop_event: threading.Event | None = None, *, poll_s: float = 0.05,
              ready: Callable[[Daemon], None] | None = None) -> None:
        """Answer requests on ``ser`` until ``stop_event`` (default: the daemon's) is set.

        A measurement (MEASURE or the trigger button) runs in a worker thread;
        meanwhile STATUS and PING are answered and every other request gets
        ERROR BUSY. The MEASURE reply carries its request's id. On the way
        out the worker is waited for -- stopped first through the daemon's
        stop event when that is set or on KeyboardInterrupt/SystemExit, left
        to finish and store its record after a port error -- then the heater
        is switched off. Port errors propagate. ``ready(self)`` is called
        once the link is served.
        """
        stop = stop_event if stop_event is not None else self.stop_event
        endpoint = SerialEndpoint(ser, max_payload=self.max_payload, poll_s=poll_s)
        self.endpoint = endpoint
        abort = True
        try:
            if ready is not None:
                ready(self)  # the link is up: requests from now on are answered
            while not stop.is_set() and not self.stop_event.is_set():
                self.notifier.beat("serve")
                for req in endpoint.poll():
                    self._dispatch(endpoint, req)
                    if stop.is_set() or self.stop_event.is_set():
                        break
                if not self.measuring:
                    self._check_faults()  # periodic: a fault heals without a request
                self._poll_button()
            abort = self.stop_event.is_set()
        except Exception:
            abort = False  # a port error: the running measurement completes and is stored
            raise
        finally:
            try:
                self._join_worker(abort=abort)
            finally:
                try:
                    self.heater.off()
                finally:
                    # Replies already queued go out within one write timeout, and the write in
                    # progress ends within another (bench/reliability_bench.py, blocked_writer):
                    # a host that stopped reading cannot hold up a stop longer.
                    endpoint.close(timeout_s=endpoint.write_timeout_s)

    def wake(self) -> None:
        """Wake the serve loop's read so that it sees a stop event set from another thread at once."""
        endpoint = self.endpoint
        if endpoint is not None:
            endpoint.wake()

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


