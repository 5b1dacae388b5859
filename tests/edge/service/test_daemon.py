"""The daemon over a virtual null-modem cable, driven by host.client.DeviceClient."""

import contextlib
import hashlib
import json

import numpy as np
import pytest
import serial

from tests.support.bundles import (
    make_arrays,
    make_golden,
    manifest_extra,
    npz_bytes,
    write_raw_bundle,
)
from tests.support.daemons import FakeEstimator, assert_heater_safe, sim_config, sim_daemon
from tests.support.fuzz_text import text as fuzz_text
from edge.estimation.estimate import mlp_golden_check
from edge.model import bundle as B
from edge.service.config import Config
from edge.service.daemon import FIRMWARE_VERSION
from edge.service.main import main
from firmware_sim.daemon_thread import DaemonThread
from edge.protocol.commands import Command
from edge.protocol.errors import ErrorCode
from edge.protocol.frame import encode_frame
from edge.protocol.messages import encode_request
from firmware_sim.rigs.daemon_rig import make_rig
from firmware_sim.ptylink import NullModem
from host.client import DeviceClient, DeviceError

pytestmark = [pytest.mark.hil, pytest.mark.slow]
MAX_ON = Config().heater.max_on_time_s


@pytest.fixture(scope="module")
def bundles(tmp_path_factory):
    d = tmp_path_factory.mktemp("bundles")
    out = {}
    for tag, seed in (("factory", 1), ("new", 2)):
        arrays = make_arrays(seed=seed, hidden=(12, 5))
        b = B.write_bundle(d / tag, arrays, make_golden(arrays), manifest_extra(tag), golden_check=mlp_golden_check)
        out[tag] = b
    arrays = make_arrays(seed=3, hidden=(12, 5))
    g = make_golden(arrays)
    g["mlp_outputs"] = g["mlp_outputs"] + 0.01  # golden vectors that do not reproduce
    bad = write_raw_bundle(d / "bad_golden", npz_bytes(arrays), npz_bytes(g))
    out["bad_golden_blob"] = B.pack_entries([(n.encode(), (bad / n).read_bytes()) for n in B.BUNDLE_FILES])
    arrays = make_arrays(seed=4, hidden=(12, 5))
    arrays["x_mean"] = arrays["x_mean"].copy()
    arrays["x_mean"][0] = np.nan
    nan = write_raw_bundle(d / "nan", npz_bytes(arrays), npz_bytes(make_golden(make_arrays(seed=4, hidden=(12, 5)))))
    out["nan_blob"] = B.pack_entries([(n.encode(), (nan / n).read_bytes()) for n in B.BUNDLE_FILES])
    arrays = make_arrays(seed=5, hidden=(12, 5))
    arrays["x_mean"] = np.array([object()] * 8, dtype=object)
    obj = write_raw_bundle(d / "obj", npz_bytes(arrays, allow_pickle=True), npz_bytes(make_golden(make_arrays(seed=5))))
    out["object_blob"] = B.pack_entries([(n.encode(), (obj / n).read_bytes()) for n in B.BUNDLE_FILES])
    return out


@contextlib.contextmanager
def running(tmp_path, bundles=None, estimator=None, rig=None, **sections):
    rig = rig or make_rig()
    if bundles is not None:
        sections.setdefault("paths", {})["factory_model"] = str(bundles["factory"].path)
    cfg = sim_config(tmp_path, **sections)
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
        with DaemonThread(cfg, rig.board, port, estimator=estimator or FakeEstimator(rig.parts)) as dt:
            with DeviceClient(nm.host_port, timeout_s=5.0) as client:
                yield client, dt.daemon, rig, nm
            assert dt.thread.is_alive()
        assert not dt.thread.is_alive() and dt.error is None
    assert_heater_safe(rig.parts, cfg.heater.max_on_time_s)


def test_info_status_ping(tmp_path, bundles):
    with running(tmp_path, bundles) as (c, d, rig, nm):
        info = c.info()
        assert info["firmware_version"] == FIRMWARE_VERSION and info["board"] == "sim"
        assert info["model_sha256"] == bundles["factory"].sha256 and info["model_version"] == "factory"
        assert info["model_source"] == "factory" and info["protocol_version"] == 1
        st = c.status()
        assert st["state"] == "idle" and st["heater_on"] is False and st["history_total"] == 0
        assert c.ping("hi") == {"echo": "hi"}


