"""``thermotouch estimate`` refuses records whose units, sign or layout look wrong (issue 36, "Bad input").

Each case was answered on main (an effusivity of 49100 for t_s in ms, "n/a ... no_signal" with exit 0 for
a constant temperature or a flux in mV); now: one line, exit 2, what looks wrong and the ``--accept`` that
says it is intended.
"""

import json

import numpy as np
import pytest

from edge.estimation.record import TouchRecord
from edge.physics.forward import simulate
from edge.physics.probe import FLUX_SENSITIVITY_V_per_W_m2
from edge.physics.solids import Solid
from host.cli.main import main
from host.records import write_touch

GLASS = Solid(1.097, 2458.4, 809.0)


@pytest.fixture(scope="module")
def glass():
    """A 2-s exact-model touch of glass with 0.2 s of baseline: t_s, T_K, q_W_m2."""
    r = simulate(GLASS, 7.7e7, 2.0, back="infinite", scheme="exact", dt_s=0.01)
    t = np.concatenate(([-0.2, -0.1], r.t_s))
    T = np.concatenate(([298.15, 298.15], 298.15 + r.T_f_K))
    q = np.concatenate(([0.0, 0.0], r.q_f_W_m2))
    return t, T, q


def write(path, header, *cols):
    path.write_text(header + "\n" + "\n".join(",".join(repr(float(v)) for v in row) for row in zip(*cols)) + "\n")
    return path


def estimate(capsys, *argv):
    code = main(["estimate", *map(str, argv)])
    out, err = capsys.readouterr()
    return code, out, err


def refused(capsys, path, needle, check, *extra):
    code, out, err = estimate(capsys, "--csv", path, *extra)
    lines = err.strip().splitlines()
    assert code == 2 and out == "" and len(lines) == 1, (code, out, err)
    assert lines[0].startswith("thermotouch estimate: ") and needle in lines[0], lines[0]
    if check is not None:
        assert f"--accept {check}" in lines[0]
    return lines[0]


def test_the_plain_record_is_answered(capsys, tmp_path, glass):
    t, T, q = glass
    code, out, err = estimate(capsys, "--csv", write(tmp_path / "ok.csv", "t_s,T_K,q_W_m2", t, T, q))
    assert code == 0 and "effusivity" in out, err


def test_time_in_milliseconds(capsys, tmp_path, glass):
    t, T, q = glass
    p = write(tmp_path / "ms.csv", "t_s,T_K,q_W_m2", t * 1000, T, q)
    refused(capsys, p, "milliseconds", "time-units")


def test_header_sample_rate_disagrees(capsys, tmp_path, glass):
    t, T, q = glass
    rec = TouchRecord(probe="paper", t_s=t, T_C=T - 273.15, q_W_m2=q, power_W=5.0, heater_on_s=2.0,
                      sample_rate_Hz=1000.0, baseline_s=0.2, meta={"measurement_id": 7})
    p = tmp_path / "export.csv"
    write_touch(p, rec)
    refused(capsys, p, "sample_rate_Hz 1000", "time-units")


def test_a_long_armed_export_at_its_stated_rate_is_not_milliseconds(capsys, tmp_path):
    """An export states its rate: 1 Hz over 90 s of arming and heating is what the device said, not ms."""
    t = np.arange(-80.0, 11.0)
    T_C = np.where(t > 0, 20.0 + 0.3 * np.sqrt(np.clip(t, 0, None)), 20.0)
    q = np.where(t > 0, 700.0, 0.0)
    rec = TouchRecord(probe="paper", t_s=t, T_C=T_C, q_W_m2=q, power_W=5.0, heater_on_s=10.0, sample_rate_Hz=1.0,
                      baseline_s=80.0, arm_s=80.0, meta={"measurement_id": 9})
    p = tmp_path / "armed.csv"
    write_touch(p, rec)
    code, out, err = estimate(capsys, "--csv", p)
    assert code in (0, 1) and "milliseconds" not in err and "--accept" not in err, err


def test_celsius_in_a_kelvin_column(capsys, tmp_path, glass):
    t, T, q = glass
    refused(capsys, write(tmp_path / "c.csv", "t_s,T_K,q_W_m2", t, T - 273.15, q), "looks like degC",
            "temperature-units")


def test_kelvin_in_a_celsius_column(capsys, tmp_path, glass):
    t, T, q = glass
    refused(capsys, write(tmp_path / "k.csv", "t_s,T_C,q_W_m2", t, T, q), "looks like kelvin", "temperature-units")


@pytest.mark.parametrize("scale", [1e3, 1.0], ids=["mV", "V"])
def test_flux_in_sensor_volts(capsys, tmp_path, glass, scale):
    t, T, q = glass
    p = write(tmp_path / "mv.csv", "t_s,T_K,q_W_m2", t, T, q * FLUX_SENSITIVITY_V_per_W_m2 * scale)
    refused(capsys, p, "mV or V", "flux-units")


def test_inverted_flux_sign(capsys, tmp_path, glass):
    t, T, q = glass
    refused(capsys, write(tmp_path / "neg.csv", "t_s,T_K,q_W_m2", t, T, -q), "negative", "flux-sign")


def test_constant_temperature(capsys, tmp_path, glass):
    t, T, q = glass
    p = write(tmp_path / "flat.csv", "t_s,T_K,q_W_m2", t, np.full_like(T, 298.15), q)
    refused(capsys, p, "throughout", "constant-temperature")


def test_accepting_a_check_goes_on_and_no_answer_exits_1(capsys, tmp_path, glass):
    """--accept waives the check; a record that then gives no estimate exits 1 in one line, like measure."""
    t, T, q = glass
    p = write(tmp_path / "flat.csv", "t_s,T_K,q_W_m2", t, np.full_like(T, 298.15), q)
    code, out, err = estimate(capsys, "--csv", p, "--accept", "constant-temperature")
    lines = err.strip().splitlines()
    assert code == 1 and len(lines) == 1 and "gave no estimate" in lines[0], (code, out, err)
    code, out, err = estimate(capsys, "--csv", p, "--accept", "constant-temperature", "--json")
    assert code == 1 and json.loads(out)["effusivity_W_s05_m2K"] is None and "gave no estimate" in err


@pytest.mark.parametrize("header,needle", [("t_s,T_K,T_K,q_W_m2", "'T_K' appears twice"),
                                           ("t_s,T_K,dT_K,q_W_m2", "T_K and dT_K together")])
def test_duplicated_or_conflicting_columns(capsys, tmp_path, glass, header, needle):
    t, T, q = glass
    p = write(tmp_path / "dup.csv", header, t, T, T - 298.15, q)
    refused(capsys, p, needle, None)


def test_unknown_check_name_refused(capsys, tmp_path, glass):
    t, T, q = glass
    refused(capsys, write(tmp_path / "ok.csv", "t_s,T_K,q_W_m2", t, T, q), "unknown check", None,
            "--accept", "everything")


def test_another_heads_export_refused(capsys, tmp_path, glass):
    """A small-heater export read as a paper-probe record: refused (kept from main)."""
    t, T, q = glass
    rec = TouchRecord(probe="small-heater", t_s=t, T_C=T - 273.15, q_W_m2=q, power_W=0.119, heater_on_s=2.0,
                      sample_rate_Hz=100.0, baseline_s=0.2, meta={"measurement_id": 8})
    p = tmp_path / "sh.csv"
    write_touch(p, rec)
    refused(capsys, p, "small-heater", None, "--probe", "paper")
