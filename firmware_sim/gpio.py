"""A simulated GPIO character device with a python-gpiod 2.x compatible API.

Two sides live here:

* The *device-code side* mirrors the subset of python ``gpiod`` 2.x that the
  edge code uses: ``Chip(path)``, ``Chip.request_lines``, ``request_lines``,
  ``LineSettings``, ``line.Direction/Value/Edge/Bias/Drive/Clock``,
  ``EdgeEvent`` and ``LineRequest`` with the same names, signatures, return
  types and exceptions (``RequestReleasedError``, ``ChipClosedError``,
  ``OSError(EBUSY)`` for a line that is already requested, ``OSError(EPERM)``
  for setting an input line).
* The *simulator side* (:class:`SimChip`) drives inputs at virtual times
  (:meth:`SimChip.schedule_input`, :meth:`SimChip.press`) and records the
  physical level of every line (:meth:`SimChip.line_history`), from which the
  thermal world reads the heater-enable state.

A real process sees one kernel, so ``Chip`` and ``request_lines`` must know
which simulated chips exist. They are therefore bound to a :class:`GpioSim`
(a simulated kernel with its clock and chips); ``GpioSim.gpiod`` is the object
to inject into edge code in place of the real ``gpiod`` module::

    gsim = GpioSim(clock)
    chip = gsim.add_chip("/dev/gpiochip0", num_lines=54)
    gpiod = gsim.gpiod
    req = gpiod.request_lines("/dev/gpiochip0", config={17: gpiod.LineSettings(
        direction=gpiod.line.Direction.OUTPUT)}, consumer="heater")

Time is the shared :class:`firmware_sim.clock.VirtualClock`. Scheduled input
changes are applied at their exact scheduled times when the clock advances
past them, so edge-event timestamps do not depend on how coarsely the device
code sleeps. ``LineRequest.wait_edge_events`` advances the virtual clock (to
the next scheduled change, or to the timeout) instead of sleeping.

Debounce follows the kernel's software debouncer (gpiolib-cdev): a level
change is reported only once the line has been stable for the debounce
period, and the event is time-stamped at the end of that period.

A released line (its request released, or its process dead: the kernel
releases a dead process's requests) stops being driven: with a pull-up or
pull-down bias it returns to an input at that level; with no bias it keeps
its last output value, as most GPIO controllers do. Device code that needs a
safe level after its own death requests the line with the bias that pulls it
there (:meth:`edge.hw.board.GpioLine.request_fail_safe_output`).

``GpioSim(clock, state_dir=DIR)`` mirrors every line's state to files with
the holder's pid (:mod:`firmware_sim.gpio_state`), so another process can
read a line after the simulated device process died.
"""

from __future__ import annotations

import bisect
import errno as _errno
import heapq
import itertools
import os
import threading
import types
from collections import deque
from dataclasses import dataclass
from datetime import timedelta
from enum import Enum
from typing import Any, Iterable

from firmware_sim.gpio_state import LineStateDir

__all__ = [
    "Value",
    "Direction",
    "Bias",
    "Drive",
    "Edge",
    "Clock",
    "line",
    "LineSettings",
    "EdgeEvent",
    "LineRequest",
    "Chip",
    "ChipInfo",
    "ChipClosedError",
    "RequestReleasedError",
    "SimChip",
    "GpioSim",
]


# --------------------------------------------------------------------------
# Types mirroring gpiod.line, gpiod.LineSettings, gpiod.EdgeEvent
# (enum values equal those of libgpiod's python bindings)


class Value(Enum):
    """Logical line states."""

    INACTIVE = 0
    ACTIVE = 1

    def __bool__(self) -> bool:
        return self is Value.ACTIVE


class Direction(Enum):
    """Direction settings."""

    AS_IS = 1
    INPUT = 2
    OUTPUT = 3


class Bias(Enum):
    """Internal bias settings."""

    AS_IS = 1
    UNKNOWN = 2
    DISABLED = 3
    PULL_UP = 4
    PULL_DOWN = 5


class Drive(Enum):
    """Drive settings."""

    PUSH_PULL = 1
    OPEN_DRAIN = 2
    OPEN_SOURCE = 3


class Edge(Enum):
    """Edge detection settings."""

    NONE = 1
    RISING = 2
    FALLING = 3
    BOTH = 4


