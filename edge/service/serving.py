"""The daemon's serve loop: requests read while a measurement runs in a worker thread, ABORT, the trigger button.

While a measurement runs, STATUS, PING and ABORT (:data:`ANSWERED_WHILE_MEASURING`) are answered
and every other request gets ERROR ``BUSY``; the MEASURE reply is sent with its request's id when
the measurement ends (see :mod:`edge.service.daemon`).
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

from edge.hw.drivers.heater import HeaterError
from edge.protocol.commands import Command
from edge.protocol.endpoint import SerialEndpoint
from edge.protocol.errors import CommandError, ErrorCode
from edge.protocol.messages import Request
from edge.service.status_commands import State
from edge.service.worker import measurement_budget_s

__all__ = [
    "ANSWERED_WHILE_MEASURING", "ABORT_WAIT_s", "Serving",
]

log = logging.getLogger("thermotouch.edge")

#: Requests answered while a measurement runs (everything else gets BUSY).
ANSWERED_WHILE_MEASURING = frozenset({Command.STATUS, Command.PING, Command.ABORT})
#: Longest ABORT waits for the aborted measurement to be stored, s.
ABORT_WAIT_s = 10.0


class Serving:
    """Serving a serial link: dispatch, the measurement worker, ABORT, the trigger button, waking and stopping.

    Mixed into :class:`edge.service.daemon.Daemon`, whose constructor sets the attributes used
    here; the methods are the daemon's own (``self`` is the daemon).
    """

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
            # A streaming MEASURE's events go to this link with its id (edge.service.events).
            self._event_link = (endpoint, req.request_id) if req.args.get("stream") else None
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
              ready: Callable[[Any], None] | None = None) -> None:
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
                    self.notifier.beat("serve")  # per request: a burst of requests is not one long turn
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
