"""The serve loop during a measurement: STATUS answered, other commands BUSY, the heater still safe.

serve() runs a measurement in a worker thread. A sensor hook holds the
measurement in its heating phase (in wall time; virtual time stands still
meanwhile) so the host can talk to the daemon while it measures.
"""

from __future__ import annotations

import threading
import time

import pytest
import serial

from tests.support.daemons import FakeEstimator, HookedSensors, assert_heater_safe, sim_config
from edge.service.config import Config
from edge.service.daemon import Daemon
from firmware_sim.daemon_thread import DaemonThread
from edge.protocol.commands import Command
from edge.protocol.errors import ErrorCode
from edge.protocol.endpoint import read_available
from edge.protocol.messages import ErrorReply, Reply, decode_reply, encode_request
from edge.protocol.frame import FrameDecoder
from firmware_sim.rigs.daemon_rig import make_rig
from firmware_sim.ptylink import NullModem

pytestmark = pytest.mark.hil
MAX_ON = Config().heater.max_on_time_s
WAIT_s = 20.0  # generous bound on wall-time waits (never reached when things work)


class RawHost:
    """Host side speaking raw frames, so requests can overlap (DeviceClient sends one at a time)."""

    def __init__(self, port: str) -> None:
        self.ser = serial.Serial(port, timeout=0.02)
        self.decoder = FrameDecoder()
        self.replies: dict[int, Reply | ErrorReply] = {}

    def send(self, command: Command, rid: int, args: dict | None = None) -> None:
        self.ser.write(encode_request(command, rid, args))
        self.ser.flush()

    def reply(self, rid: int, timeout_s: float = WAIT_s) -> Reply | ErrorReply:
        deadline = time.monotonic() + timeout_s
        while rid not in self.replies:
            if time.monotonic() > deadline:
                raise AssertionError(f"no reply to request {rid}")
            # What has arrived, as soon as a byte has (a read of 4096 would wait out the port's timeout).
            for frame in self.decoder.feed(read_available(self.ser)):
                self.replies[frame.request_id] = decode_reply(frame)
        return self.replies.pop(rid)

    def ask(self, command: Command, rid: int, args: dict | None = None) -> Reply | ErrorReply:
        self.send(command, rid, args)
        return self.reply(rid)

    def close(self) -> None:
        self.ser.close()


def hold_heating(daemon: Daemon, rig, release: threading.Event | None = None) -> threading.Event:
    """Hold the daemon's next measurement at its fifth heating read until ``release`` (or the heater is cut).

    Returns the event set once the hold begins.
    """
    heating = threading.Event()
    reads: list[int] = []

    def hook(n, heater_on):
        if heater_on:
            reads.append(n)
        if heater_on and len(reads) == 5:
            heating.set()
            deadline = time.monotonic() + WAIT_s
            while time.monotonic() < deadline and rig.parts.chip.level(rig.parts.heater_enable_offset) == 1:
                if release is not None and release.is_set():
                    return
                time.sleep(0.002)

    daemon.sensors = HookedSensors(daemon.sensors, daemon.heater, hook)
    return heating


def test_status_answers_during_a_measurement_and_other_commands_are_busy(tmp_path):
    rig = make_rig()
    cfg = sim_config(tmp_path)
    release = threading.Event()
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
        with DaemonThread(cfg, rig.board, port, estimator=FakeEstimator()) as dt:
            d = dt.daemon
            heating = hold_heating(d, rig, release)
            host = RawHost(nm.host_port)
            try:
                host.send(Command.MEASURE, 10, {"contact_time_s": 1.5})
                assert heating.wait(WAIT_s)
                st = host.ask(Command.STATUS, 11)
                assert isinstance(st, Reply) and st.request_id == 11
                assert st.body["state"] == "measuring" and st.body["phase"] == "heating"
                assert st.body["heater_on"] is True
                # Baseline (0.5 s) and four heating samples have passed on the board clock.
                assert cfg.measurement.baseline_s < st.body["measurement_elapsed_s"] < 1.5
                for rid, command, args in ((12, Command.CONFIG_SET, {"values": {"heater.power_W": 1.0}}),
                                           (13, Command.RESULT, {}),
                                           (14, Command.MEASURE, {}),
                                           (15, Command.SERIES, {"measurement_id": 1}),
                                           (16, Command.MODEL_BEGIN, {"size": 10, "sha256": "ab" * 32}),
                                           (17, Command.INFO, {})):
                    r = host.ask(command, rid, args)
                    assert isinstance(r, ErrorReply) and r.code == ErrorCode.BUSY, (command, r)
                    assert "measurement is running" in r.message
                assert host.ask(Command.PING, 18, {"echo": "alive"}).body == {"echo": "alive"}
                assert d.history.count() == 0 and rig.parts.chip.level(rig.parts.heater_enable_offset) == 1
                release.set()
                done = host.reply(10)
                assert isinstance(done, Reply) and done.command == Command.MEASURE
                assert done.body["measurement_id"] == 1 and done.body["status"] == "ok"
                assert done.body["contact_time_s"] == pytest.approx(1.5)
                # Right after the reply the daemon takes requests again.
                after = host.ask(Command.STATUS, 19)
                assert after.body["state"] == "idle" and "phase" not in after.body
                assert host.ask(Command.RESULT, 20).body["measurement_id"] == 1
                assert host.ask(Command.CONFIG_SET, 21, {"values": {"heater.power_W": 1.0}}).body["config"][
                    "heater.power_W"] == 1.0
            finally:
                host.close()
            assert d.history.count() == 1  # the refused MEASURE did not measure
    inv = assert_heater_safe(rig.parts, MAX_ON)
    assert inv["n_intervals"] == 1


