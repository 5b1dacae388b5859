"""A bounded, thread-safe memo of read-only arrays keyed by exact inputs (NumPy only).

The fits evaluate the same pieces over and over -- a calibration rebuilds every touch's chain
for each trial of the probe's parameters, a model's set-up asks for the same Bessel values on the
same nodes -- and most pieces depend on only some of the parameters.  Keys hold the inputs
exactly (floats, ints, and arrays as ``tobytes()``), so a hit returns the very numbers a
recomputation gives; values are arrays (or tuples of arrays) made read-only, shared by every
caller.  Least recently used entries go first.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Any, Callable

import numpy as np

__all__ = ["BoundedMemo"]


def _freeze(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        value.flags.writeable = False
    elif isinstance(value, tuple):
        for v in value:
            _freeze(v)
    return value


class BoundedMemo:
    """At most ``max_entries`` values by key, least recently used evicted first."""

    def __init__(self, max_entries: int) -> None:
        self.max_entries = int(max_entries)
        self._d: OrderedDict = OrderedDict()
        self._lock = threading.Lock()

    def get(self, key: tuple) -> Any:
        """The value kept under ``key``, or None."""
        with self._lock:
            hit = self._d.get(key)
            if hit is not None:
                self._d.move_to_end(key)
            return hit

    def put(self, key: tuple, value: Any) -> Any:
        """Keep ``value`` (made read-only) under ``key``; returns it."""
        _freeze(value)
        with self._lock:
            self._d[key] = value
            self._d.move_to_end(key)
            while len(self._d) > self.max_entries:
                self._d.popitem(last=False)
        return value

    def __call__(self, key: tuple, compute: Callable[[], Any]) -> Any:
        """The value under ``key``, computed by ``compute()`` and kept if absent."""
        hit = self.get(key)
        return hit if hit is not None else self.put(key, compute())

    def __len__(self) -> int:
        return len(self._d)

    def clear(self) -> None:
        with self._lock:
            self._d.clear()