class Clock(Enum):
    """Event clock settings."""

    MONOTONIC = 1
    REALTIME = 2
    HTE = 3


#: Stand-in for the ``gpiod.line`` submodule (the real package does not
#: re-export these enums at top level, so portable code uses ``gpiod.line.X``).
line = types.SimpleNamespace(
    Value=Value, Direction=Direction, Bias=Bias, Drive=Drive, Edge=Edge, Clock=Clock
)


def _coerce(enum_cls: type[Enum], value: Any, what: str) -> Any:
    """Accept our enum members, or members of the real gpiod enums by name."""
    if isinstance(value, enum_cls):
        return value
    name = getattr(value, "name", None)
    if isinstance(name, str) and name in enum_cls.__members__:
        return enum_cls[name]
    raise TypeError(f"{what} must be a {enum_cls.__name__} member, got {value!r}")


@dataclass(repr=False)
class LineSettings:
    """Stores a set of line properties (mirrors ``gpiod.LineSettings``)."""

    direction: Direction = Direction.AS_IS
    edge_detection: Edge = Edge.NONE
    bias: Bias = Bias.AS_IS
    drive: Drive = Drive.PUSH_PULL
    active_low: bool = False
    debounce_period: timedelta = timedelta()
    event_clock: Clock = Clock.MONOTONIC
    output_value: Value = Value.INACTIVE

    def __repr__(self) -> str:
        return (
            f"LineSettings(direction={self.direction}, edge_detection={self.edge_detection}, "
            f"bias={self.bias}, drive={self.drive}, active_low={self.active_low}, "
            f"debounce_period={self.debounce_period!r}, event_clock={self.event_clock}, "
            f"output_value={self.output_value})"
        )


def _normalise_settings(s: Any) -> LineSettings:
    """Copy settings (ours or real gpiod's) into a validated LineSettings."""
    if s is None:
        return LineSettings()
    deb = getattr(s, "debounce_period", timedelta())
    if not isinstance(deb, timedelta):
        raise TypeError(f"debounce_period must be a datetime.timedelta, got {deb!r}")
    if deb < timedelta():
        raise ValueError(f"debounce_period must be >= 0, got {deb!r}")
    return LineSettings(
        direction=_coerce(Direction, s.direction, "direction"),
        edge_detection=_coerce(Edge, s.edge_detection, "edge_detection"),
        bias=_coerce(Bias, s.bias, "bias"),
        drive=_coerce(Drive, s.drive, "drive"),
        active_low=bool(s.active_low),
        debounce_period=deb,
        event_clock=_coerce(Clock, s.event_clock, "event_clock"),
        output_value=_coerce(Value, s.output_value, "output_value"),
    )


@dataclass(frozen=True, init=False, repr=False)
class EdgeEvent:
    """Immutable edge event (mirrors ``gpiod.EdgeEvent``)."""

    class Type(Enum):
        """Possible edge event types."""

        RISING_EDGE = 1
        FALLING_EDGE = 2

    event_type: Type
    timestamp_ns: int
    line_offset: int
    global_seqno: int
    line_seqno: int

    def __init__(
        self,
        event_type: int,
        timestamp_ns: int,
        line_offset: int,
        global_seqno: int,
        line_seqno: int,
    ):
        object.__setattr__(self, "event_type", EdgeEvent.Type(event_type))
        object.__setattr__(self, "timestamp_ns", timestamp_ns)
        object.__setattr__(self, "line_offset", line_offset)
        object.__setattr__(self, "global_seqno", global_seqno)
        object.__setattr__(self, "line_seqno", line_seqno)

    def __repr__(self) -> str:
        return (
            f"<EdgeEvent type={self.event_type} timestamp_ns={self.timestamp_ns} "
            f"line_offset={self.line_offset} global_seqno={self.global_seqno} "
            f"line_seqno={self.line_seqno}>"
        )

    __str__ = __repr__


class ChipClosedError(Exception):
    """Error raised when an already closed chip is used."""

    def __init__(self) -> None:
        super().__init__("I/O operation on closed chip")


class RequestReleasedError(Exception):
    """Error raised when a released request is used."""

    def __init__(self) -> None:
        super().__init__("GPIO lines have been released")


@dataclass(frozen=True)
class ChipInfo:
    """Snapshot of the chip's properties (mirrors ``gpiod.ChipInfo``)."""

    name: str
    label: str
    num_lines: int


