"""Where the thermal worlds get the heater duty from: the board's enable line times its PWM, or a schedule.

:class:`HeaterDrive` is the protocol every world reads (``duty_at``,
``change_times``); :class:`BoardDrive` mirrors a simulated board's GPIO and
PWM histories (the wiring of the heater, :mod:`firmware_sim.wiring`),
:class:`ScheduleDrive` and :class:`ManualDrive` drive a world without a board
(tests, benches).
"""

from __future__ import annotations

from bisect import bisect_right
from typing import Protocol, Sequence

import numpy as np

__all__ = ["HeaterDrive", "BoardDrive", "ScheduleDrive", "ManualDrive"]


class HeaterDrive(Protocol):
    """Where the commanded heater duty comes from."""

    def duty_at(self, t_s: float) -> float:
        """Commanded effective duty (0..1) at ``t_s``, enable line included."""

    def change_times(self) -> Sequence[float]:
        """Every time the duty may have changed (s), any order."""


class BoardDrive:
    """Heater duty from a sim board's enable line and PWM channel.

    The GPIO and PWM fakes record every change (append-only histories); this
    drive mirrors them incrementally, so :meth:`duty_at` is a bisection and
    :meth:`changes_since` returns only what is new -- neither grows with the
    length of the session.
    """

    def __init__(self, parts) -> None:
        self.parts = parts
        self._en_t: list[float] = []
        self._en_level: list[int] = []
        self._pwm_t: list[float] = []
        self._pwm_frac: list[float] = []

    def _histories(self) -> tuple[Sequence, Sequence]:
        # The fakes' live append-only lists: O(1) per call, however long the session.
        p = self.parts
        return p.chip.live_line_history(p.heater_enable_offset), p.pwm_tree.live_history(p.pwm_chip, p.pwm_channel)

    def _sync(self) -> None:
        en, pwm = self._histories()
        if len(en) < len(self._en_t) or len(pwm) < len(self._pwm_t):   # not append-only: start over
            self._en_t, self._en_level, self._pwm_t, self._pwm_frac = [], [], [], []
        for t, level in en[len(self._en_t):]:
            self._en_t.append(float(t))
            self._en_level.append(level)
        for h in pwm[len(self._pwm_t):]:
            self._pwm_t.append(float(h.t_s))
            self._pwm_frac.append(float(h.fraction))

    def duty_at(self, t_s: float) -> float:
        """``parts.heater_duty_at(t_s)`` from the mirrored histories."""
        self._sync()
        if not self._en_t:
            return float(self.parts.heater_duty_at(t_s))
        i = bisect_right(self._en_t, t_s) - 1
        if self._en_level[max(i, 0)] != 1:
            return 0.0
        j = bisect_right(self._pwm_t, t_s) - 1
        return self._pwm_frac[j] if j >= 0 else 0.0

    def change_times(self) -> list[float]:
        self._sync()
        return self._en_t + self._pwm_t

    def changes_since(self, revision) -> tuple[tuple[int, int], list[float]]:
        """``(revision, times)``: the change times recorded since ``revision`` (None: all)."""
        en, pwm = self._histories()
        if revision is not None and revision == (len(en), len(pwm)) == (len(self._en_t), len(self._pwm_t)):
            return revision, []
        self._sync()
        a, b = (0, 0) if revision is None else revision
        return (len(self._en_t), len(self._pwm_t)), self._en_t[a:] + self._pwm_t[b:]


class ScheduleDrive:
    """A fixed duty schedule: ``duties[i]`` from ``times_s[i]`` on (0 before)."""

    def __init__(self, times_s: Sequence[float], duties: Sequence[float]) -> None:
        self.times = np.asarray(times_s, dtype=float)
        self.duties = np.asarray(duties, dtype=float)
        if self.times.shape != self.duties.shape or self.times.ndim != 1:
            raise ValueError("times_s and duties must be 1-D sequences of the same length")
        if np.any(np.diff(self.times) <= 0):
            raise ValueError("times_s must be strictly increasing")
        if np.any((self.duties < 0) | (self.duties > 1)):
            raise ValueError("duties must lie in [0, 1]")

    def duty_at(self, t_s: float) -> float:
        i = int(np.searchsorted(self.times, t_s, side="right")) - 1
        return float(self.duties[i]) if i >= 0 else 0.0

    def change_times(self) -> list[float]:
        return self.times.tolist()

    def changes_since(self, revision) -> tuple[int, list[float]]:
        """``(revision, times)``: all change times the first time, none after (the schedule is fixed)."""
        return 1, ([] if revision == 1 else self.times.tolist())


class ManualDrive:
    """A duty set as time goes on (a session driven without a board): ``set(t_s, duty)``.

    Times may not decrease; a later entry at the same time wins.
    """

    def __init__(self) -> None:
        self._t: list[float] = []
        self._d: list[float] = []

    def set(self, t_s: float, duty: float) -> None:
        t, d = float(t_s), float(duty)
        if self._t and not t >= self._t[-1]:
            raise ValueError(f"t_s={t_s} s is before the last setting ({self._t[-1]} s)")
        if not 0.0 <= d <= 1.0:
            raise ValueError(f"duty must lie in [0, 1], got {duty!r}")
        self._t.append(t)
        self._d.append(d)

    def duty_at(self, t_s: float) -> float:
        i = bisect_right(self._t, t_s) - 1
        return self._d[i] if i >= 0 else 0.0

    def change_times(self) -> list[float]:
        return list(self._t)

    def changes_since(self, revision) -> tuple[int, list[float]]:
        """``(revision, times)``: the settings' times since ``revision`` (None: all)."""
        return len(self._t), self._t[revision or 0:]
