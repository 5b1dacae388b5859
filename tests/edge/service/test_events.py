"""A streaming MEASURE over a real pty link: the events it pushes, their bounds, and a slow or broken host.

One simulated daemon serves the module (a touch takes ~0.1 s of wall time on the virtual clock).
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest
import serial

from edge.protocol.commands import MAX_EVENT_SAMPLES, EventKind
from edge.service.config import Config
from edge.service.events import EVENT_PERIOD_s, EventStream
from firmware_sim.daemon_thread import DaemonThread
from firmware_sim.ptylink import NullModem
from firmware_sim.rigs.daemon_rig import make_rig
from host.client import DeviceClient
from tests.support.daemons import FakeEstimator, HookedSensors, assert_heater_safe, sim_config

pytestmark = pytest.mark.hil
MAX_ON = Config().heater.max_on_time_s


@pytest.fixture(scope="module")
def probe(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("events")
    rig = make_rig()
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
        with DaemonThread(sim_config(tmp, measurement={"cooldown_s": 0.0}), rig.board, port,
                          estimator=FakeEstimator(rig.parts)) as dt:
            with DeviceClient(nm.host_port, timeout_s=5.0) as client:
                yield client, dt.daemon, rig
        assert dt.error is None


def _phases(events):
    return [e.body["phase"] for e in events if e.kind == EventKind.PHASE]


def test_a_streaming_measure_pushes_phases_samples_and_the_running_answer_before_its_reply(probe):
    client, daemon, rig = probe
    events = []
    rec = client.measure(contact_time_s=1.5, on_event=events.append)
    assert rec["status"] == "ok"
    assert [e.body["seq"] for e in events] == list(range(len(events)))  # none lost on a reading host
    phases = _phases(events)
    assert phases[0] == "baseline" and phases[-3:] == ["heating", "estimating", "done"]
    done = events[-1].body
    assert done["measurement_id"] == rec["measurement_id"] and done["status"] == "ok"
    assert done["events_sent"] == len(events) - 1 and done["events_dropped"] == 0
    assert any(e.kind == EventKind.ANSWER for e in events)
    # The streamed samples are the record's, on the record's time origin once heater-on is subtracted.
    t_on = next(e.body["t_s"] for e in events if e.body.get("phase") == "heating")
    batches = [e.body for e in events if e.kind == EventKind.SAMPLES]
    t = np.concatenate([b["sample_t_s"] for b in batches]) - t_on
    T = np.concatenate([b["T_C"] for b in batches])
    series = client.series(rec["measurement_id"], "raw")
    assert t.size == series["raw_t_s"].size
    np.testing.assert_allclose(t, series["raw_t_s"], atol=1e-5)
    np.testing.assert_allclose(T, series["raw_T_C"], atol=1e-3)
    assert client.status()["events_dropped"] == 0
    assert_heater_safe(rig.parts, MAX_ON)


def test_events_stay_within_their_rate_and_size_bounds_at_a_high_sample_rate(probe):
    client, daemon, rig = probe
    events = []
    rec = client.measure(contact_time_s=2.0, sample_rate_Hz=100.0, on_event=events.append)
    assert rec["status"] == "ok"
    batches = [e.body for e in events if e.kind == EventKind.SAMPLES]
    answers = [e.body for e in events if e.kind == EventKind.ANSWER]
    n_phases = len(_phases(events))
    duration_s = events[-1].body["t_s"]
    per_period = math.ceil(duration_s / EVENT_PERIOD_s) + 1
    assert all(len(b["sample_t_s"]) <= MAX_EVENT_SAMPLES for b in batches)
    # One batch per period (a phase change may cut one short) and one answer per period.
    assert len(batches) <= per_period + n_phases
    assert len(answers) <= per_period + n_phases
    assert sum(len(b["sample_t_s"]) for b in batches) == rec["n_samples"]
    # A plain MEASURE gets no events at all.
    before = client.events_received + client.events_ignored
    assert client.measure(contact_time_s=0.5)["status"] == "ok"
    assert client.events_received + client.events_ignored == before


def test_a_link_that_refuses_every_event_loses_events_not_the_touch(probe, monkeypatch):
    client, daemon, rig = probe

    def refuse(rid, body, final=False):
        raise OSError("link broken")

    monkeypatch.setattr(daemon.endpoint, "send_event", refuse)
    events = []
    rec = client.measure(contact_time_s=1.0, on_event=events.append)
    assert rec["status"] == "ok" and rec["result"] is not None
    assert events == []
    assert daemon.history.get(rec["measurement_id"])["status"] == "ok"
    assert_heater_safe(rig.parts, MAX_ON)


def test_a_host_that_stops_reading_loses_events_and_the_touch_is_stored(probe, monkeypatch):
    client, daemon, rig = probe
    ep = daemon.endpoint
    real_write, real_send = ep._write_now, ep.send_event
    done_queued = threading.Event()

    def stuck_line(data, event=False):  # the host reads nothing until the touch has ended
        done_queued.wait(10.0)
        return real_write(data, event)

    def send_event(rid, body, *, final=False):
        ok = real_send(rid, body, final=final)
        if body.get("phase") == "done":
            done_queued.set()
        return ok

    monkeypatch.setattr(ep, "_write_now", stuck_line)
    monkeypatch.setattr(ep, "send_event", send_event)
    monkeypatch.setattr(ep, "max_event_bytes", 1000)  # a touch's events are ~4 kB: the share fills
    events = []
    rec = client.measure(contact_time_s=2.0, sample_rate_Hz=50.0, on_event=events.append)
    assert rec["status"] == "ok"
    done = events[-1].body
    assert done["phase"] == "done" and done["events_dropped"] > 0
    # The gaps are visible to the host as missing sequence numbers.
    seqs = [e.body["seq"] for e in events]
    assert seqs == sorted(seqs) and len(seqs) < seqs[-1] + 1
    assert client.status()["events_dropped"] >= done["events_dropped"]
    assert_heater_safe(rig.parts, MAX_ON)


def test_an_event_stream_survives_nothing_and_breaks_nothing():
    clock = iter(np.arange(0.0, 100.0, 0.01)).__next__
    sent = []
    s = EventStream(lambda body, final=False: sent.append(body) or True, clock)
    s.phase("baseline")
    s.sample(0.0, float("nan"), 1.0)
    s.close(3, "ok")
    assert [b["kind"] for b in sent] == ["phase", "samples", "phase"] and sent[1]["T_C"] == [None]
    s.sample(1.0, 25.0, 1.0)  # after close: nothing
    assert len(sent) == 3

    def boom(body, final=False):
        raise RuntimeError("no link")

    broken = EventStream(boom, clock, armed=True)
    broken.phase("baseline")  # logged, stream closed, no exception for the measurement
    assert broken.closed


def test_an_armed_stream_names_its_waiting_armed_and_its_heating_after_a_contact():
    clock = iter(np.arange(0.0, 100.0, 0.01)).__next__
    sent = []
    s = EventStream(lambda body, final=False: sent.append(body) or True, clock, armed=True)
    for p in ("baseline", "heating", "estimating", "idle"):
        s.phase(p)
    s.close(None, "aborted")
    assert [b["phase"] for b in sent] == ["armed", "contact", "heating", "estimating", "done"]
    assert sent[-1]["measurement_id"] is None


def test_a_host_that_interrupts_on_an_event_aborts_the_touch_and_the_heater_goes_off(probe, monkeypatch):
    client, daemon, rig = probe
    reads, held = [], []

    def hold(n, heater_on):  # hold the touch once, at its 5th heating read (wall time), until the heater is cut
        reads.append(heater_on)
        if sum(reads) < 5 or held:
            return
        held.append(n)
        deadline = time.monotonic() + 10.0
        while daemon.heater.is_on and time.monotonic() < deadline:
            time.sleep(0.002)

    real_sensors = daemon.sensors
    monkeypatch.setattr(daemon, "sensors", HookedSensors(real_sensors, daemon.heater, hold))

    def interrupt(event):
        if event.body.get("phase") == "heating":
            raise KeyboardInterrupt  # Ctrl-C in the robot's callback

    with pytest.raises(KeyboardInterrupt):
        client.measure(contact_time_s=2.0, on_event=interrupt)
    assert client.last_abort is not None and client.last_abort["aborted"]
    rec = daemon.history.get(client.last_abort["measurement_id"])
    assert rec["status"] == "aborted" and rec["reason"] == "host_abort"
    assert_heater_safe(rig.parts, MAX_ON)
    daemon.sensors = real_sensors
    assert client.measure(contact_time_s=0.5)["status"] == "ok"  # the stale reply and events are skipped


def test_a_sensor_fault_while_streaming_ends_the_touch_as_without_events(probe, monkeypatch):
    from edge.hw.faults import SensorFault
    from host.client import DeviceError

    client, daemon, rig = probe
    reads = []

    def fail(n, heater_on):  # the converter stops answering at the 3rd heating read
        reads.append(heater_on)
        if sum(reads) == 3 and heater_on:
            raise SensorFault("mcp9600@0x60", "i2c", "bus stuck")

    monkeypatch.setattr(daemon, "sensors", HookedSensors(daemon.sensors, daemon.heater, fail))
    events = []
    with pytest.raises(DeviceError) as e:
        client.measure(contact_time_s=1.0, on_event=events.append)
    assert e.value.code.name == "SENSOR_FAULT"
    done = events[-1].body
    assert done["phase"] == "done" and done["status"] == "failed"
    assert daemon.history.get(done["measurement_id"])["reason"] == "sensor_fault"
    assert_heater_safe(rig.parts, MAX_ON)


def test_a_device_that_predates_events_still_touches_for_a_streaming_host(probe, monkeypatch):
    import edge.protocol.endpoint as endpoint_mod
    from edge.protocol.errors import ProtocolError

    client, daemon, rig = probe
    real = endpoint_mod.decode_request

    def old_device(frame):  # the device's own table without ``stream``, as before events
        req = real(frame)
        if "stream" in req.args:
            raise ProtocolError("MEASURE has no argument 'stream'", "stream", request_id=req.request_id)
        return req

    monkeypatch.setattr(endpoint_mod, "decode_request", old_device)
    n = daemon.history.count()
    events = []
    rec = client.measure(contact_time_s=0.5, on_event=events.append)
    assert rec["status"] == "ok" and events == [] and daemon.history.count() == n + 1
