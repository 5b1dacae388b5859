"""The heater watchdog's own thread, on a clock that cannot notify its steps (a real device's).

Its clock-hook path (the simulator's virtual clock) is tested through the sequence in
``tests/edge/service/test_safety.py``; here the wall-clock thread alone must cut the heater,
and must not run while there is nothing to watch.
"""

from __future__ import annotations

import threading
import time

import pytest

from edge.measure.watchdog import HeaterWatchdog, Trip
from tests.support.waiting import wait_until


class _Heater:
    """A heater whose on-time the test sets (``on_time_s``); ``off()`` is recorded.

    The watchdog's thread polls in wall time, but the on-time it compares with its limit is the
    test's to move: on a loaded machine the thread may first run after any wall-clock span, and
    whether it polled before the limit or cut at it must not depend on when it got to run.
    """

    def __init__(self) -> None:
        self.on_time_s: float | None = None
        self.offs = 0

    def on(self) -> None:
        self.on_time_s = 0.0

    def off(self) -> None:
        self.offs += 1
        self.on_time_s = None

    @property
    def current_on_time_s(self) -> float:
        return 0.0 if self.on_time_s is None else self.on_time_s


class _WallClock:
    """No ``on_advance``: the watchdog has only its thread."""

    def now(self) -> float:
        return time.monotonic()


def _counting(wd: HeaterWatchdog) -> list[int]:
    calls = [0]
    inner = wd.check

    def check():
        calls[0] += 1
        return inner()

    wd.check = check  # the thread looks the method up on the instance each time
    return calls


def test_disarmed_the_thread_sleeps_and_armed_it_cuts_the_heater_at_its_limit():
    heater = _Heater()
    wd = HeaterWatchdog(heater, _WallClock(), limit_s=0.2, guard_s=0.05, poll_s=0.005)
    try:
        calls = _counting(wd)
        time.sleep(0.1)          # 20 polls' worth of wall time
        assert calls[0] == 0
        heater.on()
        wd.arm()
        heater.on_time_s = 0.1   # below limit - guard: polled, not cut
        wait_until(lambda: calls[0] >= 3, "the armed watchdog to poll")
        assert wd.tripped is None and heater.offs == 0 and heater.on_time_s == 0.1
        heater.on_time_s = wd.limit_s - wd.guard_s  # reached: cut at the next poll
        wait_until(lambda: wd.tripped is not None, "the watchdog to trip", timeout_s=5.0)
        assert wd.tripped == Trip.MAX_ON_TIME and heater.offs >= 1 and heater.on_time_s is None
        wd.disarm()
        # The thread may be in the one poll it was waiting out when disarm() came (that check finds
        # it disarmed and does nothing); after it the thread sleeps: at most that one call more.
        settled = calls[0]
        time.sleep(0.1)
        assert calls[0] <= settled + 1
    finally:
        wd.close()
    assert not wd._thread.is_alive()


def test_the_thread_cuts_at_once_on_abort_and_close_ends_it_while_disarmed_or_armed():
    abort = threading.Event()
    heater = _Heater()
    wd = HeaterWatchdog(heater, _WallClock(), limit_s=60.0, abort_event=abort, poll_s=0.005)
    heater.on()
    wd.arm()
    abort.set()
    wait_until(lambda: wd.tripped is not None, "the watchdog to trip", timeout_s=5.0)
    assert wd.tripped == Trip.ABORT and heater.on_time_s is None
    wd.close()
    assert not wd._thread.is_alive()

    idle = HeaterWatchdog(_Heater(), _WallClock(), limit_s=1.0)   # never armed: asleep until woken
    idle.close()  # joins the thread (2 s at most): only a wake-up by close() ends it
    assert not idle._thread.is_alive()


@pytest.mark.parametrize("limit_s,guard_s", [(0.01, 0.02), (1.0, -0.1)])
def test_limits_that_leave_no_time_are_refused(limit_s, guard_s):
    with pytest.raises(ValueError, match="limit_s > guard_s >= 0"):
        HeaterWatchdog(_Heater(), _WallClock(), limit_s=limit_s, guard_s=guard_s)
