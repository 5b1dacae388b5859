"""The daemon's trigger-button path on the simulator: one measurement per press, none for presses during one.

The scene's touch presses the trigger (``touch.press_trigger``); a second
touch comes from :meth:`firmware_sim.Simulator.add_touch`. Virtual time only
moves while the daemon measures, so the test moves it to each press while
the daemon is idle. The heater invariant is read from the simulated GPIO/PWM
history.
"""

from __future__ import annotations

import pytest
import serial

from tests.support.daemons import FakeEstimator, assert_heater_safe
from tests.support.waiting import wait_until
from firmware_sim.daemon_thread import DaemonThread
from firmware_sim import load_scene
from firmware_sim.ptylink import NullModem
from firmware_sim.run import config_for_scene
from host.client import DeviceClient

pytestmark = pytest.mark.hil

BASELINE_s, CONTACT_s, COOLDOWN_s = 0.2, 1.5, 1.0


def _spy_button_polls(button) -> list:
    """Record what each of the serve loop's button polls (``wait_for_event``) returned."""
    polls: list = []
    real = button.wait_for_event

    def wait_for_event(timeout_s=None):
        ev = real(timeout_s)
        polls.append(ev)
        return ev

    button.wait_for_event = wait_for_event
    return polls


def _wait_until_presses_drained(polls: list, what: str) -> None:
    """Until a button poll made from now on found no event: every press pending before it has been read.

    The serve loop polls the button only while idle and not measuring, one event a turn, so a press
    that started a measurement would hold this wait until that measurement ended (and show in the
    history); virtual time stands still while the daemon is idle, so no new press can come in.
    """
    n = len(polls)
    wait_until(lambda: None in polls[n:], what)


def test_each_press_measures_once_and_presses_during_a_measurement_are_ignored(tmp_path):
    sim = load_scene("glass_15V")  # its touch presses the trigger at start_s = 0.5 s
    t1 = sim.scene.touch.start_s
    assert sim.scene.touch.press_trigger
    cfg = config_for_scene(sim.scene, tmp_path, {"measurement": {
        "trigger_button": True, "baseline_s": BASELINE_s, "contact_time_s": CONTACT_s, "cooldown_s": COOLDOWN_s}})
    trig = sim.parts.trigger_offset
    # Presses while the first measurement runs (baseline, heating): not new requests.
    for at in (t1 + 0.1, t1 + BASELINE_s + 0.8):
        sim.parts.chip.press(trig, at, 0.05)
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
        with DaemonThread(cfg, sim.board(), port, estimator=FakeEstimator()) as dt:
            d = dt.daemon
            assert d.button is not None
            polls = _spy_button_polls(d.button)
            assert sim.now() == 0.0 and d.history.count() == 0
            sim.advance_to(t1 + 0.05)  # the scene's press, past the 20-ms debounce
            wait_until(lambda: d.history.count() == 1 and d.state == "idle", "the first measurement")
            t_idle = sim.now()
            assert t_idle > t1 + BASELINE_s + CONTACT_s
            # The ignored presses are read once idle; nothing else is pending, so no measurement starts.
            _wait_until_presses_drained(polls, "the presses during the first measurement to be read")
            assert not d.measuring
            assert d.history.count() == 1 and d.state == "idle" and sim.now() == t_idle
            # A second touch with its own press, after the cool-down, and a press during that measurement.
            t2 = t_idle + COOLDOWN_s + 0.5
            sim.add_touch(t2, 2.5)
            sim.parts.chip.press(trig, t2 + BASELINE_s + 0.5, 0.05)
            sim.advance_to(t2 + 0.05)
            wait_until(lambda: d.history.count() == 2 and d.state == "idle", "the second measurement")
            _wait_until_presses_drained(polls, "the press during the second measurement to be read")
            assert not d.measuring
            with DeviceClient(nm.host_port, timeout_s=5.0) as c:
                items = [c.result(2), c.result(1)]   # one reply each (a record carries the whole answer)
                assert c.history(0, 10)["total"] == 2
                st = c.status()
            limit = d.config.heater.max_on_time_s
    assert st["state"] == "idle" and st["measurements"] == 2
    assert [r["measurement_id"] for r in items] == [2, 1]
    assert all(r["status"] == "ok" and r["contact_time_s"] == pytest.approx(CONTACT_s) for r in items)
    # One heating per accepted press, starting a baseline after it; none for the presses in between.
    iv = sim.heater_intervals()
    assert len(iv) == 2
    for (a, b), t_press in zip(iv, (t1, t2)):
        assert t_press + BASELINE_s <= a < t_press + BASELINE_s + 0.2
        assert b - a == pytest.approx(CONTACT_s, abs=0.02)
    inv = assert_heater_safe(sim.parts, limit)
    assert inv["n_intervals"] == 2
    sim.close()
