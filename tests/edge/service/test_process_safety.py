"""The heater against the ends a daemon process can meet: every catchable signal, interpreter exit,
SIGKILL, and a freeze that only systemd's watchdog notices.

Each test runs a real daemon process on the simulator (tests/support/daemon_proc.py) and reads
the simulated hardware from outside it once it has ended: the GPIO line states (mirrored to files
with the holder's pid, :mod:`firmware_sim.gpiod.state`, which releases a dead holder's line as the
kernel does) and the sysfs PWM tree (plain files).
"""

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import serial

from edge.protocol.commands import Command
from edge.protocol.messages import encode_request
from edge.service.config import Config
from firmware_sim.gpiod.state import read_line

pytestmark = pytest.mark.hil
MAX_ON = Config().heater.max_on_time_s
SCRIPT = Path(__file__).resolve().parents[2] / "support" / "daemon_proc.py"
ENABLE = 17


def _pwm(tmp):
    d = tmp / "pwm" / "pwmchip0" / "pwm0"
    return {n: (d / n).read_text().strip() for n in ("duty_cycle", "enable")}


def _start(tmp, env=None):
    proc = subprocess.Popen([sys.executable, str(SCRIPT), str(tmp)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    host_port = proc.stdout.readline().strip()
    assert host_port.startswith("/dev/"), proc.stderr.read()
    return proc, host_port


def _heat(proc, host_port):
    """MEASURE and wait until the heater is on (the daemon then waits in a read, mid-heating)."""
    host = serial.Serial(host_port, timeout=0.05)
    host.write(encode_request(Command.MEASURE, 1, {}))
    host.flush()
    assert proc.stdout.readline().strip() == "HEATING"
    return host


def _kill(proc):
    if proc.poll() is None:
        proc.kill()
        proc.wait()


@pytest.mark.parametrize("sig", [signal.SIGHUP, signal.SIGQUIT, signal.SIGUSR1, signal.SIGUSR2, signal.SIGPIPE,
                                 signal.SIGALRM, signal.SIGABRT, signal.SIGXCPU, signal.SIGPWR,
                                 signal.SIGRTMIN], ids=lambda s: signal.Signals(s).name)
def test_every_catchable_signal_mid_heating_leaves_the_heater_off(tmp_path, sig):
    proc, host_port = _start(tmp_path)
    try:
        host = _heat(proc, host_port)
        assert read_line(tmp_path / "gpio", "gpiochip0", ENABLE)["level"] == 1  # heating now
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
        host.close()
    finally:
        _kill(proc)
    # Not an asked-for stop: a non-zero status makes systemd restart the daemon.
    assert proc.returncode == 128 + sig, err
    report = json.loads(out.strip().splitlines()[-1])
    assert report["invariant"]["off_now"] and report["invariant"]["longest_on_s"] <= MAX_ON
    (rec,) = report["records"]
    assert rec["status"] == "aborted" and rec["reason"] == "stopped"
    line = read_line(tmp_path / "gpio", "gpiochip0", ENABLE)
    assert line["level"] == 0 and not line["requested"]
    assert _pwm(tmp_path) == {"duty_cycle": "0", "enable": "0"}


def test_sigkill_mid_heating_the_released_enable_line_falls_inactive(tmp_path):
    proc, host_port = _start(tmp_path)
    try:
        host = _heat(proc, host_port)
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        host.close()
    finally:
        _kill(proc)
    assert proc.returncode == -signal.SIGKILL
    line = read_line(tmp_path / "gpio", "gpiochip0", ENABLE)
    # The kernel released the dead process's line request; its pull-down bias took it low.
    assert line["released_by_death"] and line["bias"] == "PULL_DOWN"
    assert line["level"] == 0
    # Nothing ran to stop the PWM: the enable line alone cut the power.
    pwm = _pwm(tmp_path)
    assert pwm["enable"] == "1" and int(pwm["duty_cycle"]) > 900_000


_EXIT_SCRIPT = """
import sys, threading
sys.path.insert(0, {root!r})
from pathlib import Path
from edge.hw.drivers.heater import Heater
from edge.service.main import install_signal_handlers
from firmware_sim.rigs.daemon_rig import make_rig
tmp = Path({tmp!r})
rig = make_rig(gpio_state_dir=tmp / "gpio", pwm_root=tmp / "pwm")
heater = Heater(rig.board, supply_voltage_V=15.0, resistance_ohm=44.0)
install_signal_handlers(threading.Event(), heater_off=heater.off)
heater.on(1.0)
print("ON", flush=True)
raise RuntimeError("a bug escapes main() with the heater on")
"""


def test_interpreter_exit_drives_the_heater_off(tmp_path):
    root = str(Path(__file__).resolve().parents[3])
    r = subprocess.run([sys.executable, "-c", _EXIT_SCRIPT.format(root=root, tmp=str(tmp_path))],
                       capture_output=True, text=True, timeout=60)
    assert r.stdout.strip() == "ON" and "a bug escapes main()" in r.stderr
    assert _pwm(tmp_path)["duty_cycle"] == "0"  # only the atexit hook could have done this
    assert read_line(tmp_path / "gpio", "gpiochip0", ENABLE)["level"] == 0


def test_a_frozen_daemon_stops_petting_and_the_watchdog_kill_leaves_the_heater_off(tmp_path):
    # The test plays systemd: a notify socket, WatchdogSec=1, SIGABRT then SIGKILL when the pets stop.
    watchdog_s = 1.0
    sock_path = str(tmp_path / "notify.sock")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(sock_path)
    sock.settimeout(0.05)
    env = dict(os.environ, NOTIFY_SOCKET=sock_path, WATCHDOG_USEC=str(int(watchdog_s * 1e6)))
    proc, host_port = _start(tmp_path, env)
    messages = []

    def drain(until_s):
        while time.monotonic() < until_s:
            try:
                messages.append((time.monotonic(), sock.recv(4096).decode()))
            except socket.timeout:
                pass

    try:
        drain(time.monotonic() + 1.5)
        assert any("READY=1" in m for _, m in messages)
        assert sum(m == "WATCHDOG=1" for _, m in messages) >= 2  # idle: the serve loop pets
        host = _heat(proc, host_port)
        os.kill(proc.pid, signal.SIGSTOP)  # frozen mid-heating, heater on
        t_frozen = time.monotonic()
        assert read_line(tmp_path / "gpio", "gpiochip0", ENABLE)["level"] == 1
        # Watchdog stand-in: no pet for WatchdogSec -> SIGABRT; still there after TimeoutAbortSec -> SIGKILL.
        last_pet = max(t for t, m in messages if m == "WATCHDOG=1")
        while time.monotonic() - last_pet < watchdog_s:
            n = len(messages)
            drain(time.monotonic() + 0.05)
            last_pet = max([last_pet] + [t for t, m in messages[n:] if m == "WATCHDOG=1"])
            assert time.monotonic() - t_frozen < 10, "pets went on from a frozen daemon"
        os.kill(proc.pid, signal.SIGABRT)
        time.sleep(0.5)
        assert proc.poll() is None  # frozen: the pending SIGABRT cannot run
        proc.kill()
        proc.wait(10)
        host.close()
    finally:
        _kill(proc)
        sock.close()
    assert proc.returncode == -signal.SIGKILL
    line = read_line(tmp_path / "gpio", "gpiochip0", ENABLE)
    assert line["released_by_death"] and line["level"] == 0
