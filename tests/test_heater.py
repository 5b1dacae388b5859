"""Heater driver against the simulated board: power model, on/off, on-time, fail-safe off()."""

import errno

import pytest

from edge.physics.probe import (
    HEATER_AREA_m2,
    HEATER_THICKNESS_m,
    duty_for_power,
    heater_power_W,
    volumetric_heat_W_m3,
)
from edge.hw.drivers.heater import Heater, HeaterError, HeaterOffError
from edge.hw.sysfs_pwm import PwmError
from firmware_sim.board import make_sim_board

V_SUPPLY, R_HEATER = 12.0, 24.0  # 6 W at full duty
EN = 17


@pytest.fixture
def board():
    b = make_sim_board()
    yield b
    b.close()


def parts(board):
    return board.extras["sim"]


def make_heater(board, **kw):
    return Heater(board, supply_voltage_v=V_SUPPLY, resistance_ohm=R_HEATER, **kw)


class Failing:
    """Wraps an object; the named methods raise ``exc`` (others pass through)."""

    def __init__(self, inner, exc, *names):
        self._inner, self._exc, self._names = inner, exc, names

    def __getattr__(self, name):
        if name in self._names:
            def boom(*a, **k):
                raise self._exc
            return boom
        return getattr(self._inner, name)


# ---- power model


def test_power_model():
    assert heater_power_W(0.5, 12.0, 24.0) == pytest.approx(3.0)
    assert duty_for_power(1.5, 12.0, 24.0) == pytest.approx(0.25)
    assert HEATER_AREA_m2 == pytest.approx(55e-3 * 60e-3)
    assert volumetric_heat_W_m3(3.3) == pytest.approx(3.3 / (3.3e-3 * 20e-6))
    assert HEATER_THICKNESS_m == 20e-6
    with pytest.raises(ValueError, match="exceeds the maximum"):
        duty_for_power(7.0, 12.0, 24.0)
    with pytest.raises(ValueError, match="resistance_ohm"):
        heater_power_W(0.5, 12.0, 0.0)
    with pytest.raises(ValueError, match="duty"):
        heater_power_W(1.2, 12.0, 24.0)


# ---- normal operation


def test_construction_holds_heater_off_with_pwm_ready(board):
    p = parts(board)
    h = make_heater(board)
    assert p.chip.level(EN) == 0 and p.chip.consumer(EN) == "thermotouch-heater"
    assert p.pwm_tree.state()[1:4] == (1_000_000, 0, True)
    assert not h.is_on and h.power_w == 0.0 and h.max_power_w == pytest.approx(6.0)


def test_on_off_drives_both_channels_and_counts_on_time(board):
    p = parts(board)
    h = make_heater(board)
    board.clock.sleep(0.5)
    h.on(0.25)
    assert p.chip.level(EN) == 1 and p.pwm_tree.state().duty_ns == 250_000
    assert h.is_on and h.power_w == pytest.approx(1.5)
    board.clock.sleep(2.0)
    assert h.current_on_time_s == pytest.approx(2.0)
    h.off()
    assert p.chip.level(EN) == 0 and p.pwm_tree.state().duty_ns == 0 and not h.is_on
    board.clock.sleep(1.0)
    assert h.on_time_s == pytest.approx(2.0)
    assert p.heater_duty_at(0.4) == 0.0 and p.heater_duty_at(1.0) == 0.25 and p.heater_duty_at(2.6) == 0.0
    assert h.on_power(3.0) == pytest.approx(0.5)
    board.clock.sleep(1.0)
    h.off()
    assert h.on_time_s == pytest.approx(3.0)


def test_pulse_is_exact_in_virtual_time_and_respects_max(board):
    p = parts(board)
    h = make_heater(board, max_pulse_s=3.0)
    assert h.pulse(0.5, 2.0) == pytest.approx(2.0)
    assert p.chip.line_history(EN)[-2:] == [(0.0, 1), (pytest.approx(2.0), 0)]
    with pytest.raises(ValueError, match="max_pulse_s"):
        h.pulse(0.5, 3.5)
    assert not h.is_on


def test_pulse_switches_off_when_the_wait_is_interrupted(board):
    p = parts(board)
    h = make_heater(board)

    class Interrupted(Exception):
        pass

    def sleep(dt):
        board.clock.advance(0.3)
        raise Interrupted

    h._clock = type("C", (), {"monotonic": board.clock.monotonic, "sleep": staticmethod(sleep)})()
    with pytest.raises(Interrupted):
        h.pulse(0.5, 2.0)
    assert not h.is_on and p.chip.level(EN) == 0 and h.on_time_s == pytest.approx(0.3)


