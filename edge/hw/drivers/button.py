"""The trigger button, read through gpiod edge events.

Debouncing is done by the kernel (the line's ``debounce_period``; on a Pi the
GPIO controller has no hardware debouncer, so gpiolib debounces in
software): a level change is reported only after the contacts have been
stable for the debounce period. Event times are the kernel's time stamps,
which are on the board clock's time base (CLOCK_MONOTONIC on the device,
virtual time in the simulator).
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass
from typing import Any

__all__ = ["ButtonEvent", "Button"]


@dataclass(frozen=True)
class ButtonEvent:
    """A debounced button transition.

    Attributes
    ----------
    pressed : bool
        True for a press (line became active), False for a release.
    t_s : float
        Kernel time stamp of the transition (s).
    """

    pressed: bool
    t_s: float


class Button:
    """The trigger button on ``board.trigger``.

    Parameters
    ----------
    board : Board
        Provides ``trigger`` (GpioLine) and ``clock``.
    debounce_s : float
        Kernel debounce period (s); contacts must be stable this long.
    consumer : str
        GPIO consumer label.
    """

    def __init__(self, board: Any, *, debounce_s: float = 0.02, consumer: str = "thermotouch-button") -> None:
        if not (isinstance(debounce_s, (int, float)) and debounce_s >= 0):
            raise ValueError(f"debounce_s must be a number >= 0, got {debounce_s!r}")
        self._line = board.trigger
        self._clock = board.clock
        self.debounce_s = float(debounce_s)
        self._req = self._line.request_input(consumer, edge="both", debounce_s=self.debounce_s)
        self._queue: deque[ButtonEvent] = deque()
        self._lock = threading.Lock()

    @property
    def is_pressed(self) -> bool:
        """Current (debounced) state."""
        return bool(self._req.get_value(self._line.offset))

    def _convert(self, ev: Any) -> ButtonEvent:
        return ButtonEvent(pressed=ev.event_type.name == "RISING_EDGE", t_s=ev.timestamp_ns * 1e-9)

    def _fill(self, timeout_s: float | None) -> bool:
        """Wait up to ``timeout_s`` for kernel events and queue them."""
        if not self._req.wait_edge_events(timeout_s):
            return False
        self._queue.extend(self._convert(e) for e in self._req.read_edge_events())
        return True

    def wait_for_event(self, timeout_s: float | None = None) -> ButtonEvent | None:
        """Next press or release, or None after ``timeout_s`` seconds (None: forever)."""
        if timeout_s is not None and not timeout_s >= 0:
            raise ValueError(f"timeout_s must be >= 0 or None, got {timeout_s!r}")
        with self._lock:
            deadline = None if timeout_s is None else self._clock.monotonic() + timeout_s
            while not self._queue:
                remaining = None if deadline is None else max(0.0, deadline - self._clock.monotonic())
                if not self._fill(remaining):
                    return None  # the wait timed out
            return self._queue.popleft()

    def _wait_for(self, pressed: bool, timeout_s: float | None) -> ButtonEvent | None:
        if timeout_s is not None and not timeout_s >= 0:
            raise ValueError(f"timeout_s must be >= 0 or None, got {timeout_s!r}")
        deadline = None if timeout_s is None else self._clock.monotonic() + timeout_s
        while True:
            remaining = None if deadline is None else max(0.0, deadline - self._clock.monotonic())
            ev = self.wait_for_event(remaining)
            if ev is None:
                return None
            if ev.pressed == pressed:
                return ev

    def wait_for_press(self, timeout_s: float | None = None) -> ButtonEvent | None:
        """Wait for the next press (earlier releases are discarded); None on timeout."""
        return self._wait_for(True, timeout_s)

    def wait_for_release(self, timeout_s: float | None = None) -> ButtonEvent | None:
        """Wait for the next release (earlier presses are discarded); None on timeout."""
        return self._wait_for(False, timeout_s)

    def clear(self) -> int:
        """Drop every pending event without waiting; return how many."""
        with self._lock:
            while self._fill(0.0):
                pass
            n = len(self._queue)
            self._queue.clear()
            return n

    def close(self) -> None:
        """Release the line."""
        self._req.release()

    def __enter__(self) -> Button:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
