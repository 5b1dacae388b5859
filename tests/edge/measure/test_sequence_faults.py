"""Faults that clear, clear (ISSUE #35 §4): the read-time limit is measured per touch."""

import pytest

from edge.status import Reason, Status
from firmware_sim.rigs.daemon_rig import heater_on_intervals
from tests.support.daemons import HookedSensors, assert_heater_safe, make_sequence

pytestmark = pytest.mark.hil


def test_one_slow_read_stops_its_touch_before_heating_and_the_next_touch_measures():
    rig, heater, seq, params = make_sequence()
    slow = {"armed": True}

    def hook(n, heater_on):
        if slow["armed"] and n == 1:  # one baseline read hangs 10 s on the board's clock, then the bus is fine
            slow["armed"] = False
            rig.clock.advance(10.0)

    seq.sensors = HookedSensors(seq.sensors, heater, hook)
    out = seq.run(params)
    assert out.status == Status.ABORTED and out.reason == Reason.MAX_ON_TIME
    assert "too slow" in out.error and "heater stayed off" in out.error
    assert heater_on_intervals(rig.parts) == []  # not even a millisecond's pulse
    assert heater.disabled is None  # nothing latched
    for _ in range(2):
        out = seq.run(params)
        assert out.status == Status.OK, out.error
    assert len(heater_on_intervals(rig.parts)) == 2
    assert_heater_safe(rig.parts, 10.0)
    seq.close()