def _timeout_s(timeout: timedelta | float | None) -> float | None:
    if timeout is None:
        return None
    sec = timeout.total_seconds() if isinstance(timeout, timedelta) else float(timeout)
    if sec < 0:
        raise ValueError(f"timeout must be >= 0, got {timeout!r}")
    return sec


def _to_ns(t_s: float) -> int:
    return int(round(t_s * 1e9))


# --------------------------------------------------------------------------
# Simulator side: the chip's lines and their physical levels


class _Line:
    """State of one simulated line (all levels are physical: 0 low, 1 high)."""

    __slots__ = (
        "offset",
        "name",
        "external",
        "settings",
        "request",
        "out_value",
        "level",
        "reported",
        "debounce_due",
        "history",
    )

    def __init__(self, offset: int, name: str, t0: float) -> None:
        self.offset = offset
        self.name = name
        self.external: int | None = None  # level driven from outside; None = floating
        self.settings = LineSettings(direction=Direction.INPUT)
        self.request: LineRequest | None = None
        self.out_value = 0  # physical level driven while an output
        self.level = 0
        self.reported = 0  # debounced level as seen by edge detection
        self.debounce_due: float | None = None
        self.history: list[tuple[float, int]] = [(t0, 0)]

    def is_output(self) -> bool:
        return self.settings.direction is Direction.OUTPUT

    def effective_level(self) -> int:
        if self.is_output():
            return self.out_value
        if self.external is not None:
            return self.external
        if self.settings.bias is Bias.PULL_UP:
            return 1
        return 0  # pull-down, or a floating input read deterministically as low


