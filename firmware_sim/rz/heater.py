"""The faithful world's heater film: duty, supply, resistance with its TCR, and the power they make.

:class:`FilmHeater` is a mix-in of :class:`firmware_sim.rz.probe_world.FaithfulWorld`: the
electrical side of the world (the duty the drive commands or a heater fault overrides, the
supply with any sag, ``P = d V^2 / R(T_heater)``, the switching instants the march integrates
over exactly).  The host supplies ``scene``, ``clock``, ``drive``, ``stack``, ``as_built``,
``R0``, ``_faults``, the switch-time cache (``_drive_rev``, ``_drive_times``, ``_sw``,
``_sw_faults``), the march's ``_steps`` and ``_advance_to``, and ``_resistance_in_step``.
"""

from __future__ import annotations

import numpy as np

from edge.physics.probe import heater_power_W
from edge.physics.schedule import PowerSchedule
from firmware_sim.heater_faults import HEATER_FAULTS, effective_duty, supply_voltage

__all__ = ["FilmHeater"]


class FilmHeater:
    """Heater power of the faithful world (a mix-in; see the module docstring)."""

    def duty_at(self, t_s: float) -> float:
        """Effective duty at ``t_s``: commanded, unless a heater fault overrides it."""
        return effective_duty(self._faults, t_s, self.drive.duty_at(t_s) if self.drive is not None else 0.0)

    def supply_voltage_at(self, t_s: float) -> float:
        """Heater supply voltage (V) at ``t_s``, with any sag."""
        return supply_voltage(self._faults, t_s, self.scene.heater.supply_voltage_V)

    def _switch_times(self) -> np.ndarray:
        """Every time the duty or supply may change (drive and heater faults), sorted.

        Every query asks; a drive that reports its changes incrementally
        (``changes_since``: the board's, ScheduleDrive, ManualDrive) is read
        only for what is new, so a long session costs no more per query.
        """
        d = self.drive
        since = getattr(d, "changes_since", None) if d is not None else None
        n_faults = len(self._faults)
        if since is not None:
            rev, new = since(self._drive_rev)
            if rev == self._drive_rev and not new and n_faults == self._sw_faults and self._sw is not None:
                return self._sw
            self._drive_rev = rev
            self._drive_times.update(float(x) for x in new)
            times = set(self._drive_times)
        else:
            times = set(d.change_times()) if d is not None else set()
        for f in self._faults:
            if f.kind in HEATER_FAULTS:
                times.add(f.at_s)
                if f.until_s is not None:
                    times.add(f.until_s)
        self._sw = np.array(sorted(times), dtype=float)
        self._sw_faults = n_faults
        return self._sw

    def _dv2(self, t: float) -> float:
        """duty * V^2 at ``t`` (W ohm)."""
        return heater_power_W(self.duty_at(t), self.supply_voltage_at(t), 1.0)

    def _nominal_energy(self, t_a: float, t_b: float, switches: np.ndarray) -> float:
        """Integral of duty * V^2 over [t_a, t_b) (J ohm), exact over the switching instants."""
        i0 = switches.searchsorted(t_a, side="right")
        i1 = switches.searchsorted(t_b, side="right")
        if i0 == i1:
            # No switch inside the step (nearly every step): the one piece, summed as below.
            return 0 + self._dv2(t_a) * (t_b - t_a)
        edges = [t_a] + [float(x) for x in switches[i0:i1] if t_a < x < t_b] + [t_b]
        return sum(self._dv2(a) * (b - a) for a, b in zip(edges[:-1], edges[1:]))

    def resistance_ohm(self, T_heater_C: float) -> float:
        """Film resistance (ohm) at ``T_heater_C``."""
        r = self.R0 * (1.0 + self.as_built.heater_tcr_per_K * (T_heater_C - self.as_built.heater_reference_C))
        if not r > 0:
            raise ValueError(f"heater resistance {r} ohm at {T_heater_C} degC: TCR out of range")
        return r

    def _film_power(self, dv2: float, R: float) -> float:
        """Power in a film of resistance ``R`` for ``d V^2 = dv2``, less what its leads take (W)."""
        r_lead = self.as_built.heater_lead_resistance_ohm
        if r_lead == 0.0:
            return dv2 / R
        return dv2 * R / (R + r_lead) ** 2

    def heater_power_W(self, t_s: float) -> float:
        """Electrical power in the film at ``t_s`` (W), ``d V^2 R / (R + R_lead)^2`` with ``R = R(T_heater)``."""
        dv2 = self._dv2(float(t_s))
        if dv2 == 0.0:
            return 0.0
        if self.as_built.heater_tcr_per_K == 0.0:
            return self._film_power(dv2, self.R0)
        return self._film_power(dv2, self._resistance_in_step(float(t_s)))

    def q_v_at(self, t_s: float) -> float:
        """Heater power density at ``t_s`` (W/m^3) over the nominal film."""
        return self.stack.q_v_from_power(self.heater_power_W(t_s))

    def power_schedule(self, t_end_s: float | None = None) -> PowerSchedule:
        """q_v(t) from 0 to ``t_end_s`` (default now): switching instants, and with a TCR every step start."""
        t_end = self.clock.now() if t_end_s is None else float(t_end_s)
        sw = self._switch_times()
        times = {0.0} | {float(x) for x in sw if 0.0 < x <= t_end + 1e-12}
        if self.as_built.heater_tcr_per_K != 0.0 and t_end > 0:
            self._advance_to(t_end)
            times |= {s[0] for s in self._steps if 0.0 < s[0] <= t_end}
        ts = sorted(times)
        q = [self.q_v_at(t) for t in ts]
        keep = [0] + [i for i in range(1, len(q)) if q[i] != q[i - 1]]
        return PowerSchedule(np.array([ts[i] for i in keep]), np.array([q[i] for i in keep]))
