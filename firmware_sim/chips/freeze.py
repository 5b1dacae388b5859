"""A converter that freezes from a time on (the scene's ``converter_frozen`` fault), for every chip emulator.

A frozen converter completes no conversion: the MCP9600's hot-junction registers and its
STATUS update flag stop changing, an ADS1115 single shot never reports done (OS stays 0) and in
continuous mode its result register stops changing, an ADS122C04 never sets DRDY. The I2C
interface still answers -- a locked-up modulator or a dead conversion clock, not a missing chip
(that is ``i2c_nack``). A window may end (``until_s``): the converter then resumes.
"""

from __future__ import annotations

import math

__all__ = ["Freezable"]


class Freezable:
    """Mix-in: :meth:`freeze` windows and the queries the emulators' conversion loops ask."""

    _freezes: list[tuple[float, float]]

    def freeze(self, at_s: float, until_s: float | None = None) -> None:
        """Complete no conversion ending in ``[at_s, until_s)`` (``until_s`` None: never again)."""
        if not hasattr(self, "_freezes"):
            self._freezes = []
        self._freezes.append((float(at_s), math.inf if until_s is None else float(until_s)))

    def frozen_at(self, t_s: float) -> bool:
        """Whether a conversion ending at ``t_s`` is lost to a freeze."""
        return any(a <= t_s < b for a, b in getattr(self, "_freezes", ()))

    def thaw_s(self, t_s: float) -> float:
        """When the freeze holding ``t_s`` ends (``t_s`` itself when none holds it; inf: never)."""
        t = float(t_s)
        while True:
            ends = [b for a, b in getattr(self, "_freezes", ()) if a <= t < b]
            if not ends:
                return t
            t = max(ends)
            if math.isinf(t):
                return t