def test_measure_result_and_history_paging(tmp_path, bundles):
    with running(tmp_path, bundles) as (c, d, rig, nm):
        recs = [c.measure(contact_time_s=1.0 + 0.2 * i) for i in range(5)]
        assert [r["measurement_id"] for r in recs] == [1, 2, 3, 4, 5]
        assert all(r["status"] == "ok" and r["result"]["effusivity_W_s05_m2K"] > 0 for r in recs)
        assert recs[2]["contact_time_s"] == pytest.approx(1.4)
        assert c.result()["measurement_id"] == 5
        assert c.result(2)["contact_time_s"] == pytest.approx(1.2)
        with pytest.raises(DeviceError) as ei:
            c.result(99)
        assert ei.value.code == ErrorCode.NOT_FOUND
        # Newest first, as many as fit one reply (a record carries the whole typed answer, issue #33: with
        # the sensor chain and the running decision two of these records take about one 4-kB reply).
        p = c.history(0, 2)
        assert p["total"] == 5 and [r["measurement_id"] for r in p["items"]] == [5, 4][:len(p["items"])]
        seen, offset = [], 0
        while True:
            items = c.history(offset, 2)["items"]
            if not items:
                break
            assert 1 <= len(items) <= 2
            seen += [r["measurement_id"] for r in items]
            offset += len(items)
        assert seen == [5, 4, 3, 2, 1]
        assert [r["measurement_id"] for r in c.history(4, 100)["items"]] == [1]
        assert c.history(5, 2)["items"] == []
        assert c.status()["last_measurement_id"] == 5


def test_history_page_is_cut_to_fit_one_reply(tmp_path):
    big = {"effusivity_W_s05_m2K": 1.0, "note": "x" * 900, "flags": []}
    with running(tmp_path, estimator=lambda *a: dict(big)) as (c, d, rig, nm):
        for _ in range(6):
            c.measure(contact_time_s=0.5)
        p = c.history(0, 6)
        assert p["total"] == 6 and 1 <= len(p["items"]) < 6
        assert len(json.dumps(p)) <= 4096
        rest = c.history(len(p["items"]), 6)["items"]
        assert rest[0]["measurement_id"] == 6 - len(p["items"])


def test_measure_arguments_are_checked(tmp_path):
    with running(tmp_path) as (c, d, rig, nm):
        with pytest.raises(DeviceError) as ei:
            c.measure(power_W=20.0)
        assert ei.value.code == ErrorCode.BAD_ARGUMENT and ei.value.field == "power_W"
        with pytest.raises(DeviceError) as ei:
            c.measure(contact_time_s=15.0)
        assert ei.value.field == "contact_time_s"
        with pytest.raises(DeviceError) as ei:
            c.measure(voltage_V=30.0)
        assert ei.value.field == "voltage_V"
        rec = c.measure(voltage_V=10.0, contact_time_s=1.0)
        assert rec["power_W"] == pytest.approx(100 / 44.0)
        assert c.status()["history_total"] == 1


def test_config_get_set_validation_and_persistence(tmp_path):
    with running(tmp_path) as (c, d, rig, nm):
        assert c.config_get("heater.power_W", "heater.max_on_time_s") == {"heater.power_W": 5.0,
                                                                          "heater.max_on_time_s": 10.0}
        assert len(c.config_get()) > 40
        for values, field in ((({"heater.power_W": 99.0}), "heater.power_W"),
                              ({"heater.max_on_time_s": 30.0}, "heater.max_on_time_s"),
                              ({"measurement.sample_rate_Hz": "fast"}, "measurement.sample_rate_Hz"),
                              ({"nosuch.key": 1}, "nosuch.key"),
                              ({"measurement.contact_time_s": 10.0}, "measurement.contact_time_s")):
            with pytest.raises(DeviceError) as ei:
                c.config_set(**values)
            assert ei.value.code == ErrorCode.BAD_ARGUMENT and ei.value.field == field
        with pytest.raises(DeviceError) as ei:
            c.config_get("nosuch.key")
        assert ei.value.field == "nosuch.key"
        new = c.config_set(**{"heater.power_W": 2.0, "measurement.contact_time_s": 1.0})
        assert new["heater.power_W"] == 2.0 and new["heater.max_on_time_s"] == 10.0  # the full set
        rec = c.measure()
        assert rec["power_W"] == 2.0 and rec["contact_time_s"] == 1.0
    # A restarted daemon keeps the runtime settings and the history.
    with running(tmp_path) as (c, d, rig, nm):
        assert c.config_get("heater.power_W") == {"heater.power_W": 2.0}
        assert c.history()["total"] == 1


