"""The heater against the ends a daemon process can meet: every catchable signal, interpreter exit,
SIGKILL, and a freeze that only systemd's watchdog notices.

Each test runs a real daemon process on the simulator (tests/support/daemon_proc.py) and reads
the simulated hardware from outside it once it has ended. The processes are forked from one
interpreter that has done the imports (:class:`tests.support.daemon_proc.ForkServer`, ~0.5 s saved
a test); from the fork on each is the script's own process, signals, ``atexit`` and exit status
included. What is read from outside: the GPIO line states (mirrored to files
with the holder's pid, :mod:`firmware_sim.gpiod.state`, which releases a dead holder's line as the
kernel does) and the sysfs PWM tree (plain files). One test checks in this process that the stop
signal's handler wakes the serve loop (its port read), as thermotouch-edge and daemon_proc.py install it.
"""

import json
import os
import signal
import socket
import threading
import time
from pathlib import Path

import pytest
import serial

from edge.protocol.commands import Command
from edge.protocol.messages import encode_request
from edge.service.config import Config
from edge.service.main import install_signal_handlers
from firmware_sim.gpiod.state import read_line
from tests.support.daemon_proc import ForkServer
from tests.support.daemons import assert_stopped_by_signal
from tests.support.killpoints import work_root
from tests.support.waiting import wait_until

pytestmark = [pytest.mark.hil, pytest.mark.slow]
MAX_ON = Config().heater.max_on_time_s
ENABLE = 17


@pytest.fixture(scope="module")
def forks():
    with ForkServer() as server:
        yield server


@pytest.fixture
def state_dir(tmp_path):
    """The daemon's state directory, on tmpfs when there is one: its history and model store fsync at
    start and at the record's store (~0.1 s a test on a disk). These tests are about signals, not power
    loss: a kill does not drop the page cache."""
    with work_root(tmp_path) as d:
        yield d


def _pwm(tmp):
    d = tmp / "pwm" / "pwmchip0" / "pwm0"
    return {n: (d / n).read_text().strip() for n in ("duty_cycle", "enable")}


def _start(forks, tmp, env=None):
    """The daemon process on ``tmp`` (``python daemon_proc.py TMP``, forked), and its host-side port."""
    proc = forks.spawn(tmp, env)
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


def _kill(forks, proc):
    forks.reap(proc)


def test_the_first_stop_signal_wakes_the_serve_loop_once():
    """thermotouch-edge's serve loop waits in a port read: the signal that stops it cuts that read short."""
    stop, wakes = threading.Event(), []
    handlers = install_signal_handlers(stop, wake=lambda: wakes.append(stop.is_set()))
    try:
        signal.raise_signal(signal.SIGUSR1)
        signal.raise_signal(signal.SIGTERM)  # already stopping: no second wake-up
    finally:
        handlers.restore()
    assert stop.is_set() and wakes == [True]  # after the event is set, so the woken loop sees it
    assert handlers.received == [signal.SIGUSR1, signal.SIGTERM]


@pytest.mark.parametrize("sig", [signal.SIGHUP, signal.SIGQUIT, signal.SIGUSR1, signal.SIGUSR2, signal.SIGPIPE,
                                 signal.SIGALRM, signal.SIGABRT, signal.SIGXCPU, signal.SIGPWR,
                                 signal.SIGRTMIN], ids=lambda s: signal.Signals(s).name)
def test_every_catchable_signal_mid_heating_leaves_the_heater_off(forks, state_dir, sig):
    proc, host_port = _start(forks, state_dir)
    try:
        host = _heat(proc, host_port)
        assert read_line(state_dir / "gpio", "gpiochip0", ENABLE)["level"] == 1  # heating now
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
        host.close()
    finally:
        _kill(forks, proc)
    # Not an asked-for stop: a non-zero status makes systemd restart the daemon.
    assert proc.returncode == 128 + sig, err
    report = json.loads(out.strip().splitlines()[-1])
    assert report["invariant"]["off_now"] and report["invariant"]["longest_on_s"] <= MAX_ON
    (rec,) = report["records"]
    assert rec["status"] == "aborted" and rec["reason"] == "stopped"
    line = read_line(state_dir / "gpio", "gpiochip0", ENABLE)
    assert line["level"] == 0 and not line["requested"]
    assert _pwm(state_dir) == {"duty_cycle": "0", "enable": "0"}


def test_sigint_mid_heating_is_an_asked_for_stop_that_keeps_the_record(forks, state_dir):
    """SIGINT (Ctrl-C in a terminal), as test_safety.py's fresh process takes SIGTERM: exit 0, the touch stored
    as aborted, the history closed, the heater off."""
    proc, host_port = _start(forks, state_dir)
    try:
        host = _heat(proc, host_port)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        host.close()
    finally:
        _kill(forks, proc)
    assert_stopped_by_signal(proc.returncode, out, err, state_dir / "history.db", MAX_ON)


