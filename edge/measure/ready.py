"""Is the probe ready for the next touch? Its temperature has settled (STATUS ``ready``).

After a touch the heated probe relaxes towards a steady temperature; a
baseline taken before it has settled drifts, and a drifting baseline is what
the sequence flags ``unstable_baseline`` (drift of the straight-line fit over
the baseline above ``measurement.unstable_baseline_K``). :class:`Readiness`
applies that same test to idle readings of the probe, over the last
``baseline_s`` of board-clock time: ready when the window is covered and its
drift is below the threshold. A robot polls STATUS and touches when
``ready`` is true instead of waiting a fixed cool-down.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

__all__ = ["Readiness"]

#: Most idle readings kept (at 200 Hz, 10 s).
_MAX_READINGS = 2000


class Readiness:
    """Idle readings of the probe temperature on the board clock, and whether they have settled."""

    def __init__(self) -> None:
        self._t: deque[float] = deque(maxlen=_MAX_READINGS)
        self._T: deque[float] = deque(maxlen=_MAX_READINGS)

    @property
    def last_t(self) -> float:
        """Board-clock time of the latest reading (-inf: none)."""
        return self._t[-1] if self._t else -math.inf

    def reset(self) -> None:
        """Forget every reading (after a heating, or a failed read)."""
        self._t.clear()
        self._T.clear()

    def add(self, t_s: float, T_C: float) -> None:
        """One reading: board-clock time (s), thermocouple (°C)."""
        if self._t and t_s <= self._t[-1]:
            return  # the clock did not move: nothing new to judge by
        if not math.isfinite(T_C):
            self.reset()
            return
        self._t.append(float(t_s))
        self._T.append(float(T_C))

    def drift_K(self, window_s: float) -> float | None:
        """Temperature change over the last ``window_s`` from its straight-line fit; None until covered."""
        if len(self._t) < 3:
            return None
        t = np.fromiter(self._t, float)
        T = np.fromiter(self._T, float)
        last = t[-1]
        if last - t[0] < window_s * 0.999:
            return None
        keep = t >= last - window_s
        if keep.sum() < 3:
            keep[-3:] = True
        x = t[keep] - t[keep][0]
        span = float(x[-1])
        if not span > 0:
            return None
        return float(np.polyfit(x, T[keep], 1)[0]) * span

    def settled(self, window_s: float, max_drift_K: float) -> bool:
        """Whether the last ``window_s`` of readings drift by less than ``max_drift_K``."""
        d = self.drift_K(window_s)
        return d is not None and abs(d) < max_drift_K