class SimChip:
    """One simulated GPIO chip: the hardware side of the character device.

    Parameters
    ----------
    gsim : GpioSim
        The simulated kernel owning this chip (gives the clock and the lock).
    path : str
        Device path, e.g. ``"/dev/gpiochip0"``.
    num_lines : int
        Number of lines (offsets ``0 .. num_lines-1``).
    label : str
        Chip label reported by :meth:`Chip.get_info`.
    line_names : dict of int to str, optional
        Names of lines, for requests by name.
    """

    def __init__(
        self,
        gsim: "GpioSim",
        path: str,
        num_lines: int,
        label: str = "sim-gpio",
        line_names: dict[int, str] | None = None,
    ) -> None:
        if not isinstance(num_lines, int) or num_lines <= 0:
            raise ValueError(f"num_lines must be a positive int, got {num_lines!r}")
        self._gsim = gsim
        self.path = path
        self.label = label
        self.name = os.path.basename(path)
        t0 = gsim.clock.now()
        names = dict(line_names or {})
        for off in names:
            if not 0 <= off < num_lines:
                raise ValueError(f"line_names has offset {off} outside 0..{num_lines - 1}")
        self._lines = [_Line(i, names.get(i, ""), t0) for i in range(num_lines)]
        # pending external drives: heap of (t_s, seq, offset, level or None)
        self._pending: list[tuple[float, int, int, int | None]] = []
        self._seq = itertools.count()

    # ---- information

    @property
    def num_lines(self) -> int:
        """Number of lines on the chip."""
        return len(self._lines)

    def _line(self, offset: int) -> _Line:
        if not isinstance(offset, int) or not 0 <= offset < len(self._lines):
            raise ValueError(
                f"offset must be an int in 0..{len(self._lines) - 1} on {self.path}, got {offset!r}"
            )
        return self._lines[offset]

    def level(self, offset: int) -> int:
        """Current physical level (0 or 1) of line ``offset``."""
        with self._gsim.lock:
            return self._line(offset).level

    def line_history(self, offset: int) -> list[tuple[float, int]]:
        """Physical level changes of line ``offset`` as ``(t_s, level)`` pairs.

        The first entry is the level when the chip was created.
        """
        with self._gsim.lock:
            return list(self._line(offset).history)

    def level_at(self, offset: int, t_s: float) -> int:
        """Physical level of line ``offset`` at simulated time ``t_s``.

        A change recorded at exactly ``t_s`` counts as already happened.
        """
        hist = self.line_history(offset)
        i = bisect.bisect_right([t for t, _ in hist], t_s) - 1
        return hist[max(i, 0)][1]

    def is_requested(self, offset: int) -> bool:
        """Whether line ``offset`` is currently held by a request."""
        with self._gsim.lock:
            return self._line(offset).request is not None

    def consumer(self, offset: int) -> str | None:
        """Consumer string of the request holding line ``offset``, if any."""
        with self._gsim.lock:
            req = self._line(offset).request
            return None if req is None else req._consumer

    # ---- driving inputs from the simulator

    def set_input(self, offset: int, level: int | None) -> None:
        """Drive line ``offset`` from outside to ``level`` (0/1) now; ``None`` floats it."""
        self.schedule_input(offset, level, self._gsim.clock.now())

    def schedule_input(self, offset: int, level: int | None, at_s: float) -> None:
        """Drive line ``offset`` to ``level`` (0, 1, or None = float) at time ``at_s`` (s).

        Changes scheduled at or before the current time apply immediately.
        """
        self._line(offset)
        if level not in (0, 1, None):
            raise ValueError(f"level must be 0, 1 or None, got {level!r}")
        at_s = float(at_s)
        if not at_s >= 0.0:
            raise ValueError(f"at_s must be >= 0, got {at_s!r}")
        with self._gsim.lock:
            heapq.heappush(self._pending, (at_s, next(self._seq), offset, level))
            now = self._gsim.clock.now()
        if at_s <= now:
            self._process_until(now)

    def press(
        self,
        offset: int,
        at_s: float,
        hold_s: float,
        *,
        pressed_level: int = 0,
        bounces: int = 0,
        bounce_interval_s: float = 0.5e-3,
    ) -> None:
        """Schedule a button press on line ``offset``.

        The switch connects the line to ``pressed_level`` at ``at_s`` for
        ``hold_s`` seconds and then lets it float (the line's bias decides the
        released level, e.g. pull-up for a switch to ground). ``bounces``
        extra open/close pairs, ``bounce_interval_s`` apart, model contact
        chatter after both the press and the release.
        """
        if not hold_s > 0:
            raise ValueError(f"hold_s must be > 0, got {hold_s!r}")
        if not isinstance(bounces, int) or bounces < 0:
            raise ValueError(f"bounces must be an int >= 0, got {bounces!r}")
        if not bounce_interval_s > 0:
            raise ValueError(f"bounce_interval_s must be > 0, got {bounce_interval_s!r}")
        if 2 * bounces * bounce_interval_s >= hold_s:
            raise ValueError("hold_s must be longer than the bounce chatter (2*bounces*bounce_interval_s)")
        t = float(at_s)
        self.schedule_input(offset, pressed_level, t)
        for k in range(bounces):
            self.schedule_input(offset, None, t + (2 * k + 1) * bounce_interval_s)
            self.schedule_input(offset, pressed_level, t + (2 * k + 2) * bounce_interval_s)
        t_rel = t + hold_s
        self.schedule_input(offset, None, t_rel)
        for k in range(bounces):
            self.schedule_input(offset, pressed_level, t_rel + (2 * k + 1) * bounce_interval_s)
            self.schedule_input(offset, None, t_rel + (2 * k + 2) * bounce_interval_s)

    # ---- time evolution

    def next_change_s(self) -> float | None:
        """Time of the next scheduled input change or debounce expiry, if any."""
        with self._gsim.lock:
            times = [p[0] for p in self._pending[:1]]
            times += [ln.debounce_due for ln in self._lines if ln.debounce_due is not None]
            return min(times) if times else None

    def _process_until(self, t_end: float) -> None:
        """Apply every scheduled change and debounce expiry up to ``t_end``."""
        with self._gsim.lock:
            while True:
                t_raw = self._pending[0][0] if self._pending else None
                due = [(ln.debounce_due, ln.offset) for ln in self._lines if ln.debounce_due is not None]
                t_deb, off_deb = min(due) if due else (None, -1)
                # A line stable for exactly the debounce period is reported
                # before a change landing at that same instant.
                if t_deb is not None and t_deb <= t_end and (t_raw is None or t_deb <= t_raw):
                    self._debounce_expired(self._lines[off_deb], t_deb)
                elif t_raw is not None and t_raw <= t_end:
                    t, _, off, lvl = heapq.heappop(self._pending)
                    ln = self._lines[off]
                    ln.external = lvl
                    self._update_level(ln, t)
                else:
                    return

    def _update_level(self, ln: _Line, t: float, *, quiet: bool = False) -> None:
        """Recompute the physical level of ``ln`` at time ``t`` and detect edges."""
        new = ln.effective_level()
        if new == ln.level:
            return
        ln.level = new
        ln.history.append((t, new))
        self._gsim._mirror(self, ln, t)
        s = ln.settings
        if quiet or ln.request is None or ln.is_output() or s.edge_detection is Edge.NONE:
            ln.reported = new
            ln.debounce_due = None
            return
        deb = s.debounce_period.total_seconds()
        if deb > 0:
            ln.debounce_due = t + deb
        else:
            self._report(ln, t)

    def _debounce_expired(self, ln: _Line, t: float) -> None:
        ln.debounce_due = None
        if ln.level != ln.reported:
            self._report(ln, t)

    def _report(self, ln: _Line, t: float) -> None:
        """Report the line's current level as an edge at time ``t``."""
        if ln.level == ln.reported:
            return
        ln.reported = ln.level
        logical_active = (ln.level == 1) != ln.settings.active_low
        edge = ln.settings.edge_detection
        if logical_active and edge in (Edge.RISING, Edge.BOTH):
            etype = EdgeEvent.Type.RISING_EDGE
        elif not logical_active and edge in (Edge.FALLING, Edge.BOTH):
            etype = EdgeEvent.Type.FALLING_EDGE
        else:
            return
        assert ln.request is not None
        ln.request._push_event(etype, _to_ns(t), ln.offset)

    # ---- called by LineRequest

    def _claim(self, req: "LineRequest", cfg: dict[int, LineSettings]) -> None:
        with self._gsim.lock:
            self._process_until(self._gsim.clock.now())
            for off, s in cfg.items():
                ln = self._line(off)
                if ln.request is not None:
                    raise OSError(
                        _errno.EBUSY,
                        f"{os.strerror(_errno.EBUSY)}: line {off} of {self.path} "
                        f"is already requested by {ln.request._consumer!r}",
                    )
                if s.direction is Direction.OUTPUT and s.edge_detection is not Edge.NONE:
                    raise OSError(
                        _errno.EINVAL,
                        f"{os.strerror(_errno.EINVAL)}: edge detection on output line {off} of {self.path}",
                    )
            now = self._gsim.clock.now()
            for off, s in cfg.items():
                ln = self._lines[off]
                if s.direction is Direction.AS_IS:
                    s = _replace(s, direction=ln.settings.direction)
                if s.bias is Bias.AS_IS:
                    s = _replace(s, bias=ln.settings.bias)
                ln.settings = s
                ln.request = req
                if s.direction is Direction.OUTPUT:
                    ln.out_value = int(bool(s.output_value)) ^ int(s.active_low)
                # Requesting a line does not produce edge events.
                self._update_level(ln, now, quiet=True)
                ln.reported = ln.level
                ln.debounce_due = None
                self._gsim._mirror(self, ln)

    def _release(self, offsets: Iterable[int]) -> None:
        with self._gsim.lock:
            for off in offsets:
                ln = self._lines[off]
                ln.request = None
                ln.debounce_due = None
                # A biased output stops being driven and is pulled to its bias level;
                # otherwise direction, bias and the driven level stay as configured.
                direction = ln.settings.direction
                if direction is Direction.OUTPUT and ln.settings.bias in (Bias.PULL_UP, Bias.PULL_DOWN):
                    direction = Direction.INPUT
                ln.settings = LineSettings(direction=direction, bias=ln.settings.bias)
                self._update_level(ln, self._gsim.clock.now(), quiet=True)
                self._gsim._mirror(self, ln)

    def _get(self, off: int) -> Value:
        with self._gsim.lock:
            self._process_until(self._gsim.clock.now())
            ln = self._lines[off]
            # Inputs with a debouncer read the debounced level, as in the kernel.
            lvl = ln.reported if ln.settings.debounce_period > timedelta() else ln.level
            if ln.is_output():
                lvl = ln.out_value
            return Value((lvl == 1) != ln.settings.active_low)

    def _set(self, values: dict[int, Value]) -> None:
        with self._gsim.lock:
            for off in values:
                if not self._lines[off].is_output():
                    raise OSError(
                        _errno.EPERM,
                        f"{os.strerror(_errno.EPERM)}: line {off} of {self.path} is not an output",
                    )
            now = self._gsim.clock.now()
            for off, v in values.items():
                ln = self._lines[off]
                v = _coerce(Value, v, "value")
                ln.out_value = int(bool(v)) ^ int(ln.settings.active_low)
                self._update_level(ln, now)


