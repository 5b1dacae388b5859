"""``gpiod.line``: the line enums (values equal those of libgpiod's python bindings)."""

from __future__ import annotations

from enum import Enum
from typing import Any

__all__ = ["Value", "Direction", "Bias", "Drive", "Edge", "Clock", "coerce_enum"]


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


def coerce_enum(enum_cls: type[Enum], value: Any, what: str) -> Any:
    """Accept our enum members, or members of the real gpiod enums by name."""
    if isinstance(value, enum_cls):
        return value
    name = getattr(value, "name", None)
    if isinstance(name, str) and name in enum_cls.__members__:
        return enum_cls[name]
    raise TypeError(f"{what} must be a {enum_cls.__name__} member, got {value!r}")
