"""``gpiod.LineRequest``: a set of requested lines -- values and edge events in virtual time."""

from __future__ import annotations

from collections import deque
from datetime import timedelta
from typing import Any, Iterable

from firmware_sim.gpiod.edge_event import EdgeEvent
from firmware_sim.gpiod.exception import RequestReleasedError
from firmware_sim.gpiod.line import Value
from firmware_sim.gpiod.line_settings import LineSettings


__all__ = ["LineRequest"]


def _timeout_s(timeout: timedelta | float | None) -> float | None:
    if timeout is None:
        return None
    sec = timeout.total_seconds() if isinstance(timeout, timedelta) else float(timeout)
    if sec < 0:
        raise ValueError(f"timeout must be >= 0, got {timeout!r}")
    return sec


class LineRequest:
    """A set of requested lines (mirrors ``gpiod.LineRequest``).

    Created by :meth:`Chip.request_lines`; not to be instantiated directly.
    """

    def __init__(
        self,
        chip: Any,
        cfg: dict[int, LineSettings],
        lines: list[int | str],
        name_map: dict[str, int],
        consumer: str | None,
        event_buffer_size: int | None,
    ) -> None:
        self._chip: Any = chip  # the SimChip that owns the lines
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

    def _check_released(self) -> Any:
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