def _replace(s: LineSettings, **kw: Any) -> LineSettings:
    d = dict(s.__dict__)
    d.update(kw)
    return LineSettings(**d)


# --------------------------------------------------------------------------
# Device-code side: Chip and LineRequest


class LineRequest:
    """A set of requested lines (mirrors ``gpiod.LineRequest``).

    Created by :meth:`Chip.request_lines`; not to be instantiated directly.
    """

    def __init__(
        self,
        chip: SimChip,
        cfg: dict[int, LineSettings],
        lines: list[int | str],
        name_map: dict[str, int],
        consumer: str | None,
        event_buffer_size: int | None,
    ) -> None:
        self._chip: SimChip | None = chip
        self._cfg = cfg
        self._offsets = list(cfg)
        self._lines = lines
        self._name_map = name_map
        self._consumer = consumer or "?"
        size = event_buffer_size or 16 * len(cfg)
        self._events: deque[EdgeEvent] = deque()
        self._buffer_size = max(int(size), 1)
        self._global_seqno = 0
        self._line_seqno = {off: 0 for off in cfg}
        #: Events dropped because the buffer was full (the kernel drops the oldest).
        self.overflows = 0

    # ---- context management

    def __bool__(self) -> bool:
        return self._chip is not None

    def __enter__(self) -> LineRequest:
        self._check_released()
        return self

    def __exit__(self, exc_type, exc_value, traceback) -> None:
        self.release()

    def _check_released(self) -> SimChip:
        if self._chip is None:
            raise RequestReleasedError()
        return self._chip

    def release(self) -> None:
        """Release the lines; the object must not be used afterwards."""
        if self._chip is not None:
            self._chip._release(self._offsets)
            self._chip = None

    # ---- values

    def _line_to_offset(self, line_id: int | str) -> int:
        if isinstance(line_id, int):
            off = line_id
        elif (off := self._name_map.get(line_id)) is None:
            raise ValueError(f"unknown line name: {line_id}")
        if off not in self._cfg:
            raise ValueError(f"line {line_id!r} is not part of this request (offsets {self._offsets})")
        return off

    def get_value(self, line: int | str) -> Value:
        """Get a single line's logical value."""
        return self.get_values([line])[0]

    def get_values(self, lines: Iterable[int | str] | None = None) -> list[Value]:
        """Get the logical values of ``lines`` (all requested lines if None)."""
        chip = self._check_released()
        lines = lines or self._lines
        return [chip._get(self._line_to_offset(x)) for x in lines]

    def set_value(self, line: int | str, value: Value) -> None:
        """Set a single line's logical value."""
        self.set_values({line: value})

    def set_values(self, values: dict[int | str, Value]) -> None:
        """Set the logical values of a subset of the requested lines."""
        chip = self._check_released()
        chip._set({self._line_to_offset(k): v for k, v in values.items()})

    # ---- edge events

    def _push_event(self, etype: EdgeEvent.Type, ts_ns: int, offset: int) -> None:
        self._global_seqno += 1
        self._line_seqno[offset] += 1
        if len(self._events) >= self._buffer_size:
            self._events.popleft()
            self.overflows += 1
        self._events.append(
            EdgeEvent(etype.value, ts_ns, offset, self._global_seqno, self._line_seqno[offset])
        )

    def wait_edge_events(self, timeout: timedelta | float | None = None) -> bool:
        """Wait for edge events, advancing the virtual clock instead of sleeping.

        Returns True as soon as events are ready, False on timeout. With
        ``timeout=None`` and nothing scheduled that could ever produce an
        event, raises RuntimeError rather than blocking forever.
        """
        chip = self._check_released()
        sec = _timeout_s(timeout)
        clock = chip._gsim.clock
        chip._process_until(clock.now())
        if self._events:
            return True
        deadline = None if sec is None else clock.now() + sec
        while True:
            nxt = chip.next_change_s()
            if nxt is None or (deadline is not None and nxt > deadline):
                if deadline is None:
                    raise RuntimeError(
                        f"wait_edge_events(timeout=None) on {chip.path} would block forever: "
                        "no input change is scheduled"
                    )
                clock.advance_to(deadline)
                chip._process_until(clock.now())
                return bool(self._events)
            clock.advance_to(nxt)
            chip._process_until(clock.now())
            if self._events:
                return True

    def read_edge_events(self, max_events: int | None = None) -> list[EdgeEvent]:
        """Read up to ``max_events`` queued events (all if None).

        Like the kernel read(), blocks (advancing virtual time) when the
        queue is empty.
        """
        self._check_released()
        if not self._events:
            self.wait_edge_events(None)
        n = len(self._events) if max_events is None else max(0, min(int(max_events), len(self._events)))
        return [self._events.popleft() for _ in range(n)]

    # ---- properties

    @property
    def chip_name(self) -> str:
        """Name of the chip this request was made on."""
        return self._check_released().name

    @property
    def num_lines(self) -> int:
        """Number of requested lines."""
        self._check_released()
        return len(self._offsets)

    @property
    def offsets(self) -> list[int]:
        """Requested offsets."""
        self._check_released()
        return list(self._offsets)

    @property
    def lines(self) -> list[int | str]:
        """Requested lines as given (offsets or names)."""
        self._check_released()
        return list(self._lines)

    def __str__(self) -> str:
        if self._chip is None:
            return "<LineRequest RELEASED>"
        return f'<LineRequest chip="{self._chip.name}" num_lines={len(self._offsets)} offsets={self._offsets}>'


