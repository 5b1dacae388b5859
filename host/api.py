"""The documented Python API of a ThermoTouch probe: typed results, streaming touches, asyncio.

::

    from host.api import Probe

    with Probe.connect("/dev/ttyACM0") as probe:
        m = probe.measure(contact_time_s=2.0)
        print(m.object, m.effusivity_W_s05_m2K, "+-", m.effusivity_W_s05_m2K_u)
        for event in probe.stream(contact_time_s=2.0):   # phases, sample batches, running answers
            print(event)                                   # ... and last, the Measurement

Built on :class:`host.client.DeviceClient` (one client, its retries and typed errors); see
docs/python-api.md for the guide and the event vocabulary. Uncertainties are standard
uncertainties (coverage factor k = 1), in the unit of their value.
"""

from __future__ import annotations

import asyncio
import math
import queue
import threading
from dataclasses import dataclass, field
from typing import Any, AsyncIterator, Iterator, Mapping

from edge.protocol.commands import Command, EventKind
from edge.protocol.messages import Event
from host.client import (BadReply, ClientError, DeviceClient, DeviceError, DeviceNotAnswering,
                         PortUnavailable)

__all__ = [
    "Probe", "Measurement", "RunningAnswer", "Phase", "Samples", "StreamItem",
    "ClientError", "DeviceError", "DeviceNotAnswering", "PortUnavailable", "BadReply",
]

#: Longest a stream waits for its touch's thread after the consumer stopped early, s.
STREAM_JOIN_s = 15.0


def _float(x: Any) -> float:
    """A reply's number, NaN for null (a value the device did not determine)."""
    return math.nan if x is None else float(x)


@dataclass(frozen=True)
class Measurement:
    """One stored touch's answer, typed (a MEASURE or RESULT reply, or a HISTORY item).

    Values are NaN where the device gave none (``status`` not ``ok``, or no signal); ``*_u`` are
    standard uncertainties (k = 1). ``determined_by`` says, per property (``e``, ``k``, ``alpha``),
    whether the data or the prior determined it. ``record`` is the device's whole reply.
    """

    measurement_id: int
    status: str
    reason: str | None
    flags: tuple[str, ...]
    effusivity_W_s05_m2K: float
    effusivity_W_s05_m2K_u: float
    k_W_mK: float
    k_W_mK_u: float
    alpha_m2_s: float
    alpha_m2_s_u: float
    determined_by: Mapping[str, str]
    object: str | None
    object_posterior: float
    material: str | None
    method: str | None
    probe: str | None
    power_W: float
    contact_time_s: float
    started_utc: str | None
    created_utc: str | None
    model_sha256: str | None
    calibration_sha256: str | None
    device_id: str | None
    record: Mapping[str, Any] = field(repr=False, compare=False, default_factory=dict)

    @property
    def ok(self) -> bool:
        """Whether the touch ended normally (``status == "ok"``; it may still carry flags)."""
        return self.status == "ok"

    @classmethod
    def from_record(cls, record: Mapping[str, Any], device_id: str | None = None) -> Measurement:
        """Type a result record (MEASURE/RESULT reply or HISTORY item); ``device_id`` fills a record without one."""
        res = record.get("result") or {}
        header = record.get("header") or {}
        return cls(
            measurement_id=int(record["measurement_id"]), status=str(record.get("status")),
            reason=record.get("reason"), flags=tuple(record.get("flags") or ()),
            effusivity_W_s05_m2K=_float(res.get("effusivity_W_s05_m2K")),
            effusivity_W_s05_m2K_u=_float(res.get("effusivity_W_s05_m2K_u")),
            k_W_mK=_float(res.get("k_W_mK")), k_W_mK_u=_float(res.get("k_W_mK_u")),
            alpha_m2_s=_float(res.get("alpha_m2_s")), alpha_m2_s_u=_float(res.get("alpha_m2_s_u")),
            determined_by=dict(res.get("determined_by") or {}), object=res.get("object"),
            object_posterior=_float(res.get("object_posterior")), material=res.get("material"),
            method=res.get("method"), probe=res.get("probe"),
            power_W=_float(record.get("power_W")), contact_time_s=_float(record.get("contact_time_s")),
            started_utc=record.get("started_utc"), created_utc=record.get("created_utc"),
            model_sha256=record.get("model_sha256") or res.get("model_sha256"),
            calibration_sha256=res.get("calibration_sha256"),
            device_id=record.get("device_id") or header.get("device_id") or device_id,
            record=dict(record))


