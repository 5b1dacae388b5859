"""The daemon's measurement worker: one measurement at a time in a thread, so the serve loop keeps answering.

The serve loop starts the worker for a MEASURE request or a press of the
trigger button and, while :attr:`MeasurementWorker.busy` is set, answers
STATUS and PING only. On the way out it joins the worker within a budget
that covers a whole measurement, and stops it through the daemon's stop
event (which the heater watchdog and the sequence watch) when told to
abort or when the budget runs out.
"""

from __future__ import annotations

import logging
import threading
from typing import Any, Callable

__all__ = ["WORKER_JOIN_s", "measurement_budget_s", "MeasurementWorker"]

log = logging.getLogger("thermotouch.edge")

#: Longest wait for a running measurement when serve() ends, s, before it is stopped.
WORKER_JOIN_s = 60.0  # margin for estimation and storage beyond a measurement's own phases


def measurement_budget_s(measurement: Any, heater: Any) -> float:
    """Longest a healthy measurement can take: baseline (or arming and settling) + heating limit + cooldown + a margin.

    Parameters
    ----------
    measurement, heater : namespace
        The ``[measurement]`` and ``[heater]`` configuration sections.

    Returns
    -------
    float
        Seconds.
    """
    # A MEASURE may arm for up to the protocol's bound (edge.protocol.commands: MAX_ARM_s) whatever the config says.
    from edge.protocol.commands import MAX_ARM_s, MAX_SETTLE_s  # noqa: PLC0415

    arming = max(measurement.arm_s, MAX_ARM_s) + max(measurement.settle_s, MAX_SETTLE_s)
    return measurement.baseline_s + arming + heater.max_on_time_s + measurement.cooldown_s + WORKER_JOIN_s


class MeasurementWorker:
    """Runs one job at a time in a daemon thread and tracks whether one is requested or running.

    Parameters
    ----------
    stop_event : threading.Event
        The daemon's stop event; :meth:`join` sets it to stop a running job.
    """

    def __init__(self, stop_event: threading.Event) -> None:
        self.stop_event = stop_event
        self._thread: threading.Thread | None = None
        self._busy = threading.Event()  # set while a measurement is requested or running

    @property
    def busy(self) -> bool:
        """Whether a job is running (it may still be sending its reply)."""
        return self._busy.is_set()

    def release(self) -> None:
        """Mark the job done before it returns (e.g. before its reply goes out).

        A host that reads the MEASURE reply and asks again at once must not
        be refused BUSY by a worker that is only unwinding.
        """
        self._busy.clear()

    def start(self, fn: Callable[[], None], name: str) -> None:
        """Run ``fn`` in a new thread named ``thermotouch-<name>``; its exceptions are logged, not raised."""
        def run() -> None:
            try:
                fn()
            except Exception:  # e.g. the reply cannot be written: the host went away (the record is stored)
                log.exception("%s failed", name)
            finally:
                self._busy.clear()

        self._busy.set()
        self._thread = threading.Thread(target=run, name=f"thermotouch-{name}", daemon=True)
        self._thread.start()

    def join(self, *, abort: bool, timeout_s: float) -> None:
        """Wait for the job; ``abort`` (or a timeout) stops it through the stop event.

        Without ``abort`` (a lost port) the job may be in its cooldown, so
        the caller's ``timeout_s`` should cover a whole measurement
        (:func:`measurement_budget_s`) before the job is stopped.
        """
        w = self._thread
        if w is None:
            return
        if abort:
            self.stop_event.set()
        w.join(timeout_s)
        if w.is_alive():
            log.error("measurement worker still running after %.0f s: stopping it", timeout_s)
            self.stop_event.set()
            w.join(timeout_s)
        if not w.is_alive():
            self._thread = None
