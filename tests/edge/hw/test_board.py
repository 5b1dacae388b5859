"""Board abstraction: hardware-free import, factory registry, rpi device checks, sim board end to end."""

import os
import subprocess
import sys

import pytest

from edge.hw.board import (
    Board,
    BoardError,
    GpioLine,
    SystemClock,
    board_kinds,
    make_board,
    register_board_factory,
    unregister_board_factory,
)
from edge.hw.drivers.button import Button
from edge.hw.drivers.heater import Heater
from firmware_sim.clock import VirtualClock
from firmware_sim.pwm import SimPwmTree
from firmware_sim.board import make_sim_board, register_sim_board


def test_edge_imports_without_devices_or_hardware_packages():
    code = (
        "import sys\n"
        "import edge.hw.board, edge.hw.sysfs_pwm, edge.hw.drivers.heater, edge.hw.drivers.button\n"
        "bad = [m for m in ('gpiod', 'smbus2', 'firmware_sim', 'scipy', 'host') if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == ""


def test_rpi_board_names_every_missing_device(tmp_path):
    with pytest.raises(BoardError) as ei:
        make_board("rpi", i2c_bus=str(tmp_path / "i2c-1"), gpio_chip=str(tmp_path / "gpiochip0"),
                   pwm_root=str(tmp_path))
    msg = str(ei.value)
    for name in ("i2c-1", "gpiochip0", "pwmchip0", "dtoverlay=pwm"):
        assert name in msg


@pytest.mark.skipif(os.path.exists("/dev/i2c-1"), reason="this machine has a real I2C bus")
def test_rpi_board_with_defaults_fails_clearly_here():
    with pytest.raises(BoardError, match="/dev/i2c-1"):
        make_board("rpi")


def test_rpi_board_rejects_a_file_that_is_not_a_gpio_chip(tmp_path):
    pytest.importorskip("gpiod")
    (tmp_path / "i2c-1").write_text("")
    (tmp_path / "gpiochip0").write_text("")
    with SimPwmTree(VirtualClock(), tmp_path / "pwm") as tree:
        with pytest.raises(BoardError, match="not a GPIO character device"):
            make_board("rpi", i2c_bus=str(tmp_path / "i2c-1"), gpio_chip=str(tmp_path / "gpiochip0"),
                       pwm_root=str(tree.root))


def test_registry_rules():
    assert "rpi" in board_kinds()
    with pytest.raises(ValueError, match="unknown board kind 'nope'.*rpi"):
        make_board("nope")
    built = []

    def factory(**opts):
        built.append(opts)
        return make_sim_board()

    register_board_factory("t-registry", factory)
    try:
        with pytest.raises(ValueError, match="already registered"):
            register_board_factory("t-registry", lambda **o: None)
        b = make_board("t-registry", extra=1)
        assert isinstance(b, Board) and built == [{"extra": 1}]
        b.close()
        register_board_factory("t-registry", lambda **o: "not a board", replace=True)
        with pytest.raises(TypeError, match="not Board"):
            make_board("t-registry")
    finally:
        unregister_board_factory("t-registry")
    assert "t-registry" not in board_kinds()
    with pytest.raises(TypeError):
        register_board_factory("t-x", "not callable")


def test_sim_board_via_registry_runs_a_touch_cycle():
    register_sim_board("t-sim")  # own name: never clobber the simulator's "sim"
    board = make_board("t-sim", heater_enable_offset=5, trigger_offset=6)
    sim = board.extras["sim"]
    try:
        with Heater(board, supply_voltage_V=12.0, resistance_ohm=24.0) as heater, Button(board) as button:
            sim.chip.press(6, at_s=0.4, hold_s=0.2, bounces=2)
            press = button.wait_for_press(timeout_s=10.0)
            assert press is not None
            board.clock.sleep(0.5)  # baseline
            heater.pulse(0.5, 2.0)
            assert heater.on_time_s == pytest.approx(2.0)
        t_on = press.t_s + 0.5
        assert sim.heater_duty_at(t_on - 0.01) == 0.0
        assert sim.heater_duty_at(t_on + 1.0) == 0.5
        assert sim.heater_duty_at(t_on + 2.01) == 0.0
        assert not sim.chip.is_requested(5) and not sim.chip.is_requested(6)
        assert sim.pwm_tree.violations == []
    finally:
        unregister_board_factory("t-sim")
        board.close()
    assert not sim.pwm_tree.root.exists()


def test_board_close_closes_i2c_runs_hooks_and_is_idempotent():
    calls = []

    class Bus:
        def close(self):
            calls.append("i2c")

    def bad_hook():
        calls.append("bad")
        raise RuntimeError("hook failed")

    clock = VirtualClock()
    b = make_sim_board(clock=clock)
    board = Board(name="t", i2c=Bus(), heater_enable=b.heater_enable, trigger=b.trigger, pwm=b.pwm,
                  clock=clock, on_close=[bad_hook, lambda: calls.append("last")])
    with pytest.raises(BoardError, match="hook failed"):
        board.close()
    assert calls == ["i2c", "bad", "last"] and board.closed
    board.close()
    assert calls == ["i2c", "bad", "last"]
    b.close()


def test_board_and_gpioline_validate_arguments():
    b = make_sim_board()
    try:
        with pytest.raises(ValueError, match="bias"):
            GpioLine(b.trigger.gpiod, "/dev/gpiochip0", 3, bias="pull-sideways")
        with pytest.raises(ValueError, match="offset"):
            GpioLine(b.trigger.gpiod, "/dev/gpiochip0", -1)
        with pytest.raises(ValueError, match="edge"):
            b.trigger.request_input("x", edge="sideways")
        with pytest.raises(TypeError, match="heater_enable"):
            Board(name="x", i2c=None, heater_enable=17, trigger=b.trigger, pwm=b.pwm, clock=b.clock)
        with pytest.raises(TypeError, match="clock"):
            Board(name="x", i2c=None, heater_enable=b.heater_enable, trigger=b.trigger, pwm=b.pwm, clock=object())
        with pytest.raises(ValueError, match="same clock"):
            make_sim_board(gpio=b.extras["sim"].gpio)
    finally:
        b.close()


def test_system_clock_is_monotonic():
    c = SystemClock()
    t0 = c.monotonic()
    c.sleep(-1.0)  # negative sleeps are clamped, not an error
    assert c.monotonic() >= t0


@pytest.mark.parametrize("active_low, bias, released_level", [(False, "PULL_DOWN", 0), (True, "PULL_UP", 1)])
def test_heater_enable_is_requested_to_fall_inactive_when_released(active_low, bias, released_level):
    from edge.hw.board import GpioLine

    board = make_sim_board()
    parts = board.extras["sim"]
    line = GpioLine(parts.gpio.gpiod, "/dev/gpiochip0", 17, active_low=active_low)
    assert line.inactive_bias == bias.lower().replace("_", "-")
    req = line.request_fail_safe_output("heater")
    assert parts.chip.level(17) == released_level  # requested inactive
    req.set_value(17, parts.gpio.gpiod.line.Value.ACTIVE)
    assert parts.chip.level(17) != released_level
    req.release()  # as the kernel does when the process dies
    assert parts.chip.level(17) == released_level
    # The heater driver requests it so.
    h = Heater(board, supply_voltage_V=15.0, resistance_ohm=44.0)
    h.on(1.0)
    assert parts.chip.level(17) == 1
    h._req.release()
    assert parts.chip.level(17) == 0
    board.close()


def test_a_disabled_heater_refuses_to_switch_on():
    board = make_sim_board()
    h = Heater(board, supply_voltage_V=15.0, resistance_ohm=44.0)
    h.on(0.5)
    h.disable("stuck on")
    assert not h.is_on and h.disabled == "stuck on"
    with pytest.raises(Exception, match="disabled: stuck on"):
        h.on(0.5)
    h.close()
    board.close()
