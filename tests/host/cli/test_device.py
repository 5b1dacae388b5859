"""The user's device commands (measure, info, history, flash, sim) and the errors a user meets.

Every command runs over a real pseudo-terminal link: ``--sim SCENE`` starts
the edge daemon on the scene's simulator behind a NullModem; ``--port`` tests
point at the host side of a simulated probe started by the test.
"""

from __future__ import annotations

import csv
import json
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from edge.estimation.estimate import mlp_golden_check
from host.client import DeviceClient
from host.device import DeviceUnavailable, describe_error, open_device, simulated_probe
from tests.support.cli import run

# measure --plot draws in this process (matplotlib): one worker pays for its import (tests/support/schedule.py).
pytestmark = [pytest.mark.hil, pytest.mark.slow, pytest.mark.shares_import("matplotlib")]

RESULT_KEYS = {"effusivity_W_s05_m2K", "effusivity_W_s05_m2K_u", "k_W_mK", "k_W_mK_u", "alpha_m2_s",
               "alpha_m2_s_u", "material", "material_confidence", "method", "model_sha256", "flags"}


def assert_touched(code: int, err: str) -> None:
    """The touch ran: exit 0, or exit 1 with one line when the device gave no estimate (e.g. no_contact)."""
    assert code == 0 or (code == 1 and "gave no estimate" in one_line_error(err)), err