def _raw_upload(c, blob, sha=None, size=None):
    sha = sha or hashlib.sha256(blob).hexdigest()
    c.request(Command.MODEL_BEGIN, {"size": size or len(blob), "sha256": sha})
    for off in range(0, len(blob), 4000):
        c.request(Command.MODEL_CHUNK, {"offset": off, "data": blob[off:off + 4000]})
    return c.request(Command.MODEL_COMMIT)


def test_model_upload_switches_and_hostile_bundles_are_refused(tmp_path, bundles):
    with running(tmp_path, bundles) as (c, d, rig, nm):
        factory = bundles["factory"].sha256
        hostile = {
            "wrong_hash": lambda blob: _raw_upload(c, blob, sha="0" * 64),
            "bad_golden": lambda blob: _raw_upload(c, bundles["bad_golden_blob"]),
            "nan": lambda blob: _raw_upload(c, bundles["nan_blob"]),
            "object_array": lambda blob: _raw_upload(c, bundles["object_blob"]),
            "truncated": lambda blob: _raw_upload(c, blob[:-100]),
            "garbage": lambda blob: _raw_upload(c, b"TTBUNDLE" + bytes(range(256)) * 4),
        }
        new_blob = B.bundle_to_bytes(bundles["new"].path)
        for name, attempt in hostile.items():
            with pytest.raises(DeviceError) as ei:
                attempt(new_blob)
            assert ei.value.code == ErrorCode.MODEL_REJECTED, name
            assert c.info()["model_sha256"] == factory, name
        # Incomplete upload: commit refused, nothing changes.
        c.request(Command.MODEL_BEGIN, {"size": len(new_blob), "sha256": hashlib.sha256(new_blob).hexdigest()})
        c.request(Command.MODEL_CHUNK, {"offset": 0, "data": new_blob[:100]})
        with pytest.raises(DeviceError) as ei:
            c.request(Command.MODEL_COMMIT)
        assert ei.value.code == ErrorCode.BAD_STATE
        # The upload stays open and can continue after a premature commit; then it is abandoned.
        assert c.request(Command.MODEL_CHUNK, {"offset": 100, "data": new_blob[100:200]})["received"] == 200
        c.request(Command.MODEL_ABORT)
        with pytest.raises(DeviceError) as ei:
            c.request(Command.MODEL_CHUNK, {"offset": 200, "data": new_blob[200:300]})
        assert ei.value.code == ErrorCode.BAD_STATE
        # Oversized announcement.
        with pytest.raises(DeviceError) as ei:
            c.request(Command.MODEL_BEGIN, {"size": 64 * 1024 * 1024, "sha256": "1" * 64})
        assert ei.value.code in (ErrorCode.MODEL_REJECTED, ErrorCode.BAD_ARGUMENT)
        assert c.measure(contact_time_s=0.5)["model_sha256"] == "f" * 64  # the old model keeps serving
        # A valid upload switches, with a resent chunk in the middle.
        res = c.upload_model(new_blob, chunk_size=1000)
        assert res["bundle_sha256"] == bundles["new"].sha256 and res["model_version"] == "new"
        info = c.info()
        assert info["model_sha256"] == bundles["new"].sha256 and info["model_source"] == "current"
        assert d._model_sha256() == bundles["new"].sha256
    with running(tmp_path, bundles) as (c, d, rig, nm):
        assert c.info()["model_sha256"] == bundles["new"].sha256  # survives a restart


