"""The simulated state of one GPIO line (all levels physical: 0 low, 1 high).

What decides a line's level: an output drives its ``out_value``; an input
follows what drives it from outside, else its bias (pull-up reads high,
pull-down or a floating input read low -- deterministically).

What a released line does
-------------------------
Releasing a request (or the death of the process holding it: the kernel
releases a dead process's requests) drops the request and any pending
debounce, and the line stops being driven: with a pull-up or pull-down bias
it returns to an input at that level; with no bias it keeps its direction
and driven level, as most GPIO controllers do. Device code that needs a safe
level after its own death requests the line with the bias that pulls it
there (:meth:`edge.hw.board.GpioLine.request_fail_safe_output`).
"""

from __future__ import annotations

from datetime import timedelta
from typing import Any

from firmware_sim.gpiod.line import Bias, Direction, Value
from firmware_sim.gpiod.line_settings import LineSettings


__all__ = ["SimLine"]


class SimLine:
    """State of one simulated line."""

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
        self.request: Any = None  # the LineRequest holding the line, if any
        self.out_value = 0  # physical level driven while an output
        self.level = 0
        self.reported = 0  # debounced level as seen by edge detection
        self.debounce_due: float | None = None
        self.history: list[tuple[float, int]] = [(t0, 0)]

    def is_output(self) -> bool:
        return self.settings.direction is Direction.OUTPUT

    def effective_level(self) -> int:
        """The physical level the line's drivers and bias produce now."""
        if self.is_output():
            return self.out_value
        if self.external is not None:
            return self.external
        if self.settings.bias is Bias.PULL_UP:
            return 1
        return 0  # pull-down, or a floating input read deterministically as low

    def logical_value(self) -> Value:
        """The value a request reads: debounced for inputs with a debouncer, the driven one for outputs."""
        lvl = self.reported if self.settings.debounce_period > timedelta() else self.level
        if self.is_output():
            lvl = self.out_value
        return Value((lvl == 1) != self.settings.active_low)

    def drive(self, value: Value) -> None:
        """Set the driven (physical) output level from a logical ``value``."""
        self.out_value = int(bool(value)) ^ int(self.settings.active_low)

    def release(self) -> None:
        """Drop the request (see the module docstring: a biased output falls back to its bias)."""
        self.request = None
        self.debounce_due = None
        direction = self.settings.direction
        if direction is Direction.OUTPUT and self.settings.bias in (Bias.PULL_UP, Bias.PULL_DOWN):
            direction = Direction.INPUT
        self.settings = LineSettings(direction=direction, bias=self.settings.bias)