class Chip:
    """A simulated GPIO chip handle (mirrors ``gpiod.Chip``).

    Use the class bound to a kernel, ``GpioSim(...).gpiod.Chip(path)``; the
    unbound module-level class has no kernel to look the path up in.
    """

    _gsim: "GpioSim | None" = None

    def __init__(self, path: str):
        gsim = type(self)._gsim
        if gsim is None:
            raise RuntimeError(
                "firmware_sim.gpio.Chip is not bound to a simulated kernel; "
                "use GpioSim(clock).gpiod.Chip(path)"
            )
        self._sim: SimChip | None = gsim._lookup(path)
        self._path = path

    def __bool__(self) -> bool:
        return self._sim is not None

    def __enter__(self) -> Chip:
        self._check_closed()
        return self

    def __exit__(self, exc_type, exc_value, traceback) -> None:
        self.close()

    def _check_closed(self) -> SimChip:
        if self._sim is None:
            raise ChipClosedError()
        return self._sim

    def close(self) -> None:
        """Close the chip handle (requests made through it stay valid)."""
        self._sim = None

    @property
    def path(self) -> str:
        """Filesystem path used to open this chip."""
        self._check_closed()
        return self._path

    def get_info(self) -> ChipInfo:
        """Chip name, label and number of lines."""
        sim = self._check_closed()
        return ChipInfo(name=sim.name, label=sim.label, num_lines=sim.num_lines)

    def line_offset_from_id(self, id: str | int) -> int:
        """Map a line name or offset to its offset on this chip."""
        sim = self._check_closed()
        if not isinstance(id, int):
            for ln in sim._lines:
                if ln.name and ln.name == id:
                    return ln.offset
            try:
                offset = int(id)
            except ValueError:
                raise OSError(_errno.ENOENT, f"{os.strerror(_errno.ENOENT)}: no line named {id!r}") from None
        else:
            offset = id
        if not 0 <= offset < sim.num_lines:
            raise ValueError("line offset of out range")
        return offset

    def request_lines(
        self,
        config: dict[Any, LineSettings | None],
        consumer: str | None = None,
        event_buffer_size: int | None = None,
        output_values: dict[int | str, Value] | None = None,
    ) -> LineRequest:
        """Request a set of lines for exclusive use (see ``gpiod.Chip.request_lines``)."""
        sim = self._check_closed()
        mapped_out = None
        if output_values:
            mapped_out = {self.line_offset_from_id(k): v for k, v in output_values.items()}
        cfg: dict[int, LineSettings] = {}
        lines: list[int | str] = []
        name_map: dict[str, int] = {}
        for key, settings in config.items():
            keys = [key] if isinstance(key, (int, str)) else list(key)
            for line_id in keys:
                off = self.line_offset_from_id(line_id)
                if off in cfg:
                    raise ValueError(f"line must be configured exactly once - offset {off} repeats")
                s = _normalise_settings(settings)
                if mapped_out is not None:
                    s = _replace(s, output_value=_coerce(Value, mapped_out.get(off, Value.INACTIVE), "output_values"))
                cfg[off] = s
                lines.append(line_id)
                if isinstance(line_id, str):
                    name_map[line_id] = off
                elif sim._lines[off].name and sim._lines[off].name not in name_map:
                    name_map[sim._lines[off].name] = off
        if not cfg:
            raise ValueError("config must name at least one line")
        req = LineRequest(sim, cfg, lines, name_map, consumer, event_buffer_size)
        sim._claim(req, cfg)
        return req

    def __repr__(self) -> str:
        return "<Chip CLOSED>" if self._sim is None else f'Chip("{self._path}")'