def test_chunks_must_be_contiguous(tmp_path, bundles):
    blob = B.bundle_to_bytes(bundles["new"].path)
    with running(tmp_path, bundles) as (c, d, rig, nm):
        c.request(Command.MODEL_BEGIN, {"size": len(blob), "sha256": hashlib.sha256(blob).hexdigest()})
        assert c.request(Command.MODEL_CHUNK, {"offset": 0, "data": blob[:500]})["received"] == 500
        assert c.request(Command.MODEL_CHUNK, {"offset": 0, "data": blob[:500]})["received"] == 500  # resend
        with pytest.raises(DeviceError) as ei:
            c.request(Command.MODEL_CHUNK, {"offset": 900, "data": blob[900:1000]})
        assert ei.value.field == "offset"
        with pytest.raises(DeviceError) as ei:
            c.request(Command.MODEL_CHUNK, {"offset": len(blob) - 10, "data": b"\0" * 100})
        assert ei.value.field == "offset"
        c.request(Command.MODEL_ABORT)
        with pytest.raises(DeviceError) as ei:
            c.request(Command.MODEL_COMMIT)
        assert ei.value.code == ErrorCode.BAD_STATE


def test_garbage_on_the_line_does_not_stop_the_daemon(tmp_path):
    rng = np.random.default_rng(7)
    with running(tmp_path) as (c, d, rig, nm):
        raw = c.ser
        good = encode_request(Command.PING, 1000, {"echo": "x"})
        junk = [rng.bytes(int(rng.integers(1, 3000))) for _ in range(20)]
        for i in range(30):  # mutated valid frames
            b = bytearray(good)
            for _ in range(int(rng.integers(1, 4))):
                b[int(rng.integers(1, len(b) - 1))] = int(rng.integers(0, 256))
            junk.append(bytes(b))
        junk += [b"\x00" * 50, b"\xff" * 20000, good[:-3],
                 encode_frame(0x7E, 5, b"{}"), encode_frame(Command.MEASURE, 6, b"[1,2]"),
                 encode_frame(Command.CONFIG_SET, 8, b'{"values": {"heater.power_W": 1e400}}'),
                 encode_frame(Command.HISTORY, 9, b'{"offset": -1}')]
        for j in junk:
            raw.write(j)
        raw.flush()
        # Whatever the junk provoked (error replies, a measurement), the daemon answers.
        for _ in range(3):
            try:
                assert c.ping("after")["echo"] == "after"
                break
            except Exception:
                continue
        else:
            pytest.fail("daemon stopped answering")
        assert c.info()["board"] == "sim" and d.state in ("idle",)
        assert c.status()["heater_on"] is False


def test_console_script_rejects_a_bad_config(tmp_path, capsys):
    p = tmp_path / "edge.toml"
    p.write_text("[heater]\nmax_on_time_s = 99\n")
    assert main(["--config", str(p)]) == 2
    assert "heater.max_on_time_s" in capsys.readouterr().err
    p.write_text("[heater]\npower_W = 1.0\n")
    assert main(["--config", str(p), "--check-config"]) == 0


PAPER_SCENES = ("glass_12V", "glass_15V", "glass_18V", "pmma_8V", "pmma_15V", "pmma_20V",
                "alu_15V", "alu_20V", "alu_25V")


@pytest.mark.parametrize("scene", PAPER_SCENES)
def test_paper_scene_over_the_virtual_serial_link(tmp_path, scene):
    with sim_daemon(scene, tmp_path) as (c, d, sim):
        info = c.info()
        assert info["board"] == "sim" and info["calibrated"] is False and info["calibration_sha256"] is None
        rec = c.measure()
        # No calibration installed: the only flag says so; the sensor chain's answer rides along.
        assert rec["status"] == "ok" and rec["flags"] == ["uncalibrated"], rec
        assert rec["result"]["effusivity_W_s05_m2K"] > 0
        assert rec["result"]["sensor_chain"]["calibration_sha256"] is None
        assert c.history()["total"] == 1
        limit = d.config.heater.max_on_time_s
    # The scene world's own record of the film's power, and the GPIO/PWM history, agree: one safe pulse.
    (a, b), = sim.heater_intervals()
    assert b - a == pytest.approx(d.config.measurement.contact_time_s, abs=0.01) and b - a <= limit
    assert not sim.heater_is_on()
    assert_heater_safe(sim.parts, limit)


