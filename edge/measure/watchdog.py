"""The heater's safety net: the limits a measurement must respect and the watchdog that enforces them.

The sampling loop in :mod:`edge.measure.sequence` stops heating on time by
itself; :class:`HeaterWatchdog` is the independent second line, for when
that loop is stuck in a driver call: a thread (and, on a clock that can
notify time steps such as the simulator's, a clock hook) cuts the heater
``guard_s`` before ``max_on_time_s`` and at once when the abort event is set.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from edge.hw.drivers.heater import Heater, HeaterOffError

__all__ = ["Limits", "Trip", "HeaterWatchdog"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Limits:
    """Safety limits: ``max_on_time_s`` (s), ``over_temperature_C`` (°C), the heater-fault
    thresholds ``fault_flux_W_m2`` (W/m^2) and ``fault_rise_K`` (K), and the duty limit: at most
    ``max_duty`` of any ``duty_window_s`` with the heater on (see ``[heater]`` in the config)."""

    max_on_time_s: float
    over_temperature_C: float
    fault_flux_W_m2: float = 150.0
    fault_rise_K: float = 0.5
    max_duty: float = 0.5
    duty_window_s: float = 60.0


class Trip(StrEnum):
    """Why the watchdog cut the heater."""

    #: The heater's on-time reached the limit (less the guard).
    MAX_ON_TIME = "max_on_time"
    #: The abort event was set.
    ABORT = "abort"


class HeaterWatchdog:
    """Cuts the heater independently of the sampling loop.

    While armed it switches the heater off when its current on-time reaches
    ``limit_s - guard_s`` or when ``abort_event`` is set. It checks from its
    own thread every ``poll_s`` of wall time and, if ``clock`` has
    ``on_advance`` (the simulator's virtual clock), on every clock step.
    Disarmed, the thread sleeps until :meth:`arm` or :meth:`close`: an idle
    device has nothing to watch, and a thread waking every ``poll_s`` takes
    the interpreter's lock from the one doing the work.

    Parameters
    ----------
    heater : Heater
    clock : Clock
    limit_s : float
        The on-time limit (s).
    abort_event : threading.Event, optional
    guard_s : float
        Margin below the limit (s) that covers the check resolution.
    poll_s : float
        Wall-clock polling period (s).
    """

    def __init__(self, heater: Heater, clock: Any, limit_s: float, *, abort_event: threading.Event | None = None,
                 guard_s: float = 0.02, poll_s: float = 0.005) -> None:
        if not limit_s > guard_s >= 0:
            raise ValueError(f"need limit_s > guard_s >= 0, got limit_s={limit_s!r} guard_s={guard_s!r}")
        self.heater = heater
        self.clock = clock
        self.limit_s = float(limit_s)
        self.guard_s = float(guard_s)
        self.poll_s = float(poll_s)
        self.abort_event = abort_event
        self._armed = False
        self._stop = threading.Event()
        self._lock = threading.Lock()
        # Wakes the thread on arm() and close() (shares the lock that guards _armed).
        self._wake = threading.Condition(self._lock)
        #: Why the watchdog last cut the heater, or None.
        self.tripped: Trip | None = None
        on_advance = getattr(clock, "on_advance", None)
        if callable(on_advance):
            on_advance(lambda _old, _new: self.check())
        self._thread = threading.Thread(target=self._run, name="heater-watchdog", daemon=True)
        self._thread.start()

    def arm(self) -> None:
        """Start watching (call right before switching the heater on)."""
        with self._lock:
            self.tripped = None
            self._armed = True
            self._wake.notify_all()

    def disarm(self) -> None:
        """Stop watching (after the heater is off)."""
        with self._lock:
            self._armed = False

    def check(self) -> Trip | None:
        """One check; cuts the heater and returns the reason if a limit is hit."""
        with self._lock:
            if not self._armed:
                return None
        reason = None
        if self.abort_event is not None and self.abort_event.is_set():
            reason = Trip.ABORT
        elif self.heater.current_on_time_s >= self.limit_s - self.guard_s:
            reason = Trip.MAX_ON_TIME
        if reason is None:
            return None
        try:
            self.heater.off()
        except HeaterOffError:
            log.critical("watchdog (%s): switching the heater off failed", reason)
        with self._lock:
            if self._armed and self.tripped is None:
                self.tripped = reason
                log.warning("watchdog cut the heater: %s", reason)
        return reason

    def _run(self) -> None:
        while True:
            with self._lock:
                while not self._armed and not self._stop.is_set():
                    self._wake.wait()
            if self._stop.wait(self.poll_s):
                return
            try:
                self.check()
            except Exception:  # never let the watchdog thread die
                log.exception("heater watchdog check failed")

    def close(self) -> None:
        """Stop the thread (the clock hook stays registered but is disarmed)."""
        self.disarm()
        self._stop.set()
        with self._lock:
            self._wake.notify_all()
        self._thread.join(timeout=2.0)
