"""A virtual clock shared by every simulated part.

Simulated time only moves when the device code sleeps or waits (or when a test
calls :meth:`VirtualClock.advance`), so a 2-s touch runs in a fraction of a
second of wall time and every run is reproducible.
"""

from __future__ import annotations

import threading
from typing import Callable


class VirtualClock:
    """Monotonic simulated time in seconds, starting at ``start_s``.

    Listeners registered with :meth:`on_advance` are called with
    ``(t_old_s, t_new_s)`` after every advance; the thermal world and the chip
    models use this to integrate up to the new time.
    """

    def __init__(self, start_s: float = 0.0) -> None:
        if not start_s >= 0.0:
            raise ValueError(f"start_s must be >= 0, got {start_s!r}")
        self._t = float(start_s)
        self._lock = threading.RLock()
        self._listeners: list[Callable[[float, float], None]] = []

    def now(self) -> float:
        """Current simulated time in seconds."""
        with self._lock:
            return self._t

    def monotonic(self) -> float:
        """Alias of :meth:`now`, with the signature of ``time.monotonic``."""
        return self.now()

    def monotonic_ns(self) -> int:
        """Current simulated time in integer nanoseconds."""
        return int(round(self.now() * 1e9))

    def advance(self, dt_s: float) -> float:
        """Move simulated time forward by ``dt_s`` seconds; return the new time."""
        if not dt_s >= 0.0:
            raise ValueError(f"dt_s must be >= 0, got {dt_s!r}")
        with self._lock:
            t_old = self._t
            self._t = t_old + float(dt_s)
            t_new = self._t
            listeners = list(self._listeners)
        for fn in listeners:
            fn(t_old, t_new)
        return t_new

    def advance_to(self, t_s: float) -> float:
        """Move simulated time forward to ``t_s`` (no-op if already past it)."""
        with self._lock:
            dt = t_s - self._t
        return self.advance(dt) if dt > 0 else self.now()

    def sleep(self, dt_s: float) -> None:
        """Sleep ``dt_s`` simulated seconds (returns at once in wall time)."""
        self.advance(max(0.0, float(dt_s)))

    def on_advance(self, fn: Callable[[float, float], None]) -> None:
        """Register ``fn(t_old_s, t_new_s)`` to be called after each advance."""
        with self._lock:
            self._listeners.append(fn)
