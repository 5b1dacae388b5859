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
(before/after the touch, and while ``no_contact`` holds). Within a phase the
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

Evaluation is lazy: the chips ask for values at the times they sample; one
Talbot inversion per query covers all terms. Results at times before "now"
are cached (the past no longer changes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Protocol, Sequence

import numpy as np

from edge.physics import laplace, typek
from edge.physics.probe import heater_power_W
from edge.physics.schedule import PowerSchedule
from edge.physics.solids import Solid

from firmware_sim.scene.model import FLUX_SATURATION_V, Fault, Scene

__all__ = ["AIR", "HeaterDrive", "BoardDrive", "ScheduleDrive", "WorldState", "Truth", "ThermalWorld",
           "wire_chips", "OPEN_TC_INPUT_V"]

#: Still air near 300 K (Incropera 7e, Table A.4).
AIR = Solid(k_W_mK=0.0263, rho_kg_m3=1.1614, c_J_kgK=1007.0)
#: What an open thermocouple input shows the ADS122C04 (burn-out current
#: sources pull it towards the rail): far above full scale at gain 128.
OPEN_TC_INPUT_V = 1.65
_HEATER_FAULTS = ("heater_stuck_on", "heater_dead", "supply_sag")


class HeaterDrive(Protocol):
    """Where the commanded heater duty comes from."""

    def duty_at(self, t_s: float) -> float:
        """Commanded effective duty (0..1) at ``t_s``, enable line included."""

    def change_times(self) -> Sequence[float]:
        """Every time the duty may have changed (s), any order."""


class BoardDrive:
    """Heater duty from a sim board's enable line and PWM channel."""

    def __init__(self, parts) -> None:
        self.parts = parts

    def duty_at(self, t_s: float) -> float:
        return float(self.parts.heater_duty_at(t_s))

    def change_times(self) -> list[float]:
        p = self.parts
        times = [t for t, _ in p.chip.line_history(p.heater_enable_offset)]
        times += [h.t_s for h in p.pwm_tree.history(p.pwm_chip, p.pwm_channel)]
        return times


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


class WorldState(NamedTuple):
    """The world at one instant (temperatures in °C, flux in W/m^2)."""

    t_s: float
    surface_C: float       # T_f, bottom of the sensing layer (probe side of any contact resistance)
    thermocouple_C: float  # surface_C through the thermocouple's lag
    q_f_W_m2: float        # heat flux from the probe into what it touches
    contact: bool


@dataclass(frozen=True)
class Truth:
    """Exact series for checks: times (s), °C, W/m^2, contact flag, q_v (W/m^3)."""

    t_s: np.ndarray
    surface_C: np.ndarray
    thermocouple_C: np.ndarray
    q_f_W_m2: np.ndarray
    contact: np.ndarray
    q_v_W_m3: np.ndarray


@dataclass(frozen=True)
class _Phase:
    start_s: float
    end_s: float   # math.inf for the last
    contact: bool


class _Eval(NamedTuple):
    surface_C: float
    thermocouple_C: float
    q_f: float
    q_int_J_m2: float    # integral of q_f over the phase up to t
    e_heat_J_m2: float   # heater energy released in the phase up to t (per area)


class ThermalWorld:
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
        self._faults: list[Fault] = [f for f in scene.faults if f.kind in self._world_kinds()]
        self._touches: list[tuple[float, float]] = [(scene.touch.start_s, scene.touch.end_s)]
        self._cache: dict[float, WorldState] = {}
        self._start_cache: dict[tuple, tuple[float, float]] = {}

    @staticmethod
    def _world_kinds() -> tuple[str, ...]:
        return ("open_thermocouple", "flux_saturation", "no_contact") + _HEATER_FAULTS

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
        if fault.kind not in self._world_kinds():
            raise ValueError(f"fault kind {fault.kind!r} is not modelled by the thermal world")
        now = self.clock.now() if now_s is None else min(float(now_s), self.clock.now())
        if fault.at_s < now - 1e-12:
            raise ValueError(f"fault at_s={fault.at_s} s is in the past (now {now} s)")
        self._faults.append(fault)
        self._start_cache.clear()
        if self._cache and fault.at_s < self.clock.now():
            self._cache = {t: st for t, st in self._cache.items() if t < fault.at_s}

    def _active(self, kind: str, t_s: float) -> list[Fault]:
        return [f for f in self._faults if f.kind == kind and f.active(t_s)]

    # ---- heater

    def duty_at(self, t_s: float) -> float:
        """Effective duty at ``t_s``: commanded, unless a heater fault overrides it."""
        if self._active("heater_dead", t_s):
            return 0.0
        stuck = self._active("heater_stuck_on", t_s)
        if stuck:
            return float(stuck[-1].params.get("duty", 1.0))
        return self.drive.duty_at(t_s) if self.drive is not None else 0.0

    def supply_voltage_at(self, t_s: float) -> float:
        """Heater supply voltage (V) at ``t_s``, with any sag."""
        v = self.scene.heater.supply_voltage_V
        for f in self._active("supply_sag", t_s):
            v = f.params["voltage_V"] if "voltage_V" in f.params else v * f.params["factor"]
        return v

    def heater_power_W(self, t_s: float) -> float:
        """Electrical power in the film at ``t_s`` (W)."""
        return heater_power_W(self.duty_at(t_s), self.supply_voltage_at(t_s), self.scene.heater.resistance_ohm)

    def q_v_at(self, t_s: float) -> float:
        """Heater power density at ``t_s`` (W/m^3)."""
        return self.stack.q_v_from_power(self.heater_power_W(t_s))

    def _switch_times(self, t0: float, t1: float) -> list[float]:
        """Times in (t0, t1) at which q_v may change."""
        times = set(self.drive.change_times()) if self.drive is not None else set()
        for f in self._faults:
            if f.kind in _HEATER_FAULTS:
                times.add(f.at_s)
                if f.until_s is not None:
                    times.add(f.until_s)
        return sorted(t for t in times if t0 < t < t1)

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
        return tuple(self._touches)

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
        for a, b in self._touches:
            if start < b and a < end:
                raise ValueError(f"touch [{start}, {end}) s overlaps the touch [{a}, {b}) s")
        self._touches.append((start, end))
        self._touches.sort()
        self._start_cache.clear()

    def contact_at(self, t_s: float) -> bool:
        """Whether the probe touches the object at ``t_s``."""
        on = any(a <= t_s < b for a, b in self._touches)
        return on and not self._active("no_contact", t_s)

    def phases(self) -> list[_Phase]:
        """Contact/air phases covering [0, inf)."""
        edges = {0.0}
        for a, b in self._touches:
            edges.update((a, b))
        for f in self._faults:
            if f.kind == "no_contact":
                edges.add(f.at_s)
                if f.until_s is not None:
                    edges.add(f.until_s)
        edges_l = sorted(edges) + [math.inf]
        out: list[_Phase] = []
        for a, b in zip(edges_l[:-1], edges_l[1:]):
            c = self.contact_at(a)
            if out and out[-1].contact == c:
                out[-1] = _Phase(out[-1].start_s, b, c)
            else:
                out.append(_Phase(a, b, c))
        return out

    def _base_C(self, contact: bool) -> float:
        env = self.scene.environment
        return env.initial_temperature_C if contact else env.ambient_temperature_C

    # ---- transfer functions

    def _admittance(self, s: np.ndarray, contact: bool) -> np.ndarray:
        if not contact:
            return laplace.object_admittance(s, AIR, None, "infinite")
        o = self.scene.object
        Y = laplace.object_admittance(s, o.solid, o.thickness_m, o.back)
        rc = self.scene.contact_resistance_m2K_W
        return Y / (1.0 + rc * Y) if rc > 0 else Y

    def _heater_transfer(self, s: np.ndarray, contact: bool) -> tuple[np.ndarray, np.ndarray]:
        if not contact:
            return laplace.probe_transfer(s, AIR, self.stack, None, "infinite", 0.0)
        o = self.scene.object
        return laplace.probe_transfer(s, o.solid, self.stack, o.thickness_m, o.back,
                                      self.scene.contact_resistance_m2K_W)

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

    def _phase_index(self, phases: list[_Phase], t: float) -> int:
        for i, ph in enumerate(phases):
            if ph.start_s <= t < ph.end_s:
                return i
        return len(phases) - 1

    def _start_state(self, phases: list[_Phase], k: int) -> tuple[float, float]:
        """(probe mean temperature, thermocouple reading) in °C at the start of phase k."""
        if k == 0:
            amb = self.scene.environment.ambient_temperature_C
            return amb, amb
        key = tuple(phases[: k + 1])
        hit = self._start_cache.get(key)
        if hit is not None:
            return hit
        prev = phases[k - 1]
        t_mean0, _ = self._start_state(phases, k - 1)
        ev = self._eval_phase(phases, k - 1, prev.end_s)
        rho_c_L = self._probe.rho_c_J_m3K * self._L
        state = (t_mean0 + (ev.e_heat_J_m2 - ev.q_int_J_m2) / rho_c_L, ev.thermocouple_C)
        if self.clock.now() > prev.end_s:
            self._start_cache[key] = state
        return state

    def _eval_phase(self, phases: list[_Phase], k: int, t: float) -> _Eval:
        ph = phases[k]
        base = self._base_C(ph.contact)
        t_mean0, y0 = self._start_state(phases, k)
        theta0 = t_mean0 - base
        tau = self.scene.sensors.thermocouple_time_constant_s
        L_h = self.stack.heater_thickness_m

        # Heater steps in [start, t): the level at the phase start is a step there.
        times = [ph.start_s] + self._switch_times(ph.start_s, t)
        levels = [self.q_v_at(x) for x in times]
        dq = np.diff(np.concatenate(([0.0], levels)))
        edges = np.append(times, t)
        e_heat = float(np.dot(levels, np.diff(edges))) * L_h

        lag_ic = t - ph.start_s
        # At the very instant of contact, report the right-hand limit (the contact temperature).
        rows_lag = [max(lag_ic, 1e-9)] if theta0 != 0.0 else []
        w_ic = [theta0] if rows_lag else []
        n_ic = len(rows_lag)
        w_h = []
        for t0, d in zip(times, dq):
            if d != 0.0 and t - t0 > 0:
                rows_lag.append(t - t0)
                w_h.append(d)

        decay = math.exp(-lag_ic / tau) if tau > 0 else 0.0
        if not rows_lag:
            T = q = qi = 0.0
            y_excess = 0.0
        else:
            lags = np.array(rows_lag)
            wi = np.zeros((lags.size, 1))
            wh = np.zeros((lags.size, 1))
            wi[:n_ic, 0] = w_ic
            wh[n_ic:, 0] = w_h
            contact = ph.contact

            def F(s):
                T_h, q_h = self._heater_transfer(s, contact)
                if n_ic:
                    T_i, q_i = self._ic_transfer(s, contact)
                    Ts, qs = wh * T_h + wi * T_i, wh * q_h + wi * q_i
                else:
                    Ts, qs = wh * T_h, wh * q_h
                return Ts, Ts / (1.0 + tau * s), qs, qs / s

            T_r, y_r, q_r, qi_r = laplace.talbot_invert(F, lags)
            T, y_excess, q, qi = float(T_r.sum()), float(y_r.sum()), float(q_r.sum()), float(qi_r.sum())
        surface = base + T
        if tau > 0:
            y = base + (y0 - base) * decay + y_excess
        else:
            y = surface
        return _Eval(surface, y, q, qi, e_heat)

    def state(self, t_s: float) -> WorldState:
        """The world at virtual time ``t_s`` (>= 0)."""
        t = float(t_s)
        if not t >= 0.0:
            raise ValueError(f"t_s must be >= 0, got {t_s!r}")
        hit = self._cache.get(t)
        if hit is not None:
            return hit
        phases = self.phases()
        k = self._phase_index(phases, t)
        ev = self._eval_phase(phases, k, t)
        st = WorldState(t, ev.surface_C, ev.thermocouple_C, ev.q_f, phases[k].contact)
        if t < self.clock.now():
            if len(self._cache) > 200_000:
                self._cache.clear()
            self._cache[t] = st
        return st

    def truth(self, t_s: Sequence[float]) -> Truth:
        """Exact series at times ``t_s`` (s)."""
        t = np.asarray(t_s, dtype=float).ravel()
        states = [self.state(x) for x in t]
        return Truth(
            t,
            np.array([s.surface_C for s in states]),
            np.array([s.thermocouple_C for s in states]),
            np.array([s.q_f_W_m2 for s in states]),
            np.array([s.contact for s in states]),
            np.array([self.q_v_at(x) for x in t]),
        )

    # ---- what the chips see

    def thermocouple_C(self, t_s: float) -> float:
        """Hot-junction temperature (°C) the thermocouple reports at ``t_s``."""
        return self.state(t_s).thermocouple_C

    def cold_junction_C(self, t_s: float) -> float:
        """Board (cold-junction, ADC die) temperature (°C)."""
        return self.scene.environment.ambient_temperature_C

    def thermocouple_open(self, t_s: float) -> bool:
        """Whether the thermocouple is disconnected at ``t_s``."""
        return bool(self._active("open_thermocouple", t_s))

    def thermocouple_emf_V(self, t_s: float) -> float:
        """Differential thermocouple EMF at the ADC pins (V); the rail when open."""
        if self.thermocouple_open(t_s):
            return OPEN_TC_INPUT_V
        return (typek.emf_mV(self.thermocouple_C(t_s)) - typek.emf_mV(self.cold_junction_C(t_s))) * 1e-3

    def flux_voltage_V(self, t_s: float) -> float:
        """Flux-sensor output (V): ``S * q_f`` clipped to the sensor range, or a saturation fault's level."""
        sat = self._active("flux_saturation", t_s)
        if sat:
            return float(sat[-1].params.get("voltage_V", FLUX_SATURATION_V))
        sens = self.scene.sensors
        q = min(max(self.state(t_s).q_f_W_m2, -sens.flux_range_W_m2), sens.flux_range_W_m2)
        return sens.flux_sensitivity_V_per_W_m2 * q

    def ads1115_input_V(self, mux: str, t_s: float) -> float:
        """ADS1115 pins: flux sensor across AIN0-AIN1; AIN2, AIN3 tied to GND."""
        if mux == "AIN0_AIN1":
            return self.flux_voltage_V(t_s)
        return 0.0

    def ads122c04_input_V(self, mux: str, t_s: float) -> float:
        """ADS122C04 pins: thermocouple across AIN0-AIN1, flux sensor across AIN2-AIN3."""
        if mux in ("AIN0_AIN1", "AIN1_AIN0"):
            v = self.thermocouple_emf_V(t_s)
            return v if mux == "AIN0_AIN1" else -v
        if mux in ("AIN2_AIN3", "AIN3_AIN2"):
            v = self.flux_voltage_V(t_s)
            return v if mux == "AIN2_AIN3" else -v
        return 0.0


def wire_chips(world: ThermalWorld, *, mcp9600=None, ads1115=None, ads122c04=None) -> None:
    """Point chip models' analog inputs at ``world`` (adapter over their public attributes)."""
    if mcp9600 is not None:
        mcp9600.hot_junction_C = world.thermocouple_C
        mcp9600.cold_junction_C = world.cold_junction_C
        mcp9600.open_circuit = world.thermocouple_open
    if ads1115 is not None:
        ads1115.inputs = world.ads1115_input_V
    if ads122c04 is not None:
        ads122c04.inputs = world.ads122c04_input_V
        ads122c04.temperature_C = world.cold_junction_C

