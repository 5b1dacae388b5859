"""Trigger button driver against the simulated GPIO: debounced events in virtual time."""

import errno

import pytest

from edge.hw.drivers.button import Button, ButtonEvent
from firmware_sim.board import make_sim_board

TRIG = 27


def chip(board):
    return board.extras["sim"].chip


def test_press_with_chatter_gives_one_press_and_one_release(board):
    btn = Button(board, debounce_s=0.02)
    assert not btn.is_pressed
    chip(board).press(TRIG, at_s=1.0, hold_s=0.5, bounces=4, bounce_interval_s=1e-3)
    ev = btn.wait_for_press(timeout_s=5.0)
    assert ev == ButtonEvent(True, pytest.approx(1.028))  # last bounce 1.008 + 20 ms
    assert board.clock.monotonic() == pytest.approx(1.028)  # returned as soon as it happened
    assert btn.is_pressed
    rel = btn.wait_for_release(timeout_s=5.0)
    assert rel.pressed is False and rel.t_s == pytest.approx(1.528)
    assert btn.wait_for_event(timeout_s=1.0) is None


def test_timeout_returns_none_after_exactly_the_timeout(board):
    btn = Button(board)
    t0 = board.clock.monotonic()
    assert btn.wait_for_press(timeout_s=2.5) is None
    assert board.clock.monotonic() - t0 == pytest.approx(2.5)
    with pytest.raises(ValueError, match="timeout_s"):
        btn.wait_for_press(timeout_s=-1)


def test_press_after_the_timeout_is_not_returned_early(board):
    btn = Button(board)
    chip(board).press(TRIG, at_s=3.0, hold_s=0.1)
    assert btn.wait_for_press(timeout_s=2.0) is None
    assert board.clock.monotonic() == pytest.approx(2.0)
    ev = btn.wait_for_press(timeout_s=2.0)
    assert ev is not None and ev.t_s == pytest.approx(3.02)


def test_glitch_shorter_than_debounce_is_ignored(board):
    btn = Button(board, debounce_s=0.02)
    c = chip(board)
    c.schedule_input(TRIG, 0, at_s=0.5)
    c.schedule_input(TRIG, None, at_s=0.505)
    assert btn.wait_for_event(timeout_s=1.0) is None
    assert not btn.is_pressed


def test_wait_for_press_skips_a_pending_release(board):
    btn = Button(board, debounce_s=0.0)
    c = chip(board)
    c.press(TRIG, at_s=0.1, hold_s=0.1)
    c.press(TRIG, at_s=0.5, hold_s=0.1)
    board.clock.sleep(0.3)  # first press and release are queued in the kernel
    assert btn.wait_for_release(1.0).t_s == pytest.approx(0.2)
    ev = btn.wait_for_press(1.0)
    assert ev.t_s == pytest.approx(0.5)


def test_clear_drops_stale_events(board):
    btn = Button(board, debounce_s=0.0)
    chip(board).press(TRIG, at_s=0.1, hold_s=0.1)
    board.clock.sleep(1.0)
    assert btn.clear() == 2
    assert btn.wait_for_event(timeout_s=0.5) is None


def test_active_high_button_with_pull_down():
    board = make_sim_board(trigger_active_low=False, trigger_bias="pull-down")
    try:
        btn = Button(board, debounce_s=0.01)
        chip(board).press(TRIG, at_s=0.2, hold_s=0.3, pressed_level=1)
        assert btn.wait_for_press(1.0).t_s == pytest.approx(0.21)
    finally:
        board.close()


def test_close_releases_the_line(board):
    with Button(board):
        with pytest.raises(OSError) as ei:
            Button(board)
        assert ei.value.errno == errno.EBUSY
    Button(board).close()


def test_bad_debounce(board):
    with pytest.raises(ValueError, match="debounce_s"):
        Button(board, debounce_s=-0.1)
