"""Every heater safety path on the simulator, with fault injection.

Each test reads the heater invariant (on-time <= limit, off at the end) from
the simulated GPIO/PWM history, not from the driver's bookkeeping.
"""

import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import serial

from tests.support.daemons import (
    CrashingEstimator,
    FakeEstimator,
    HookedSensors,
    assert_heater_safe,
    assert_stopped_by_signal,
    make_sequence,
    sim_config,
)
from edge.service.config import Config
from edge.service.daemon import Daemon
from edge.service.main import install_signal_handlers
from edge.protocol.commands import Command
from edge.protocol.errors import CommandError, ErrorCode
from edge.protocol.messages import encode_request
from edge.measure.sensors import make_sensors
from firmware_sim.rigs.daemon_rig import make_rig
from firmware_sim.daemon_thread import DaemonThread
from firmware_sim.ptylink import NullModem
from host.client import DeviceClient, DeviceError

pytestmark = pytest.mark.hil
MAX_ON = Config().heater.max_on_time_s


def _hooked(rig_kw=None, *, cfg=None, hook=None, estimator=None):
    rig = make_rig(**(rig_kw or {}))
    cfg = cfg or Config()
    holder = {}

    def h(n, on):
        hook(n, on, holder)

    sensors = make_sensors(rig.board, cfg.sensors)
    rig_, heater, seq, params = make_sequence(rig, cfg=cfg, estimator=estimator,
                                              sensors=HookedSensors(sensors, None, h))
    seq.sensors.heater = heater
    holder.update(rig=rig, heater=heater, seq=seq)
    return rig, heater, seq, params


def test_exception_mid_heating_cuts_the_heater_and_keeps_the_data():
    def hook(n, on, _):
        if on and n == 12:
            raise RuntimeError("driver bug")

    rig, heater, seq, params = _hooked(hook=hook)
    out = seq.run(params)
    assert (out.status, out.reason) == ("failed", "internal") and "driver bug" in out.error
    assert out.raw_t_s.size == 12 and out.result is None and seq.estimator.context.method.calls == []
    inv = assert_heater_safe(rig.parts, MAX_ON)
    assert inv["n_intervals"] == 1 and inv["longest_on_s"] < params.contact_time_s
    seq.close()


def test_keyboard_interrupt_mid_heating_propagates_after_the_heater_is_off():
    def hook(n, on, _):
        if on and n == 10:
            raise KeyboardInterrupt

    rig, heater, seq, params = _hooked(hook=hook)
    with pytest.raises(KeyboardInterrupt):
        seq.run(params)
    assert_heater_safe(rig.parts, MAX_ON)
    assert not heater.is_on
    seq.close()


@pytest.mark.parametrize("fault", ["nack_thermocouple", "nack_flux", "stuck_bus"])
def test_sensor_fault_mid_heating(fault):
    def hook(n, on, holder):
        if on and n == 10:
            bus = holder["rig"].bus
            if fault == "nack_thermocouple":
                bus.nack(0x60)
            elif fault == "nack_flux":
                bus.nack(0x48)
            else:
                bus.stuck()

    rig, heater, seq, params = _hooked(hook=hook)
    out = seq.run(params)
    assert (out.status, out.reason) == ("failed", "sensor_fault")
    assert ("mcp9600@0x60" in out.error) == (fault != "nack_flux")
    assert_heater_safe(rig.parts, MAX_ON)
    seq.close()


def test_open_thermocouple_cuts_the_heater():
    def hook(n, on, holder):
        if on and n == 9:
            holder["rig"].mcp.set_open(True)

    rig, heater, seq, params = _hooked(hook=hook)
    out = seq.run(params)
    assert (out.status, out.reason) == ("failed", "open_thermocouple")
    inv = assert_heater_safe(rig.parts, MAX_ON)
    assert inv["longest_on_s"] < 1.0
    seq.close()


def test_over_temperature_without_contact_cuts_the_heater():
    cfg = Config({"heater": {"over_temperature_C": 32.0}})
    rig, heater, seq, params = make_sequence(cfg=cfg, contact=False)
    out = seq.run(params)
    assert (out.status, out.reason) == ("aborted", "over_temperature")
    assert max(out.raw_T_C) > 32.0 and out.result is None
    inv = assert_heater_safe(rig.parts, MAX_ON)
    assert inv["longest_on_s"] < params.contact_time_s
    seq.close()