def test_context_manager_switches_off_and_releases_on_exception(board):
    p = parts(board)
    with pytest.raises(ZeroDivisionError):
        with make_heater(board) as h:
            h.on(0.8)
            1 / 0
    assert p.chip.level(EN) == 0 and not p.chip.is_requested(EN)
    assert p.pwm_tree.state()[2:4] == (0, False)
    assert h.closed
    h.off()  # no-op after close
    with pytest.raises(HeaterError, match="closed"):
        h.on(0.5)


@pytest.mark.parametrize("duty", [0.0, -0.1, 1.01, float("nan")])
def test_on_rejects_bad_duty(board, duty):
    h = make_heater(board)
    with pytest.raises(ValueError, match="duty"):
        h.on(duty)
    assert not h.is_on


def test_bad_construction_arguments(board):
    with pytest.raises(ValueError, match="supply_voltage_v"):
        Heater(board, supply_voltage_v=-1, resistance_ohm=10)
    with pytest.raises(ValueError, match="pwm_period_ns"):
        Heater(board, supply_voltage_v=5, resistance_ohm=10, pwm_period_ns=0)


# ---- failure paths: off() must try both channels


def test_off_still_zeroes_pwm_when_enable_line_fails(board):
    p = parts(board)
    h = make_heater(board)
    h.on(0.5)
    h._req = Failing(h._req, OSError(errno.EIO, "gpio gone"), "set_value")
    with pytest.raises(HeaterOffError) as ei:
        h.off()
    assert set(ei.value.failures) == {"enable"} and ei.value.power_cut
    assert p.pwm_tree.state().duty_ns == 0  # the other channel was still switched off
    assert not h.is_on and h.fault is ei.value


def test_off_still_drives_enable_low_when_pwm_fails(board):
    p = parts(board)
    h = make_heater(board)
    h.on(0.5)
    h._pwm = Failing(h._pwm, PwmError("sysfs gone", "/x/duty_cycle"), "set_duty_ns")
    with pytest.raises(HeaterOffError) as ei:
        h.off()
    assert set(ei.value.failures) == {"pwm"}
    assert p.chip.level(EN) == 0
    assert not h.is_on


def test_off_failing_on_both_keeps_counting_on_time(board):
    h = make_heater(board)
    h.on(0.5)
    h._req = Failing(h._req, OSError("a"), "set_value")
    h._pwm = Failing(h._pwm, OSError("b"), "set_duty_ns")
    board.clock.sleep(1.0)
    with pytest.raises(HeaterOffError, match="MAY STILL BE ON") as ei:
        h.off()
    assert not ei.value.power_cut
    assert h.is_on
    board.clock.sleep(1.0)
    assert h.on_time_s == pytest.approx(2.0)


def test_keyboard_interrupt_in_one_channel_still_tries_the_other(board):
    p = parts(board)
    h = make_heater(board)
    h.on(0.5)
    h._req = Failing(h._req, KeyboardInterrupt(), "set_value")
    with pytest.raises(KeyboardInterrupt):
        h.off()
    assert p.pwm_tree.state().duty_ns == 0


def test_failed_on_leaves_heater_off(board):
    p = parts(board)
    h = make_heater(board)
    real_req = h._req
    h._req = Failing(real_req, OSError(errno.EIO, "flaky"), "set_value")
    with pytest.raises(HeaterOffError) as ei:
        h.on(0.5)  # the enable write failed after the duty was set: off() zeroes the duty
    assert isinstance(ei.value.__cause__, OSError)  # the on() failure is kept as the cause
    assert p.pwm_tree.state().duty_ns == 0 and p.chip.level(EN) == 0
    assert h.fault is ei.value and not h.is_on
    h._req = real_req
    h.off()
    assert h.fault is None


def test_failed_on_with_clean_off_raises_heater_error(board):
    p = parts(board)
    h = make_heater(board)
    real_req = h._req

    class RefusesActive:
        def __getattr__(self, name):
            return getattr(real_req, name)

        def set_value(self, line, value):
            if value:
                raise OSError(errno.EIO, "stuck")
            real_req.set_value(line, value)

    h._req = RefusesActive()
    with pytest.raises(HeaterError, match="switching the heater on failed") as ei:
        h.on(0.5)
    assert not isinstance(ei.value, HeaterOffError)
    assert p.pwm_tree.state().duty_ns == 0 and not h.is_on and h.fault is None


def test_pwm_failure_at_construction_releases_enable_line(board):
    p = parts(board)
    board.pwm.root = board.pwm.root / "nonexistent"
    with pytest.raises(PwmError, match="no PWM chip"):
        make_heater(board)
    assert not p.chip.is_requested(EN) and p.chip.level(EN) == 0


def test_enable_line_already_taken_is_reported(board):
    make_heater(board)
    with pytest.raises(OSError) as ei:
        make_heater(board)
    assert ei.value.errno == errno.EBUSY