def test_fault_scene_reports_a_sensor_fault_with_the_heater_safe(tmp_path):
    with sim_daemon("glass_15V_faults", tmp_path) as (c, d, sim):
        with pytest.raises(DeviceError) as ei:
            c.measure()
        assert ei.value.code == ErrorCode.SENSOR_FAULT and "open_thermocouple" in ei.value.message
        assert c.result()["reason"] == "open_thermocouple"
        assert c.ping("still here")["echo"] == "still here"
    assert not sim.heater_is_on()
    assert_heater_safe(sim.parts, d.config.heater.max_on_time_s)


def test_run_sim_prints_the_port_first(tmp_path):
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "firmware_sim.run", "pmma_15V", "--workdir", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = proc.stdout.readline().strip()
        assert port.startswith("/dev/pts/"), proc.stderr.read()
        with DeviceClient(port, timeout_s=10.0) as c:
            info = c.info()
            assert info["board"] == "sim"
            if info["model_sha256"] is not None:  # the shipped bundle estimates for real
                rec = c.measure()
                assert rec["status"] == "ok" and rec["model_sha256"] == info["model_sha256"]
                assert rec["result"]["effusivity_W_s05_m2K"] > 0
            else:
                with pytest.raises(DeviceError, match="estimation_failed"):
                    c.measure()
        proc.terminate()
        proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0


