"""The thermal world behind the simulated chips.

Heater power comes from the board's enable line and PWM duty (or a fault) times
``V**2 / R`` of the scene's supply and film; it is a piecewise-constant power
density ``q_v(t)`` over virtual time. The probe stack on the object is solved
exactly in the Laplace domain (:mod:`edge.physics.laplace`: thermal quadrupoles, fixed
Talbot inversion) with the scene's finite thickness, back boundary and contact
resistance -- more faithful than anything the edge inverts, and never fed by
the edge's estimates. Outputs:

* thermocouple hot junction (°C): ``T_f`` at the bottom of the sensing layer
  through a first-order lag ``1 / (1 + tau s)`` (tau = the scene's
  thermocouple time constant);
* flux-sensor voltage (V): ``S * q_f`` with ``q_f`` clipped to the sensor's
  range;
* cold junction (°C): the board, at ambient temperature.

Phases
------
Virtual time is cut into phases with the probe in contact with the object
(the scene's touch and any added with :meth:`ThermalWorld.add_touch`, minus
``no_contact`` fault windows) or in still air
(before/after the touch, and while ``no_contact`` holds). With ``[touch]
repeat`` (the default) the probe is put down again ``repeat_gap_s`` after
each touch and stays until ``REPEAT_RELEASE_S`` after the next heating ends:
touch after touch, with the probe in air in between. Within a phase the
system is linear and time-invariant, so the answer is exact superposition of

* the unit-step responses of every heater switching in the phase, and
* the phase's initial condition: the probe (heater + sensing layer, one
  material) at a uniform temperature -- its mean temperature at the end of
  the previous phase, from an energy balance -- touching an object at its own
  base temperature. Its transform is ``T_f = theta0 / s * K / (K + Y)`` with
  ``K = k a tanh(a L)`` of the probe and ``Y`` the object's admittance
  (contact resistance included).

The uniform-probe initial condition is the one approximation: it matters only
when the heater ran before the touch or the probe and object start at
different temperatures. Air is modelled as a semi-infinite still-air solid
(pure conduction, no convection); an object touched a second time (after a
``no_contact`` gap) is taken as back at its initial temperature.

Evaluation
----------
Lazy and batched. The chips ask for values at the times they sample, on a
regular grid (a converter's conversion period). The world notices the grid
per caller (a *stream*: the MCP9600's hot junction, the ADS1115's flux
input, ...) and on a miss evaluates the asked time together with the grid
times ahead of it (up to ``_LOOKAHEAD_S``, at most ``_LOOKAHEAD_MAX`` times,
within the phase) in one vectorised Talbot inversion. Those look-ahead values
assume the heater drive, faults and touches known at the time; when any of
them changes, the values from the change on are dropped. A query within
``_MATCH_TOL_S`` of a look-ahead time (the chip's float arithmetic drifts
from the predicted grid by a few ulps) is answered from it to first order
(the time derivatives come from the same inversion), i.e. exactly. Results
at times before "now" are cached (the past no longer changes; at most
``_CACHE_MAX`` states).

Cost that does not grow with the session
----------------------------------------
Superposition restarts at every phase boundary from the phase's start state
(two numbers, above), so an evaluation superposes only the terms of its own
phase: the initial condition and the heater switchings inside the phase.
Phases that ended are kept as a compact record (start time, contact flag,
start state: 4 doubles each) for queries into the past and never
re-superposed; locating a phase or the switchings inside it is a bisection,
and the board's GPIO/PWM histories are read incrementally
(:meth:`BoardDrive.changes_since`). A heater switching's influence does not
decay below the noise within a phase here -- a pulse's heat stays in an
insulated sample, and still air gives it up over hours -- so nothing inside
a phase is dropped; what bounds the work is the restart at the phase
boundaries. :attr:`ThermalWorld.stats` counts the work (Talbot calls, rows =
terms x times, most terms at one time, phase-end evaluations).
"""

from __future__ import annotations

import math
from array import array
from bisect import bisect_left, bisect_right
from dataclasses import dataclass
from typing import NamedTuple, Sequence

import numpy as np