@dataclass(frozen=True)
class Phase:
    """The touch entered ``phase``: cooldown, baseline or armed, contact, heating, estimating, done.

    ``t_s`` is board-clock seconds since the measurement began (heating's ``t_s`` is heater-on, the
    record's time origin). ``done`` carries the stored record's id and ``events_dropped``: events
    of this touch the link lost (a slow host), also visible as gaps in ``seq``.
    """

    seq: int
    t_s: float
    phase: str
    measurement_id: int | None = None
    status: str | None = None
    events_dropped: int = 0


@dataclass(frozen=True)
class Samples:
    """A batch of raw samples: ``t_s`` (board-clock s since the measurement began), ``T_C``, ``q_W_m2``."""

    seq: int
    t_s: tuple[float, ...]
    T_C: tuple[float, ...]
    q_W_m2: tuple[float, ...]


@dataclass(frozen=True)
class RunningAnswer:
    """The running answer while the probe heats: the likeliest object and a running effusivity.

    ``u_ln_e`` is the standard uncertainty of ln(e) (relative, k = 1); ``decided`` once the
    object's posterior reached the device's ``measurement.decide_posterior``.
    """

    seq: int
    t_s: float
    object: str
    posterior: float
    effusivity_W_s05_m2K: float
    u_ln_e: float
    elapsed_s: float
    samples: int
    decided: bool
    source: str


#: What :meth:`Probe.stream` yields: events while the touch runs, then its :class:`Measurement`.
StreamItem = Phase | Samples | RunningAnswer | Measurement


def typed_event(event: Event) -> Phase | Samples | RunningAnswer:
    """The typed form of a link :class:`~edge.protocol.messages.Event`."""
    b = event.body
    if event.kind == EventKind.PHASE:
        return Phase(b["seq"], b["t_s"], b["phase"], b.get("measurement_id"), b.get("status"),
                     int(b.get("events_dropped") or 0))
    if event.kind == EventKind.SAMPLES:
        return Samples(b["seq"], tuple(b["sample_t_s"]), tuple(map(_float, b["T_C"])),
                       tuple(map(_float, b["q_W_m2"])))
    a = b["answer"]
    return RunningAnswer(b["seq"], b["t_s"], str(a.get("object")), _float(a.get("posterior")),
                         _float(a.get("effusivity_W_s05_m2K")), _float(a.get("u_ln_e")),
                         _float(a.get("elapsed_s")), int(a.get("samples") or 0), bool(a.get("decided")),
                         str(a.get("source")))


def _unpack(kind: str, item: Any) -> tuple[Any, bool]:
    """A stream queue's entry: the item and whether it is the last (the Measurement); an error is raised."""
    if kind == "error":
        raise item
    return item, kind == "end"