def test_fuzzed_requests_get_a_reply_or_a_clean_error(tmp_path):
    """Random and mutated requests straight into the handler: only CommandError, valid replies, heater safe."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    from edge.service.daemon import Daemon
    from edge.protocol.errors import CommandError, ProtocolError
    from edge.protocol.frame import Frame
    from edge.protocol.messages import decode_request, encode_reply

    rig = make_rig()
    d = Daemon(sim_config(tmp_path, measurement={"cooldown_s": 0.0, "baseline_s": 0.2}), rig.board,
               estimator=FakeEstimator())
    scalars = st.one_of(st.none(), st.booleans(), st.integers(-2**40, 2**40),
                        st.floats(allow_nan=False, allow_infinity=False), fuzz_text(max_size=20))
    keys = st.sampled_from(["offset", "limit", "keys", "values", "measurement_id", "power_W", "voltage_V",
                            "contact_time_s", "echo", "size", "sha256", "version", "heater.power_W",
                            "measurement.sample_rate_Hz", "x"])
    values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                           st.dictionaries(keys, inner, max_size=4)), max_leaves=8)
    payloads = st.one_of(st.dictionaries(keys, values, max_size=4).map(lambda o: json.dumps(o).encode()),
                         st.binary(max_size=64))
    seen = {"ok": 0, "error": 0}

    @settings(max_examples=300, deadline=None, derandomize=True,
              suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
    @given(msg_type=st.sampled_from([int(c) for c in Command] + [0x00, 0x7F, 0x85]), payload=payloads,
           rid=st.integers(0, 2**32 - 1))
    def run(msg_type, payload, rid):
        try:
            req = decode_request(Frame(msg_type, rid, payload))
        except ProtocolError:
            seen["error"] += 1
            return
        try:
            body = d.handle(req)
        except CommandError:
            seen["error"] += 1
            return
        encode_reply(req.command, rid, body)  # the reply fits the schema and the size bound
        seen["ok"] += 1

    try:
        run()
        assert seen["ok"] > 0 and seen["error"] > 0
        assert d.handle(decode_request(Frame(int(Command.PING), 1, b'{"echo":"ok"}'))) == {"echo": "ok"}
        assert d.state == "idle"
    finally:
        d.close()
    assert_heater_safe(rig.parts, MAX_ON)


def test_console_script_without_hardware_fails_cleanly(tmp_path, caplog):
    p = tmp_path / "edge.toml"
    p.write_text(f'[board]\nkind = "rpi"\ni2c_bus = "{tmp_path}/no-i2c"\ngpio_chip = "{tmp_path}/no-gpio"\n'
                 f'pwm_root = "{tmp_path}/no-pwm"\n[paths]\nhistory_db = "{tmp_path}/h.db"\n'
                 f'model_store = "{tmp_path}/m"\n')
    import signal

    saved = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        assert main(["--config", str(p)]) == 1
    finally:
        for s, h in saved.items():
            signal.signal(s, h)
    assert "missing device" in caplog.text
    assert not (tmp_path / "h.db").exists()  # nothing was started before the board (and heater) existed


def test_series_pages_fit_the_payload_bound_and_reassemble_exactly(tmp_path):
    rig = make_rig()
    # The rig's MCP9600 converts at 12.5 Hz, the cap of any configured rate: 8 s of heating give > 100 samples.
    with running(tmp_path, rig=rig) as (c, d, _, nm):
        mid = c.measure(contact_time_s=8.0)["measurement_id"]
        stored = d.history.get(mid, series=True)
        whole = c.series(mid)
        assert stored["raw_t_s"].size > 100 and stored["grid_t_s"].size > 50
        for key in ("raw_t_s", "raw_T_C", "raw_q_W_m2", "grid_t_s", "grid_dT_K", "grid_q_W_m2"):
            assert np.array_equal(whole[key], stored[key]), key
        # One reply carries as many samples as fit in max_payload; the rest follows from offset + len(t_s).
        first = c.series_page(mid, "raw")
        n = len(first["t_s"])
        assert first["total"] == stored["raw_t_s"].size and 0 < n < first["total"]
        assert len(json.dumps(first, separators=(",", ":"))) <= d.max_payload
        assert first["T_C"] == stored["raw_T_C"][:n].tolist() and "dT_K" not in first
        nxt = c.series_page(mid, "raw", offset=n, limit=5)
        assert nxt["offset"] == n and nxt["t_s"] == stored["raw_t_s"][n:n + 5].tolist()
        tail = c.series_page(mid, "grid", offset=stored["grid_t_s"].size - 3)
        assert tail["dT_K"] == stored["grid_dT_K"][-3:].tolist() and "T_C" not in tail
        end = c.series_page(mid, "grid", offset=stored["grid_t_s"].size)
        assert end["t_s"] == [] and end["total"] == stored["grid_t_s"].size
        # Small pages give the same series.
        assert np.array_equal(c.series(mid, "grid", limit=7)["grid_q_W_m2"], stored["grid_q_W_m2"])
        for args, code, field in (({"measurement_id": 99}, ErrorCode.NOT_FOUND, "measurement_id"),
                                  ({"measurement_id": mid, "offset": 10**5}, ErrorCode.BAD_ARGUMENT, "offset")):
            with pytest.raises(DeviceError) as ei:
                c.request(Command.SERIES, args)
            assert (ei.value.code, ei.value.field) == (code, field)


def test_series_of_an_aborted_measurement_and_non_finite_samples(tmp_path):
    with running(tmp_path) as (c, d, rig, nm):
        rec = {"status": "aborted", "reason": "stopped", "flags": [], "config": {},
               "raw_t_s": np.linspace(-1.0, 0.5, 40), "raw_T_C": np.full(40, 25.0), "raw_q_W_m2": np.zeros(40)}
        rec["raw_T_C"][[3, 17]] = (np.nan, np.inf)
        mid = d.history.add(rec)
        s = c.series(mid)
        assert c.series_page(mid, "grid")["total"] == 0
    assert s["grid_t_s"] is None and s["grid_dT_K"] is None  # no resampled series for a cut-short run
    assert np.array_equal(s["raw_t_s"], rec["raw_t_s"])
    # JSON has no NaN: non-finite samples travel as null and come back as NaN.
    assert np.isnan(s["raw_T_C"][[3, 17]]).all()
    assert np.array_equal(np.delete(s["raw_T_C"], [3, 17]), np.full(38, 25.0))
