"""The armed sequence's exit paths: the heater is never switched on while waiting for a touch.

A probe held in air (no contact in the world) is armed; the run ends ``no_contact`` when ``arm_s``
runs out, ``host_abort`` on ABORT and ``stopped`` when the daemon stops -- each with the heater
never on, and the samples taken in air kept in the record.
"""

from __future__ import annotations

import dataclasses

import pytest

from edge.status import Reason, Status
from tests.support.daemons import HookedSensors, make_sequence


def _armed(hook=None, arm_s=1.5):
    rig, heater, seq, params = make_sequence(contact=False)
    if hook is not None:
        seq.sensors = HookedSensors(seq.sensors, heater, lambda n, on: hook(n, on, seq))
    params = dataclasses.replace(params, arm_s=arm_s, settle_s=0.5)
    try:
        out = seq.run(params)
        on_after_run = heater.is_on     # before close(), which switches it off anyway
    finally:
        seq.close()   # its watchdog thread would otherwise outlive the test
    return rig, on_after_run, out


def _never_heated(rig, on_after_run, out):
    assert not on_after_run and out.heater_on_s == 0.0
    # The samples in air are kept.
    assert out.raw_t_s is not None and out.raw_t_s.size >= 5


def test_no_touch_within_arm_s_ends_no_contact():
    rig, on_after_run, out = _armed()
    assert out.status == Status.ABORTED and out.reason == Reason.NO_CONTACT
    _never_heated(rig, on_after_run, out)


@pytest.mark.parametrize("event,reason", [("cancel_event", Reason.HOST_ABORT), ("abort_event", Reason.STOPPED)])
def test_abort_or_stop_while_armed_ends_at_once_with_the_heater_never_on(event, reason):
    def hook(n, heater_on, seq):
        assert not heater_on            # armed: the heater stays off
        if n == 6:
            getattr(seq, event).set()

    rig, on_after_run, out = _armed(hook, arm_s=30.0)
    assert out.status == Status.ABORTED and out.reason == reason
    _never_heated(rig, on_after_run, out)