from edge.physics import laplace
from edge.physics.probe import heater_power_W
from edge.physics.schedule import PowerSchedule
from edge.physics.solids import Solid

from firmware_sim.drive import BoardDrive, HeaterDrive, ManualDrive, ScheduleDrive
from firmware_sim.heater_faults import HEATER_FAULTS, WORLD_FAULTS, active, effective_duty, supply_voltage
from firmware_sim.scene.model import Fault, Scene
from firmware_sim.world_protocol import OPEN_TC_INPUT_V, REPEAT_RELEASE_S, SensorSignals, Truth, WorldState

# The drives, the states and the constants are re-exported: their home was this module.
__all__ = ["AIR", "HeaterDrive", "BoardDrive", "ScheduleDrive", "ManualDrive", "WorldState", "Truth",
           "ThermalWorld", "OPEN_TC_INPUT_V", "REPEAT_RELEASE_S"]

#: Still air near 300 K (Incropera 7e, Table A.4).
AIR = Solid(k_W_mK=0.0263, rho_kg_m3=1.1614, c_J_kgK=1007.0)
#: Look-ahead of a batched evaluation on a caller's sampling grid (s) and its
#: largest number of times; a query within _MATCH_TOL_S of a look-ahead time uses it.
_LOOKAHEAD_S = 0.1
_LOOKAHEAD_MAX = 128
_MATCH_TOL_S = 1e-9
#: Length given to an open repeat touch until a heating closes it (s).
_OPEN_TOUCH_S = 1e6
#: Past states kept for repeated queries (the cache is cleared when full).
_CACHE_MAX = 8192
#: Rows (times x terms) per Talbot call: bounds the temporary arrays (rows x 24 complex).
_ROWS_PER_CALL = 2048


@dataclass(frozen=True)
class _Phase:
    start_s: float
    end_s: float   # math.inf for the last
    contact: bool


class _Evals(NamedTuple):
    """Exact values at the times of one evaluation (arrays over the times)."""

    surface_C: np.ndarray
    thermocouple_C: np.ndarray
    q_f: np.ndarray
    q_int_J_m2: np.ndarray    # integral of q_f over the phase up to t
    e_heat_J_m2: np.ndarray   # heater energy released in the phase up to t (per area)
    d_surface: np.ndarray | None = None       # time derivatives (K/s, W/m^2/s), if asked for
    d_thermocouple: np.ndarray | None = None
    d_q_f: np.ndarray | None = None


class _Stream:
    """One caller's sampling grid and its look-ahead values."""

    __slots__ = ("last_t", "step", "t", "vals", "n", "next", "lo", "hi", "contact")

    def __init__(self) -> None:
        self.last_t = math.nan
        self.step = math.nan
        self.t: list[float] = []           # look-ahead times; the first self.n are valid
        self.vals: tuple[list[float], ...] = ()   # surface, thermocouple, q_f and their derivatives
        self.n = 0
        self.next = 0
        self.lo = self.hi = 0.0            # the phase they lie in
        self.contact = False


