"""The thin-film heater: an enable line gating a PWM-driven power switch.

The heater dissipates power only while the enable line is active *and* the
PWM duty cycle is non-zero, so either channel alone can cut the power. The
driver always tries both when switching off and reports any failure only
after both attempts (:class:`HeaterOffError`).

Power model: a resistive film of resistance R on a supply V, switched with
duty d, dissipates ``P = d * V**2 / R`` (W); spread over the 55 x 60 mm,
20 um film this is a volumetric source ``q_v = P / (area * thickness)``
(W/m^3).
"""

from __future__ import annotations

import logging
import math
import threading
from typing import Any

from edge.physics.solids import DEFAULT_STACK, ProbeStack

__all__ = [
    "HEATER_THICKNESS_M",
    "HEATER_AREA_M2",
    "HEATER_VOLUME_M3",
    "heater_power_w",
    "duty_for_power",
    "volumetric_heat_w_m3",
    "HeaterError",
    "HeaterOffError",
    "Heater",
]

log = logging.getLogger(__name__)

# The heater's geometry has one home, the probe stack (edge.physics.solids); these are views of it.
HEATER_AREA_M2 = DEFAULT_STACK.heater_area_m2
HEATER_THICKNESS_M = DEFAULT_STACK.heater_thickness_m
HEATER_VOLUME_M3 = HEATER_AREA_M2 * HEATER_THICKNESS_M