class Probe:
    """A connected probe. Use :meth:`connect` (and ``with``) or wrap an open :class:`DeviceClient`.

    Every method raises the client's typed errors: :class:`PortUnavailable`,
    :class:`DeviceNotAnswering`, :class:`DeviceError` (the device refused, ``.code`` says why),
    :class:`BadReply`; all are :class:`ClientError`.
    """

    def __init__(self, client: DeviceClient) -> None:
        self.client = client
        self._device_id: str | None = None
        self._device_id_known = False

    @classmethod
    def connect(cls, port: str, *, timeout_s: float = 3.0, retries: int = 1) -> Probe:
        """Open the probe on ``port`` (a device path or pyserial URL)."""
        return cls(DeviceClient(port, timeout_s=timeout_s, retries=retries))

    def close(self) -> None:
        """Close the port (if this probe opened it)."""
        self.client.close()

    def __enter__(self) -> Probe:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- what the device is and does --------------------------------------------------------
    def info(self) -> dict[str, Any]:
        """Firmware, model, board, device identity (INFO)."""
        return self.client.info()

    def status(self) -> dict[str, Any]:
        """State, ``ready``, faults, event counters (STATUS)."""
        return self.client.status()

    @property
    def device_id(self) -> str | None:
        """The device's identity (INFO ``device_id``; asked once)."""
        if not self._device_id_known:
            self._device_id = self.client.info().get("device_id")
            self._device_id_known = True
        return self._device_id

    # -- touches --------------------------------------------------------------------------------
    @staticmethod
    def _measure_args(kw: dict[str, Any]) -> dict[str, Any]:
        allowed = {"power_W", "voltage_V", "contact_time_s", "sample_rate_Hz", "until_decided", "arm_s",
                   "settle_s", "timeout_s"}
        bad = set(kw) - allowed
        if bad:
            raise TypeError(f"unknown measure argument(s): {', '.join(sorted(bad))}")
        return kw

    def measure(self, **kw: Any) -> Measurement:
        """Run one touch and return its :class:`Measurement`.

        Keywords (all optional; the device's configuration otherwise): ``power_W`` or ``voltage_V``,
        ``contact_time_s``, ``sample_rate_Hz``, ``until_decided``, ``arm_s``, ``settle_s``,
        ``timeout_s``. Interrupted (Ctrl-C) or timed out, the touch is aborted on the device first.
        """
        rec = self.client.measure(**self._measure_args(kw))
        return Measurement.from_record(rec, self.device_id)

    def stream(self, **kw: Any) -> Iterator[StreamItem]:
        """Run one touch, yielding its events as they arrive, then its :class:`Measurement` (last).

        Events are :class:`Phase`, :class:`Samples` and :class:`RunningAnswer` (best effort: a slow
        consumer may miss some, see :attr:`Phase.events_dropped`). Leaving the loop early aborts the
        touch (the heater goes off, the record is stored with status ``aborted``). Keywords as
        :meth:`measure`.
        """
        q: queue.Queue = queue.Queue()
        stop = threading.Event()
        th = self._start(kw, q.put, stop)
        try:
            while True:
                item, last = _unpack(*q.get())
                yield item
                if last:
                    return
        finally:
            self._stop_stream(stop, th)
            th.join(STREAM_JOIN_s)

    async def astream(self, **kw: Any) -> AsyncIterator[StreamItem]:
        """:meth:`stream` for asyncio: ``async for event in probe.astream(...)``; the loop stays free."""
        loop = asyncio.get_running_loop()
        q: asyncio.Queue = asyncio.Queue()
        stop = threading.Event()
        th = self._start(kw, lambda item: loop.call_soon_threadsafe(q.put_nowait, item), stop)
        try:
            while True:
                item, last = _unpack(*await q.get())
                yield item
                if last:
                    return
        finally:
            self._stop_stream(stop, th)
            await asyncio.to_thread(th.join, STREAM_JOIN_s)

    def _stop_stream(self, stop: threading.Event, th: threading.Thread) -> None:
        """The consumer left: if the touch still runs, cut it now (its thread then gets the aborted record)."""
        stop.set()
        if th.is_alive():
            try:
                self.client.send_abort()
            except ClientError:
                pass  # the port is gone: so is the touch's host, and the device's watchdogs stay

    def _start(self, kw: dict[str, Any], put: Any, stop: threading.Event) -> threading.Thread:
        args = self._measure_args(kw)
        device_id = self.device_id  # asked before the touch: the link is busy during it

        def on_event(event: Event) -> None:
            if not stop.is_set():
                put(("event", typed_event(event)))

        def run() -> None:
            try:
                rec = self.client.measure(on_event=on_event, **args)
                put(("end", Measurement.from_record(rec, device_id)))
            except BaseException as e:  # handed to the consumer
                put(("error", e))

        th = threading.Thread(target=run, name="thermotouch-stream", daemon=True)
        th.start()
        return th

    def abort(self) -> dict[str, Any]:
        """Cut a running touch (from another thread): heater off, record stored as ``aborted``."""
        return self.client.abort()

    # -- stored results -----------------------------------------------------------------------
    def result(self, measurement_id: int | None = None) -> Measurement:
        """A stored touch by id (default: the latest)."""
        return Measurement.from_record(self.client.result(measurement_id), self.device_id)

    def history(self, offset: int = 0, limit: int = 20) -> list[Measurement]:
        """Stored touches, newest first (summaries: ``record`` has no candidates or sensor-chain detail)."""
        page = self.client.history(offset, limit)
        return [Measurement.from_record(item, self.device_id) for item in page["items"]]

    def series(self, measurement_id: int) -> dict[str, Any]:
        """A stored touch's raw and resampled series as arrays (:meth:`DeviceClient.series`)."""
        return self.client.series(measurement_id)

    # -- calibration -----------------------------------------------------------------------------
    def calibration(self) -> dict[str, Any]:
        """The installed calibration: ``calibrated``, ``sha256``, ``calibration`` (text), ``signed_by``."""
        return self.client.request(Command.CALIBRATION_GET)

    def install_calibration(self, text: str, signature: str | None = None) -> dict[str, Any]:
        """Install a calibration file's text (``thermotouch calibrate --out``); later touches use it."""
        args = {"calibration": text} if signature is None else {"calibration": text, "signature": signature}
        return self.client.request(Command.CALIBRATION_SET, args)
