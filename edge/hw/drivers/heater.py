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
import threading
from typing import Any

from edge.checks import positive_number, unit_fraction
from edge.physics.probe import duty_for_power, heater_power_W

__all__ = ["HeaterError", "HeaterOffError", "Heater"]

log = logging.getLogger(__name__)

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
    supply_voltage_V : float
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
        supply_voltage_V: float,
        resistance_ohm: float,
        pwm_period_ns: int = 1_000_000,
        max_pulse_s: float | None = None,
        consumer: str = "thermotouch-heater",
    ) -> None:
        self.supply_voltage_V = positive_number("supply_voltage_V", supply_voltage_V)
        self.resistance_ohm = positive_number("resistance_ohm", resistance_ohm)
        if isinstance(pwm_period_ns, bool) or not isinstance(pwm_period_ns, int) or pwm_period_ns <= 0:
            raise ValueError(f"pwm_period_ns must be an int > 0, got {pwm_period_ns!r}")
        self.max_pulse_s = None if max_pulse_s is None else positive_number("max_pulse_s", max_pulse_s)
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
        #: Why :meth:`disable` latched the heater off, or None.
        self.disabled: str | None = None

        # Enable line first: from here on the heater is held off. Biased towards
        # inactive, so the kernel's release of the line when this process dies
        # (SIGKILL, OOM, a crash in C, a watchdog kill) lets it fall inactive.
        self._req = self._line.request_fail_safe_output(consumer)
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
    def max_power_W(self) -> float:
        """Power at full duty, V**2/R (W)."""
        return self.supply_voltage_V**2 / self.resistance_ohm

    def power_for_duty(self, duty: float) -> float:
        """Mean power (W) at ``duty``."""
        return heater_power_W(duty, self.supply_voltage_V, self.resistance_ohm)

    def duty_for_power(self, power_W: float) -> float:
        """Duty (0..1) that gives ``power_W`` (W)."""
        return duty_for_power(power_W, self.supply_voltage_V, self.resistance_ohm)

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
    def power_W(self) -> float:
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
        d = unit_fraction("duty", duty)
        if d == 0.0:
            raise ValueError("duty must be > 0 to switch on; use off()")
        with self._lock:
            if self._closed:
                raise HeaterError("heater is closed")
            if self.disabled is not None:
                raise HeaterError(f"heater is disabled: {self.disabled}")
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

    def on_power(self, power_W: float) -> float:
        """Switch on at mean power ``power_W`` (W); return the duty used."""
        d = self.duty_for_power(power_W)
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

    def disable(self, reason: str) -> None:
        """Switch off (both channels) and refuse :meth:`on` from now on (a heater fault).

        The enable line stays requested and driven inactive: a driven level
        holds against any leakage, and the process's death still releases it
        to its inactive bias.
        """
        with self._lock:
            if self.disabled is None:
                self.disabled = str(reason)
                log.critical("heater disabled: %s", reason)
            self.off()

    def pulse(self, duty: float, duration_s: float) -> float:
        """Heat at ``duty`` for ``duration_s`` seconds of board-clock time.

        The heater is switched off on every exit path. Returns the on-time
        of this pulse (s).
        """
        dur = positive_number("duration_s", duration_s)
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