def _positive(name: str, v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a number, got {v!r}") from None
    if not (f > 0 and math.isfinite(f)):
        raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
    return f


def _duty(name: str, v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a number, got {v!r}") from None
    if not 0.0 <= f <= 1.0:
        raise ValueError(f"{name} must be in [0, 1], got {v!r}")
    return f


def heater_power_w(duty: float, supply_voltage_v: float, resistance_ohm: float) -> float:
    """Mean electrical power (W) at PWM duty ``duty`` (0..1): ``d * V**2 / R``."""
    d = _duty("duty", duty)
    v = _positive("supply_voltage_v", supply_voltage_v)
    r = _positive("resistance_ohm", resistance_ohm)
    return d * v * v / r


def duty_for_power(power_w: float, supply_voltage_v: float, resistance_ohm: float) -> float:
    """PWM duty (0..1) that gives mean power ``power_w`` (W).

    Raises ValueError if the supply cannot deliver that much (duty > 1).
    """
    p = float(power_w)
    if not (p >= 0 and math.isfinite(p)):
        raise ValueError(f"power_w must be a finite number >= 0, got {power_w!r}")
    v = _positive("supply_voltage_v", supply_voltage_v)
    r = _positive("resistance_ohm", resistance_ohm)
    p_max = v * v / r
    if p > p_max * (1 + 1e-12):
        raise ValueError(
            f"power_w={p} W exceeds the maximum {p_max:.6g} W of a {r} ohm heater on {v} V"
        )
    return min(1.0, p / p_max)


def volumetric_heat_w_m3(
    power_w: float,
    *,
    area_m2: float = HEATER_AREA_M2,
    thickness_m: float = HEATER_THICKNESS_M,
) -> float:
    """Volumetric heat source q_v (W/m^3) of power ``power_w`` spread over the film."""
    p = float(power_w)
    if not (p >= 0 and math.isfinite(p)):
        raise ValueError(f"power_w must be a finite number >= 0, got {power_w!r}")
    stack = ProbeStack(heater_thickness_m=_positive("thickness_m", thickness_m),
                       heater_area_m2=_positive("area_m2", area_m2))
    return stack.q_v_from_power(p)


class HeaterError(RuntimeError):
    """A heater command failed."""


class HeaterOffError(HeaterError):
    """Switching the heater off failed on at least one channel.

    Attributes
    ----------
    failures : dict of str to BaseException
        ``"enable"`` and/or ``"pwm"`` mapped to what each raised. If only one
        channel failed, the other one did cut the power.
    """

    def __init__(self, failures: dict[str, BaseException]) -> None:
        self.failures = dict(failures)
        parts = ", ".join(f"{k}: {type(e).__name__}: {e}" for k, e in self.failures.items())
        cut = "power was cut by the other channel" if len(self.failures) == 1 else "HEATER MAY STILL BE ON"
        super().__init__(f"heater off failed on {sorted(self.failures)} ({parts}); {cut}")

    @property
    def power_cut(self) -> bool:
        """True if at least one channel switched off."""
        return len(self.failures) < 2


class Heater:
    """Drives the heater through a :class:`edge.hw.board.Board`.

    Construction drives the enable line inactive, exports the PWM channel
    and sets it to ``pwm_period_ns`` with zero duty, enabled. Use as a
    context manager (or call :meth:`close`) so the heater is switched off on
    every exit path.

    Parameters
    ----------
    board : Board
        Provides ``heater_enable`` (GpioLine), ``pwm`` (SysfsPwm), ``clock``.
    supply_voltage_v : float
        Heater supply voltage V (V).
    resistance_ohm : float
        Heater film resistance R (ohm).
    pwm_period_ns : int
        PWM period (ns); default 1 ms (1 kHz), far faster than the film's
        thermal response.
    max_pulse_s : float, optional
        Longest duration :meth:`pulse` accepts (s).
    consumer : str
        GPIO consumer label.
    """

    def __init__(
        self,
        board: Any,
        *,
        supply_voltage_v: float,
        resistance_ohm: float,
        pwm_period_ns: int = 1_000_000,
        max_pulse_s: float | None = None,
        consumer: str = "thermotouch-heater",
    ) -> None:
        self.supply_voltage_v = _positive("supply_voltage_v", supply_voltage_v)
        self.resistance_ohm = _positive("resistance_ohm", resistance_ohm)
        if isinstance(pwm_period_ns, bool) or not isinstance(pwm_period_ns, int) or pwm_period_ns <= 0:
            raise ValueError(f"pwm_period_ns must be an int > 0, got {pwm_period_ns!r}")
        self.max_pulse_s = None if max_pulse_s is None else _positive("max_pulse_s", max_pulse_s)
        self.pwm_period_ns = pwm_period_ns
        self._line = board.heater_enable
        self._pwm = board.pwm
        self._clock = board.clock
        self._lock = threading.RLock()
        self._duty = 0.0
        self._on_since: float | None = None
        self._accumulated_s = 0.0
        self._closed = False
        #: The last HeaterOffError, or None once an off() fully succeeded.
        self.fault: HeaterOffError | None = None

        # Enable line first: from here on the heater is held off.
        self._req = self._line.request_output(consumer, value=False)
        try:
            self._pwm.open()
            self._pwm.configure(pwm_period_ns, 0)
            if not self._pwm.enabled:
                self._pwm.enable()
        except BaseException:
            self._req.release()
            raise

    # ---- power model

    @property
    def max_power_w(self) -> float:
        """Power at full duty, V**2/R (W)."""
        return self.supply_voltage_v**2 / self.resistance_ohm

    def power_for_duty(self, duty: float) -> float:
        """Mean power (W) at ``duty``."""
        return heater_power_w(duty, self.supply_voltage_v, self.resistance_ohm)

    def duty_for_power(self, power_w: float) -> float:
        """Duty (0..1) that gives ``power_w`` (W)."""
        return duty_for_power(power_w, self.supply_voltage_v, self.resistance_ohm)

    # ---- state

    @property
    def is_on(self) -> bool:
        """True from :meth:`on` until an :meth:`off` that cut the power."""
        with self._lock:
            return self._on_since is not None

    @property
    def duty(self) -> float:
        """Commanded duty (0 when off)."""
        with self._lock:
            return self._duty if self._on_since is not None else 0.0

    @property
    def power_w(self) -> float:
        """Commanded mean power (W)."""
        return self.power_for_duty(self.duty)

    @property
    def current_on_time_s(self) -> float:
        """Seconds since the heater was last switched on (0 if off)."""
        with self._lock:
            if self._on_since is None:
                return 0.0
            return max(0.0, self._clock.monotonic() - self._on_since)

    @property
    def on_time_s(self) -> float:
        """Cumulative on-time (s) over this object's life, including now."""
        with self._lock:
            return self._accumulated_s + self.current_on_time_s

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` has run."""
        return self._closed

    # ---- commands

    def on(self, duty: float) -> None:
        """Switch on (or change power) at PWM ``duty`` in (0, 1].

        Any failure switches the heater off (both channels) before raising.
        """
        d = _duty("duty", duty)
        if d == 0.0:
            raise ValueError("duty must be > 0 to switch on; use off()")
        with self._lock:
            if self._closed:
                raise HeaterError("heater is closed")
            try:
                self._pwm.set_duty_ns(min(self.pwm_period_ns, int(round(d * self.pwm_period_ns))))
                self._duty = d
                if self._on_since is None:
                    # Count from before the enable edge: on-time is never under-reported.
                    self._on_since = self._clock.monotonic()
                self._req.set_value(self._line.offset, self._line.gpiod.line.Value.ACTIVE)
            except BaseException as e:
                try:
                    self.off()
                except HeaterOffError as off_err:
                    raise off_err from e
                if isinstance(e, Exception):
                    raise HeaterError(f"switching the heater on failed: {e}") from e
                raise

    def on_power(self, power_w: float) -> float:
        """Switch on at mean power ``power_w`` (W); return the duty used."""
        d = self.duty_for_power(power_w)
        self.on(d)
        return d

    def off(self) -> None:
        """Drive the enable line inactive AND the duty to 0.

        Both are attempted whatever happens to the other; afterwards a
        :class:`HeaterOffError` lists the channel(s) that failed. Safe to call
        repeatedly; a no-op after a successful :meth:`close`.
        """
        with self._lock:
            if self._closed and self.fault is None:
                return
            failures: dict[str, BaseException] = {}
            try:
                # Enable first: a GPIO write is the fastest way to cut power.
                self._req.set_value(self._line.offset, self._line.gpiod.line.Value.INACTIVE)
            except BaseException as e:
                failures["enable"] = e
            try:
                self._pwm.set_duty_ns(0)
            except BaseException as e:
                failures["pwm"] = e
            if len(failures) < 2 and self._on_since is not None:
                self._accumulated_s += max(0.0, self._clock.monotonic() - self._on_since)
                self._on_since = None
            if not failures:
                self._duty = 0.0
                self.fault = None
                return
            err = HeaterOffError(failures)
            self.fault = err
            log.critical("%s", err)
            for e in failures.values():
                if not isinstance(e, Exception):  # KeyboardInterrupt/SystemExit: let it through
                    raise e
            raise err

    def pulse(self, duty: float, duration_s: float) -> float:
        """Heat at ``duty`` for ``duration_s`` seconds of board-clock time.

        The heater is switched off on every exit path. Returns the on-time
        of this pulse (s).
        """
        dur = _positive("duration_s", duration_s)
        if self.max_pulse_s is not None and dur > self.max_pulse_s:
            raise ValueError(f"duration_s={dur} s exceeds max_pulse_s={self.max_pulse_s} s")
        before = self.on_time_s
        try:
            self.on(duty)
            self._clock.sleep(dur)
        finally:
            self.off()
        return self.on_time_s - before

    def close(self) -> None:
        """Switch off, disable the PWM output and release the enable line.

        The line is released only after it was driven inactive: a released
        GPIO keeps its last level on most controllers.
        """
        with self._lock:
            if self._closed:
                return
            errors: list[BaseException] = []
            try:
                self.off()
            except HeaterOffError as e:
                errors.append(e)
            try:
                self._pwm.disable()
            except Exception as e:
                errors.append(e)
            if "enable" not in getattr(self.fault, "failures", {}):
                self._req.release()
            self._closed = True
            if errors:
                raise HeaterError(f"closing the heater failed: {errors}") from errors[0]

    def __enter__(self) -> Heater:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        self.close()
