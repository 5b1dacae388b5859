"""Host-side client for a ThermoTouch probe on a serial port.

::

    with DeviceClient("/dev/ttyACM0") as dev:
        print(dev.info())
        record = dev.measure(power_W=0.5, contact_time_s=2.0)
        series = dev.series(record["measurement_id"])   # raw and resampled arrays

Requests carry incrementing request ids; replies are matched by id and stale
replies (to earlier, timed-out requests) are dropped.  Idempotent commands
are resent after a timeout (``retries`` times) with the *same* id, so a late
reply to the first attempt still counts.  Failures raise:

* :class:`PortUnavailable` - the port does not exist, is locked by another
  process, or vanished;
* :class:`DeviceNotAnswering` - no matching reply within the timeout;
* :class:`DeviceError` - the device answered with an ERROR reply;
* :class:`BadReply` - the device answered with something that breaks the protocol.
"""

from __future__ import annotations

import errno
import hashlib
import threading
import time
from typing import Any, Callable, Mapping

import numpy as np
import serial

from edge.protocol.endpoint import read_available
from edge.protocol.messages import (
    CHUNK_HEADER_SIZE,
    SESSION_CHUNK_HEADER_SIZE,
    ErrorReply,
    Event,
    decode_event,
    decode_reply,
    encode_request,
    is_event,
)
from edge.protocol.commands import COMMANDS, Command, SERIES_KINDS
from edge.protocol.frame import DEFAULT_MAX_PAYLOAD, FrameDecoder
from edge.protocol.errors import ErrorCode, ProtocolError

__all__ = [
    "ClientError", "PortUnavailable", "DeviceNotAnswering", "DeviceError", "BadReply",
    "DeviceClient",
]


class ClientError(Exception):
    """Base of the client's exceptions."""


class PortUnavailable(ClientError):
    """The serial port cannot be used (no such port, busy, or gone)."""

    def __init__(self, port: str, reason: str) -> None:
        self.port = port
        self.reason = reason
        super().__init__(f"serial port {port!r} unavailable: {reason}")


class DeviceNotAnswering(ClientError):
    """No reply to a request within the timeout, after all attempts."""

    def __init__(self, command: Command, timeout_s: float, attempts: int) -> None:
        self.command = command
        self.timeout_s = timeout_s
        self.attempts = attempts
        super().__init__(f"device did not answer {command.name} within {timeout_s:g} s "
                         f"({attempts} attempt{'s' if attempts != 1 else ''})")


class DeviceError(ClientError):
    """The device answered with an ERROR reply."""

    def __init__(self, code: ErrorCode, message: str, field: str | None = None,
                 command: Command | None = None) -> None:
        self.code = code
        self.message = message
        self.field = field
        self.command = command
        where = f"{command.name}: " if command is not None else ""
        extra = f" (field {field!r})" if field else ""
        super().__init__(f"{where}device error {code.name}: {message}{extra}")


class BadReply(ClientError):
    """A reply with the right id that breaks the protocol (schema, JSON, type)."""


#: Requests that name the upload session from MODEL_BEGIN.
_SESSION_COMMANDS = frozenset({Command.MODEL_CHUNK, Command.MODEL_COMMIT, Command.MODEL_ABORT})
#: Longest wait for the device to confirm an ABORT, s, over all attempts. The device replies once
#: the heater is off and the record stored (one sample period plus an fsync); a lost frame is
#: resent, but a device that is gone must not hold a Ctrl-C for long.
ABORT_TIMEOUT_s = 6.0
#: Attempts the ABORT deadline is split into.
ABORT_ATTEMPTS = 3


try:
    import termios
    _TTY_ERRORS: tuple[type[BaseException], ...] = (termios.error,)
except ImportError:  # no termios (Windows): pyserial raises SerialException there
    _TTY_ERRORS = ()

#: Attempts of one terminal call interrupted by signals before the port is called unusable.
TTY_EINTR_ATTEMPTS = 20


