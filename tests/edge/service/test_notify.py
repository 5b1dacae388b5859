"""systemd notify protocol: sd_notify, the gated watchdog pets, the daemon's two loops, the hardware hook."""

import socket
import threading
import time

import pytest

from edge.service.daemon import Daemon
from edge.service.notify import Notifier, sd_notify, watchdog_interval_s
from firmware_sim.rigs.daemon_rig import make_rig
from tests.support.daemons import FakeEstimator, HookedSensors, sim_config


@pytest.fixture
def notify_socket(tmp_path):
    path = str(tmp_path / "notify.sock")
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(path)
    s.settimeout(0.01)
    yield path, s
    s.close()


def _drain(s):
    out = []
    while True:
        try:
            out.append(s.recv(4096).decode())
        except socket.timeout:
            return out


def test_sd_notify_sends_one_datagram_and_is_a_no_op_without_the_socket(notify_socket):
    path, s = notify_socket
    assert sd_notify("READY=1", "STATUS=up", env={"NOTIFY_SOCKET": path})
    assert _drain(s) == ["READY=1\nSTATUS=up"]
    assert not sd_notify("READY=1", env={})
    assert not sd_notify("READY=1", env={"NOTIFY_SOCKET": path + ".gone"})  # never raises


def test_watchdog_interval_from_the_environment():
    assert watchdog_interval_s({"WATCHDOG_USEC": "2500000"}) == 2.5
    assert watchdog_interval_s({}) is None and watchdog_interval_s({"WATCHDOG_USEC": "x"}) is None
    assert watchdog_interval_s({"WATCHDOG_USEC": "1000000", "WATCHDOG_PID": "1"}) is None  # another process's


def test_pets_go_out_only_while_every_running_loop_beats(notify_socket):
    path, s = notify_socket
    now = [0.0]
    n = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "4000000"}, clock=lambda: now[0])
    assert n.pet_interval_s == 1.0
    n.beat("serve")
    assert _drain(s) == ["WATCHDOG=1"]
    n.beat("measure")
    for _ in range(3):  # both loops turn: a pet per interval
        now[0] += 1.0
        n.beat("measure")
        n.beat("serve")
    assert _drain(s) == ["WATCHDOG=1"] * 3
    for _ in range(5):  # the measurement loop is stuck, the serve loop still turns: no pets
        now[0] += 1.0
        n.beat("serve")
    assert _drain(s) == []
    n.done("measure")  # it ended: the serve loop alone keeps the watchdog fed again
    now[0] += 1.0
    n.beat("serve")
    assert _drain(s) == ["WATCHDOG=1"]


def test_hardware_watchdog_is_pet_and_closed_with_the_magic_character(tmp_path):
    dev = tmp_path / "watchdog"
    dev.write_bytes(b"")
    now = [0.0]
    n = Notifier({}, clock=lambda: now[0], hw_watchdog=str(dev))
    assert n.pet_interval_s == Notifier.HW_PET_INTERVAL_s  # no systemd: pets for the device alone
    for _ in range(3):
        now[0] += 1.0
        n.beat("serve")
    n.close()
    n.close()
    assert dev.read_bytes() == b"\0\0\0V"


def test_daemon_pets_from_its_serve_loop_and_its_measurement_loop(tmp_path, notify_socket, monkeypatch):
    path, s = notify_socket
    # The gate is the mechanism under test, not the period: WatchdogSec=0.04 s pets every 0.01 s, and every
    # wall-time span below is counted in pet periods.
    pet_s = 0.01
    monkeypatch.setenv("NOTIFY_SOCKET", path)
    monkeypatch.setenv("WATCHDOG_USEC", str(int(4 * pet_s * 1e6)))
    rig = make_rig()
    d = Daemon(sim_config(tmp_path), rig.board, estimator=FakeEstimator())
    assert d.notifier.pet_interval_s == pytest.approx(pet_s)
    stuck, release = threading.Event(), threading.Event()

    def hook(n, on):
        if n <= 12:
            # A read takes wall time (0.3 pet periods), so the measurement spans several pet periods before
            # it is stuck: its loop beats between reads, a pet goes out at least every fourth read.
            # (After the release one more pet at most: the serve loop below stops beating.)
            time.sleep(0.3 * pet_s)
        if on and n == 12:
            stuck.set()
            release.wait(20)

    d.sensors = HookedSensors(d.sensors, d.heater, hook)
    beats = []
    real_beat = d.notifier.beat
    d.notifier.beat = lambda loop: (beats.append(loop), real_beat(loop))[1]
    # The notify socket is read all along, as systemd does: a unix datagram queue holds only
    # net.unix.max_dgram_qlen (10) messages, and a pet sent to a full one blocks the loop that sends it.
    got, reading = [], threading.Event()

    def read_notify_socket():
        while not reading.is_set():
            got.extend(_drain(s))

    reader = threading.Thread(target=read_notify_socket, daemon=True)
    reader.start()

    def received():
        """Messages received once every pet sent so far has arrived (the loops are not beating)."""
        deadline = time.monotonic() + 20
        while got.count("WATCHDOG=1") < d.notifier.pets and time.monotonic() < deadline:
            time.sleep(0.001)
        return len(got)

    result = {}
    th = threading.Thread(target=lambda: result.setdefault("rec", d.measure()))
    th.start()
    try:
        assert stuck.wait(20)
        # The measurement loop is stuck in a read; a serve loop keeps beating, yet no pet goes out.
        def serve_for(dt_s):
            """Beat as a serve loop does for ``dt_s``, the last beat at or after its end."""
            t_end = time.monotonic() + dt_s
            while True:
                last = time.monotonic() >= t_end
                d.notifier.beat("serve")
                if last:
                    return
                time.sleep(0.2 * pet_s)

        # At most one pet: the loop's last beat came right before the read. A beat a full pet period
        # after the stuck read began sends it if it is due, so none is pending after this.
        serve_for(2 * pet_s)
        n = received()
        serve_for(6 * pet_s)  # six pet periods
        received()
        assert got[n:] == []
    finally:
        release.set()
        th.join(20)
        reading.set()
        reader.join(20)
    assert result["rec"]["status"] == "ok"
    assert "measure" in beats and d.notifier.pets >= 3  # pets went out while it ran
    d.close()


def test_the_systemd_unit_is_a_notify_service_with_a_watchdog_and_heater_off_after_stop():
    from pathlib import Path

    unit = (Path(__file__).resolve().parents[3] / "edge" / "service" / "thermotouch-edge.service").read_text()
    lines = {ln.strip() for ln in unit.splitlines()}
    assert "Type=notify" in lines and "NotifyAccess=main" in lines
    assert any(ln.startswith("WatchdogSec=") for ln in lines)
    assert any(ln.startswith("ExecStopPost=") and ln.endswith("--heater-off") for ln in lines)
    assert "RestrictAddressFamilies=AF_UNIX" in lines  # the notify socket is a unix socket