class ThermalWorld(SensorSignals):
    """Exact thermal model of the probe on the scene's object.

    Parameters
    ----------
    scene : Scene
    clock : VirtualClock
        Only ``now()`` is used (to know which past values may be cached).
    drive : HeaterDrive, optional
        Commanded duty; default none (heater off unless a fault turns it on).
    """

    def __init__(self, scene: Scene, clock, drive: HeaterDrive | None = None) -> None:
        self.scene = scene
        self.clock = clock
        self.drive = drive
        self.stack = scene.stack
        self._probe = self.stack.material
        self._L = self.stack.total_thickness_m
        self._faults: list[Fault] = [f for f in scene.faults if f.kind in WORLD_FAULTS]
        # Touch windows, sorted and disjoint: starts and ends (bisection, 16 bytes a touch).
        self._touch_a = array("d", [scene.touch.start_s])
        self._touch_b = array("d", [scene.touch.end_s])
        #: Whether the last touch is an open repeat touch (``[touch] repeat``).
        self._repeat_open = False
        # Phases covering [0, inf): start, contact flag and start state (probe mean and
        # thermocouple, NaN until known); phase k ends where k + 1 starts.
        self._ph_start = array("d")
        self._ph_contact = array("b")
        self._ph_mean = array("d")
        self._ph_y = array("d")
        # Every time q_v may change (drive and heater faults), sorted, unique.
        self._sw = array("d")
        self._drive_rev = None
        self._drive_all: list[float] = []
        self._cache: dict[float, WorldState] = {}
        self._streams: dict[str, _Stream] = {}
        #: Work counters: Talbot calls, rows (terms x times) inverted, times evaluated,
        #: most terms at one time, phase-end evaluations (start states), queries,
        #: queries answered from a look-ahead.
        self.stats = {"talbot_calls": 0, "talbot_rows": 0, "times": 0, "max_terms": 0,
                      "phase_ends": 0, "queries": 0, "lookahead_hits": 0}
        for f in self._faults:
            if f.kind in HEATER_FAULTS:
                self._add_switches([f.at_s] + ([f.until_s] if f.until_s is not None else []))
        self._recut(0.0)
        if scene.touch.repeat:
            self._open_repeat(scene.touch.end_s)

    def repeat_touches(self) -> None:
        """Touch after touch from now on (what ``[touch] repeat = true`` does; no-op if already on)."""
        if self._repeat_open:
            return
        self._open_repeat(max(self._touch_b[-1], self.clock.now()))

    # ---- faults

    @property
    def faults(self) -> tuple[Fault, ...]:
        """Faults the world models (bus faults live on the SimBus)."""
        return tuple(self._faults)

    def add_fault(self, fault: Fault, *, now_s: float | None = None) -> None:
        """Add a fault; it may not start before the current virtual time.

        ``now_s`` is "now" as the caller read it (default: read the clock);
        on a wall clock the clock has moved on by the time this runs, and
        states cached since ``fault.at_s`` are dropped.
        """
        if fault.kind not in WORLD_FAULTS:
            raise ValueError(f"fault kind {fault.kind!r} is not modelled by the thermal world")
        now = self.clock.now() if now_s is None else min(float(now_s), self.clock.now())
        if fault.at_s < now - 1e-12:
            raise ValueError(f"fault at_s={fault.at_s} s is in the past (now {now} s)")
        self._faults.append(fault)
        self._forget_from(fault.at_s)
        if fault.kind in HEATER_FAULTS:
            self._add_switches([fault.at_s] + ([fault.until_s] if fault.until_s is not None else []))
        if fault.kind == "no_contact":
            self._recut(fault.at_s)
        if self._cache and fault.at_s < self.clock.now():
            self._cache = {t: st for t, st in self._cache.items() if t < fault.at_s}

    def _active(self, kind: str, t_s: float) -> list[Fault]:
        return active(self._faults, kind, t_s)

    # ---- heater

    def duty_at(self, t_s: float) -> float:
        """Effective duty at ``t_s``: commanded, unless a heater fault overrides it."""
        return effective_duty(self._faults, t_s, self.drive.duty_at(t_s) if self.drive is not None else 0.0)

    def supply_voltage_at(self, t_s: float) -> float:
        """Heater supply voltage (V) at ``t_s``, with any sag."""
        return supply_voltage(self._faults, t_s, self.scene.heater.supply_voltage_V)

    def heater_power_W(self, t_s: float) -> float:
        """Electrical power in the film at ``t_s`` (W)."""
        return heater_power_W(self.duty_at(t_s), self.supply_voltage_at(t_s), self.scene.heater.resistance_ohm)

    def q_v_at(self, t_s: float) -> float:
        """Heater power density at ``t_s`` (W/m^3)."""
        return self.stack.q_v_from_power(self.heater_power_W(t_s))

    def _switch_times(self, t0: float, t1: float) -> list[float]:
        """Times in (t0, t1) at which q_v may change."""
        self._sync_drive()
        return self._sw[bisect_right(self._sw, t0):bisect_left(self._sw, t1)].tolist()

    def _sync_drive(self) -> None:
        """Take in the drive's new change times (cheap when there are none)."""
        d = self.drive
        if d is None:
            return
        since = getattr(d, "changes_since", None)
        if since is not None:
            rev, new = since(self._drive_rev)
            if rev == self._drive_rev and not new:
                return
            self._drive_rev = rev
        else:   # a plain HeaterDrive: compare all its change times
            all_t = sorted(set(float(x) for x in d.change_times()))
            if all_t == self._drive_all:
                return
            old = set(self._drive_all)
            new = [x for x in all_t if x not in old]
            self._drive_all = all_t
        if new:
            self._add_switches(new)
            self._touch_on_heating(new)

    def _touch_on_heating(self, times: Sequence[float]) -> None:
        """Touch after touch (``[touch] repeat``): a heating in the open repeat touch closes it.

        The open touch ends ``REPEAT_RELEASE_S`` after the heater's switch-off
        inside it, and the next one opens ``repeat_gap_s`` later (the probe
        in air in between). The drive's change is learnt before any value
        after it is handed out (every query syncs first), and the new edges
        lie after the change, so nothing handed out changes.
        """
        if not self._repeat_open:
            return
        a = self._touch_a[-1]
        for x in sorted(times):
            if x > a and self.drive.duty_at(x) <= 0 < self.drive.duty_at(x - 1e-9):
                self._touch_b[-1] = x + REPEAT_RELEASE_S
                self._recut(x)
                self._open_repeat(self._touch_b[-1])
                return

    def _open_repeat(self, after_s: float) -> None:
        """Put the probe down again ``repeat_gap_s`` after ``after_s``, until a heating closes the touch."""
        start = after_s + self.scene.touch.repeat_gap_s
        self._touch_a.append(start)
        self._touch_b.append(start + _OPEN_TOUCH_S)
        self._repeat_open = True
        self._recut(start)

    def _add_switches(self, times: Sequence[float]) -> None:
        """New (or re-stamped) q_v change times: what was computed from the earliest on is stale."""
        for x in times:
            x = float(x)
            i = bisect_left(self._sw, x)
            if i == len(self._sw) or self._sw[i] != x:
                self._sw.insert(i, x)
        self._forget_from(min(times))

    def power_schedule(self, t_end_s: float | None = None) -> PowerSchedule:
        """q_v(t) from t = 0 to ``t_end_s`` (default now) as a PowerSchedule."""
        t_end = self.clock.now() if t_end_s is None else float(t_end_s)
        times = [0.0] + self._switch_times(0.0, t_end + 1e-12)
        q = [self.q_v_at(t) for t in times]
        keep = [0] + [i for i in range(1, len(q)) if q[i] != q[i - 1]]
        return PowerSchedule(np.array([times[i] for i in keep]), np.array([q[i] for i in keep]))

    # ---- contact phases

    @property
    def touches(self) -> tuple[tuple[float, float], ...]:
        """Contact windows ``(start_s, end_s)``: the scene's touch and any added."""
        return tuple(zip(self._touch_a.tolist(), self._touch_b.tolist()))

    def add_touch(self, start_s: float, length_s: float) -> None:
        """Put the probe on the object again for ``[start_s, start_s + length_s)``.

        It may not start in the past nor overlap another touch. The object is
        taken as back at its initial temperature (see the module docstring).
        """
        start, length = float(start_s), float(length_s)
        if not start >= self.clock.now() - 1e-12:
            raise ValueError(f"start_s={start_s} s is in the past (now {self.clock.now()} s)")
        if not (length > 0 and math.isfinite(length)):
            raise ValueError(f"length_s must be a finite number > 0, got {length_s!r}")
        end = start + length
        if self._repeat_open:
            # Touches placed by hand take over from the scene's touch after touch.
            self._touch_a.pop()
            self._touch_b.pop()
            self._repeat_open = False
            self._recut(max(self.clock.now(), self._touch_b[-1] if len(self._touch_b) else 0.0))
        i = bisect_right(self._touch_a, start)   # the touches are sorted and disjoint: check the neighbours
        for j in (i - 1, i):
            if 0 <= j < len(self._touch_a):
                a, b = self._touch_a[j], self._touch_b[j]
                if start < b and a < end:
                    raise ValueError(f"touch [{start}, {end}) s overlaps the touch [{a}, {b}) s")
        self._touch_a.insert(i, start)
        self._touch_b.insert(i, end)
        self._recut(start)

    def contact_at(self, t_s: float) -> bool:
        """Whether the probe touches the object at ``t_s``."""
        i = bisect_right(self._touch_a, t_s) - 1
        on = i >= 0 and t_s < self._touch_b[i]
        return on and not self._active("no_contact", t_s)

    def phases(self) -> list[_Phase]:
        """Contact/air phases covering [0, inf)."""
        starts = self._ph_start.tolist()
        ends = starts[1:] + [math.inf]
        return [_Phase(a, b, bool(c)) for a, b, c in zip(starts, ends, self._ph_contact)]

    def _recut(self, t_edge: float) -> None:
        """Recompute the phases from the one holding ``t_edge - 1e-9`` on.

        Touches and faults only add edges at or after ``t_edge``, so the
        phases before, the start and contact flag of that phase and its start
        state stay as they are.
        """
        if len(self._ph_start):
            k0 = max(bisect_right(self._ph_start, t_edge - 1e-9) - 1, 0)
        else:
            k0 = 0
        s0 = self._ph_start[k0] if len(self._ph_start) else 0.0
        edges = {s0}
        i = bisect_right(self._touch_b, s0)   # touches ending after s0
        edges.update(x for x in self._touch_a[i:] if x > s0)
        edges.update(self._touch_b[i:])
        for f in self._faults:
            if f.kind == "no_contact":
                edges.update(x for x in (f.at_s, f.until_s) if x is not None and x > s0)
        starts: list[float] = []
        contacts: list[bool] = []
        for e in sorted(edges):
            c = self.contact_at(e)
            if not contacts or contacts[-1] != c:
                starts.append(e)
                contacts.append(c)
        if len(self._ph_start):
            mean0, y0 = self._ph_mean[k0], self._ph_y[k0]
        else:
            amb = self.scene.environment.ambient_temperature_C
            mean0, y0 = amb, amb
        for arr in (self._ph_start, self._ph_contact, self._ph_mean, self._ph_y):
            del arr[k0:]
        self._ph_start.extend(starts)
        self._ph_contact.extend(int(c) for c in contacts)
        self._ph_mean.extend([mean0] + [math.nan] * (len(starts) - 1))
        self._ph_y.extend([y0] + [math.nan] * (len(starts) - 1))
        self._forget_from(t_edge)

    def _forget_from(self, t_s: float) -> None:
        """Drop what may depend on the drive, faults or touches from ``t_s`` on.

        Look-ahead values at times >= t_s go, and start states of the phases
        starting after t_s. (Past states before ``now`` stay; ``add_fault``
        handles a fault landing in the past on a wall clock.)
        """
        for s in self._streams.values():
            if s.n and s.t[s.n - 1] >= t_s:
                s.n = bisect_left(s.t, t_s, 0, s.n)
        k = bisect_right(self._ph_start, t_s)
        for i in range(max(k, 1), len(self._ph_start)):
            self._ph_mean[i] = math.nan
            self._ph_y[i] = math.nan

    def _base_C(self, contact: bool) -> float:
        return self.scene.object_temperature_C if contact else self.scene.environment.ambient_temperature_C

    # ---- transfer functions

    def _admittance(self, s: np.ndarray, contact: bool) -> np.ndarray:
        if not contact:
            return laplace.object_admittance(s, AIR, None, "infinite")
        o = self.scene.object
        Y = laplace.object_admittance(s, o.solid, o.thickness_m, o.back)
        rc = self.scene.touch_contact_resistance_m2K_W
        return Y / (1.0 + rc * Y) if rc > 0 else Y

    def _heater_transfer(self, s: np.ndarray, contact: bool) -> tuple[np.ndarray, np.ndarray]:
        if not contact:
            return laplace.probe_transfer(s, AIR, self.stack, None, "infinite", 0.0)
        o = self.scene.object
        return laplace.probe_transfer(s, o.solid, self.stack, o.thickness_m, o.back,
                                      self.scene.touch_contact_resistance_m2K_W)

    def _ic_transfer(self, s: np.ndarray, contact: bool) -> tuple[np.ndarray, np.ndarray]:
        # Probe slab at uniform excess 1 K from t = 0, insulated top, onto admittance Y.
        p = self._probe
        a = np.sqrt(s / p.alpha_m2_s)
        e = np.exp(-2.0 * a * self._L)
        K = p.k_W_mK * a * (1.0 - e) / (1.0 + e)
        Y = self._admittance(s, contact)
        T = K / (K + Y) / s
        return T, Y * T

    # ---- evaluation

    def _phase_of(self, t: float) -> int:
        return max(bisect_right(self._ph_start, t) - 1, 0)

    def _phase_end(self, k: int) -> float:
        return self._ph_start[k + 1] if k + 1 < len(self._ph_start) else math.inf

    def _start_state(self, phases: list[_Phase], k: int) -> tuple[float, float]:
        """(probe mean temperature, thermocouple reading) in °C at the start of ``phases[k]``."""
        return self._start_state_k(self._phase_of(phases[k].start_s))

    def _start_state_k(self, k: int) -> tuple[float, float]:
        """(probe mean temperature, thermocouple reading) in °C at the start of phase k.

        From the last phase before with a known start state, phase by phase
        (an energy balance over each); kept once the phase before has ended.
        """
        mean = self._ph_mean[k]
        if mean == mean:
            return mean, self._ph_y[k]
        j = k - 1
        while j > 0 and self._ph_mean[j] != self._ph_mean[j]:
            j -= 1
        state = (self._ph_mean[j], self._ph_y[j])
        rho_c_L = self._probe.rho_c_J_m3K * self._L
        now = self.clock.now()
        for i in range(j + 1, k + 1):
            end = self._ph_start[i]
            ev = self._eval(i - 1, np.array([end]), state)
            self.stats["phase_ends"] += 1
            state = (state[0] + (float(ev.e_heat_J_m2[0]) - float(ev.q_int_J_m2[0])) / rho_c_L,
                     float(ev.thermocouple_C[0]))
            if now > end:
                self._ph_mean[i], self._ph_y[i] = state
        return state

    def _eval(self, k: int, t: np.ndarray, start_state: tuple[float, float] | None = None,
              derivatives: bool = False) -> _Evals:
        """Exact values at times ``t`` (1-D, all in phase k): one Talbot inversion for all of them.

        Each time superposes the phase's terms: the initial condition and the
        unit-step responses of the heater switchings in [start, t).
        """
        start = self._ph_start[k]
        contact = bool(self._ph_contact[k])
        base = self._base_C(contact)
        t_mean0, y0 = self._start_state_k(k) if start_state is None else start_state
        theta0 = t_mean0 - base
        tau = self.scene.sensors.thermocouple_time_constant_s
        L_h = self.stack.heater_thickness_m
        m = t.size

        # Heater steps in [start, t): the level at the phase start is a step there.
        x = np.array([start] + self._sw[bisect_right(self._sw, start):bisect_left(self._sw, float(t.max()))].tolist())
        levels = np.array([self.q_v_at(v) for v in x])
        dq = np.diff(np.concatenate(([0.0], levels)))
        nxt = np.append(x[1:], math.inf)
        span = np.minimum(nxt[None, :], t[:, None]) - x[None, :]       # (m, n_x)
        span[:, 1:] = np.where(x[None, 1:] < t[:, None], span[:, 1:], 0.0)
        e_heat = (span @ levels) * L_h

        lag_ic = t - start
        lag = t[:, None] - x[None, :]
        use = (lag > 0) & (dq != 0.0)[None, :]
        ti, xi = np.nonzero(use)                       # time-major: a time's terms in order
        if theta0 != 0.0:
            # At the very instant of contact, report the right-hand limit (the contact temperature).
            rows_t = np.concatenate((np.arange(m), ti))
            lags = np.concatenate((np.maximum(lag_ic, 1e-9), lag[ti, xi]))
            w = np.concatenate((np.full(m, theta0), dq[xi]))
            n_ic = m
        else:
            rows_t, lags, w, n_ic = ti, lag[ti, xi], dq[xi], 0
        n_rows = lags.size
        outs = 7 if derivatives else 4
        sums = np.zeros((outs, m))
        if n_rows:
            self.stats["max_terms"] = max(self.stats["max_terms"], int(np.bincount(rows_t).max()))
        for r0 in range(0, n_rows, _ROWS_PER_CALL):
            r1 = min(r0 + _ROWS_PER_CALL, n_rows)
            vals = self._invert(contact, lags[r0:r1], w[r0:r1], max(min(n_ic, r1) - r0, 0), tau, derivatives)
            for o in range(outs):
                sums[o] += np.bincount(rows_t[r0:r1], weights=vals[o], minlength=m)
        self.stats["times"] += m
        T, y_ex, q, qi = sums[:4]
        surface = base + T
        decay = np.exp(-lag_ic / tau) if tau > 0 else None
        y = base + (y0 - base) * decay + y_ex if tau > 0 else surface
        if not derivatives:
            return _Evals(surface, y, q, qi, e_heat)
        dT, dy_ex, dq_f = sums[4:]
        dy = -(y0 - base) / tau * decay + dy_ex if tau > 0 else dT
        return _Evals(surface, y, q, qi, e_heat, dT, dy, dq_f)

    def _invert(self, contact: bool, lags: np.ndarray, w: np.ndarray, n_ic: int, tau: float,
                derivatives: bool) -> tuple[np.ndarray, ...]:
        """Talbot inversion of the weighted terms (rows): T, y excess, q, int q [, their derivatives]."""
        wi = np.zeros((lags.size, 1))
        wh = np.zeros((lags.size, 1))
        wi[:n_ic, 0] = w[:n_ic]
        wh[n_ic:, 0] = w[n_ic:]
        self.stats["talbot_calls"] += 1
        self.stats["talbot_rows"] += lags.size

        def F(s):
            T_h, q_h = self._heater_transfer(s, contact)
            if n_ic:
                T_i, q_i = self._ic_transfer(s, contact)
                Ts, qs = wh * T_h + wi * T_i, wh * q_h + wi * q_i
            else:
                Ts, qs = wh * T_h, wh * q_h
            ys = Ts / (1.0 + tau * s)
            if derivatives:
                return Ts, ys, qs, qs / s, s * Ts, s * ys, s * qs
            return Ts, ys, qs, qs / s

        return laplace.talbot_invert(F, lags)

    def _query(self, t_s: float, stream: str) -> WorldState:
        """The world at ``t_s`` for a caller sampling on its own grid (``stream``)."""
        t = float(t_s)
        if not t >= 0.0:
            raise ValueError(f"t_s must be >= 0, got {t_s!r}")
        self._sync_drive()
        self.stats["queries"] += 1
        s = self._streams.get(stream)
        if s is None:
            s = self._streams[stream] = _Stream()
        step = t - s.last_t
        regular = step > 0 and abs(step - s.step) <= 1e-6 * step
        s.last_t, s.step = t, step
        hit = self._cache.get(t)
        if hit is not None:
            return hit
        st = self._from_lookahead(s, t)
        if st is None:
            k = self._phase_of(t)
            lo, hi = self._ph_start[k], self._phase_end(k)
            times = [t]
            if regular:
                n = min(_LOOKAHEAD_MAX - 1, int(_LOOKAHEAD_S / step))
                ahead = t + step * np.arange(1, n + 1)
                times += ahead[ahead < hi].tolist()
            tt = np.array(times)
            ev = self._eval(k, tt, derivatives=len(times) > 1)
            contact = bool(self._ph_contact[k])
            st = WorldState(t, float(ev.surface_C[0]), float(ev.thermocouple_C[0]), float(ev.q_f[0]), contact)
            if len(times) > 1:
                s.t, s.n, s.next, s.lo, s.hi, s.contact = times, len(times), 1, lo, hi, contact
                s.vals = tuple(a.tolist() for a in (ev.surface_C, ev.thermocouple_C, ev.q_f,
                                                    ev.d_surface, ev.d_thermocouple, ev.d_q_f))
        if t < self.clock.now():
            if len(self._cache) >= _CACHE_MAX:
                self._cache.clear()
            self._cache[t] = st
        return st

    def _from_lookahead(self, s: _Stream, t: float) -> WorldState | None:
        if not s.n:
            return None
        i = s.next
        if not (i < s.n and abs(s.t[i] - t) <= _MATCH_TOL_S):
            i = bisect_left(s.t, t, 0, s.n)
            if i > 0 and (i == s.n or t - s.t[i - 1] < s.t[i] - t):
                i -= 1
            if i >= s.n or abs(s.t[i] - t) > _MATCH_TOL_S:
                return None
        p = s.t[i]
        d = t - p
        T, y, q, dT, dy, dq = s.vals
        if d != 0.0:
            # A few ulps off the predicted grid: first order from p, unless a phase edge or a
            # heater switching lies in between.
            a, b = min(p, t), max(p, t)
            if not (s.lo <= a and b < s.hi) or bisect_left(self._sw, a) != bisect_right(self._sw, b):
                return None
            surface, tc, q = T[i] + d * dT[i], y[i] + d * dy[i], q[i] + d * dq[i]
        else:
            surface, tc, q = T[i], y[i], q[i]
        s.next = i + 1
        self.stats["lookahead_hits"] += 1
        return WorldState(t, surface, tc, q, s.contact)

    def state(self, t_s: float) -> WorldState:
        """The world at virtual time ``t_s`` (>= 0)."""
        return self._query(t_s, "state")

    def truth(self, t_s: Sequence[float]) -> Truth:
        """Exact series at times ``t_s`` (s)."""
        t = np.asarray(t_s, dtype=float).ravel()
        if t.size and not np.all(t >= 0.0):
            raise ValueError(f"t_s must be >= 0, got {t.min()!r}")
        self._sync_drive()
        now = self.clock.now()
        out: list[WorldState | None] = [self._cache.get(x) for x in t.tolist()]
        todo = np.array([i for i, st in enumerate(out) if st is None], dtype=int)
        if todo.size:
            ks = np.searchsorted(np.asarray(self._ph_start), t[todo], side="right") - 1
            ks = np.maximum(ks, 0)
            for k in np.unique(ks):
                idx = todo[ks == k]
                contact = bool(self._ph_contact[k])
                for c0 in range(0, idx.size, 512):
                    part = idx[c0:c0 + 512]
                    ev = self._eval(int(k), t[part])
                    for j, i in enumerate(part.tolist()):
                        x = float(t[i])
                        st = WorldState(x, float(ev.surface_C[j]), float(ev.thermocouple_C[j]),
                                        float(ev.q_f[j]), contact)
                        out[i] = st
                        if x < now:
                            if len(self._cache) >= _CACHE_MAX:
                                self._cache.clear()
                            self._cache[x] = st
        return Truth(
            t,
            np.array([s.surface_C for s in out]),
            np.array([s.thermocouple_C for s in out]),
            np.array([s.q_f_W_m2 for s in out]),
            np.array([s.contact for s in out], dtype=bool),
            np.array([self.q_v_at(x) for x in t]),
        )

    # ---- signals (the World protocol; the EMF and the flux voltage come from SensorSignals)

    def thermocouple_C(self, t_s: float, *, stream: str = "thermocouple") -> float:
        """Hot-junction temperature (°C) the thermocouple reports at ``t_s``."""
        return self._query(t_s, stream).thermocouple_C

    def cold_junction_C(self, t_s: float) -> float:
        """Board (cold-junction, ADC die) temperature (°C)."""
        return self.scene.environment.ambient_temperature_C

    def sensed_flux_W_m2(self, t_s: float, *, stream: str = "flux") -> float:
        """The flux the sensor sees (W/m^2): the probe's face flux, unclipped."""
        return self._query(t_s, stream).q_f_W_m2

    @property
    def flux_sensitivity_V_per_W_m2(self) -> float:
        """The flux sensor's sensitivity (V per W/m^2): the scene's."""
        return self.scene.sensors.flux_sensitivity_V_per_W_m2
