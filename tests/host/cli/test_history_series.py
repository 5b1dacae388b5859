"""``thermotouch history --export-series``: a stored measurement's raw record as the CSV estimate reads."""

from __future__ import annotations

import json

from host.cli.main import main
from host.records import read_series


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_export_series_round_trips_into_estimate(capsys, tmp_path):
    w = tmp_path / "w"
    code, _, err = run(capsys, "measure", "--sim", "glass_15V", "--workdir", w)
    assert code == 0, err
    f = tmp_path / "m1.csv"
    code, out, err = run(capsys, "history", "--sim", "glass_15V", "--workdir", w, "--export-series", 1, f)
    assert code == 0 and "written" in out, err
    s = read_series(f)
    # The thermocouple as the device recorded it (°C), not converted (issue #33: columns as recorded).
    assert s["T_column"] == "T_C" and s["t_s"][0] < 0 < s["t_s"][-1]
    assert -10 < float(s["T"].mean()) < 60
    # Refuses to overwrite without --overwrite, and the file stays as it was.
    before = f.read_bytes()
    code, _, err = run(capsys, "history", "--sim", "glass_15V", "--workdir", w, "--export-series", 1, f)
    assert code == 2 and "--overwrite" in err and f.read_bytes() == before
    code, out, err = run(capsys, "estimate", "--csv", f, "--json")
    assert code == 0, err
    assert json.loads(out)["effusivity_W_s05_m2K"] > 0


def test_unknown_measurement_and_bad_id_are_one_line(capsys, tmp_path):
    code, _, err = run(capsys, "history", "--sim", "glass_15V", "--export-series", "x", tmp_path / "a.csv")
    assert code == 2 and "whole number" in err and len(err.strip().splitlines()) == 1
    code, _, err = run(capsys, "history", "--sim", "glass_15V", "--export-series", 5, tmp_path / "a.csv")
    assert code == 1 and "5" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "a.csv").exists()


def test_export_carries_the_stored_touch_bit_for_bit(capsys, tmp_path):
    """A stored touch (header, raw columns and read times) comes back from the file exactly as stored."""
    import numpy as np

    from edge.estimation.record import HEADER_FIELDS
    from edge.storage.history import History
    from host.records import read_touch

    w = tmp_path / "w"
    rng = np.random.default_rng(7)
    n = 700  # more than one SERIES page
    t = np.sort(rng.uniform(-3.0, 4.0, n))
    header = {"probe": "small-heater", "power_W": 0.0467, "heater_on_s": 3.9, "sample_rate_Hz": 100.0,
              "baseline_s": 0.5, "method": "default", "T_age_s": 1.0 / 3.0, "T_resolution_K": 0.0625,
              "saturated": False, "arm_s": 30.0, "contact_detected_s": 1.234567890123}
    rec = {"status": "ok", "flags": ["uncalibrated"], "result": {"calibration_sha256": None, "object_set": "library"},
           "config": {"measurement": {"noise_T_K": 0.123, "baseline_s": 0.5}}, "power_W": 0.0467,
           "heater_on_s": 3.9, "sample_rate_Hz": 100.0, "model_sha256": "c" * 64, "started_utc": "2026-11-27T12:00:00Z",
           "raw_t_s": t, "raw_T_C": 25 + rng.normal(size=n) / 3, "raw_q_W_m2": rng.normal(size=n) * 1e3 / 7,
           "raw_T_dt_s": rng.uniform(0, 2e-3, n), "raw_q_dt_s": rng.uniform(0, 2e-3, n), "touch_header": header}
    with History(w / "history.sqlite3") as h:
        mid = h.add(rec)
    f = tmp_path / "touch.csv"
    code, out, err = run(capsys, "history", "--sim", "glass_15V", "--workdir", w, "--export-series", mid, f)
    assert code == 0 and f"{n} samples" in out, err
    touch = read_touch(f)
    for name, col in (("t_s", "raw_t_s"), ("T_C", "raw_T_C"), ("q_W_m2", "raw_q_W_m2"), ("T_dt_s", "raw_T_dt_s"),
                      ("q_dt_s", "raw_q_dt_s")):
        assert np.array_equal(getattr(touch, name), rec[col]), name
    assert {k: getattr(touch, k) for k in HEADER_FIELDS} == header
    assert touch.meta["measurement_id"] == str(mid) and touch.meta["model_sha256"] == "c" * 64
    assert touch.meta["measurement.noise_T_K"] == "0.123" and touch.meta["status"] == "ok"
    assert touch.meta["started_utc"] == "2026-11-27T12:00:00Z" and touch.meta["software"]
    assert "calibration_sha256" not in touch.meta  # uncalibrated: no line rather than a 'none'


def test_a_touch_stored_before_the_touch_header_exports_with_a_rebuilt_one(capsys, tmp_path):
    """A history written by the software before schema 2: migrated when the device opens it, nothing lost."""
    import sqlite3

    import numpy as np

    from host.records import read_touch
    from tests.edge.storage.test_history import _V1_DDL

    w = tmp_path / "w"
    w.mkdir()
    t = np.arange(-5, 21) * 0.1
    db = sqlite3.connect(w / "history.sqlite3")
    db.execute(_V1_DDL)
    db.execute("INSERT INTO measurements (created_utc, status, flags, result, power_W, heater_on_s, sample_rate_Hz, "
               "config, n_samples, raw_t_s, raw_T_C, raw_q_W_m2) VALUES ('2026-01-01', 'ok', '[]', '{}', 4.5, 2.0, "
               "10.0, ?, 26, ?, ?, ?)",
               (json.dumps({"measurement": {"baseline_s": 0.5, "noise_T_K": 0.1}}), t.astype("<f8").tobytes(),
                (25 + np.clip(t, 0, None)).astype("<f8").tobytes(), np.where(t > 0, 3000.0, 0.0).tobytes()))
    db.execute("PRAGMA user_version=1")
    db.commit()
    db.close()
    f = tmp_path / "old.csv"
    code, out, err = run(capsys, "history", "--sim", "glass_15V", "--workdir", w, "--export-series", 1, f)
    assert code == 0, err
    touch = read_touch(f)
    assert np.array_equal(touch.t_s, t) and touch.power_W == 4.5 and touch.baseline_s == 0.5
    assert touch.meta["header_rebuilt"] == "true" and touch.meta["measurement.noise_T_K"] == "0.1"
