"""Shared helpers for the daemon / sequence / safety tests."""

from __future__ import annotations

import contextlib
import json
import math
import threading
import time
from pathlib import Path

import numpy as np

from edge.estimation.seam import SeamContext, TouchEstimator
from edge.service.config import Config
from edge.hw.chips import sample_rate_Hz
from edge.hw.drivers.heater import Heater
from edge.measure.sensors import make_sensors
from edge.measure.sequence import MeasurementParams, MeasurementSequence
from edge.measure.watchdog import Limits
from firmware_sim.rigs.daemon_rig import heater_invariant, make_rig


def sim_config(tmp: Path, **sections) -> Config:
    """A sim-board config with every path under ``tmp``; ``sections`` override tables.

    Like a simulated probe (:func:`firmware_sim.run.config_for_scene`) it accepts unsigned
    updates and trusts the key files in ``tmp/trusted_keys``; signed-update tests override
    ``security``.
    """
    values = {
        "board": {"kind": "sim"},
        "paths": {"model_store": str(tmp / "models"), "history_db": str(tmp / "history.db"),
                  "runtime_overrides": str(tmp / "runtime.json")},
        "measurement": {"cooldown_s": 1.0},
        "security": {"allow_unsigned": True, "trusted_keys_dir": str(tmp / "trusted_keys")},
    }
    for name, table in sections.items():
        values.setdefault(name, {}).update(table)
    return Config(values, source="test")


class FakeEstimator:
    """Semi-infinite-body effusivity from the end point; records its calls.

    ``parts``: if given, the simulated heater state is sampled at each call
    (to prove the heater is off before estimation starts).
    """

    def __init__(self, parts=None, flags=()) -> None:
        self.calls = []
        self.parts = parts
        self.flags = list(flags)
        self.heater_on_at_call = []

    def __call__(self, t, dT, q, power_W, method):
        if self.parts is not None:
            self.heater_on_at_call.append(self.parts.chip.level(self.parts.heater_enable_offset) == 1)
        self.calls.append((np.array(t), np.array(dT), np.array(q), power_W, method))
        e = 2.0 * float(np.mean(q)) * math.sqrt(t[-1] / math.pi) / float(dT[-1]) if dT[-1] > 0 else None
        return {"effusivity_W_s05_m2K": e, "effusivity_W_s05_m2K_u": None if e is None else 0.05 * e,
                "method": method, "model_sha256": "f" * 64, "flags": list(self.flags)}


class CrashingEstimator(FakeEstimator):
    def __call__(self, *args):
        super().__call__(*args)
        raise FloatingPointError("estimator blew up")


def assert_heater_safe(parts, max_on_time_s: float) -> dict:
    """The heater invariant, read from the simulated GPIO/PWM history."""
    inv = heater_invariant(parts, max_on_time_s)
    assert inv["off_now"], f"heater still on: {inv}"
    assert inv["longest_on_s"] <= max_on_time_s + 1e-9, f"heater on too long: {inv}"
    return inv


def assert_stopped_by_signal(returncode: int, out: str, err: str, history_db: Path, max_on_time_s: float) -> None:
    """A daemon process signalled mid-heating (tests/support/daemon_proc.py's report on its last line): it exited
    0, the heater went off once within its limit, the history closed holding the one record, aborted as stopped."""
    from edge.storage.history import History  # noqa: PLC0415

    assert returncode == 0, err
    report = json.loads(out.strip().splitlines()[-1])
    inv = report["invariant"]
    assert inv["off_now"] and inv["longest_on_s"] <= max_on_time_s and inv["n_intervals"] == 1
    assert report["history_closed"]
    (rec,) = report["records"]
    assert rec["status"] == "aborted" and rec["reason"] == "stopped"
    with History(history_db) as h:
        assert h.count() == 1