def test_stop_during_a_measurement_cuts_the_heater_and_stores_the_record(tmp_path):
    rig = make_rig()
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
        dt = DaemonThread(sim_config(tmp_path), rig.board, port, estimator=FakeEstimator())
        d = dt.start()
        heating = hold_heating(d, rig)
        host = RawHost(nm.host_port)
        try:
            host.send(Command.MEASURE, 1)
            assert heating.wait(WAIT_s)
            dt.stop(WAIT_s)  # what SIGTERM does: set the stop event
            assert not dt.thread.is_alive() and dt.error is None
            answer = host.reply(1)  # the worker still answers the request it held
        finally:
            host.close()
    assert d.history.closed and d.state == "stopped"
    inv = assert_heater_safe(rig.parts, MAX_ON)
    assert inv["n_intervals"] == 1 and inv["longest_on_s"] < 1.0
    from edge.storage.history import History

    with History(tmp_path / "history.db") as h:
        rec = h.get(1)
    assert rec["status"] == "aborted" and rec["reason"] == "stopped"
    assert isinstance(answer, Reply) and answer.body["reason"] == "stopped"


class BreakingPort:
    """A port whose reads raise ``exc`` once ``when`` is set (a USB link unplugged, a Ctrl-C)."""

    def __init__(self, inner, when: threading.Event, exc: BaseException) -> None:
        self.inner, self.when, self.exc = inner, when, exc
        self.writes_after_break = 0

    def read(self, n=1):
        if self.when.is_set():
            raise self.exc
        return self.inner.read(n)

    def write(self, data):
        if self.when.is_set():
            self.writes_after_break += 1
            raise serial.SerialException("port gone")
        return self.inner.write(data)

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def __setattr__(self, name, value):
        if name == "timeout":
            self.inner.timeout = value
        else:
            object.__setattr__(self, name, value)


def _serve_with_breaking_port(tmp_path, exc: BaseException):
    rig = make_rig()
    d = Daemon(sim_config(tmp_path), rig.board, estimator=FakeEstimator())
    release = threading.Event()
    heating = hold_heating(d, rig, release)
    raised: list[BaseException] = []
    joining, join_aborts = threading.Event(), []  # serve()'s wait for the worker has begun, with this abort
    real_join_worker = d._join_worker

    def join_worker(*, abort):
        join_aborts.append(abort)
        joining.set()
        real_join_worker(abort=abort)

    d._join_worker = join_worker
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as dev_port:
        port = BreakingPort(dev_port, heating, exc)
        host = RawHost(nm.host_port)
        host.send(Command.MEASURE, 1)

        def release_soon():
            # Once serve() has failed and waits for the worker, let the measurement go on; a wait that
            # stops the worker has set the stop event first (the hold then ends on the heater cut).
            heating.wait(WAIT_s)
            joining.wait(WAIT_s)
            if join_aborts and join_aborts[0]:
                d.stop_event.wait(WAIT_s)
            release.set()

        threading.Thread(target=release_soon, daemon=True).start()
        try:
            d.serve(port)
        except BaseException as e:  # noqa: BLE001 - the test inspects it
            raised.append(e)
        host.close()
    assert not d.measuring and not rig.board.closed
    rec = d.history.get(1)
    d.close()
    return rig, rec, raised, port


def test_port_error_mid_measurement_lets_it_finish_and_store_then_propagates(tmp_path):
    rig, rec, raised, port = _serve_with_breaking_port(tmp_path, serial.SerialException("device reports readiness"))
    assert len(raised) == 1 and isinstance(raised[0], serial.SerialException)
    # The measurement completed and was stored; only its reply was lost with the port.
    assert rec["status"] == "ok" and rec["result"] is not None
    assert port.writes_after_break == 1
    inv = assert_heater_safe(rig.parts, MAX_ON)
    assert inv["n_intervals"] == 1


def test_keyboard_interrupt_in_the_serve_loop_stops_the_measurement(tmp_path):
    rig, rec, raised, port = _serve_with_breaking_port(tmp_path, KeyboardInterrupt())
    assert len(raised) == 1 and isinstance(raised[0], KeyboardInterrupt)
    assert rec["status"] == "aborted" and rec["reason"] == "stopped"
    inv = assert_heater_safe(rig.parts, MAX_ON)
    assert inv["n_intervals"] == 1 and inv["longest_on_s"] < 1.0


def test_direct_measure_calls_do_not_overlap(tmp_path):
    from edge.protocol.errors import CommandError

    rig = make_rig()
    d = Daemon(sim_config(tmp_path), rig.board, estimator=FakeEstimator())
    heating = hold_heating(d, rig, release := threading.Event())
    box = {}
    th = threading.Thread(target=lambda: box.update(rec=d.measure()), daemon=True)
    th.start()
    try:
        assert heating.wait(WAIT_s)
        assert d.state == "measuring"
        with pytest.raises(CommandError) as ei:
            d.measure()
        assert ei.value.code == ErrorCode.BUSY
    finally:
        release.set()
        th.join(WAIT_s)
    assert box["rec"]["status"] == "ok" and d.state == "idle" and d.history.count() == 1
    d.close()
    assert_heater_safe(rig.parts, MAX_ON)
