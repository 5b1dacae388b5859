"""A small, fast test rig for the edge daemon: sim board + chips + an analytic sample.

The thermal world is deliberately simple (the full simulator lives in
``firmware_sim.world``): with contact, the heater's flux ``q = P / A`` enters
a semi-infinite sample of effusivity ``e`` and the surface temperature rise
follows Duhamel's integral for piecewise-constant flux,
``dT(t) = sum_i 2 (q_i - q_{i-1}) sqrt((t - t_i) / pi) / e``; without
contact only a small fraction of the flux leaves the film, which heats as a
lump of heat capacity ``C_film``. The heater power is read from the
*simulated hardware* (enable-line level and PWM duty), never from the
driver, so a heater left on by a bug heats the world.

Fault hooks: :attr:`Rig.bus` (``nack``/``stuck``/``flaky``),
:attr:`Rig.mcp` ``.set_open(True)``, :attr:`World.contact`, and
:func:`heater_on_intervals` for the invariant.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from typing import Any

from edge.physics.probe import HEATER_AREA_m2
from firmware_sim.bus import SimBus
from firmware_sim.chips.ads1115 import ADS1115Emulator
from firmware_sim.chips.mcp9600 import MCP9600Emulator
from firmware_sim.clock import VirtualClock
from firmware_sim.gpiod.kernel import GpioSim
from firmware_sim.pwm import SimPwmTree
from firmware_sim.board import make_sim_board

__all__ = ["World", "Rig", "make_rig", "heater_on_intervals", "heater_invariant"]


class World:
    """Analytic probe-on-sample thermal model (see module docstring).

    Parameters
    ----------
    clock : VirtualClock
    parts : firmware_sim.board.SimBoardParts
    supply_voltage_V, resistance_ohm : float
        Heater electrical model.
    effusivity : float
        Sample effusivity, W s^0.5 / (m^2 K).
    T0_C : float
        Initial temperature of sample and probe, °C.
    contact : bool
        Whether the probe touches the sample.
    C_film_J_K : float
        Heat capacity of the film when it heats in air, J/K.
    """

    def __init__(self, clock: VirtualClock, parts: Any, *, supply_voltage_V: float = 15.0,
                 resistance_ohm: float = 44.0, effusivity: float = 1400.0, T0_C: float = 25.0,
                 contact: bool = True, C_film_J_K: float = 0.5) -> None:
        self.clock = clock
        self.parts = parts
        self.p_max_W = supply_voltage_V**2 / resistance_ohm
        self.effusivity = float(effusivity)
        self.T0_C = float(T0_C)
        self.contact = contact
        self.C_film_J_K = float(C_film_J_K)
        self._lock = threading.Lock()
        self._steps: list[tuple[float, float]] = []  # (t_s, flux W/m^2) from t_s on
        self._q = 0.0
        self._lump_K = 0.0
        self._t = clock.now()
        self._key = (parts.pwm_chip, parts.pwm_channel)
        clock.on_advance(self._advance)

    def heater_power_W(self) -> float:
        """Power dissipated now, from the enable line and the PWM state."""
        if self.parts.chip.level(self.parts.heater_enable_offset) != 1:
            return 0.0
        frac = self.parts.pwm_tree.history(*self._key)[-1].fraction
        return frac * self.p_max_W

    def _advance(self, t_old: float, t_new: float) -> None:
        p = self.heater_power_W()
        with self._lock:
            q = p / HEATER_AREA_m2 if self.contact else 0.0
            if not self.contact:
                self._lump_K += p * (t_new - t_old) / self.C_film_J_K
            elif self._lump_K:
                self._lump_K = 0.0
            if q != self._q:
                self._steps.append((t_old, q - self._q))
                self._q = q
                # Long histories: merge settled steps (t >> t_i) into nothing is not exact,
                # so keep them; a measurement adds two.
            self._t = t_new

    def flux_W_m2(self, t: float) -> float:
        """Heat flux through the sensor into the sample, W/m^2."""
        with self._lock:
            return self._q

    def temperature_C(self, t: float) -> float:
        """Surface (thermocouple) temperature, °C."""
        with self._lock:
            dT = 0.0
            for ti, dq in self._steps:
                if t > ti:
                    dT += 2.0 * dq * math.sqrt((t - ti) / math.pi) / self.effusivity
            return self.T0_C + dT + self._lump_K


@dataclass
class Rig:
    """Everything a daemon test needs."""

    clock: VirtualClock
    board: Any
    parts: Any
    bus: SimBus
    mcp: MCP9600Emulator
    ads: ADS1115Emulator
    world: World
    sensitivity_V_per_W_m2: float = 0.56e-6
    extra: dict = field(default_factory=dict)


def make_rig(*, effusivity: float = 1400.0, contact: bool = True, T0_C: float = 25.0,
             supply_voltage_V: float = 15.0, resistance_ohm: float = 44.0,
             sensitivity_V_per_W_m2: float = 0.56e-6, seed: int = 0,
             T_noise_V: float = 0.0, flux_noise_V: float = 0.0, gpio_state_dir: Any = None,
             pwm_root: Any = None) -> Rig:
    """Sim board with an MCP9600 at 0x60 and an ADS1115 at 0x48 on a SimBus.

    ``gpio_state_dir`` and ``pwm_root`` put the GPIO line states
    (:mod:`firmware_sim.gpiod.state`) and the sysfs PWM tree in directories
    that outlive this process (a test that kills it reads them afterwards).
    """
    clock = VirtualClock()
    bus = SimBus(clock=clock, rng=seed)
    gpio = GpioSim(clock, state_dir=gpio_state_dir)
    pwm_tree = None if pwm_root is None else SimPwmTree(clock, pwm_root)
    board = make_sim_board(clock=clock, i2c=bus, gpio=gpio, pwm_tree=pwm_tree)
    parts = board.extras["sim"]
    world = World(clock, parts, supply_voltage_V=supply_voltage_V, resistance_ohm=resistance_ohm,
                  effusivity=effusivity, T0_C=T0_C, contact=contact)
    mcp = MCP9600Emulator(clock, world.temperature_C, lambda t: T0_C, rng=seed + 1, emf_noise_rms_V=T_noise_V)
    ads = ADS1115Emulator(clock, lambda mux, t: world.flux_W_m2(t) * sensitivity_V_per_W_m2,
                     noise_rms_V=flux_noise_V, rng=seed + 2)
    bus.attach(0x60, mcp)
    bus.attach(0x48, ads)
    return Rig(clock, board, parts, bus, mcp, ads, world, sensitivity_V_per_W_m2)


def heater_on_intervals(parts: Any, t_end: float | None = None) -> list[tuple[float, float]]:
    """Intervals (s) during which the simulated heater dissipated power.

    Read from the simulated enable line's level history, gated by the PWM
    duty history (the heater needs both); ``t_end`` closes an interval still
    open (default: the clock's now).
    """
    t_end = parts.clock.now() if t_end is None else t_end
    gpio = parts.chip.line_history(parts.heater_enable_offset)
    pwm = parts.pwm_tree.history(parts.pwm_chip, parts.pwm_channel)
    times = sorted({t for t, _ in gpio} | {s.t_s for s in pwm} | {t_end})
    out: list[tuple[float, float]] = []
    start = None
    for t in times:
        if t > t_end:
            break
        on = parts.chip.level_at(parts.heater_enable_offset, t) == 1 and \
            parts.pwm_tree.duty_at(t, parts.pwm_chip, parts.pwm_channel) > 0
        if on and start is None:
            start = t
        elif not on and start is not None:
            out.append((start, t))
            start = None
    if start is not None:
        out.append((start, t_end))
    return out


def heater_invariant(parts: Any, max_on_time_s: float) -> dict:
    """Check the heater invariant on the simulated hardware.

    Returns ``{"ok", "longest_on_s", "total_on_s", "off_now", "n_intervals"}``;
    ``ok`` means every on-interval is at most ``max_on_time_s`` and the
    heater is off now (enable line inactive or duty 0).
    """
    now = parts.clock.now()
    iv = heater_on_intervals(parts, now)
    longest = max((b - a for a, b in iv), default=0.0)
    off_now = not (parts.chip.level(parts.heater_enable_offset) == 1
                   and parts.pwm_tree.history(parts.pwm_chip, parts.pwm_channel)[-1].fraction > 0)
    return {"ok": longest <= max_on_time_s + 1e-9 and off_now, "longest_on_s": longest,
            "total_on_s": sum(b - a for a, b in iv), "off_now": off_now, "n_intervals": len(iv)}