def test_baseline_above_the_limit_never_switches_the_heater_on():
    cfg = Config({"heater": {"over_temperature_C": 20.0}})
    rig, heater, seq, params = make_sequence(cfg=cfg)
    out = seq.run(params)
    assert out.reason == "over_temperature"
    assert assert_heater_safe(rig.parts, MAX_ON)["n_intervals"] == 0
    seq.close()


def test_watchdog_cuts_a_heating_whose_loop_is_stuck():
    cfg = Config({"heater": {"max_on_time_s": 2.5}})
    blocked, release = threading.Event(), threading.Event()

    def hook(n, on, _):
        if on and n == 12:
            blocked.set()
            release.wait(20)

    rig, heater, seq, params = _hooked(cfg=cfg, hook=hook)
    result = {}
    th = threading.Thread(target=lambda: result.setdefault("out", seq.run(params)))
    th.start()
    assert blocked.wait(20)
    # The sampling loop is stuck in a read; time goes on in 1-ms steps.
    t_stop = rig.clock.now() + 5.0
    while rig.parts.chip.level(rig.parts.heater_enable_offset) == 1 and rig.clock.now() < t_stop:
        rig.clock.advance(0.001)
    release.set()
    th.join(20)
    out = result["out"]
    assert (out.status, out.reason) == ("aborted", "max_on_time")
    inv = assert_heater_safe(rig.parts, 2.5)
    assert inv["longest_on_s"] <= 2.5 - seq.watchdog.guard_s + 0.0011
    seq.close()


def test_loop_check_stops_heating_when_reads_are_too_slow():
    cfg = Config({"heater": {"max_on_time_s": 2.1}})

    def hook(n, on, holder):
        if on:
            holder["rig"].clock.advance(0.3)  # every read takes 0.3 s

    rig, heater, seq, params = _hooked(cfg=cfg, hook=hook)
    out = seq.run(params)
    assert (out.status, out.reason) == ("aborted", "max_on_time")
    assert_heater_safe(rig.parts, 2.1)
    seq.close()


def test_enable_line_failure_is_cut_by_pwm_and_puts_the_daemon_in_fault(tmp_path):
    rig = make_rig()
    d = Daemon(sim_config(tmp_path), rig.board, estimator=FakeEstimator())
    real = d.heater._req
    inactive = rig.parts.gpio.gpiod.line.Value.INACTIVE

    class StuckEnable:
        def set_value(self, off, value):
            if value == inactive:
                raise OSError(5, "EIO: line stuck")
            real.set_value(off, value)

        def release(self):
            real.release()

    d.heater._req = StuckEnable()
    with pytest.raises(CommandError) as ei:
        d.measure()
    assert ei.value.code == ErrorCode.INTERNAL and "HEATER FAULT" in ei.value.message
    # Enable stuck high, but the PWM duty is 0: no power.
    assert rig.parts.chip.level(rig.parts.heater_enable_offset) == 1
    assert_heater_safe(rig.parts, MAX_ON)
    with pytest.raises(CommandError) as ei:
        d.measure()
    assert ei.value.code == ErrorCode.BAD_STATE
    assert d.history.get(1)["reason"] == "heater_fault"
    d.heater._req = real
    d.close()


def test_startup_drives_a_heater_left_on_off_first(tmp_path):
    rig = make_rig()
    # A crashed predecessor left the enable line high and the PWM at full duty.
    req = rig.board.heater_enable.request_output("crashed", value=True)
    pwm = rig.board.pwm
    pwm.open()
    pwm.configure(1_000_000, 1_000_000)
    pwm.enable()
    req.release()
    assert rig.world.heater_power_W() > 5.0
    d = Daemon(sim_config(tmp_path), rig.board, estimator=FakeEstimator())
    assert rig.world.heater_power_W() == 0.0
    assert rig.parts.chip.level(rig.parts.heater_enable_offset) == 0
    d.close()


def test_estimator_crash_after_heater_off(tmp_path):
    rig = make_rig()
    est = CrashingEstimator(rig.parts)
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
        with DaemonThread(sim_config(tmp_path), rig.board, port, estimator=est) as dt:
            with DeviceClient(nm.host_port, timeout_s=5.0) as c:
                with pytest.raises(DeviceError) as ei:
                    c.measure()
                assert ei.value.code == ErrorCode.INTERNAL
                assert "estimation_failed" in ei.value.message and "measurement 1 stored" in ei.value.message
                assert c.ping("alive")["echo"] == "alive"
                rec = dt.daemon.history.get(1, series=True)
    assert est.heater_on_at_call == [False]
    assert rec["status"] == "failed" and rec["reason"] == "estimation_failed" and rec["raw_t_s"].size > 20
    assert_heater_safe(rig.parts, MAX_ON)


