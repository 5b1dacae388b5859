"""A bounded, thread-safe memo of read-only arrays keyed by exact inputs (NumPy only).

The fits evaluate the same pieces over and over -- a calibration rebuilds every touch's chain
for each trial of the probe's parameters, a model's set-up asks for the same Bessel values on the
same nodes -- and most pieces depend on only some of the parameters.  Keys hold the inputs
exactly (floats, ints, and arrays as ``tobytes()``), so a hit returns the very numbers a
recomputation gives; values are arrays (or tuples of arrays) made read-only, shared by every
caller.  Least recently used entries go first, once there are more than ``max_entries`` or (given
``max_bytes``) their arrays hold more bytes than that; the last entry kept is never evicted.
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


def _nbytes(value: Any) -> int:
    if isinstance(value, np.ndarray):
        return int(value.nbytes)
    if isinstance(value, tuple):
        return sum(_nbytes(v) for v in value)
    return 0


class BoundedMemo:
    """At most ``max_entries`` values (and ``max_bytes`` of their arrays) by key, least recently used evicted first."""

    def __init__(self, max_entries: int, max_bytes: int | None = None) -> None:
        self.max_entries = int(max_entries)
        self.max_bytes = None if max_bytes is None else int(max_bytes)
        self._d: OrderedDict = OrderedDict()
        self._lock = threading.Lock()
        self._bytes = 0

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays kept."""
        return self._bytes

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
        size = _nbytes(value)
        with self._lock:
            old = self._d.pop(key, None)
            if old is not None:
                self._bytes -= _nbytes(old)
            self._d[key] = value
            self._bytes += size
            while len(self._d) > 1 and (len(self._d) > self.max_entries
                                        or (self.max_bytes is not None and self._bytes > self.max_bytes)):
                _, gone = self._d.popitem(last=False)
                self._bytes -= _nbytes(gone)
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
            self._bytes = 0
