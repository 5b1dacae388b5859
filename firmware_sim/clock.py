"""A virtual clock shared by every simulated part.

Simulated time only moves when the device code sleeps or waits (or when a test
calls :meth:`VirtualClock.advance`), so a 2-s touch runs in a fraction of a
second of wall time and every run is reproducible.

Two other modes serve code that does not sleep through the board clock (a
third-party driver polling with ``time.sleep`` and timing with ``time.time``):
:class:`WallClock` (simulated time follows wall time) and :class:`BusClock`
(each I2C transaction advances simulated time by its wire time). All three
satisfy :class:`SimClock`; :func:`make_clock` builds one by mode name, as
``firmware_sim.load_scene(path, clock="virtual" | "wall" | "bus")`` does.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Callable, Protocol, runtime_checkable


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
        # No lock: reading one attribute is atomic, and advance() replaces it in one store; the lock
        # would only order this read before or after an advance, which the caller cannot tell apart.
        return self._t

    #: Alias of :meth:`now`, with the signature of ``time.monotonic`` (the same function: the drivers
    #: and the sequence call it several times a sample).
    monotonic = now

    def monotonic_ns(self) -> int:
        """Current simulated time in integer nanoseconds."""
        return int(round(self._t * 1e9))

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


# ---------------------------------------------------------------------------
# The clock interface and the two other clock modes


@runtime_checkable
class SimClock(Protocol):
    """What every simulator clock offers (``VirtualClock``, ``WallClock``, ``BusClock``).

    Times are simulated seconds. ``now`` never decreases; listeners registered
    with ``on_advance`` are called as ``fn(t_old_s, t_new_s)`` when simulated
    time moves. It is a superset of :class:`edge.hw.board.Clock`
    (``monotonic()``, ``sleep(s)``), so any of them can be a board's clock.
    """

    def now(self) -> float: ...

    def monotonic(self) -> float: ...

    def monotonic_ns(self) -> int: ...

    def advance(self, dt_s: float) -> float: ...

    def advance_to(self, t_s: float) -> float: ...

    def sleep(self, dt_s: float) -> None: ...

    def on_advance(self, fn: Callable[[float, float], None]) -> None: ...


#: Values of ``firmware_sim.load_scene(..., clock=...)``.
CLOCK_MODES = ("virtual", "wall", "bus")

#: Default I2C bit rate of :class:`BusClock` (standard mode, the Pi's default).
DEFAULT_BIT_RATE_Hz = 100_000.0


def i2c_transaction_time_s(n_bytes: int, n_segments: int, bit_rate_Hz: float) -> float:
    """Time on the wire of one I2C transaction.

    ``n_bytes`` counts every byte clocked, address bytes included (one per
    segment); each byte takes 9 bit-times (8 data + ACK) and each segment 2
    more (its START or repeated START, and the STOP). A one-byte register read
    (address+W, register, address+R, data) is ``(9*4 + 2*2)/f``: 0.4 ms at
    100 kHz, 0.1 ms at 400 kHz. :class:`firmware_sim.bus.SimBus` uses the same
    formula for its ``bit_rate_Hz``.
    """
    return (9 * int(n_bytes) + 2 * int(n_segments)) / float(bit_rate_Hz)


class _OrderedClock:
    """Shared machinery of :class:`WallClock` and :class:`BusClock`.

    ``_target`` is the simulated time handed out (what :meth:`now` returns);
    ``_told`` the time listeners have been told about. Listener calls are
    serialised by a dispatch lock and come in contiguous, increasing steps
    ``(t0, t1), (t1, t2), ...``, whichever thread moved the time. A thread that
    finds another one dispatching does not wait for it (no lock-order deadlock
    with a listener that takes some other lock): it records its time and the
    dispatching thread covers it before it lets go. A call from inside a
    listener sees the time being dispatched and never starts a nested dispatch.
    """

    _MAX_ROUNDS = 16   # dispatch rounds per call; a time left over goes out on the next call

    def __init__(self, start_s: float) -> None:
        if not start_s >= 0.0:
            raise ValueError(f"start_s must be >= 0, got {start_s!r}")
        self._target = float(start_s)
        self._told = self._target
        self._lock = threading.Lock()          # guards _target, _told, _listeners (and subclass state)
        self._dispatch = threading.Lock()      # held while listeners run
        self._dispatcher: int | None = None    # thread id running listeners
        self._listeners: list[Callable[[float, float], None]] = []

    def _in_listener(self) -> bool:
        return self._dispatcher == threading.get_ident()

    def _raise_target(self, t_s: float) -> float:
        with self._lock:
            if t_s > self._target:
                self._target = t_s
            return self._target

    def _tell_listeners(self) -> None:
        if self._in_listener():
            return          # the running dispatch loop picks the new time up
        for _ in range(self._MAX_ROUNDS):
            with self._lock:
                if self._target <= self._told:
                    return
            if not self._dispatch.acquire(blocking=False):
                return      # the dispatching thread re-checks _target after it releases
            try:
                self._dispatcher = threading.get_ident()
                with self._lock:
                    t_old, t_new = self._told, self._target
                    if t_new <= t_old:
                        continue
                    self._told = t_new
                    listeners = list(self._listeners)
                for fn in listeners:
                    fn(t_old, t_new)
            finally:
                self._dispatcher = None
                self._dispatch.release()

    def monotonic(self) -> float:
        """Alias of :meth:`now`, with the signature of ``time.monotonic``."""
        return self.now()

    def monotonic_ns(self) -> int:
        """Current simulated time in integer nanoseconds."""
        return int(round(self.now() * 1e9))

    def on_advance(self, fn: Callable[[float, float], None]) -> None:
        """Register ``fn(t_old_s, t_new_s)``, called (in time order) as simulated time moves."""
        with self._lock:
            self._listeners.append(fn)

    @staticmethod
    def _check_dt(dt_s: float) -> float:
        if not dt_s >= 0.0:
            raise ValueError(f"dt_s must be >= 0, got {dt_s!r}")
        return float(dt_s)


class WallClock(_OrderedClock):
    """Simulated time that follows wall time.

    ``now() = start_s + offset + rate * (wall() - wall_at_start)``, with
    ``wall`` = ``time.monotonic``. Every :meth:`now` (the chip models call it
    on each bus access) tells the listeners -- thermal world, GPIO, PWM -- up
    to that time, so a conversion started on an emulated ADC is ready after
    its datasheet time of real time, whoever polls and however: this is the
    mode for unmodified third-party drivers that poll with ``time.sleep`` and
    time out on ``time.time``.

    :meth:`sleep` really sleeps (``dt_s / rate`` wall seconds).
    :meth:`advance` and :meth:`advance_to` jump ahead: they add to ``offset``
    (simulated time then keeps following wall time from there), which lets a
    test skip to, say, the touch without waiting.

    Parameters
    ----------
    start_s : float
        Simulated time at construction.
    rate : float
        Simulated seconds per wall second (1.0: real time).
    wall, sleeper : callables, optional
        Wall time source and sleep (default ``time.monotonic``, ``time.sleep``).
    """

    def __init__(self, start_s: float = 0.0, *, rate: float = 1.0,
                 wall: Callable[[], float] = time.monotonic,
                 sleeper: Callable[[float], None] = time.sleep) -> None:
        if not (rate > 0 and math.isfinite(rate)):
            raise ValueError(f"rate must be a finite number > 0, got {rate!r}")
        super().__init__(start_s)
        self.rate = float(rate)
        self._wall = wall
        self._sleeper = sleeper
        self._start = self._target
        self._offset = 0.0
        self._wall0 = float(wall())

    def _following(self) -> float:
        return self._start + self._offset + self.rate * (float(self._wall()) - self._wall0)

    def now(self) -> float:
        """Current simulated time (s); tells the listeners up to it first."""
        if self._in_listener():
            with self._lock:
                return self._target
        with self._lock:
            t = self._following()
            if t > self._target:
                self._target = t
            t = self._target
        self._tell_listeners()
        return t

    def advance(self, dt_s: float) -> float:
        """Jump ``dt_s`` simulated seconds ahead (no waiting); return the new time."""
        dt = self._check_dt(dt_s)
        if self._in_listener():
            # No wall reading here (see now()); the running dispatch covers the jump.
            with self._lock:
                self._offset += dt
                self._target += dt
                return self._target
        with self._lock:
            t_before = max(self._target, self._following())
            self._offset += dt
            self._target = max(self._target, t_before + dt, self._following())
            t = self._target
        self._tell_listeners()
        return t

    def advance_to(self, t_s: float) -> float:
        """Jump ahead to ``t_s`` (no-op if already past it)."""
        dt = t_s - self.now()
        return self.advance(dt) if dt > 0 else self.now()

    def sleep(self, dt_s: float) -> None:
        """Sleep ``dt_s`` simulated seconds: ``dt_s / rate`` seconds of wall time."""
        dt = max(0.0, float(dt_s))
        if dt > 0:
            self._sleeper(dt / self.rate)
        self.now()


class BusClock(_OrderedClock):
    """Simulated time that moves by bus traffic (and sleeps), not by wall time.

    Each I2C transaction on a :class:`~firmware_sim.bus.SimBus` using this
    clock advances it, after the transaction, by its wire time
    :func:`i2c_transaction_time_s` at ``bit_rate_Hz`` (default 100 kHz) plus
    ``per_transaction_s`` (a fixed overhead; 0 by default). :meth:`sleep` and
    :meth:`advance` advance it like :class:`VirtualClock` (no wall waiting).
    A driver that busy-polls a status register thus sees time pass by its own
    polling, deterministically.

    Parameters
    ----------
    start_s : float
    bit_rate_Hz : float
        SCL frequency of the emulated bus (100e3 standard, 400e3 fast mode).
    per_transaction_s : float
        Extra time per transaction (e.g. ~1e-4 for the Pi's i2c-dev ioctl).
    """

    def __init__(self, start_s: float = 0.0, *, bit_rate_Hz: float = DEFAULT_BIT_RATE_Hz,
                 per_transaction_s: float = 0.0) -> None:
        if not (bit_rate_Hz > 0 and math.isfinite(bit_rate_Hz)):
            raise ValueError(f"bit_rate_Hz must be a finite number > 0, got {bit_rate_Hz!r}")
        if not per_transaction_s >= 0:
            raise ValueError(f"per_transaction_s must be >= 0, got {per_transaction_s!r}")
        super().__init__(start_s)
        self.bit_rate_Hz = float(bit_rate_Hz)
        self.per_transaction_s = float(per_transaction_s)
        #: number of bus transactions counted so far
        self.transactions = 0

    def now(self) -> float:
        """Current simulated time in seconds."""
        with self._lock:
            return self._target

    def transaction_time_s(self, n_bytes: int, n_segments: int) -> float:
        """The quantum one transaction advances the clock by."""
        return i2c_transaction_time_s(n_bytes, n_segments, self.bit_rate_Hz) + self.per_transaction_s

    def bus_transaction(self, n_bytes: int, n_segments: int) -> float:
        """Called by SimBus after each transaction; advances by its quantum, returns the new time."""
        with self._lock:
            self.transactions += 1
        return self.advance(self.transaction_time_s(n_bytes, n_segments))

    def advance(self, dt_s: float) -> float:
        """Move simulated time forward by ``dt_s`` seconds; return the new time."""
        dt = self._check_dt(dt_s)
        with self._lock:
            self._target += dt
            t = self._target
        self._tell_listeners()
        return t

    def advance_to(self, t_s: float) -> float:
        """Move simulated time forward to ``t_s`` (no-op if already past it)."""
        t = self._raise_target(float(t_s))
        self._tell_listeners()
        return t

    def sleep(self, dt_s: float) -> None:
        """Sleep ``dt_s`` simulated seconds (returns at once in wall time)."""
        self.advance(max(0.0, float(dt_s)))


def check_clock_mode(mode: object) -> str:
    """Return ``mode`` if it is one of :data:`CLOCK_MODES`, else raise ValueError naming it and them."""
    if not isinstance(mode, str) or mode not in CLOCK_MODES:
        allowed = ", ".join(repr(m) for m in CLOCK_MODES)
        raise ValueError(f"clock must be one of {allowed}; got {mode!r}")
    return mode


def make_clock(mode: str = "virtual", *, bit_rate_Hz: float | None = None, start_s: float = 0.0) -> SimClock:
    """A clock for ``mode`` in :data:`CLOCK_MODES`.

    ``bit_rate_Hz`` sets a :class:`BusClock`'s quantum (default
    :data:`DEFAULT_BIT_RATE_Hz`); the other modes ignore it.
    """
    check_clock_mode(mode)
    if mode == "wall":
        return WallClock(start_s)
    if mode == "bus":
        return BusClock(start_s, bit_rate_Hz=DEFAULT_BIT_RATE_Hz if bit_rate_Hz is None else bit_rate_Hz)
    return VirtualClock(start_s)