def one_line_error(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def test_measure_on_a_simulated_probe_prints_values_with_uncertainties(capsys):
    code, out, err = run(capsys, "measure", "--sim", "glass_15V")
    assert code == 0, err
    assert "effusivity" in out and "±" in out and "W s^0.5/m^2/K" in out
    assert "conductivity" in out and "diffusivity" in out and "mm^2/s" in out
    assert "material" in out and "flags: uncalibrated" in out and "method default" in out


def test_measure_json_has_the_estimation_keys_and_a_glass_like_effusivity(capsys):
    code, out, err = run(capsys, "measure", "--sim", "pmma_15V", "--json", "--voltage", "12", "--time", "1.5")
    assert code == 0, err
    d = json.loads(out)
    assert RESULT_KEYS <= set(d)
    assert d["contact_time_s"] == pytest.approx(1.5) and d["power_W"] == pytest.approx(12.0 ** 2 / 50.0)
    # PMMA's effusivity (558 W s^0.5/m^2/K) through the MCP9600 at a reduced voltage: within 15 %.
    assert d["effusivity_W_s05_m2K"] == pytest.approx(558.0, rel=0.15)


def test_measure_with_the_paper_method_restores_the_device_setting(capsys, tmp_path):
    code, out, err = run(capsys, "measure", "--sim", "glass_15V", "--workdir", str(tmp_path), "--method", "paper",
                         "--json")
    assert code == 0, err
    assert json.loads(out)["method"] == "paper"
    with open_device(sim="glass_15V", workdir=tmp_path) as s:
        assert s.client.config_get("estimation.method")["estimation.method"] == "default"


def test_measure_plot_writes_a_png_with_both_panels(capsys, tmp_path):
    png = tmp_path / "touch.png"
    code, out, err = run(capsys, "measure", "--sim", "glass_15V", "--plot", str(png))
    assert code == 0, err
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


def test_info_history_and_export_over_a_port(capsys, tmp_path):
    with simulated_probe("glass_12V", tmp_path / "dev") as (port, daemon, sim):
        code, out, err = run(capsys, "measure", "--port", port, "--json")
        assert code == 0, err
        mid = json.loads(out)["measurement_id"]
        code, out, err = run(capsys, "info", "--port", port)
        assert code == 0 and "board      sim" in out and "1 measurement(s) stored" in out, out + err
        csv_path = tmp_path / "h.csv"
        code, out, err = run(capsys, "history", "--port", port, "--export", str(csv_path))
        assert code == 0, err
        assert "1 measurement(s)" in out
        rows = list(csv.DictReader(csv_path.open()))
        assert len(rows) == 1 and int(rows[0]["measurement_id"]) == mid and rows[0]["status"] == "ok"
        assert float(rows[0]["effusivity_W_s05_m2K"]) == pytest.approx(1477.0, rel=0.1)
        code, out, err = run(capsys, "history", "--port", port, "--json")
        assert code == 0 and [i["measurement_id"] for i in json.loads(out)] == [mid]
        assert daemon.history.count() == 1


def _capture_plots(monkeypatch, record_only=()):
    """Record plot_touch's arguments (and still write the PNG, but to the paths in ``record_only``)."""
    import host.plots

    calls = []
    real = host.plots.plot_touch

    def spy(path, series, result, fit, label="", **kw):
        calls.append({"series": series, "result": result, "fit": fit, "label": label, **kw})
        if Path(path) in record_only:
            return Path(path)
        return real(path, series, result, fit, label, **kw)

    monkeypatch.setattr(host.plots, "plot_touch", spy)
    return calls


def test_measure_plot_over_a_port_reads_the_series_over_the_link(capsys, tmp_path, monkeypatch):
    import numpy as np

    calls = _capture_plots(monkeypatch)
    png = tmp_path / "port.png"
    with simulated_probe("glass_15V", tmp_path / "dev") as (port, daemon, sim):
        code, out, err = run(capsys, "measure", "--port", port, "--plot", str(png))
        assert code == 0, err
        stored = daemon.history.get(1, series=True)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"plot: {png}\n" in out  # the device runs the shipped bundle, which the host has: fitted
    (c,) = calls
    # The series came over SERIES pages, bit for bit what the probe stored.
    for key in ("raw_t_s", "raw_T_C", "raw_q_W_m2", "grid_t_s", "grid_dT_K", "grid_q_W_m2"):
        assert c["series"][key].dtype == np.float64 and np.array_equal(c["series"][key], stored[key]), key
    # The title identifies the measurement, never the port (ISSUE #36 plots).
    assert c["series"]["T0_C"] == stored["T0_C"] and port not in c["label"]
    assert c["result"]["measurement_id"] == 1 and c["result"]["started_utc"] == stored["started_utc"]
    # The host's re-estimate with the same bundle reproduces the device's result.
    assert c["fit"] is not None and c["fit"].fit_T_K is not None
    assert c["fit"].effusivity_W_s05_m2K == pytest.approx(c["result"]["effusivity_W_s05_m2K"], rel=1e-9)


def test_measure_plot_over_a_port_without_the_devices_bundle_plots_the_measurement_only(
        capsys, tmp_path, monkeypatch):
    from thermotouch_models import DEFAULT_BUNDLE

    from edge.model.bundle import load_bundle

    # A bundle the host does not ship: the default one with another version label (hence another sha256).
    other = tmp_path / "other_bundle"
    shutil.copytree(DEFAULT_BUNDLE, other)
    manifest = json.loads((other / "manifest.json").read_text())
    manifest["model_version"] = "site-retrained"
    (other / "manifest.json").write_text(json.dumps(manifest))
    sha = load_bundle(other, golden_check=mlp_golden_check).sha256
    # b.png, a fit drawn over the series, is drawn by test_measure_plot_over_a_port_reads_the_series_over_the_link;
    # here what the CLI hands the plot (the fit or none) is the point, so that one is recorded, not drawn.
    calls = _capture_plots(monkeypatch, record_only={tmp_path / "b.png"})
    with simulated_probe("pmma_15V", tmp_path / "dev", overrides={"paths": {"factory_model": str(other)}}) \
            as (port, daemon, sim):
        code, out, err = run(capsys, "measure", "--port", port, "--plot", str(tmp_path / "a.png"))
        assert code == 0, err
        assert "measured series only" in out and sha[:12] in out and "--bundle" in out
        assert calls[-1]["fit"] is None and calls[-1]["series"]["raw_t_s"].size > 20
        assert "measured series only" in calls[-1]["label"] and sha[:12] in calls[-1]["label"]
        # Given the device's bundle, the host fits again.
        code, out, err = run(capsys, "measure", "--port", port, "--plot", str(tmp_path / "b.png"),
                             "--bundle", str(other))
        assert_touched(code, err)  # a later touch on this scene may report no_contact: plotted all the same
        assert "measured series only" not in out and calls[-1]["fit"] is not None
        # A bundle that is not the device's model is not used for the fit.
        code, out, err = run(capsys, "measure", "--port", port, "--plot", str(tmp_path / "c.png"),
                             "--bundle", str(DEFAULT_BUNDLE))
        assert_touched(code, err)
        assert "measured series only" in out and "the device used" in out and calls[-1]["fit"] is None
    assert (tmp_path / "a.png").stat().st_size > 20_000 and (tmp_path / "c.png").exists()


def test_measure_bundle_option_errors_are_one_line(capsys, tmp_path):
    code, out, err = run(capsys, "measure", "--port", "/dev/thermotouch-not-needed", "--bundle", str(tmp_path))
    assert code == 2 and "--bundle" in one_line_error(err)
    # Not a bundle: refused before the device is touched.
    code, out, err = run(capsys, "measure", "--port", "/dev/thermotouch-not-needed", "--plot",
                         str(tmp_path / "x.png"), "--bundle", str(tmp_path / "nowhere"))
    assert code == 2
    line = one_line_error(err)
    assert "--bundle" in line and "manifest.json" in line and not (tmp_path / "x.png").exists()


def test_flash_installs_the_bundle_and_confirms_its_sha(capsys, tmp_path):
    from thermotouch_models import DEFAULT_BUNDLE

    from edge.model.bundle import load_bundle

    code, out, err = run(capsys, "flash", str(DEFAULT_BUNDLE), "--sim", "pmma_8V", "--workdir", str(tmp_path))
    assert code == 0, err
    sha = load_bundle(DEFAULT_BUNDLE, golden_check=mlp_golden_check).sha256
    assert sha in out
    with open_device(sim="pmma_8V", workdir=tmp_path) as s:
        info = s.client.info()
    assert info["model_sha256"] == sha and info["model_source"] == "current"


# --- errors a user meets ----------------------------------------------------------------

def test_no_such_port(capsys):
    code, out, err = run(capsys, "info", "--port", "/dev/thermotouch-does-not-exist")
    assert code == 1
    assert one_line_error(err) == "thermotouch info: no such serial port: /dev/thermotouch-does-not-exist"


def test_device_busy(capsys):
    with simulated_probe("glass_15V") as (port, _, _):
        with DeviceClient(port):  # exclusive: the port is now in use
            code, out, err = run(capsys, "measure", "--port", port)
    assert code == 1
    assert "busy" in one_line_error(err) and port in err


def test_device_not_answering(capsys):
    from firmware_sim.ptylink import NullModem

    with NullModem() as nm:  # nothing runs on the device side
        # Nothing will ever answer, so the timeout's length does not matter; the client waits it out
        # once per attempt (INFO is resent once), so keep it short.
        code, out, err = run(capsys, "info", "--port", nm.host_port, "--timeout", "0.05")
    assert code == 1
    line = one_line_error(err)
    assert "not answering" in line and "INFO" in line


def test_bundle_refused_locally(capsys, tmp_path):
    from thermotouch_models import DEFAULT_BUNDLE

    bad = tmp_path / "bad"
    shutil.copytree(DEFAULT_BUNDLE, bad)
    arrays = bad / "arrays.npz"
    arrays.write_bytes(arrays.read_bytes()[:-100])
    code, out, err = run(capsys, "flash", str(bad), "--port", "/dev/thermotouch-not-needed")
    assert code == 2
    line = one_line_error(err)
    assert "refused" in line and "arrays.npz" in line


def test_bundle_refused_by_the_device_is_one_line():
    from edge.protocol.commands import Command
    from edge.protocol.errors import ErrorCode
    from host.client import DeviceError

    line = describe_error(DeviceError(ErrorCode.MODEL_REJECTED, "golden check failed", None, Command.MODEL_COMMIT),
                          "/dev/ttyACM0")
    assert line == "device on /dev/ttyACM0 refused the bundle: golden check failed"
    busy = describe_error(DeviceError(ErrorCode.BUSY, "cannot change the configuration while measuring"))
    assert busy.startswith("device busy:")


def test_scene_invalid(capsys, tmp_path):
    scene = tmp_path / "bad.toml"
    from firmware_sim.scene.files import scene_path

    text = scene_path("glass_15V").read_text()
    scene.write_text(text.replace("k_W_mK = 1.097", "k_W_mK = -1.0"))
    code, out, err = run(capsys, "measure", "--sim", str(scene))
    assert code == 2
    line = one_line_error(err)
    assert "invalid scene" in line and "object.k_W_mK" in line
    code, out, err = run(capsys, "sim", "no_such_scene")
    assert code == 2 and "invalid scene" in one_line_error(err)


def test_measure_failure_names_the_reason(capsys):
    code, out, err = run(capsys, "measure", "--sim", "glass_15V_faults")
    assert code == 1
    line = one_line_error(err)
    assert "SENSOR_FAULT" in line and "open_thermocouple" in line


def test_open_device_needs_exactly_one_source():
    with pytest.raises(DeviceUnavailable, match="exactly one"):
        with open_device():
            pass


def test_sim_command_prints_the_port_first_and_stops_on_sigint(tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "host.cli", "sim", "pmma_15V", "--workdir", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = proc.stdout.readline().strip()
        assert port.startswith("/dev/pts/"), proc.stderr.read()
        with DeviceClient(port, timeout_s=10.0) as c:
            assert c.measure()["status"] == "ok"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert "Traceback" not in err


def test_measure_stream_prints_phases_and_running_answers_before_the_answer(capsys):
    code, out, err = run(capsys, "measure", "--sim", "glass_15V", "--stream")
    assert code == 0, err
    lines = out.splitlines()
    first_answer = next(i for i, ln in enumerate(lines) if ln.startswith("measurement "))
    live = lines[:first_answer]
    assert any(ln.strip().endswith("heating") for ln in live)
    assert any("running answer:" in ln for ln in live)
    assert live[-1].strip().endswith("done")            # the stream ends before the answer is printed


def test_measure_stream_json_is_one_object_per_line_with_the_answer_last(capsys):
    code, out, err = run(capsys, "measure", "--sim", "pmma_15V", "--stream", "--json")
    assert code == 0, err
    objs = [json.loads(ln) for ln in out.splitlines()]
    kinds = {o.get("event") for o in objs[:-1]}
    assert {"phase", "samples", "runninganswer"} <= kinds
    assert "event" not in objs[-1] and RESULT_KEYS <= set(objs[-1])
    streamed = [t for o in objs if o.get("event") == "samples" for t in o["t_s"]]
    assert streamed == sorted(streamed) and len(streamed) >= 20   # 2.5 s at the scene's 10 Hz