def test_lost_host_mid_measurement_loses_nothing(tmp_path):
    rig = make_rig()
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
        with DaemonThread(sim_config(tmp_path), rig.board, port, estimator=FakeEstimator()) as dt:
            # The host asks for a measurement and vanishes without reading the reply.
            with serial.Serial(nm.host_port, timeout=0.05) as host:
                host.write(encode_request(Command.MEASURE, 7, {}))
                host.flush()
            # Stored, and the serve loop done with it: RESULT meanwhile is BUSY by design.
            deadline = time.monotonic() + 20
            while (dt.daemon.history.count() == 0 or dt.daemon.measuring) and time.monotonic() < deadline:
                time.sleep(0.01)
            with DeviceClient(nm.host_port, timeout_s=5.0) as c:
                rec = c.result()
                assert rec["measurement_id"] == 1 and rec["status"] == "ok" and rec["result"] is not None
                assert c.status()["heater_on"] is False
    assert_heater_safe(rig.parts, MAX_ON)


def test_signal_handler_stops_a_measurement_in_the_main_thread(tmp_path):
    rig = make_rig()
    stop = threading.Event()
    old = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        install_signal_handlers(stop)
        d = Daemon(sim_config(tmp_path), rig.board, estimator=FakeEstimator(), stop_event=stop)

        def hook(n, on):
            if on and n == 10:
                signal.raise_signal(signal.SIGINT)

        d.sensors = HookedSensors(d.sensors, d.heater, hook)
        rec = d.measure()
        assert rec["status"] == "aborted" and rec["reason"] == "stopped"
        assert stop.is_set()
        d.close()
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    inv = assert_heater_safe(rig.parts, MAX_ON)
    assert inv["longest_on_s"] < 1.5


@pytest.mark.slow  # a fresh interpreter running daemon_proc.py (SIGINT and every other signal, forked from
# one that has done the imports: test_process_safety.py)
@pytest.mark.parametrize("sig", [signal.SIGTERM])
def test_real_signal_to_a_daemon_process_mid_heating(tmp_path, sig):
    script = Path(__file__).resolve().parents[2] / "support" / "daemon_proc.py"
    proc = subprocess.Popen([sys.executable, str(script), str(tmp_path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        host_port = proc.stdout.readline().strip()
        assert host_port.startswith("/dev/"), proc.stderr.read()
        with serial.Serial(host_port, timeout=0.05) as host:
            host.write(encode_request(Command.MEASURE, 1, {}))
            host.flush()
            assert proc.stdout.readline().strip() == "HEATING"
            proc.send_signal(sig)
            out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert_stopped_by_signal(proc.returncode, out, err, tmp_path / "history.db", MAX_ON)


def test_both_heater_channels_failing_still_stores_the_record(tmp_path):
    # Nothing can cut the power: the daemon must say so loudly and still keep the data.
    rig = make_rig()
    d = Daemon(sim_config(tmp_path), rig.board, estimator=FakeEstimator())
    real_req, real_pwm = d.heater._req, d.heater._pwm
    inactive = rig.parts.gpio.gpiod.line.Value.INACTIVE

    class StuckEnable:
        def set_value(self, off, value):
            if value == inactive:
                raise OSError(5, "EIO: line stuck")
            real_req.set_value(off, value)

        def release(self):
            real_req.release()

    class StuckPwm:
        def __getattr__(self, name):
            return getattr(real_pwm, name)

        def set_duty_ns(self, duty_ns):
            if duty_ns == 0:
                raise OSError(5, "EIO: pwm stuck")
            real_pwm.set_duty_ns(duty_ns)

    d.heater._req, d.heater._pwm = StuckEnable(), StuckPwm()
    with pytest.raises(CommandError) as ei:
        d.measure()
    assert "HEATER FAULT" in ei.value.message and "stored" in ei.value.message
    rec = d.history.get(1)
    assert rec is not None and rec["reason"] == "heater_fault"
    assert d.state == "fault"
    d.heater._req, d.heater._pwm = real_req, real_pwm
    d.heater.off()
    d.close()
