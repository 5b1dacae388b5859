"""A :class:`edge.hw.board.Board` built from the simulator's GPIO and PWM fakes.

``make_sim_board()`` wires a :class:`~firmware_sim.gpiod.kernel.GpioSim` chip, a
:class:`~firmware_sim.pwm.SimPwmTree` and a
:class:`~firmware_sim.clock.VirtualClock` into a Board with the same line
offsets and PWM channel as the real Pi; the parts stay reachable as
``board.extras["sim"]`` (a :class:`SimBoardParts`) so a test or the thermal
world can press the button and watch the heater. :func:`register_sim_board`
makes it available as ``edge.hw.board.make_board("sim", ...)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from edge.hw.board import Board, GpioLine, register_board_factory
from edge.hw.sysfs_pwm import SysfsPwm
from firmware_sim.clock import VirtualClock
from firmware_sim.gpiod.kernel import GpioSim
from firmware_sim.gpiod.sim_chip import SimChip
from firmware_sim.pwm import SimPwmTree

__all__ = ["SimBoardParts", "make_sim_board", "register_sim_board"]


@dataclass
class SimBoardParts:
    """The simulated hardware behind a sim board."""

    clock: VirtualClock
    gpio: GpioSim
    chip: SimChip
    pwm_tree: SimPwmTree
    heater_enable_offset: int
    trigger_offset: int
    pwm_chip: int
    pwm_channel: int

    def heater_enabled_at(self, t_s: float) -> bool:
        """Whether the heater-enable line was at its active level at ``t_s``."""
        return self.chip.level_at(self.heater_enable_offset, t_s) == 1

    def heater_duty_at(self, t_s: float) -> float:
        """Effective heater duty at ``t_s``: PWM fraction gated by the enable line."""
        if not self.heater_enabled_at(t_s):
            return 0.0
        return self.pwm_tree.duty_at(t_s, self.pwm_chip, self.pwm_channel)


def make_sim_board(
    *,
    clock: VirtualClock | None = None,
    i2c: Any = None,
    gpio: GpioSim | None = None,
    pwm_tree: SimPwmTree | None = None,
    gpio_chip: str = "/dev/gpiochip0",
    heater_enable_offset: int = 17,
    trigger_offset: int = 27,
    trigger_active_low: bool = True,
    trigger_bias: str = "pull-up",
    pwm_chip: int = 0,
    pwm_channel: int = 0,
) -> Board:
    """Build a Board on simulated GPIO/PWM (defaults mirror ``make_rpi_board``).

    Parts not passed in are created (a new clock, GPIO kernel with a 54-line
    chip at ``gpio_chip``, and a temporary PWM tree removed on
    ``board.close()``). ``i2c`` is the simulator's smbus2-compatible bus, or
    None for GPIO/PWM-only use. The heater-enable line is active-high.
    """
    clock = clock if clock is not None else VirtualClock()
    gpio = gpio if gpio is not None else GpioSim(clock)
    if gpio.clock is not clock:
        raise ValueError("gpio must run on the same clock as the board")
    try:
        chip = gpio.chip(gpio_chip)
    except FileNotFoundError:
        chip = gpio.add_chip(gpio_chip, num_lines=54)
    on_close = []
    if pwm_tree is None:
        pwm_tree = SimPwmTree(clock)
        on_close.append(pwm_tree.close)
    elif pwm_tree.clock is not clock:
        raise ValueError("pwm_tree must run on the same clock as the board")
    parts = SimBoardParts(clock, gpio, chip, pwm_tree, heater_enable_offset, trigger_offset, pwm_chip, pwm_channel)
    return Board(
        name="sim",
        i2c=i2c,
        heater_enable=GpioLine(gpio.gpiod, gpio_chip, heater_enable_offset),
        trigger=GpioLine(gpio.gpiod, gpio_chip, trigger_offset, active_low=trigger_active_low, bias=trigger_bias),
        pwm=SysfsPwm(pwm_tree.root, pwm_chip, pwm_channel, io=pwm_tree.io, clock=clock),
        clock=clock,
        on_close=on_close,
        extras={"sim": parts},
    )


def register_sim_board(name: str = "sim", *, replace: bool = True) -> None:
    """Register :func:`make_sim_board` as board kind ``name``."""
    register_board_factory(name, make_sim_board, replace=replace)
