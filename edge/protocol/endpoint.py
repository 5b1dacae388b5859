"""Device-side serial transport: turn a byte stream into requests and back.

:class:`SerialEndpoint` wraps a pyserial-like object (``read(n)``,
``write(b)``, a settable ``timeout`` and optionally ``in_waiting``), decodes
request frames, answers malformed ones with ERROR replies by itself, and
hands valid :class:`~edge.protocol.messages.Request` objects to the caller.  The
daemon supplies the dispatching as ``handler(request) -> dict``::

    endpoint = SerialEndpoint(serial.Serial("/dev/ttyAMA0", 115200))
    endpoint.serve(handler, stop_event)

Handler failures never end the loop: :class:`~edge.protocol.messages.CommandError`
(and its subclass ``ProtocolError``) becomes an ERROR reply with its code,
any other exception an ``INTERNAL`` ERROR reply.

A host that stops reading must not wedge the device: replies are queued
(at most ``max_pending_bytes``) and written by a writer thread, each within
``write_timeout_s``. A reply that does not fit the queue, or cannot be
written in time, is dropped with one log line; the serve loop itself never
blocks on the port's output, so it keeps reading requests, answering STATUS
and noticing its stop event.

Events (a streaming MEASURE's EVENT frames, :meth:`SerialEndpoint.send_event`) share that queue, so
they reach the host in order before the reply, but under a tighter bound: an event is queued only
while the queue holds at most ``max_event_bytes`` (default :data:`EVENT_QUEUE_SHARE` of ``max_pending_bytes``), so
replies always find room; an event the port does not take in time drops the events queued behind
it too. Dropped events are counted (:attr:`SerialEndpoint.events_dropped`), never retried: a slow
or gone host loses events, not the touch or its reply.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from typing import Any, Callable, Iterator, Mapping

from edge.protocol.frame import DEFAULT_MAX_PAYLOAD, FrameDecoder, DecoderStats
from edge.protocol.errors import CommandError, ErrorCode, ProtocolError
from edge.protocol.messages import Request, decode_request, encode_error, encode_event, encode_reply

__all__ = ["SerialEndpoint", "Handler", "WRITE_TIMEOUT_s", "MAX_PENDING_BYTES", "MAX_EVENT_BYTES"]

#: Longest one reply may take to be written before it is dropped, s.
WRITE_TIMEOUT_s = 0.5
#: Most reply bytes queued for the port; replies beyond it are dropped.
MAX_PENDING_BYTES = 64 * 1024
#: Share of the queue events may fill (the rest is kept for replies).
EVENT_QUEUE_SHARE = 0.25
#: Most queued bytes under which an event is still queued, at the default queue bound.
MAX_EVENT_BYTES = int(MAX_PENDING_BYTES * EVENT_QUEUE_SHARE)

log = logging.getLogger(__name__)

#: ``handler(request)`` returns the reply body (a JSON-able dict) or None for ``{}``.
Handler = Callable[[Request], "Mapping[str, Any] | None"]


def read_available(ser) -> bytes:
    """One blocking read (up to the port's timeout), then whatever else is already waiting."""
    data = ser.read(1)
    if data:
        waiting = getattr(ser, "in_waiting", 0)
        if waiting:
            data += ser.read(waiting)
    return data


class SerialEndpoint:
    """Request/reply endpoint on the device side of a serial line.

    Parameters
    ----------
    ser : serial.Serial-like
        Open port.  Its ``timeout`` is set to ``poll_s`` so that loops notice
        ``stop_event`` promptly.
    max_payload : int
        Payload bound for received and sent frames, bytes.
    partial_timeout_s : float
        An unfinished frame older than this (s since its last byte) is
        discarded, so a half-sent frame cannot swallow the next request.
    poll_s : float
        Read timeout per poll, s.
    validate_replies : bool
        Check handler replies against the command's reply schema; a
        violation is sent as an INTERNAL error naming the field.
    clock : callable
        Monotonic time source in seconds (wall time: serial I/O is real even
        under the simulator's virtual clock).
    write_timeout_s : float
        Longest one reply may take to be written (the port's ``write_timeout``
        is set to it); a reply not written by then is dropped.
    max_pending_bytes : int
        Bound on reply bytes waiting for the port; a reply that would exceed
        it is dropped at once.
    max_event_bytes : int
        An event is queued only if the queue then holds at most this many bytes.
    """

    def __init__(self, ser: Any, *, max_payload: int = DEFAULT_MAX_PAYLOAD,
                 partial_timeout_s: float = 0.5, poll_s: float = 0.05,
                 validate_replies: bool = True,
                 clock: Callable[[], float] = time.monotonic,
                 write_timeout_s: float = WRITE_TIMEOUT_s,
                 max_pending_bytes: int = MAX_PENDING_BYTES, max_event_bytes: int | None = None) -> None:
        if not partial_timeout_s > 0:
            raise ValueError(f"partial_timeout_s must be > 0, got {partial_timeout_s!r}")
        if not poll_s > 0:
            raise ValueError(f"poll_s must be > 0, got {poll_s!r}")
        if not write_timeout_s > 0:
            raise ValueError(f"write_timeout_s must be > 0, got {write_timeout_s!r}")
        if not max_pending_bytes > 0:
            raise ValueError(f"max_pending_bytes must be > 0, got {max_pending_bytes!r}")
        self.ser = ser
        self.max_payload = max_payload
        self.decoder = FrameDecoder(max_payload)
        self.partial_timeout_s = float(partial_timeout_s)
        self.poll_s = float(poll_s)
        self.validate_replies = validate_replies
        self._clock = clock
        self._last_rx = clock()
        self._write_lock = threading.Lock()
        self.requests_handled = 0
        self.errors_sent = 0
        self.write_timeout_s = float(write_timeout_s)
        self.max_pending_bytes = int(max_pending_bytes)
        #: Replies dropped because the queue was full or the port did not take them in time.
        self.replies_dropped = 0
        self.max_event_bytes = int(self.max_pending_bytes * EVENT_QUEUE_SHARE if max_event_bytes is None
                                   else max_event_bytes)
        #: Events queued for the port, and events dropped (queue over its event bound, or not written in time).
        self.events_sent = 0
        self.events_dropped = 0
        # (frame bytes, is_event)
        self._queue: collections.deque[tuple[bytes, bool]] = collections.deque()
        self._queued_bytes = 0
        self._cond = threading.Condition()
        self._writing = False
        self._closed = False
        self._writer: threading.Thread | None = None
        #: A port error met by the writer thread (re-raised by the next poll()).
        self.write_error: BaseException | None = None
        try:
            ser.timeout = self.poll_s
        except (AttributeError, ValueError):
            log.debug("port %r has no settable timeout; polling with its own", ser)
        try:
            ser.write_timeout = self.write_timeout_s
        except (AttributeError, ValueError):
            log.debug("port %r has no settable write_timeout", ser)

    @property
    def stats(self) -> DecoderStats:
        """The decoder's counters (frames, bytes dropped, CRC errors, ...)."""
        return self.decoder.stats

    # -- receiving -----------------------------------------------------------

    def _read_available(self) -> bytes:
        return read_available(self.ser)

    def wake(self) -> None:
        """Cut short a :meth:`poll` waiting for bytes (from another thread), if the port can.

        pyserial's POSIX ports wake a blocked read through ``cancel_read``; a
        port without it is simply polled again within ``poll_s``. Used when a
        stop is requested from another thread, so that stopping costs no
        read timeout.
        """
        cancel = getattr(self.ser, "cancel_read", None)
        if cancel is None:
            return
        try:
            cancel()
        except (OSError, ValueError):
            pass  # the port is closing or closed: the loop ends on its own

    def poll(self) -> list[Request]:
        """Read once (waiting at most ``poll_s``); return the valid requests received.

        Frames that decode but fail validation are answered here with an
        ERROR reply and not returned. A port error met by the writer thread
        is raised here.
        """
        err, self.write_error = self.write_error, None
        if err is not None:
            raise err
        data = self._read_available()
        now = self._clock()
        if data:
            if self.decoder.pending and now - self._last_rx > self.partial_timeout_s:
                self._drop_partial()
            self._last_rx = now
            frames = self.decoder.feed(data)
        else:
            if self.decoder.pending and now - self._last_rx > self.partial_timeout_s:
                self._drop_partial()
            return []
        requests = []
        for frame in frames:
            try:
                requests.append(decode_request(frame))
            except ProtocolError as exc:
                log.info("rejected frame id=%d: %s", frame.request_id, exc)
                self.send_error(frame.request_id, exc.code, exc.message, exc.field)
        return requests

    def _drop_partial(self) -> None:
        dropped = self.decoder.discard_partial()
        log.info("discarded %d bytes of a partial frame after %.3f s silence",
                 dropped, self.partial_timeout_s)

    def requests(self, stop_event: threading.Event | None = None) -> Iterator[Request]:
        """Yield valid requests until ``stop_event`` is set (forever if None)."""
        while stop_event is None or not stop_event.is_set():
            yield from self.poll()

    # -- sending ---------------------------------------------------------------

    def _write(self, data: bytes, event: bool = False) -> bool:
        """Queue ``data`` for the writer thread; drop it if the queue is full. True if queued."""
        with self._cond:
            if self._closed:
                self._dropped(len(data), "the endpoint is closed", event)
                return False
            bound = self.max_event_bytes if event else self.max_pending_bytes
            if self._queued_bytes + len(data) > bound:
                self._dropped(len(data), f"{self._queued_bytes} B already wait for a host that is not reading", event)
                return False
            if event:
                self.events_sent += 1
            self._queue.append((data, event))
            self._queued_bytes += len(data)
            if self._writer is None:
                self._writer = threading.Thread(target=self._write_loop, name="thermotouch-serial-writer",
                                                daemon=True)
                self._writer.start()
            self._cond.notify_all()
        return True

    def _drop_event(self, n: int, why: str) -> None:
        # Events are best effort and may come by the hundred: counted, logged at DEBUG only.
        self.events_dropped += 1
        log.debug("event of %d B dropped (%s); %d dropped so far", n, why, self.events_dropped)

    def _dropped(self, n: int, why: str, event: bool) -> None:
        (self._drop_event if event else self._drop)(n, why)

    def _drop(self, n: int, why: str) -> None:
        self.replies_dropped += 1
        # One line per dropped reply; DEBUG after the first few so a flood cannot fill the log.
        level = logging.WARNING if self.replies_dropped <= 3 or self.replies_dropped % 1000 == 0 else logging.DEBUG
        log.log(level, "reply of %d B dropped (%s); %d dropped so far", n, why, self.replies_dropped)

    def _write_loop(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._closed:
                    self._cond.wait()
                if not self._queue:
                    return
                data, event = self._queue.popleft()
                self._queued_bytes -= len(data)
                self._writing = True
            try:
                if not self._write_now(data, event) and event:
                    self._drop_queued_events()
            except BaseException as e:  # a port error: the serve loop re-raises it
                self.write_error = e
                with self._cond:
                    self._queue.clear()
                    self._queued_bytes = 0
            finally:
                with self._cond:
                    self._writing = False
                    self._cond.notify_all()

    def _drop_queued_events(self) -> None:
        """An event was not taken in time: the host is slow or gone, so the events behind it go too."""
        with self._cond:
            keep = collections.deque(item for item in self._queue if not item[1])
            for data, _ in (item for item in self._queue if item[1]):
                self._queued_bytes -= len(data)
                self._drop_event(len(data), "an earlier event was not taken in time")
            self._queue = keep

    def _write_now(self, data: bytes, event: bool = False) -> bool:
        # No flush(): pyserial writes straight to the fd, and tcdrain() on a line whose host
        # does not read would block without any timeout -- the very wedge this avoids.
        with self._write_lock:
            try:
                n = self.ser.write(data)
            except Exception as e:
                # pyserial's SerialTimeoutException: the host is not reading; anything else propagates.
                if type(e).__name__ != "SerialTimeoutException" and not isinstance(e, TimeoutError):
                    raise
                self._dropped(len(data), f"not written within {self.write_timeout_s:g} s", event)
                return False
            if isinstance(n, int) and n < len(data):
                self._dropped(len(data), f"only {n} B written", event)
                return False
            return True

    def flush(self, timeout_s: float | None = None) -> bool:
        """Wait until every queued reply is written or dropped; True if the queue is empty.

        Waits at most ``timeout_s`` (default: ``write_timeout_s`` per queued reply, at most 2 s).
        """
        deadline = time.monotonic() + (min(2.0, self.write_timeout_s * (len(self._queue) + 1))
                                       if timeout_s is None else timeout_s)
        with self._cond:
            while self._queue or self._writing:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
        return True

    def close(self, timeout_s: float | None = None) -> None:
        """Write what is queued (within ``timeout_s``, see :meth:`flush`), then stop the writer thread.

        Replies still queued after that are dropped; the port itself is not closed.
        """
        self.flush(timeout_s)
        with self._cond:
            self._closed = True
            for data, event in self._queue:
                self._dropped(len(data), "the endpoint is closing", event)
            self._queue.clear()
            self._queued_bytes = 0
            self._cond.notify_all()
            writer = self._writer
        if writer is not None:
            writer.join(self.write_timeout_s + 0.5)

    def send_reply(self, request: Request, body: Mapping[str, Any] | None = None) -> None:
        """Send a successful reply to ``request``.

        Raises
        ------
        ProtocolError
            If ``body`` violates the reply schema or is too large (nothing is sent).
        """
        frame = encode_reply(request.command, request.request_id, body,
                             max_payload=self.max_payload, validate=self.validate_replies)
        self._write(frame)

    def send_event(self, request_id: int, body: Mapping[str, Any], *, final: bool = False) -> bool:
        """Queue an EVENT frame for ``request_id`` (best effort: False if it was dropped).

        Never blocks on the port. A ``final`` event (one per request, e.g. ``done`` with the drop
        count) is queued under the replies' bound, so a host that lost events learns how many.
        A body that breaks the event schema raises ProtocolError (nothing is sent).
        """
        frame = encode_event(request_id, body, max_payload=self.max_payload)
        if final:
            self.events_sent += 1
            return self._write(frame)
        return self._write(frame, event=True)

    def send_error(self, request_id: int, code: ErrorCode, message: str, field: str | None = None) -> None:
        """Send an ERROR reply addressed to ``request_id``."""
        frame = encode_error(request_id, code, message, field, max_payload=self.max_payload)
        self.errors_sent += 1
        self._write(frame)

    def handle(self, request: Request, handler: Handler) -> None:
        """Run ``handler`` on ``request`` and send its reply or an ERROR reply.

        Never raises for handler failures; I/O errors of the port do propagate.
        """
        try:
            body = handler(request)
        except CommandError as exc:
            log.info("%s id=%d failed: %s", request.command.name, request.request_id, exc)
            self.send_error(request.request_id, exc.code, exc.message, exc.field)
            return
        except Exception as exc:  # the loop must survive any handler bug
            log.exception("%s id=%d: handler raised", request.command.name, request.request_id)
            self.send_error(request.request_id, ErrorCode.INTERNAL, f"{type(exc).__name__}: {exc}")
            return
        try:
            frame = encode_reply(request.command, request.request_id, body,
                                 max_payload=self.max_payload, validate=self.validate_replies)
        except ProtocolError as exc:
            # The handler's reply breaks the schema or the size bound: a
            # device bug, reported as INTERNAL so the host sees which field.
            log.error("%s id=%d: bad reply: %s", request.command.name, request.request_id, exc)
            self.send_error(request.request_id, ErrorCode.INTERNAL, f"bad reply: {exc.message}", exc.field)
            return
        except Exception as exc:
            log.exception("%s id=%d: cannot encode reply", request.command.name, request.request_id)
            self.send_error(request.request_id, ErrorCode.INTERNAL, f"bad reply: {type(exc).__name__}: {exc}")
            return
        self.requests_handled += 1
        self._write(frame)

    def serve(self, handler: Handler, stop_event: threading.Event) -> None:
        """Answer requests with ``handler`` until ``stop_event`` is set.

        Requests are handled one at a time in arrival order.  Returns within
        about ``poll_s`` of ``stop_event`` being set (plus the running
        handler's duration).  Port errors (e.g. ``serial.SerialException``)
        propagate to the caller.
        """
        try:
            for request in self.requests(stop_event):
                self.handle(request, handler)
                if stop_event.is_set():
                    break
        finally:
            self.close()
