"""The heater's duty over a sliding window is bounded in the sequence (ISSUE #35 §6)."""

import dataclasses

import pytest

from edge.measure.watchdog import Limits
from edge.service.config import Config
from firmware_sim.rigs.daemon_rig import heater_on_intervals
from tests.support.daemons import assert_heater_safe, make_sequence

pytestmark = pytest.mark.hil


def _max_window_on_s(intervals, window_s):
    """Largest heater-on time in any window of ``window_s`` (it peaks where a window ends at an off)."""
    best = 0.0
    for _, end in intervals:
        lo = end - window_s
        best = max(best, sum(max(0.0, min(b, end) - max(a, lo)) for a, b in intervals))
    return best


@pytest.mark.slow  # six 5-s touches and their rests: over a minute of simulated sampling
def test_back_to_back_touches_are_held_to_the_duty_limit():
    rig, heater, seq, params = make_sequence()
    seq.limits = dataclasses.replace(seq.limits, max_duty=0.25, duty_window_s=40.0)
    # What runtime settings allowed: no cool-down, the shortest baseline, 5-s touches.
    params = dataclasses.replace(params, cooldown_s=0.0, baseline_s=0.1, contact_time_s=5.0)
    for _ in range(6):
        out = seq.run(params)
        assert out.status == "ok", out.error
    on = heater_on_intervals(rig.parts)
    assert len(on) == 6
    assert _max_window_on_s(on, 40.0) <= 0.25 * 40.0 + 0.05  # one sample period of slack at the edges
    assert on[-1][0] - on[0][0] > 40.0  # they were spread out, not refused
    assert_heater_safe(rig.parts, Config().heater.max_on_time_s)
    seq.close()


def test_the_wait_is_zero_when_the_window_has_room_and_exact_when_not():
    rig, heater, seq, params = make_sequence()
    seq.limits = Limits(10.0, 80.0, max_duty=0.5, duty_window_s=20.0)
    assert seq.duty_wait_s(5.0, now=100.0) == 0.0
    seq._log_heating(90.0, 98.0)  # 8 s on, ended 2 s ago
    # A 5-s touch starting at t ends at t + 5; the window [t - 15, t + 5] may hold 10 s, so at most
    # 5 s of the past heating: 98 - (t - 15) <= 5 gives t = 108 s, a wait of 8 s.
    assert seq.duty_wait_s(5.0, now=100.0) == pytest.approx(8.0, abs=1e-6)
    seq.close()


def test_a_touch_longer_than_the_duty_allows_is_refused_before_heating():
    rig, heater, seq, params = make_sequence()
    seq.limits = Limits(10.0, 80.0, max_duty=0.1, duty_window_s=20.0)
    out = seq.run(dataclasses.replace(params, contact_time_s=3.0))
    assert out.status == "aborted" and "duty limit" in out.error
    assert heater_on_intervals(rig.parts) == []
    seq.close()
