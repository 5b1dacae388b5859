"""``gpiod.LineSettings``: the properties requested for one line."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import timedelta
from typing import Any

from firmware_sim.gpiod.line import Bias, Clock, Direction, Drive, Edge, Value, coerce_enum

__all__ = ["LineSettings", "normalise_settings", "replace_settings"]


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


def normalise_settings(s: Any) -> LineSettings:
    """Copy settings (ours or real gpiod's) into a validated LineSettings."""
    if s is None:
        return LineSettings()
    deb = getattr(s, "debounce_period", timedelta())
    if not isinstance(deb, timedelta):
        raise TypeError(f"debounce_period must be a datetime.timedelta, got {deb!r}")
    if deb < timedelta():
        raise ValueError(f"debounce_period must be >= 0, got {deb!r}")
    return LineSettings(
        direction=coerce_enum(Direction, s.direction, "direction"),
        edge_detection=coerce_enum(Edge, s.edge_detection, "edge_detection"),
        bias=coerce_enum(Bias, s.bias, "bias"),
        drive=coerce_enum(Drive, s.drive, "drive"),
        active_low=bool(s.active_low),
        debounce_period=deb,
        event_clock=coerce_enum(Clock, s.event_clock, "event_clock"),
        output_value=coerce_enum(Value, s.output_value, "output_value"),
    )


def replace_settings(s: LineSettings, **kw: Any) -> LineSettings:
    """A copy of ``s`` with the given properties replaced."""
    d = dict(s.__dict__)
    d.update(kw)
    return LineSettings(**d)