# --------------------------------------------------------------------------
# The simulated kernel


class GpioSim:
    """A simulated GPIO subsystem: chips by path, sharing one virtual clock.

    Parameters
    ----------
    clock : VirtualClock
        Simulated time; edge events are time-stamped with it and scheduled
        input changes are applied as it advances.
    """

    def __init__(self, clock: Any, *, state_dir: str | os.PathLike | None = None) -> None:
        self.clock = clock
        self.lock = threading.RLock()
        self._chips: dict[str, SimChip] = {}
        #: Where line states are mirrored for other processes (None: not mirrored).
        self.state_dir = None if state_dir is None else LineStateDir(state_dir)
        clock.on_advance(self._on_advance)
        self.gpiod = self._make_module()

    def add_chip(
        self,
        path: str = "/dev/gpiochip0",
        num_lines: int = 54,
        label: str = "sim-gpio",
        line_names: dict[int, str] | None = None,
    ) -> SimChip:
        """Create a chip at ``path`` (54 lines like the Pi's main GPIO bank)."""
        with self.lock:
            if path in self._chips:
                raise ValueError(f"a simulated GPIO chip already exists at {path!r}")
            chip = SimChip(self, path, num_lines, label, line_names)
            self._chips[path] = chip
            return chip

    def chip(self, path: str) -> SimChip:
        """The simulator-side view of the chip at ``path``."""
        return self._lookup(path)

    def _lookup(self, path: str) -> SimChip:
        try:
            return self._chips[str(path)]
        except KeyError:
            raise FileNotFoundError(
                _errno.ENOENT, f"{os.strerror(_errno.ENOENT)}: no simulated GPIO chip at", str(path)
            ) from None

    def _on_advance(self, t_old: float, t_new: float) -> None:
        for chip in list(self._chips.values()):
            chip._process_until(t_new)

    def _mirror(self, chip: SimChip, ln: _Line, t: float | None = None) -> None:
        """Write one line's state to ``state_dir`` (if set), with the holder's pid."""
        if self.state_dir is None:
            return
        self.state_dir.write(chip.name, ln.offset, {
            "t_s": self.clock.now() if t is None else t, "level": ln.level,
            "direction": ln.settings.direction.name, "bias": ln.settings.bias.name,
            "active_low": ln.settings.active_low,
            "consumer": None if ln.request is None else ln.request._consumer,
            "pid": None if ln.request is None else os.getpid()})

    def _make_module(self) -> types.SimpleNamespace:
        bound_chip = type("Chip", (Chip,), {"_gsim": self, "__module__": __name__})
        gsim = self

        def request_lines(
            path: str,
            config: dict[Any, LineSettings | None],
            consumer: str | None = None,
            event_buffer_size: int | None = None,
            output_values: dict[int | str, Value] | None = None,
        ) -> LineRequest:
            """Open the chip at ``path``, request lines, close the chip, return the request."""
            with bound_chip(path) as chip:
                return chip.request_lines(
                    config=config,
                    consumer=consumer,
                    event_buffer_size=event_buffer_size,
                    output_values=output_values,
                )

        def is_gpiochip_device(path: str) -> bool:
            """True if ``path`` names a simulated chip."""
            return str(path) in gsim._chips

        return types.SimpleNamespace(
            __name__="firmware_sim.gpio(bound)",
            __version__="2.5.0-sim",
            Chip=bound_chip,
            ChipInfo=ChipInfo,
            LineSettings=LineSettings,
            LineRequest=LineRequest,
            EdgeEvent=EdgeEvent,
            ChipClosedError=ChipClosedError,
            RequestReleasedError=RequestReleasedError,
            line=line,
            request_lines=request_lines,
            is_gpiochip_device=is_gpiochip_device,
            sim=self,
        )

