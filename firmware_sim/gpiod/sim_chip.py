"""``SimChip``: the hardware side of one simulated GPIO chip.

The simulator drives inputs at virtual times (:meth:`SimChip.schedule_input`,
:meth:`SimChip.press`) and reads back the physical level of every line
(:meth:`SimChip.level`, :meth:`SimChip.line_history`, :meth:`SimChip.level_at`),
from which the thermal world reads the heater-enable state. Scheduled changes
and debounce expiries are applied in time order as the clock advances; edges
are reported to the request holding the line
(:meth:`firmware_sim.gpiod.line_request.LineRequest._push_event`).
"""

from __future__ import annotations

import bisect
import errno as _errno
import heapq
import itertools
import os
from typing import Any, Iterable

from firmware_sim.gpiod.edge_event import EdgeEvent
from firmware_sim.gpiod.line import Bias, Direction, Edge, Value, coerce_enum
from firmware_sim.gpiod.line_settings import LineSettings, replace_settings
from firmware_sim.gpiod.sim_line import SimLine


__all__ = ["SimChip"]


def _to_ns(t_s: float) -> int:
    return int(round(t_s * 1e9))


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
        gsim: Any,
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
        self._lines = [SimLine(i, names.get(i, ""), t0) for i in range(num_lines)]
        # pending external drives: heap of (t_s, seq, offset, level or None)
        self._pending: list[tuple[float, int, int, int | None]] = []
        self._seq = itertools.count()

    # ---- information

    @property
    def num_lines(self) -> int:
        """Number of lines on the chip."""
        return len(self._lines)

    def _line(self, offset: int) -> SimLine:
        if not isinstance(offset, int) or not 0 <= offset < len(self._lines):
            raise ValueError(
                f"offset must be an int in 0..{len(self._lines) - 1} on {self.path}, got {offset!r}"
            )
        return self._lines[offset]

    def level(self, offset: int) -> int:
        """Current physical level (0 or 1) of line ``offset``."""
        with self._gsim.lock:
            return self._line(offset).level

    def live_line_history(self, offset: int) -> list[tuple[float, int]]:
        """The append-only list behind :meth:`line_history` (read it, never modify it).

        For readers that follow a long session incrementally: no copy per call.
        """
        return self._line(offset).history

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

    def _update_level(self, ln: SimLine, t: float, *, quiet: bool = False) -> None:
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

    def _debounce_expired(self, ln: SimLine, t: float) -> None:
        ln.debounce_due = None
        if ln.level != ln.reported:
            self._report(ln, t)

    def _report(self, ln: SimLine, t: float) -> None:
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

    def _claim(self, req: Any, cfg: dict[int, LineSettings]) -> None:
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
                    s = replace_settings(s, direction=ln.settings.direction)
                if s.bias is Bias.AS_IS:
                    s = replace_settings(s, bias=ln.settings.bias)
                ln.settings = s
                ln.request = req
                if s.direction is Direction.OUTPUT:
                    ln.drive(s.output_value)
                # Requesting a line does not produce edge events.
                self._update_level(ln, now, quiet=True)
                ln.reported = ln.level
                ln.debounce_due = None
                self._gsim._mirror(self, ln)

    def _release(self, offsets: Iterable[int]) -> None:
        with self._gsim.lock:
            now = self._gsim.clock.now()
            for off in offsets:
                ln = self._lines[off]
                ln.release()
                self._update_level(ln, now, quiet=True)
                self._gsim._mirror(self, ln)

    def _get(self, off: int) -> Value:
        with self._gsim.lock:
            self._process_until(self._gsim.clock.now())
            # Inputs with a debouncer read the debounced level, as in the kernel.
            return self._lines[off].logical_value()

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
                ln.drive(coerce_enum(Value, v, "value"))
                self._update_level(ln, now)