def test_sigkill_mid_heating_the_released_enable_line_falls_inactive(forks, state_dir):
    proc, host_port = _start(forks, state_dir)
    try:
        host = _heat(proc, host_port)
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        host.close()
    finally:
        _kill(forks, proc)
    assert proc.returncode == -signal.SIGKILL
    line = read_line(state_dir / "gpio", "gpiochip0", ENABLE)
    # The kernel released the dead process's line request; its pull-down bias took it low.
    assert line["released_by_death"] and line["bias"] == "PULL_DOWN"
    assert line["level"] == 0
    # Nothing ran to stop the PWM: the enable line alone cut the power.
    pwm = _pwm(state_dir)
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


def test_interpreter_exit_drives_the_heater_off(forks, state_dir):
    root = str(Path(__file__).resolve().parents[3])
    # As ``python -c SCRIPT``: the exception escapes the main program, the interpreter exits.
    returncode, out, err = forks.run_code(_EXIT_SCRIPT.format(root=root, tmp=str(state_dir)), timeout_s=60)
    assert returncode == 1 and out.strip() == "ON" and "a bug escapes main()" in err
    assert _pwm(state_dir)["duty_cycle"] == "0"  # only the atexit hook could have done this
    assert read_line(state_dir / "gpio", "gpiochip0", ENABLE)["level"] == 0


def _all_threads_stopped(pid) -> bool:
    """Whether every thread of process ``pid`` is in the stopped state (a SIGSTOP has taken effect)."""
    return all((t / "stat").read_text().rsplit(")", 1)[1].split()[0] == "T"
               for t in Path(f"/proc/{pid}/task").iterdir())


def _pending_and_stopped(pid, sig):
    """Whether ``sig`` is pending (sent, not yet delivered) to process ``pid``, and it is stopped."""
    fields = dict(line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines())
    pending = int(fields["SigPnd"], 16) | int(fields["ShdPnd"], 16)
    return bool(pending >> (sig - 1) & 1), fields["State"].split()[0] == "T"


def test_a_frozen_daemon_stops_petting_and_the_watchdog_kill_leaves_the_heater_off(forks, state_dir):
    # The test plays systemd: a notify socket, WatchdogSec=0.2 (pets every 0.05 s), SIGABRT then SIGKILL
    # when the pets stop. The period is the test's choice; what it shows is the same at systemd's 1..60 s.
    watchdog_s = 0.2
    sock_path = str(state_dir / "notify.sock")
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(sock_path)
    sock.settimeout(0.05)
    env = dict(os.environ, NOTIFY_SOCKET=sock_path, WATCHDOG_USEC=str(int(watchdog_s * 1e6)))
    proc, host_port = _start(forks, state_dir, env)
    messages = []

    def drain(until_s, done=lambda: False):
        while time.monotonic() < until_s and not done():
            try:
                messages.append((time.monotonic(), sock.recv(4096).decode()))
            except socket.timeout:
                pass

    def n_pets():
        return sum(m == "WATCHDOG=1" for _, m in messages)

    try:
        drain(time.monotonic() + 20, lambda: n_pets() >= 2)
        assert any("READY=1" in m for _, m in messages)
        assert n_pets() >= 2  # idle: the serve loop pets
        host = _heat(proc, host_port)
        os.kill(proc.pid, signal.SIGSTOP)  # frozen mid-heating, heater on
        # A stop takes effect as each thread next runs: on a loaded machine that can be long after the
        # kill (a SIGABRT sent before it would still be handled). Frozen is when every thread is stopped.
        wait_until(lambda: _all_threads_stopped(proc.pid), "the daemon to freeze")
        t_frozen = time.monotonic()
        assert read_line(state_dir / "gpio", "gpiochip0", ENABLE)["level"] == 1
        # Watchdog stand-in: no pet for WatchdogSec -> SIGABRT; still there after TimeoutAbortSec -> SIGKILL.
        last_pet = max(t for t, m in messages if m == "WATCHDOG=1")
        while time.monotonic() - last_pet < watchdog_s:
            n = len(messages)
            drain(time.monotonic() + 0.05)
            last_pet = max([last_pet] + [t for t, m in messages[n:] if m == "WATCHDOG=1"])
            assert time.monotonic() - t_frozen < 10, "pets went on from a frozen daemon"
        os.kill(proc.pid, signal.SIGABRT)
        # Frozen: the SIGABRT stays pending, its handler (heater off) cannot run -- the kernel says so,
        # no waiting needed to see it.
        assert _pending_and_stopped(proc.pid, signal.SIGABRT) == (True, True)
        assert proc.poll() is None
        proc.kill()
        proc.wait(10)
        host.close()
    finally:
        _kill(forks, proc)
        sock.close()
    assert proc.returncode == -signal.SIGKILL
    line = read_line(state_dir / "gpio", "gpiochip0", ENABLE)
    assert line["released_by_death"] and line["level"] == 0
