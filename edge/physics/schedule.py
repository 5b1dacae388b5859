"""Piecewise-constant heater power density q_v(t).

The probe model is linear in q_v, so any drive - constant, stepped, or the
PWM-averaged series of the real heater - is a sum of steps.  A schedule is a
list of switching times and the q_v that holds from each one on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from edge.checks import finite_array, finite_nonnegative, strictly_increasing


@dataclass(frozen=True)
class PowerSchedule:
    """q_v(t) = q_v_W_m3[j] for t_start_s[j] <= t < t_start_s[j+1] (W/m^3).

    ``t_start_s[0]`` must be 0 (heating starts with the record); the last value
    holds to the end of the record.
    """

    t_start_s: np.ndarray
    q_v_W_m3: np.ndarray
    #: Allow negative values: a measured surface flux used as a drive.
    signed: bool = False

    def __post_init__(self) -> None:
        t = finite_array("q_v_times_s", self.t_start_s)
        q = finite_array("q_v_W_m3", self.q_v_W_m3)
        if t.shape != q.shape:
            raise ValueError(
                f"q_v_W_m3 has {q.size} values but q_v_times_s has {t.size}: the series must match"
            )
        if t[0] != 0.0:
            raise ValueError(f"q_v_times_s must start at 0, got {t[0]!r}")
        strictly_increasing("q_v_times_s", t)
        if not self.signed and np.any(q < 0):
            raise ValueError("q_v_W_m3 must be >= 0 (the heater only heats)")
        object.__setattr__(self, "t_start_s", t)
        object.__setattr__(self, "q_v_W_m3", q)

    @classmethod
    def constant(cls, q_v_W_m3: float) -> "PowerSchedule":
        """A heater switched on at t = 0 at constant q_v (W/m^3)."""
        return cls(np.array([0.0]), np.array([finite_nonnegative("q_v_W_m3", q_v_W_m3)]))

    @classmethod
    def coerce(cls, q_v, q_v_times_s=None) -> "PowerSchedule":
        """Accept a schedule, a scalar q_v, or a series with its switching times."""
        if isinstance(q_v, PowerSchedule):
            return q_v
        if np.ndim(q_v) == 0:
            if q_v_times_s is not None:
                raise ValueError("q_v_times_s given but q_v is a scalar")
            return cls.constant(q_v)
        if q_v_times_s is None:
            raise ValueError("q_v is a series: q_v_times_s (switching times, s) is required")
        return cls(np.asarray(q_v_times_s), np.asarray(q_v))

    def value_at(self, t_s: np.ndarray) -> np.ndarray:
        """q_v at times ``t_s`` (right-continuous)."""
        idx = np.searchsorted(self.t_start_s, np.asarray(t_s, dtype=float), side="right") - 1
        return self.q_v_W_m3[np.clip(idx, 0, None)]

    def energy_density(self, t_end_s: float) -> float:
        """Integral of q_v from 0 to ``t_end_s`` (J/m^3)."""
        edges = np.append(self.t_start_s, np.inf)
        dur = np.clip(np.minimum(edges[1:], t_end_s) - edges[:-1], 0.0, None)
        return float(np.dot(dur, self.q_v_W_m3))

    @property
    def peak(self) -> float:
        """Largest q_v in the schedule (W/m^3)."""
        return float(self.q_v_W_m3.max())