def make_sequence(rig=None, *, cfg: Config | None = None, estimator=None, sensors=None, **rig_kw):
    """(rig, heater, sequence, params) on a fresh rig."""
    rig = rig or make_rig(**rig_kw)
    cfg = cfg or Config()
    heater = Heater(rig.board, supply_voltage_V=cfg.heater.supply_voltage_V, resistance_ohm=cfg.heater.resistance_ohm)
    sensors = sensors or make_sensors(rig.board, cfg.sensors)
    est = estimator if estimator is not None else FakeEstimator(rig.parts)
    # The sequence's hook is the one estimate path; ``est`` stands in for the probe head's estimator
    # (reach it as ``seq.estimator.context.method``).
    hook = TouchEstimator(SeamContext(method=est, thresholds=cfg.measurement))
    seq = MeasurementSequence(heater, sensors, rig.clock,
                              Limits(cfg.heater.max_on_time_s, cfg.heater.over_temperature_C), hook, cfg.measurement)
    m = cfg.measurement
    params = MeasurementParams(power_W=cfg.heater.power_W, contact_time_s=m.contact_time_s, baseline_s=m.baseline_s,
                               sample_rate_Hz=sample_rate_Hz(cfg.sensors, m.sample_rate_Hz),
                               cooldown_s=m.cooldown_s)
    return rig, heater, seq, params


class HookedSensors:
    """Wraps real sensors; ``hook(n, heater_on)`` runs before read number n (0-based)."""

    def __init__(self, inner, heater, hook) -> None:
        self.inner = inner
        self.heater = heater
        self.hook = hook
        self.n = 0

    def read(self):
        n = self.n
        self.n += 1
        self.hook(n, self.heater.is_on)
        return self.inner.read()


@contextlib.contextmanager
def sim_daemon(scene, workdir, estimator=None):
    """The unchanged daemon on ``scene``'s simulator (as ``thermotouch sim`` runs it), a client on its port.

    Yields ``(client, daemon, simulator)``; on exit the daemon is stopped and its thread must end.
    """
    from firmware_sim.run import run_sim
    from host.client import DeviceClient

    stop, ports, box = threading.Event(), [], {}
    th = threading.Thread(target=run_sim, args=(scene, stop, ports.append),
                          kwargs=dict(estimator=estimator or FakeEstimator(), workdir=workdir,
                                      on_ready=lambda d, s: box.update(d=d, s=s)), daemon=True)
    th.start()
    deadline = time.monotonic() + 20
    while "s" not in box and th.is_alive() and time.monotonic() < deadline:
        time.sleep(0.005)
    try:
        with DeviceClient(ports[0], timeout_s=10.0) as c:
            yield c, box["d"], box["s"]
    finally:
        stop.set()
        th.join(20)
    assert not th.is_alive()


@contextlib.contextmanager
def linked_daemon(tmp_path, **sections):
    """A daemon on a fresh rig behind a virtual serial cable (``sections``: config overrides); yields a client."""
    import serial

    from firmware_sim.daemon_thread import DaemonThread
    from firmware_sim.ptylink import NullModem
    from host.client import DeviceClient

    cfg = sim_config(tmp_path, **sections)
    rig = make_rig()
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
        with DaemonThread(cfg, rig.board, port, estimator=FakeEstimator(rig.parts)) as dt:
            with DeviceClient(nm.host_port, timeout_s=5.0) as client:
                yield client
        assert dt.error is None


@contextlib.contextmanager
def strict_probe(tmp_path, key_name: str = "lab", **sections):
    """A daemon that accepts only updates signed by the one key it trusts; yields (client, that secret key)."""
    from host.keys import new_key

    keys_dir = tmp_path / "trusted_keys"
    trusted = new_key(keys_dir, key_name)
    (keys_dir / f"{key_name}.secret.json").unlink()  # the probe holds public keys only
    with linked_daemon(tmp_path, security={"allow_unsigned": False, "trusted_keys_dir": str(keys_dir)},
                       **sections) as client:
        yield client, trusted
