"""The probe's daemon: ``thermotouch-edge --config FILE``.

Start-up order matters: the configuration is parsed, then the board is built
and the heater driven OFF (enable line inactive, PWM duty 0) before anything
else -- history, model store, sensors, serial port. Then the daemon answers
protocol requests (:mod:`edge.protocol.messages`) on the serial port until SIGTERM or
SIGINT, which set the stop event: a running measurement is cut (heater off
at once through the watchdog), the loop ends, the heater driver, history
database and board are closed.

A measurement (MEASURE, or a press of the trigger button when
``measurement.trigger_button`` is set) runs in a worker thread while the
serve loop keeps reading the port: STATUS (``state = "measuring"``, its
``phase`` and ``measurement_elapsed_s`` on the board clock) and PING are
answered, every other request gets ERROR ``BUSY``, and the MEASURE reply is
sent with its request's id when the measurement ends. Only the worker
switches the heater on; the serve loop waits for it before it switches the
heater off on its way out.

:func:`run_daemon` runs the same daemon on a given board and an open
pyserial-like port (the simulator and the tests use it in a thread).

Commands
--------
PING, INFO (firmware/model versions, model sha256, board), STATUS,
MEASURE (optional ``power_W`` or ``voltage_V``, ``contact_time_s``),
RESULT (by id or latest), HISTORY (paged, newest first), SERIES (a stored
measurement's raw or resampled series, paged to fit one reply), CONFIG_GET,
CONFIG_SET (runtime keys only, validated, persisted atomically),
MODEL_BEGIN/CHUNK/COMMIT/ABORT (verified atomic install through
:class:`edge.model.store.ModelStore`).

MEASURE replies with the stored record (``measurement_id``, ``status``,
``flags``, ``result`` ...). Every measurement is committed to the history
before the reply. A sensor fault or open thermocouple answers ERROR
``SENSOR_FAULT`` and a crashed estimation ERROR ``INTERNAL``, each naming the
stored measurement id; safety cuts (over-temperature, on-time) give a record
with ``status = "aborted"`` and ``reason``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

import edge
from edge.estimation.estimate import pipeline_golden_check
from edge.hw.board import Board, make_board
from edge.service.config import RUNTIME_KEYS, Config, ConfigError, RuntimeOverrides, load_config
from edge.hw.drivers.heater import Heater, HeaterError, HeaterOffError
from edge.physics.probe import heater_power_W
from edge.hw.faults import SensorFault
from edge.storage.history import History
from edge.protocol.endpoint import SerialEndpoint
from edge.model.store import InstallError, ModelStore, ModelStoreError
from edge.protocol.frame import DEFAULT_MAX_PAYLOAD, PROTOCOL_VERSION
from edge.protocol.commands import Command
from edge.protocol.errors import CommandError, ErrorCode
from edge.protocol.messages import Request
from edge.measure.sequence import (
    EstimatorFn,
    HeaterWatchdog,
    Limits,
    MeasurementParams,
    MeasurementSequence,
    make_sensors,
)

__all__ = ["FIRMWARE_VERSION", "ModelEstimator", "Daemon", "run_daemon", "DaemonThread", "board_from_config",
           "install_signal_handlers", "main"]

log = logging.getLogger("thermotouch.edge")

FIRMWARE_VERSION = edge.__version__
#: Largest model upload held in memory (bytes); keeps the daemon within its RAM budget.
MAX_UPLOAD_BYTES = 8 * 1024 * 1024
#: Bytes kept free in a reply for the frame's JSON envelope.
_REPLY_MARGIN = 256
#: Requests answered while a measurement runs (everything else gets BUSY).
ANSWERED_WHILE_MEASURING = frozenset({Command.STATUS, Command.PING})
#: Longest wait for a running measurement when serve() ends, s, before it is stopped.
WORKER_JOIN_s = 60.0  # margin for estimation and storage beyond a measurement's own phases
#: SERIES reply names and History columns, per ``which``.
_SERIES_COLUMNS = {"raw": (("t_s", "raw_t_s"), ("T_C", "raw_T_C"), ("q_W_m2", "raw_q_W_m2")),
                   "grid": (("t_s", "grid_t_s"), ("dT_K", "grid_dT_K"), ("q_W_m2", "grid_q_W_m2"))}


class ModelEstimator:
    """The default estimator: :class:`edge.estimation.estimate.Estimator` on the store's active bundle.

    Rebuilt when the active bundle changes (after an upload or rollback).
    """

    def __init__(self, store: ModelStore, T_resolution_K: float = 0.0) -> None:
        self.store = store
        #: The thermometer's resolution (K), which the estimator carries into u(e).
        self.T_resolution_K = float(T_resolution_K)
        self._sha: str | None = None
        self._est: Any = None
        self._lock = threading.Lock()

    def model_sha256(self) -> str | None:
        try:
            return self.store.current().sha256
        except ModelStoreError:
            return None

    def __call__(self, t_s: np.ndarray, dT_K: np.ndarray, q_W_m2: np.ndarray, q_v_W_m3: float,
                 method: str) -> dict:
        from edge.estimation.estimate import Estimator  # noqa: PLC0415 - loaded on first use

        bundle = self.store.current()
        with self._lock:
            if self._sha != bundle.sha256:
                self._est, self._sha = Estimator.from_bundle(bundle), bundle.sha256
            est = self._est
        return est.estimate(t_s, dT_K, q_W_m2, method=method, q_v_W_m3=q_v_W_m3,
                            T_resolution_K=self.T_resolution_K).to_dict()


def thermocouple_resolution_K(sensors: Any) -> float:
    """Temperature step (K) of the configured thermocouple converter near room temperature."""
    from edge.hw.regmaps.mcp9600 import adc_step_V  # noqa: PLC0415
    from edge.measure.instrument import ADS122C04_STEP_V, TYPE_K_SEEBECK_V_per_K  # noqa: PLC0415

    if sensors.thermocouple == "mcp9600":
        return adc_step_V(int(sensors.mcp9600_adc_bits)) / TYPE_K_SEEBECK_V_per_K
    return ADS122C04_STEP_V * 128 / sensors.ads122c04_gain / TYPE_K_SEEBECK_V_per_K


def _factory_bundle(cfg: Config) -> Path | None:
    if cfg.paths.factory_model:
        return Path(cfg.paths.factory_model)
    try:
        from thermotouch_models import DEFAULT_BUNDLE  # noqa: PLC0415 - optional package data
    except ImportError:
        return None
    return DEFAULT_BUNDLE if (DEFAULT_BUNDLE / "manifest.json").exists() else None


def board_from_config(cfg: Config) -> Board:
    """Build the board named by ``[board] kind`` with the ``[board]`` options."""
    b = cfg.board
    if b.kind == "rpi":
        return make_board("rpi", i2c_bus=b.i2c_bus, gpio_chip=b.gpio_chip,
                          heater_enable_offset=b.heater_enable_offset, heater_active_low=b.heater_active_low,
                          trigger_offset=b.trigger_offset, trigger_active_low=b.trigger_active_low,
                          pwm_root=b.pwm_root, pwm_chip=b.pwm_chip, pwm_channel=b.pwm_channel)
    return make_board(b.kind)


class _Upload:
    """A model upload in progress (held in memory; bundles are small)."""

    def __init__(self, size: int, sha256: str, version: str | None) -> None:
        self.size = size
        self.sha256 = sha256
        self.version = version
        self.data = bytearray()


class Daemon:
    """Request handler and measurement owner for one board.

    Construction switches the heater off first. Use :meth:`serve` to answer
    a serial port and :meth:`close` (or ``with``) to shut down.

    Parameters
    ----------
    config : Config
        The file configuration; stored runtime overrides are applied on top.
    board : Board
    estimator : EstimatorFn, optional
        Default: :class:`ModelEstimator` on the model store.
    stop_event : threading.Event, optional
        Set to stop serving; also aborts a running measurement.
    model_store, history : optional
        Injected instances (default: built from ``[paths]``).
    max_payload : int
        Frame payload bound, bytes (replies are cut to fit).
    max_upload_bytes : int
        Largest model upload accepted (held in memory until commit).
    """

    def __init__(self, config: Config, board: Board, *, estimator: EstimatorFn | None = None,
                 stop_event: threading.Event | None = None, model_store: ModelStore | None = None,
                 history: History | None = None, max_payload: int = DEFAULT_MAX_PAYLOAD,
                 max_upload_bytes: int = MAX_UPLOAD_BYTES) -> None:
        self.board = board
        self.stop_event = stop_event if stop_event is not None else threading.Event()
        self.max_payload = max_payload
        self.max_upload_bytes = int(max_upload_bytes)
        h = config.heater
        # The heater goes OFF before anything else (its constructor drives both channels off).
        self.heater = Heater(board, supply_voltage_V=h.supply_voltage_V, resistance_ohm=h.resistance_ohm,
                             pwm_period_ns=h.pwm_period_ns)
        self.heater.off()
        self.state = "starting"
        self.faults: list[str] = []
        self.t_start = time.monotonic()
        try:
            self.base_config = config
            self.overrides = RuntimeOverrides(config.paths.runtime_overrides or None)
            self.config = self.overrides.load(config)
            for err in self.overrides.errors:
                log.warning("runtime override ignored: %s", err)
            self._apply_logging()
            self.history = history if history is not None else History(self.config.paths.history_db)
            self.store = model_store if model_store is not None else ModelStore(
                self.config.paths.model_store, _factory_bundle(self.config), golden_check=pipeline_golden_check)
            try:
                b = self.store.current()
                log.info("model %s (%s) from %s", b.model_version, b.sha256[:12], self.store.source)
            except ModelStoreError as e:
                log.error("no usable model yet: %s", e)
            self._model_est = ModelEstimator(self.store, thermocouple_resolution_K(self.config.sensors))
            self.estimator = estimator if estimator is not None else self._model_est
            self.watchdog = HeaterWatchdog(self.heater, board.clock, h.max_on_time_s,
                                           abort_event=self.stop_event)
            self.sensors: Any = None
            self.sensor_error: str | None = None
            self._init_sensors()
            self.button: Any = None
            if self.config.measurement.trigger_button:
                self._init_button()
            self.sequence: MeasurementSequence | None = None
            self.upload: _Upload | None = None
            self._series_cache: tuple[int, dict] | None = None
            self.last_id: int | None = self.history.latest_id()
            self.measurements = 0
            self.last_timing: dict[str, float | None] = {}
            # Presses while a measurement ran (e.g. the touch that started it) are not new requests.
            self._idle_since = board.clock.monotonic()
            # One measurement at a time; serve() runs it in a worker thread so STATUS stays answered.
            self._measure_lock = threading.Lock()
            self._worker: threading.Thread | None = None
            self._busy = threading.Event()  # set while a measurement is requested or running
            self.phase: str | None = None
            self._measure_t0: float | None = None
            self.state = "idle"
        except BaseException:
            if history is None and getattr(self, "history", None) is not None:
                self.history.close()
            self.heater.close()
            raise

    # -- set-up helpers --------------------------------------------------------------
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
        from edge.hw.drivers.button import Button  # noqa: PLC0415

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
                self.heater, self.sensors, self.board.clock, Limits(h.max_on_time_s, h.over_temperature_C),
                self._estimate, self.config.measurement, watchdog=self.watchdog, abort_event=self.stop_event,
                model_sha256=self._model_sha256, on_state=self._on_state)
        self.sequence.thresholds = self.config.measurement
        return self.sequence

    def _estimate(self, *args: Any) -> Mapping[str, Any]:
        return self.estimator(*args)

    def _model_sha256(self) -> str | None:
        return self._model_est.model_sha256()

    def _on_state(self, s: str) -> None:
        self.phase = None if s == "idle" else s

    # -- requests --------------------------------------------------------------------
    def handle(self, req: Request) -> dict[str, Any] | None:
        """Answer one validated request (raises CommandError for ERROR replies)."""
        fn = getattr(self, f"_cmd_{req.command.name.lower()}", None)
        if fn is None:  # pragma: no cover - every command has a handler
            raise CommandError(ErrorCode.UNKNOWN_COMMAND, f"{req.command.name} is not implemented")
        return fn(req.args)

    def _cmd_ping(self, args: dict) -> dict:
        return {"echo": args.get("echo")}

    def _cmd_info(self, args: dict) -> dict:
        st = self.store.status()
        return {"protocol_version": PROTOCOL_VERSION, "firmware_version": FIRMWARE_VERSION,
                "model_version": st.get("model_version"), "model_sha256": st.get("sha256"),
                "model_source": st.get("source"), "board": self.board.name}

    def _cmd_status(self, args: dict) -> dict:
        out = {"state": self.state, "heater_on": self.heater.is_on,
               "heater_on_time_s": round(self.heater.on_time_s, 6), "measurements": self.measurements,
               "last_measurement_id": self.last_id, "history_total": self.history.count(),
               "sensor_error": self.sensor_error, "faults": list(self.faults[-5:]),
               "uptime_s": round(time.monotonic() - self.t_start, 3)}
        if self.upload is not None:
            out["upload"] = {"received": len(self.upload.data), "size": self.upload.size}
        t0 = self._measure_t0
        if self.state == "measuring" and t0 is not None:
            out["phase"] = self.phase
            out["measurement_elapsed_s"] = round(self.board.clock.monotonic() - t0, 3)  # board clock
        return out

    def _cmd_measure(self, args: dict) -> dict:
        return self.measure(power_W=args.get("power_W"), voltage_V=args.get("voltage_V"),
                            contact_time_s=args.get("contact_time_s"))

    def measure(self, *, power_W: float | None = None, voltage_V: float | None = None,
                contact_time_s: float | None = None) -> dict:
        """Run one measurement, store it, return its summary (CommandError on failure).

        While it runs, :attr:`state` is ``"measuring"`` (``phase`` names the
        sequence step); a second call meanwhile raises BUSY.
        """
        if not self._measure_lock.acquire(blocking=False):
            raise CommandError(ErrorCode.BUSY, "a measurement is already running")
        try:
            return self._measure(power_W, voltage_V, contact_time_s)
        finally:
            self._measure_t0 = None
            self.phase = None
            if self.state == "measuring":
                self.state = "idle"
            self._measure_lock.release()

    def _measure(self, power_W: float | None, voltage_V: float | None, contact_time_s: float | None) -> dict:
        if self.state == "fault":
            raise CommandError(ErrorCode.BAD_STATE, "heater fault: measurements are disabled until restart; "
                               + "; ".join(self.faults[-1:]))
        if self.stop_event.is_set():
            raise CommandError(ErrorCode.BAD_STATE, "daemon is stopping")
        cfg = self.config
        h, m = cfg.heater, cfg.measurement
        if voltage_V is not None:
            if voltage_V > h.supply_voltage_V:
                raise CommandError(ErrorCode.BAD_ARGUMENT, f"voltage_V={voltage_V} exceeds the supply "
                                   f"{h.supply_voltage_V} V", "voltage_V")
            power_W = heater_power_W(1.0, voltage_V, h.resistance_ohm)
        power = h.power_W if power_W is None else power_W
        if power > self.heater.max_power_W * (1 + 1e-12):
            raise CommandError(ErrorCode.BAD_ARGUMENT, f"power_W={power} exceeds the heater's maximum "
                               f"{self.heater.max_power_W:.4g} W", "power_W")
        contact = m.contact_time_s if contact_time_s is None else contact_time_s
        if contact >= h.max_on_time_s:
            raise CommandError(ErrorCode.BAD_ARGUMENT, f"contact_time_s={contact} must be below "
                               f"heater.max_on_time_s={h.max_on_time_s}", "contact_time_s")
        params = MeasurementParams(power_W=power, contact_time_s=contact, baseline_s=m.baseline_s,
                                   sample_rate_Hz=m.sample_rate_Hz, cooldown_s=m.cooldown_s,
                                   method=cfg.estimation.method)
        seq = self._get_sequence()
        self._measure_t0 = self.board.clock.monotonic()
        self.state = "measuring"
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
        mid = self.history.add(outcome.record(cfg.to_dict()))
        commit_s = time.perf_counter() - t_commit
        #: Wall-clock costs of the last measurement after its last sample (for bench/).
        self.last_timing = {"compute_s": outcome.compute_s, "commit_s": commit_s,
                            "compute_and_commit_s": None if outcome.compute_s is None
                            else outcome.compute_s + commit_s}
        self.last_id = mid
        if outcome.compute_s is not None:
            log.debug("measurement %d: compute %.2f ms", mid, outcome.compute_s * 1e3)
        log.info("measurement %d: %s%s flags=%s", mid, outcome.status,
                 f" ({outcome.reason})" if outcome.reason else "", outcome.flags)
        if outcome.reason == "heater_fault":
            self.state = "fault"
            self.faults.append(outcome.error or "heater fault")
            raise CommandError(ErrorCode.INTERNAL, f"HEATER FAULT ({outcome.error}); measurement {mid} stored")
        if outcome.reason in ("sensor_fault", "open_thermocouple"):
            self.sensors = None if outcome.reason == "sensor_fault" else self.sensors
            self.sensor_error = outcome.error
            raise CommandError(ErrorCode.SENSOR_FAULT, f"{outcome.reason}: {outcome.error}; measurement {mid} stored")
        if outcome.status == "failed":
            raise CommandError(ErrorCode.INTERNAL, f"{outcome.reason}: {outcome.error}; measurement {mid} stored")
        return self._fit(self.history.get(mid))

    def _fit(self, record: dict) -> dict:
        """Drop bulky optional fields until a record fits in one reply."""
        for key in ("error", "result"):
            if len(json.dumps(record, default=str)) + _REPLY_MARGIN <= self.max_payload:
                break
            if key == "result" and isinstance(record.get("result"), dict):
                record["result"] = {k: v for k, v in record["result"].items()
                                    if not isinstance(v, (list, dict))}
            elif record.get(key):
                record[key] = str(record[key])[:200]
        return record

    def _cmd_result(self, args: dict) -> dict:
        mid = args.get("measurement_id")
        if mid is None:
            mid = self.history.latest_id()
            if mid is None:
                raise CommandError(ErrorCode.NOT_FOUND, "no measurement stored yet", "measurement_id")
        rec = self.history.get(mid)
        if rec is None:
            raise CommandError(ErrorCode.NOT_FOUND, f"no measurement {mid}", "measurement_id")
        return self._fit(rec)

    def _cmd_history(self, args: dict) -> dict:
        offset, limit = args.get("offset", 0), args.get("limit", 20)
        total, items = self.history.page(offset, limit)
        items = [self._fit(r) for r in items]
        # A page holds as many records as fit in one reply; the host continues at offset + len(items).
        while items and len(json.dumps({"offset": offset, "total": total, "items": items})) + _REPLY_MARGIN \
                > self.max_payload:
            items.pop()
        return {"offset": offset, "total": total, "items": items}

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
        cols = [(name, rec.get(col)) for name, col in _SERIES_COLUMNS[which]]
        total = 0 if cols[0][1] is None else int(len(cols[0][1]))
        if offset > total:
            raise CommandError(ErrorCode.BAD_ARGUMENT, f"offset {offset} is past the end of the {which} series "
                               f"({total} samples)", "offset")
        end = total if limit is None else min(total, offset + limit)
        body: dict[str, Any] = {"measurement_id": mid, "which": which, "offset": offset, "total": total}
        body.update((name, []) for name, _ in cols)
        # JSON has no NaN: a non-finite sample travels as null.
        values = [[x if math.isfinite(x) else None for x in np.asarray(a[offset:end], float).tolist()]
                  if end > offset else [] for _, a in cols]
        budget = self.max_payload - len(json.dumps(body, separators=(",", ":")))
        n = used = 0
        for i in range(end - offset):
            cost = sum(len(json.dumps(v[i])) + 1 for v in values)  # the value and its comma
            if used + cost > budget:
                break
            used += cost
            n += 1
        if n == 0 and end > offset:
            raise CommandError(ErrorCode.INTERNAL, f"max_payload {self.max_payload} B is too small for one sample")
        for (name, _), v in zip(cols, values):
            body[name] = v[:n]
        return body

    def _cmd_config_get(self, args: dict) -> dict:
        keys = args.get("keys")
        try:
            values = self.config.flat(keys)
        except ConfigError as e:
            raise CommandError(ErrorCode.BAD_ARGUMENT, str(e), e.key) from None
        return self._config_reply(values)

    def _config_reply(self, values: dict[str, Any]) -> dict[str, Any]:
        # Long paths could push the whole set past one frame; the runtime keys always fit.
        if len(json.dumps(values)) + _REPLY_MARGIN > self.max_payload:
            return {"config": {k: v for k, v in values.items() if k in RUNTIME_KEYS}, "truncated": True}
        return {"config": values}

    def _cmd_config_set(self, args: dict) -> dict:
        values = args["values"]
        if self.state not in ("idle", "fault"):
            raise CommandError(ErrorCode.BUSY, f"cannot change the configuration while {self.state}")
        try:
            new = self.config.with_updates(values)
        except ConfigError as e:
            raise CommandError(ErrorCode.BAD_ARGUMENT, str(e), e.key) from None
        self.overrides.save(new, self.base_config)
        self.config = new
        self._apply_logging()
        log.info("configuration changed: %s", {k: new.get(k) for k in values})
        return self._config_reply(new.flat())

    def _cmd_model_begin(self, args: dict) -> dict:
        size = args["size"]
        limit = min(self.store.limits.max_blob_bytes, self.max_upload_bytes)
        if size > limit:
            raise CommandError(ErrorCode.MODEL_REJECTED, f"size {size} B exceeds the upload limit of {limit} B",
                               "size")
        self.upload = _Upload(size, args["sha256"], args.get("version"))
        log.info("model upload started: %d B, sha256 %s", size, args["sha256"][:12])
        return {"size": size}

    def _cmd_model_chunk(self, args: dict) -> dict:
        up = self.upload
        if up is None:
            raise CommandError(ErrorCode.BAD_STATE, "no upload in progress (send MODEL_BEGIN first)")
        offset, data = args["offset"], args["data"]
        held = len(up.data)
        if offset + len(data) > up.size:
            raise CommandError(ErrorCode.BAD_ARGUMENT, f"chunk [{offset}, {offset + len(data)}) runs past the "
                               f"announced size {up.size}", "offset")
        if offset == held:
            up.data += data
        elif offset + len(data) <= held and up.data[offset:offset + len(data)] == data:
            pass  # a resent chunk we already hold
        else:
            raise CommandError(ErrorCode.BAD_ARGUMENT, f"chunk at offset {offset}, expected {held}", "offset")
        return {"received": len(up.data)}

    def _cmd_model_commit(self, args: dict) -> dict:
        up = self.upload
        if up is None:
            raise CommandError(ErrorCode.BAD_STATE, "no upload in progress")
        if len(up.data) != up.size:
            raise CommandError(ErrorCode.BAD_STATE, f"upload incomplete: {len(up.data)} of {up.size} B")
        self.upload = None
        try:
            bundle = self.store.install(bytes(up.data), up.sha256, up.size)
        except InstallError as e:
            detail = str(e)  # InstallError's message already carries the cause
            log.warning("model upload refused: %s", detail)
            raise CommandError(ErrorCode.MODEL_REJECTED, detail[:1000]) from None
        log.info("model %s (%s) installed", bundle.model_version, bundle.sha256[:12])
        return {"model_sha256": up.sha256, "bundle_sha256": bundle.sha256, "model_version": bundle.model_version}

    def _cmd_model_abort(self, args: dict) -> dict:
        self.upload = None
        return {}

    # -- serving ---------------------------------------------------------------------
    @property
    def measuring(self) -> bool:
        """Whether serve() has a measurement running (its worker may still be sending the reply)."""
        return self._busy.is_set()

    def _start_worker(self, fn: Callable[[], None], name: str) -> None:
        def run() -> None:
            try:
                fn()
            except Exception:  # e.g. the reply cannot be written: the host went away (the record is stored)
                log.exception("%s failed", name)
            finally:
                self._busy.clear()

        self._busy.set()
        self._worker = threading.Thread(target=run, name=f"thermotouch-{name}", daemon=True)
        self._worker.start()

    def _handle_measure(self, req: Request) -> dict[str, Any] | None:
        try:
            return self.handle(req)
        finally:
            # Before the reply goes out: a host that reads it and asks again at once is not refused BUSY.
            self._busy.clear()

    def _worker_budget_s(self) -> float:
        """Longest a healthy measurement can take: baseline + heating limit + cooldown + a margin."""
        m, h = self.config.measurement, self.config.heater
        return m.baseline_s + h.max_on_time_s + m.cooldown_s + WORKER_JOIN_s

    def _join_worker(self, *, abort: bool, timeout_s: float | None = None) -> None:
        """Wait for the measurement worker; ``abort`` (or a timeout) stops it through the stop event.

        Without ``abort`` (a lost port) the worker may be in its cooldown, so
        the wait covers a whole measurement before the worker is stopped.
        """
        w = self._worker
        if w is None:
            return
        if timeout_s is None:
            timeout_s = self._worker_budget_s()
        if abort:
            self.stop_event.set()
        w.join(timeout_s)
        if w.is_alive():
            log.error("measurement worker still running after %.0f s: stopping it", timeout_s)
            self.stop_event.set()
            w.join(timeout_s)
        if not w.is_alive():
            self._worker = None

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
            self._start_worker(lambda: endpoint.handle(req, self._handle_measure), "measure")
            return
        endpoint.handle(req, self.handle)

    def _button_measure(self) -> None:
        try:
            self.measure()
        except CommandError as e:
            log.warning("button measurement: %s", e)

    def _poll_button(self) -> None:
        if self.button is None or self.state != "idle" or self.measuring:
            return
        try:
            ev = self.button.wait_for_event(0.0)
        except Exception as e:
            log.warning("trigger button failed, disabled: %s", e)
            self.button = None
            return
        if ev is not None and ev.pressed and ev.t_s >= self._idle_since:
            log.info("trigger button pressed: measuring")
            self._start_worker(self._button_measure, "button-measure")

    def serve(self, ser: Any, stop_event: threading.Event | None = None, *, poll_s: float = 0.05) -> None:
        """Answer requests on ``ser`` until ``stop_event`` (default: the daemon's) is set.

        A measurement (MEASURE or the trigger button) runs in a worker thread;
        meanwhile STATUS and PING are answered and every other request gets
        ERROR BUSY. The MEASURE reply carries its request's id. On the way
        out the worker is waited for -- stopped first through the daemon's
        stop event when that is set or on KeyboardInterrupt/SystemExit, left
        to finish and store its record after a port error -- then the heater
        is switched off. Port errors propagate.
        """
        stop = stop_event if stop_event is not None else self.stop_event
        endpoint = SerialEndpoint(ser, max_payload=self.max_payload, poll_s=poll_s)
        abort = True
        try:
            while not stop.is_set() and not self.stop_event.is_set():
                for req in endpoint.poll():
                    self._dispatch(endpoint, req)
                    if stop.is_set():
                        break
                self._poll_button()
            abort = self.stop_event.is_set()
        except Exception:
            abort = False  # a port error: the running measurement completes and is stored
            raise
        finally:
            try:
                self._join_worker(abort=abort)
            finally:
                self.heater.off()

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
        self.state = "stopped"
        if errors:
            raise HeaterError(f"shutdown incomplete: {errors!r}") from errors[0]

    def __enter__(self) -> Daemon:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def run_daemon(config: Config, board: Board, serial_port: Any, stop_event: threading.Event, *,
               estimator: EstimatorFn | None = None, ready: Callable[[Daemon], None] | None = None,
               **kwargs: Any) -> None:
    """Run a daemon on ``board`` answering ``serial_port`` until ``stop_event`` is set.

    Blocking; run it in a thread for the simulator (see :class:`DaemonThread`).
    ``ready(daemon)`` is called once the daemon answers. The heater is off and
    the history closed when this returns, whatever happened.
    """
    daemon = Daemon(config, board, estimator=estimator, stop_event=stop_event, **kwargs)
    try:
        if ready is not None:
            ready(daemon)
        daemon.serve(serial_port, stop_event)
    finally:
        daemon.close()


class DaemonThread:
    """:func:`run_daemon` in a background thread; ``daemon`` is available after start().

    Use as a context manager: leaving it sets the stop event and joins.
    """

    def __init__(self, config: Config, board: Board, serial_port: Any, **kwargs: Any) -> None:
        self.stop_event = threading.Event()
        self.daemon: Daemon | None = None
        self.error: BaseException | None = None
        self._ready = threading.Event()
        self._args = (config, board, serial_port)
        self._kwargs = kwargs
        self.thread = threading.Thread(target=self._run, name="thermotouch-edge", daemon=True)

    def _run(self) -> None:
        def ready(d: Daemon) -> None:
            self.daemon = d
            self._ready.set()

        try:
            run_daemon(*self._args, self.stop_event, ready=ready, **self._kwargs)
        except BaseException as e:  # reported to the starter
            self.error = e
            log.exception("daemon thread ended with an error")
        finally:
            self._ready.set()

    def start(self, timeout_s: float = 10.0) -> Daemon:
        """Start and wait until the daemon answers; re-raise a start-up error."""
        self.thread.start()
        self._ready.wait(timeout_s)
        if self.daemon is None:
            raise RuntimeError(f"daemon did not start: {self.error!r}") from self.error
        return self.daemon

    def stop(self, timeout_s: float = 10.0) -> None:
        """Set the stop event and wait for the thread."""
        self.stop_event.set()
        self.thread.join(timeout_s)

    def __enter__(self) -> DaemonThread:
        self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()


# --------------------------------------------------------------------------
# Console entry point


def install_signal_handlers(stop_event: threading.Event) -> None:
    """SIGTERM and SIGINT set ``stop_event`` (call from the main thread).

    The handler only sets the event: the heater watchdog then cuts a running
    heating within its poll period, the sampling loop ends, the serve loop
    returns and :meth:`Daemon.close` runs. Switching the heater from inside
    the handler could interleave with a half-finished ``Heater.on``.
    """

    def on_signal(signum: int, _frame: Any) -> None:
        log.info("signal %s: stopping", signal.Signals(signum).name)
        stop_event.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="thermotouch-edge", description="ThermoTouch probe daemon")
    p.add_argument("--config", required=True, help="TOML configuration file")
    p.add_argument("--check-config", action="store_true", help="validate the configuration and exit")
    p.add_argument("--heater-off", action="store_true",
                   help="drive the heater off (enable line and PWM, no I2C needed) and exit; for ExecStopPost")
    return p.parse_args(argv)


def force_heater_off(cfg: Config) -> list[str]:
    """Drive the configured real heater off before (or without) building the board; failures."""
    b = cfg.board
    if b.kind != "rpi":
        return []  # simulated boards start with the heater off; Daemon() drives it off again
    from edge.hw.board import force_rpi_heater_off  # noqa: PLC0415

    return force_rpi_heater_off(gpio_chip=b.gpio_chip, heater_enable_offset=b.heater_enable_offset,
                                heater_active_low=b.heater_active_low, pwm_root=b.pwm_root,
                                pwm_chip=b.pwm_chip, pwm_channel=b.pwm_channel)


def main(argv: list[str] | None = None) -> int:
    """``thermotouch-edge --config FILE``: exit status 0 on a clean stop, 1 on failure, 2 on bad config."""
    args = _parse_args(argv)
    logging.basicConfig(stream=sys.stderr, level=logging.INFO,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        cfg = load_config(args.config)
    except ConfigError as e:
        print(f"thermotouch-edge: bad configuration: {e}", file=sys.stderr)
        return 2
    if args.check_config:
        print(f"{args.config}: OK", file=sys.stderr)
        return 0
    # Heater off before anything that can fail (I2C, model store, serial port).
    failures = force_heater_off(cfg)
    for f in failures:
        log.critical("cannot drive the heater off: %s", f)
    if args.heater_off:
        return 1 if failures else 0
    stop = threading.Event()
    install_signal_handlers(stop)
    try:
        board = board_from_config(cfg)
    except Exception as e:
        log.critical("cannot build board %r: %s", cfg.board.kind, e)
        return 1
    try:
        daemon = Daemon(cfg, board, stop_event=stop)
    except Exception as e:
        log.critical("start-up failed: %s", e)
        board.close()
        return 1
    log.info("thermotouch-edge %s on board %s, serial %s", FIRMWARE_VERSION, board.name, cfg.serial.port)
    status = 0
    try:
        import serial  # noqa: PLC0415

        while not stop.is_set():
            try:
                with serial.Serial(cfg.serial.port, cfg.serial.baud, timeout=0.05, exclusive=True) as ser:
                    daemon.serve(ser, stop)
            except (serial.SerialException, OSError) as e:
                # The link can come and go (USB gadget unplugged): heater is off, retry.
                log.warning("serial port %s: %s; retrying", cfg.serial.port, e)
                stop.wait(1.0)
    except Exception:
        log.exception("daemon failed")
        status = 1
    finally:
        try:
            daemon.close()
        except Exception as e:
            log.critical("shutdown: %s", e)
            status = 1
        try:
            board.close()
        except Exception as e:
            log.error("closing the board: %s", e)
    log.info("stopped")
    return status


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