def _tty_call(fn: Callable[[], Any], port: str) -> Any:
    """Run a pyserial call that ends in a termios call (``flush`` is tcdrain, ``reset_input_buffer`` tcflush).

    Python retries system calls a signal interrupts (PEP 475), but not the termios module's:
    a signal arriving while the line drains (SIGWINCH when the user resizes the terminal,
    SIGCHLD) raises ``termios.error(EINTR)``, which is not an OSError, and used to end the
    command as an internal error. An interrupted call is repeated; any other termios failure
    means the port is unusable.
    """
    for _ in range(TTY_EINTR_ATTEMPTS):
        try:
            return fn()
        except _TTY_ERRORS as exc:
            if exc.args and exc.args[0] == errno.EINTR:
                continue
            raise PortUnavailable(port, f"terminal call failed: {exc}") from exc
    raise PortUnavailable(port, f"terminal call interrupted by signals {TTY_EINTR_ATTEMPTS} times in a row")


def _port_name(ser: Any) -> str:
    return str(getattr(ser, "port", None) or getattr(ser, "name", None) or ser)


class DeviceClient:
    """Request/reply client for the probe's serial protocol.

    Parameters
    ----------
    port_or_serial : str or serial.Serial-like
        A device path (``/dev/ttyACM0``), a pyserial URL (``loop://``,
        ``socket://host:port``, ``rfc2217://...``), or an already open
        pyserial-like object (then the client does not own it unless
        ``own=True``).
    timeout_s : float
        Per-attempt reply timeout, s.
    retries : int
        Extra attempts for idempotent commands after a timeout.
    baudrate : int
        Line rate when opening a port by name (ignored by ptys).
    max_payload : int
        Payload bound, bytes; must not exceed the device's.
    poll_s : float
        Read timeout per poll, s (the port's ``timeout`` is set to this).
    abort_timeout_s : float
        Longest wait for an ABORT's confirmation over all its attempts, s.
    """

    def __init__(self, port_or_serial: Any, timeout_s: float = 2.0, *, retries: int = 1,
                 baudrate: int = 115200, max_payload: int = DEFAULT_MAX_PAYLOAD,
                 poll_s: float = 0.02, own: bool | None = None,
                 abort_timeout_s: float = ABORT_TIMEOUT_s) -> None:
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be > 0, got {timeout_s!r}")
        if not abort_timeout_s > 0:
            raise ValueError(f"abort_timeout_s must be > 0, got {abort_timeout_s!r}")
        self.abort_timeout_s = float(abort_timeout_s)
        if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
            raise ValueError(f"retries must be an int >= 0, got {retries!r}")
        self.timeout_s = float(timeout_s)
        self.retries = retries
        self.max_payload = max_payload
        self.poll_s = float(poll_s)
        if isinstance(port_or_serial, (str, bytes)):
            port = port_or_serial.decode() if isinstance(port_or_serial, bytes) else port_or_serial
            self.port = port
            self.ser = self._open(port, baudrate)
            self._own = True if own is None else own
        else:
            self.ser = port_or_serial
            self.port = _port_name(port_or_serial)
            self._own = False if own is None else own
        try:
            self.ser.timeout = self.poll_s
        except (AttributeError, ValueError):
            pass
        self.decoder = FrameDecoder(max_payload)
        self._next_id = 1
        self._lock = threading.Lock()
        self._id_lock = threading.Lock()  # request ids are also taken by send_abort() from another thread
        self.stale_replies = 0
        #: EVENT frames received for the running request (given to its ``on_event``), and those that
        #: broke the event schema or came with no one listening (ignored: events are best effort).
        self.events_received = 0
        self.events_ignored = 0
        self._on_event: Callable[[Event], None] | None = None
        #: Session id of this client's last MODEL_BEGIN (None before one, or from a device without sessions).
        self.upload_session: int | None = None
        # Bytes the device sent before we were listening belong to nobody.
        reset = getattr(self.ser, "reset_input_buffer", None)
        if reset is not None:
            try:
                _tty_call(reset, self.port)
            except (serial.SerialException, OSError) as exc:
                raise PortUnavailable(self.port, str(exc)) from exc

    def _open(self, port: str, baudrate: int) -> Any:
        try:
            if "://" in port:
                return serial.serial_for_url(port, baudrate=baudrate, timeout=self.poll_s)
            # exclusive=True: a second client on the same port fails loudly
            # instead of stealing half the replies.
            return serial.Serial(port, baudrate=baudrate, timeout=self.poll_s, exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise PortUnavailable(port, str(exc)) from exc

    # -- lifecycle -----------------------------------------------------------

    def close(self) -> None:
        """Close the port if the client opened it."""
        if self._own and self.ser is not None:
            try:
                self.ser.close()
            finally:
                self._own = False

    def __enter__(self) -> "DeviceClient":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- core request/reply ------------------------------------------------------

    def _new_id(self) -> int:
        rid = self._next_id
        # Wrap within u32, skipping 0 (reserved for unattributed errors).
        self._next_id = rid % 0xFFFFFFFF + 1
        return rid

    def _read_available(self) -> bytes:
        return read_available(self.ser)

    def request(self, command: Command | str, args: Mapping[str, Any] | None = None, *,
                timeout_s: float | None = None, retries: int | None = None,
                on_event: Callable[[Event], None] | None = None) -> dict[str, Any]:
        """Send one request and return the reply body.

        Parameters
        ----------
        command : Command or str
            Command (enum or name, e.g. ``"INFO"``).
        args : mapping, optional
            Arguments per :data:`edge.protocol.commands.COMMANDS`; validated before sending.
        timeout_s : float, optional
            Per-attempt timeout, s (default: the client's).
        retries : int, optional
            Extra attempts after a timeout (default: the client's, and 0 for
            non-idempotent commands such as MEASURE).
        on_event : callable, optional
            Called with each :class:`~edge.protocol.messages.Event` the device pushes for this
            request (a MEASURE with ``stream``) while the reply is awaited; an exception it raises
            propagates (the request is then abandoned: a MEASURE's caller should ABORT).

        Raises
        ------
        ProtocolError
            If ``args`` are invalid (nothing is sent).
        DeviceError, DeviceNotAnswering, PortUnavailable, BadReply
        """
        command = Command[command.upper()] if isinstance(command, str) else Command(command)
        if command in _SESSION_COMMANDS and self.upload_session is not None and "session" not in (args or {}):
            # The upload session this client opened: the device refuses MODEL_* without it.
            args = {**(args or {}), "session": self.upload_session}
        timeout = self.timeout_s if timeout_s is None else float(timeout_s)
        if retries is None:
            retries = self.retries if COMMANDS[command].idempotent else 0
        with self._lock:
            with self._id_lock:
                rid = self._new_id()
            frame = encode_request(command, rid, args, max_payload=self.max_payload)
            attempts = 0
            for _ in range(retries + 1):
                attempts += 1
                self._write(frame)
                self._on_event = on_event  # read by _await while this request's reply is awaited
                try:
                    reply = self._await(rid, command, timeout)
                finally:
                    self._on_event = None
                if reply is not None:
                    if command == Command.MODEL_BEGIN:
                        self.upload_session = reply.get("session")
                    return reply
            raise DeviceNotAnswering(command, timeout, attempts)

    def _write(self, data: bytes) -> None:
        try:
            self.ser.write(data)
            flush = getattr(self.ser, "flush", None)
            if flush is not None:
                _tty_call(flush, self.port)
        except (serial.SerialException, OSError) as exc:
            raise PortUnavailable(self.port, f"write failed: {exc}") from exc

    def _await(self, rid: int, command: Command, timeout_s: float) -> dict[str, Any] | None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                data = self._read_available()
            except (serial.SerialException, OSError) as exc:
                raise PortUnavailable(self.port, f"read failed: {exc}") from exc
            if not data:
                continue
            for frame in self.decoder.feed(data):
                if is_event(frame):
                    self._event(frame, rid, self._on_event)
                    continue
                if frame.request_id != rid:
                    self.stale_replies += 1
                    continue
                try:
                    reply = decode_reply(frame)
                except ProtocolError as exc:
                    raise BadReply(f"{command.name} reply: {exc}") from exc
                if isinstance(reply, ErrorReply):
                    raise DeviceError(reply.code, reply.message, reply.field, command)
                if reply.command != command:
                    raise BadReply(f"reply id {rid} is for {reply.command.name}, expected {command.name}")
                return reply.body
        # A reply cut off mid-frame must not glue onto the next one.
        self.decoder.discard_partial()
        return None

    def _event(self, frame: Any, rid: int, on_event: Callable[[Event], None] | None) -> None:
        if frame.request_id != rid or on_event is None:
            self.events_ignored += 1  # an earlier request's, or nobody asked
            return
        try:
            event = decode_event(frame)
        except ProtocolError:
            self.events_ignored += 1  # best effort: a bad event is no reason to lose the reply
            return
        self.events_received += 1
        on_event(event)

    # -- convenience -------------------------------------------------------------

    def ping(self, echo: str | None = None) -> dict[str, Any]:
        """Liveness check; returns ``{"echo": ...}``."""
        return self.request(Command.PING, {} if echo is None else {"echo": echo})

    def info(self) -> dict[str, Any]:
        """Firmware/model versions, model sha256, board, protocol version."""
        return self.request(Command.INFO)

    def status(self) -> dict[str, Any]:
        """Device state (``state`` plus free-form fields)."""
        return self.request(Command.STATUS)

    def measure(self, power_W: float | None = None, voltage_V: float | None = None,
                contact_time_s: float | None = None, *, timeout_s: float | None = None,
                sample_rate_Hz: float | None = None, until_decided: bool = False, arm_s: float | None = None,
                settle_s: float | None = None,
                on_event: Callable[[Event], None] | None = None) -> dict[str, Any]:
        """Run one measurement and return its result record (never retried).

        With ``on_event``, the device is asked to stream (MEASURE ``stream``) and each pushed
        :class:`~edge.protocol.messages.Event` (phases, sample batches, the running answer) is
        given to it as it arrives, before this returns. A device that predates events refuses
        ``stream`` before touching; the touch then runs without events.

        The default timeout is the client's plus the contact time (or 5 s)
        plus 10 s of margin for heating, settling and inference.

        Interrupted (``KeyboardInterrupt``, e.g. Ctrl-C) or timed out
        (:class:`DeviceNotAnswering`), the client does not leave the probe
        heating: it sends ABORT, waits for the device's confirmation (the
        heater is off and the aborted record stored; :attr:`last_abort`
        holds the ABORT reply, or None if the device did not confirm within
        :data:`ABORT_TIMEOUT_s`), then re-raises the original exception. A
        command-line caller maps the re-raised ``KeyboardInterrupt`` to exit
        status 130.

        Raises
        ------
        KeyboardInterrupt, DeviceNotAnswering
            After the ABORT (its own failure is not raised).
        DeviceError, PortUnavailable, BadReply
        """
        args = {k: v for k, v in (("power_W", power_W), ("voltage_V", voltage_V),
                                  ("contact_time_s", contact_time_s), ("sample_rate_Hz", sample_rate_Hz),
                                  ("arm_s", arm_s), ("settle_s", settle_s))
                if v is not None}
        if until_decided:
            args["until_decided"] = True
        if on_event is not None:
            args["stream"] = True
        if timeout_s is None:
            timeout_s = (self.timeout_s + (contact_time_s if contact_time_s is not None else 5.0) + 10.0
                         + (arm_s or 0.0) + (settle_s or 0.0))
        self.last_abort: dict[str, Any] | None = None
        try:
            try:
                return self.request(Command.MEASURE, args, timeout_s=timeout_s, on_event=on_event)
            except DeviceError as e:
                if not (on_event is not None and e.code == ErrorCode.BAD_ARGUMENT and e.field == "stream"):
                    raise
                # A device older than events refused the argument before the touch began: touch without them.
                del args["stream"]
                return self.request(Command.MEASURE, args, timeout_s=timeout_s)
        except (KeyboardInterrupt, DeviceNotAnswering):
            try:
                self.last_abort = self.abort()
            except ClientError:
                pass  # the device is gone or confused: the original exception says more
            raise

    def abort(self, *, timeout_s: float | None = None) -> dict[str, Any]:
        """Cut a running measurement: the device switches the heater off at once and stores the record.

        ``timeout_s`` (default: the client's ``abort_timeout_s``) bounds the
        whole wait: it is split into :data:`ABORT_ATTEMPTS` attempts, so a
        lost frame is resent and a dead device costs at most ``timeout_s``.

        Returns
        -------
        dict
            ``{"aborted": bool, "measurement_id": int | None}``: whether a
            measurement was running, and the id of its stored record
            (``status = "aborted"``, ``reason = "host_abort"``).
        """
        total = self.abort_timeout_s if timeout_s is None else float(timeout_s)
        return self.request(Command.ABORT, timeout_s=total / ABORT_ATTEMPTS, retries=ABORT_ATTEMPTS - 1)

    def send_abort(self) -> None:
        """Send an ABORT without waiting for its reply, from any thread (e.g. while :meth:`measure` waits).

        The device cuts the running touch at once; the waiting MEASURE then gets the aborted record
        (its ABORT reply is skipped as a stale reply). Prefer :meth:`abort` when nothing else waits.
        """
        with self._id_lock:
            rid = self._new_id()
        self._write(encode_request(Command.ABORT, rid, None, max_payload=self.max_payload))

    def result(self, measurement_id: int | None = None) -> dict[str, Any]:
        """Result record by id, or the latest when ``measurement_id`` is None."""
        return self.request(Command.RESULT, {} if measurement_id is None else {"measurement_id": measurement_id})

    def history(self, offset: int = 0, limit: int = 20) -> dict[str, Any]:
        """One page of stored results: ``{"offset", "total", "items"}``."""
        return self.request(Command.HISTORY, {"offset": offset, "limit": limit})

    def series_page(self, measurement_id: int, which: str = "raw", offset: int = 0,
                    limit: int | None = None) -> dict[str, Any]:
        """One SERIES reply: samples ``[offset, offset + len(t_s))`` of a stored series (see edge.protocol.messages)."""
        args: dict[str, Any] = {"measurement_id": measurement_id, "which": which, "offset": offset}
        if limit is not None:
            args["limit"] = limit
        return self.request(Command.SERIES, args)

    def series(self, measurement_id: int, which: str | None = None, *,
               limit: int | None = None) -> dict[str, np.ndarray | None]:
        """A stored measurement's series, paged over the link until complete.

        Parameters
        ----------
        measurement_id : int
        which : {"raw", "grid"}, optional
            Only this series (default: both).
        limit : int, optional
            Samples asked for per page (default: as many as fit in one reply).

        Returns
        -------
        dict
            The history's names: ``raw_t_s`` (s from heater on), ``raw_T_C``,
            ``raw_q_W_m2``, ``raw_T_dt_s``, ``raw_q_dt_s`` (each converter's read
            time against ``raw_t_s``) and ``grid_t_s``, ``grid_dT_K``, ``grid_q_W_m2``
            as float arrays (NaN for a sample the device sent as null); None
            for a series the device did not store. With the raw series, ``header``:
            the touch record's header the device sent (a dict), or None.

        Raises
        ------
        DeviceError
            NOT_FOUND for an unknown measurement.
        BadReply
            If the pages do not add up (offset, total or lengths inconsistent).
        """
        kinds = ("raw", "grid") if which is None else (which,)
        out: dict[str, np.ndarray | None] = {}
        for kind in kinds:
            if kind not in SERIES_KINDS:
                raise ValueError(f"which must be one of {', '.join(SERIES_KINDS)}, got {kind!r}")
            names = ("t_s", "T_C", "q_W_m2") if kind == "raw" else ("t_s", "dT_K", "q_W_m2")
            # Read times travel only when the device stored them (older devices and records: never).
            optional = ("T_dt_s", "q_dt_s") if kind == "raw" else ()
            parts: dict[str, list] = {n: [] for n in names + optional}
            offset, total = 0, None
            while total is None or offset < total:
                page = self.series_page(measurement_id, kind, offset, limit)
                if kind == "raw" and offset == 0:
                    out["header"] = page.get("header")
                if total is None:
                    optional = tuple(n for n in optional if n in page)
                if page["measurement_id"] != measurement_id or page["which"] != kind or page["offset"] != offset:
                    raise BadReply(f"SERIES page for {page['measurement_id']}/{page['which']} at "
                                   f"{page['offset']}, asked {measurement_id}/{kind} at {offset}")
                if total is not None and page["total"] != total:
                    raise BadReply(f"SERIES total changed from {total} to {page['total']}")
                total = page["total"]
                n = len(page["t_s"])
                if n == 0 and offset < total:
                    raise BadReply(f"SERIES page at {offset} of {total} is empty")
                if offset + n > total:
                    raise BadReply(f"SERIES page at {offset} runs past total {total}")
                for name in names + optional:
                    if name not in page or len(page[name]) != n:
                        raise BadReply(f"SERIES page at {offset}: column {name} does not match t_s")
                    parts[name].extend(page[name])
                offset += n
            for name in parts:
                key = f"{kind}_{name}"
                out[key] = np.array([np.nan if x is None else x for x in parts[name]], float) \
                    if total and (name in names or name in optional) else None
        return out

    def config_get(self, *keys: str) -> dict[str, Any]:
        """Configuration values (all, or only ``keys``)."""
        reply = self.request(Command.CONFIG_GET, {"keys": list(keys)} if keys else {})
        return reply["config"]

    def config_set(self, **values: Any) -> dict[str, Any]:
        """Set configuration values; returns the full configuration after the change."""
        if not values:
            raise ValueError("config_set needs at least one key=value")
        return self.request(Command.CONFIG_SET, {"values": values})["config"]

    def upload_model(self, data: bytes, sha256: str | None = None, chunk_size: int | None = None,
                     progress: Callable[[int, int], None] | None = None, *,
                     version: str | None = None, downgrade: bytes | str | None = None) -> dict[str, Any]:
        """Upload a model bundle in chunks and commit it.

        Parameters
        ----------
        data : bytes
            The whole bundle.
        sha256 : str, optional
            Expected hex digest; checked locally before sending (computed if None).
        chunk_size : int, optional
            Bytes per MODEL_CHUNK (default and maximum: ``max_payload - 4``).
        progress : callable, optional
            Called as ``progress(bytes_sent, total_bytes)`` after each chunk.
        version : str, optional
            Model version label passed to MODEL_BEGIN.
        downgrade : bytes or str, optional
            A signed downgrade authorisation (:func:`edge.security.keys.downgrade_document`) that lets the device
            install a signed bundle not newer than its active one (MODEL_BEGIN ``downgrade``).

        Returns
        -------
        dict
            The MODEL_COMMIT reply (``model_sha256`` and whatever the device adds).

        On any failure after MODEL_BEGIN the client sends MODEL_ABORT (best
        effort) and re-raises. MODEL_BEGIN's session id is carried by every
        later request of the upload (see :attr:`upload_session`); if another
        host began an upload meanwhile, the device refuses this one's chunks
        with BAD_STATE rather than mixing the two.
        """
        data = bytes(data)
        if not data:
            raise ValueError("data must not be empty")
        digest = hashlib.sha256(data).hexdigest()
        if sha256 is not None and sha256.lower() != digest:
            raise ValueError(f"sha256 {sha256!r} does not match the data (sha256 {digest})")
        max_chunk = self.max_payload - CHUNK_HEADER_SIZE
        if chunk_size is None:
            chunk_size = max_chunk
        if isinstance(chunk_size, bool) or not isinstance(chunk_size, int) or not 1 <= chunk_size <= max_chunk:
            raise ValueError(f"chunk_size must be an int in [1, {max_chunk}], got {chunk_size!r}")
        begin = {"size": len(data), "sha256": digest}
        if version is not None:
            begin["version"] = version
        if downgrade is not None:
            begin["downgrade"] = downgrade.decode("utf-8") if isinstance(downgrade, bytes) else downgrade
        self.upload_session = None
        self.request(Command.MODEL_BEGIN, begin)  # sets upload_session; later MODEL_* requests carry it
        if self.upload_session is not None:
            chunk_size = min(chunk_size, self.max_payload - SESSION_CHUNK_HEADER_SIZE)
        try:
            for offset in range(0, len(data), chunk_size):
                chunk = data[offset:offset + chunk_size]
                reply = self.request(Command.MODEL_CHUNK, {"offset": offset, "data": chunk})
                if reply["received"] != offset + len(chunk):
                    raise BadReply(f"device holds {reply['received']} B after chunk at {offset} "
                                   f"(expected {offset + len(chunk)} B)")
                if progress is not None:
                    progress(offset + len(chunk), len(data))
            result = self.request(Command.MODEL_COMMIT)
        except BaseException:
            try:
                self.request(Command.MODEL_ABORT, retries=0)
            except ClientError:
                pass
            raise
        if result["model_sha256"].lower() != digest:
            raise BadReply(f"device installed sha256 {result['model_sha256']}, expected {digest}")
        return result
