"""Parquet exports (ISSUE #36): ``history --export F.parquet`` and ``--export-series ID F.parquet`` round-trip.

The history table has the CSV export's columns, typed, with the export's identity in its metadata; a
touch record's table has the CSV's columns bit for bit and its header as metadata, and ``estimate`` and
``calibrate`` read it as they read the CSV -- checking the probe head and each column's unit.
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from edge.estimation.record import HEADER_FIELDS
from edge.storage.history import History
from host.cli.history import read_history_parquet
from host.cli.main import main
from host.records import COLUMN_UNITS, RecordError, read_parquet, read_series, read_touch, write_parquet

SIM = ("--sim", "glass_15V")


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _store_touches(w, n=1, seed=7):
    """``n`` stored touches with their raw series and touch header (as the device stores them)."""
    rng = np.random.default_rng(seed)
    k = 300
    t = np.sort(rng.uniform(-3.0, 4.0, k))
    header = {"probe": "paper", "power_W": 5.0, "heater_on_s": 3.9, "sample_rate_Hz": 100.0,
              "baseline_s": 0.5, "method": "default", "T_age_s": 1.0 / 3.0, "T_resolution_K": 0.0625,
              "saturated": False, "arm_s": 0.0, "contact_detected_s": 0.1234567890123}
    recs = []
    with History(w / "history.sqlite3") as h:
        for i in range(n):
            rec = {"status": "ok", "flags": ["uncalibrated"],
                   "result": {"effusivity_W_s05_m2K": 1400.0 + i / 3, "effusivity_W_s05_m2K_u": 30.0 + i,
                              "k_W_mK": None if i % 2 else 1.1, "material": f"=glass{i}", "method": "default",
                              "probe": "paper", "calibration_sha256": "d" * 64, "object_set": "library"},
                   "power_W": 5.0 + i, "heater_on_s": 3.9, "sample_rate_Hz": 100.0, "model_sha256": "c" * 64,
                   "started_utc": f"2026-11-27T12:{i % 60:02d}:00Z", "raw_t_s": t,
                   "raw_T_C": 25 + rng.normal(size=k) / 3, "raw_q_W_m2": rng.normal(size=k) * 1e3 / 7,
                   "raw_T_dt_s": rng.uniform(0, 2e-3, k), "raw_q_dt_s": rng.uniform(0, 2e-3, k),
                   "touch_header": header}
            rec["id"] = h.add(rec)
            recs.append(rec)
    return recs, header


def test_a_touch_exported_to_parquet_reads_back_as_the_csv_does_bit_for_bit(capsys, tmp_path):
    w = tmp_path / "w"
    (rec,), header = _store_touches(w)
    files = {}
    for fmt in ("csv", "parquet"):
        files[fmt] = tmp_path / f"touch.{fmt}"
        code, out, err = run(capsys, "history", *SIM, "--workdir", w, "--export-series", rec["id"], files[fmt])
        assert code == 0 and "300 samples" in out, err
    a, b = read_touch(files["csv"]), read_touch(files["parquet"])
    for name, col in (("t_s", "raw_t_s"), ("T_C", "raw_T_C"), ("q_W_m2", "raw_q_W_m2"), ("T_dt_s", "raw_T_dt_s"),
                      ("q_dt_s", "raw_q_dt_s")):
        assert np.array_equal(getattr(b, name), rec[col]) and np.array_equal(getattr(a, name), getattr(b, name))
    assert {k: getattr(b, k) for k in HEADER_FIELDS} == header
    assert b.meta == a.meta
    for key in ("device_id", "calibration_sha256", "model_sha256", "software", "measurement_id", "started_utc"):
        assert b.meta[key], key                       # traceability: device, calibration, model, software, id, time
    assert b.meta["measurement_id"] == str(rec["id"]) and b.meta["started_utc"] == rec["started_utc"]
    cols, meta = read_parquet(files["parquet"], "touch")
    assert meta["probe"] == "paper" and float(meta["power_W"]) == 5.0
    assert all(cols[c].dtype == np.float64 for c in cols)
    s = read_series(files["parquet"])
    assert s["T_column"] == "T_C" and np.array_equal(s["t_s"], read_series(files["csv"])["t_s"])


def test_history_exported_to_parquet_has_the_csv_columns_typed_and_the_export_identity(capsys, tmp_path):
    w = tmp_path / "w"
    recs, _ = _store_touches(w, n=30)
    f_csv, f_pq = tmp_path / "h.csv", tmp_path / "h.parquet"
    for f in (f_csv, f_pq):
        code, out, err = run(capsys, "history", *SIM, "--workdir", w, "--export", f)
        assert code == 0 and "30 measurement(s)" in out, err
    rows, meta = read_history_parquet(f_pq)
    with f_csv.open(newline="") as fh:
        csv_rows = list(csv.DictReader(fh))
    assert len(rows) == len(csv_rows) == 30 and list(rows[0]) == list(csv_rows[0])   # same columns, same order
    for r, c in zip(rows, csv_rows):
        assert r["measurement_id"] == int(c["measurement_id"])
        assert r["effusivity_W_s05_m2K"] == float(c["effusivity_W_s05_m2K"])       # exact: typed, not text
        assert r["k_W_mK"] is None if c["k_W_mK"] == "" else r["k_W_mK"] == float(c["k_W_mK"])
        assert c["material"] == "'" + r["material"]   # the CSV quotes what a spreadsheet would run; a table need not
        assert r["calibration_sha256"] == "d" * 64 and r["power_W"] == float(c["power_W"])
    assert rows[0]["measurement_id"] == recs[-1]["id"]                                # newest first, as the CSV
    assert meta["device_id"].startswith("tt-") and meta["software"] and meta["probe"] == "paper"
    assert meta["records"] == "30" and meta["exported_utc"].endswith("Z") and "k = 1" in meta["uncertainty"]
    cols, _ = read_parquet(f_pq, "history")
    assert isinstance(cols["power_W"], np.ndarray)
    # Read as a touch record it is refused by name (estimate and calibrate read touches).
    code, _, err = run(capsys, "estimate", "--csv", f_pq)
    assert code == 2 and "a Parquet table of kind 'history', not a touch" in err


def test_probe_head_and_units_are_checked_when_a_parquet_record_is_read(capsys, tmp_path):
    w = tmp_path / "w"
    (rec,), _ = _store_touches(w)
    f = tmp_path / "touch.parquet"
    assert run(capsys, "history", *SIM, "--workdir", w, "--export-series", rec["id"], f)[0] == 0
    with pytest.raises(RecordError, match="taken with probe 'paper', not --probe small-heater"):
        read_touch(f, probe="small-heater")
    cols, meta = read_parquet(f, "touch")
    kelvin = tmp_path / "kelvin.parquet"
    write_parquet(kelvin, cols, meta, {**COLUMN_UNITS, "T_C": "K"}, "touch")     # a column in another unit
    code, _, err = run(capsys, "estimate", "--csv", kelvin)
    assert code == 2 and "column 'T_C': unit 'K', but the name says degC" in err and len(err.splitlines()) == 1
    code, _, err = run(capsys, "estimate", "--csv", f, "--probe", "small-heater")
    assert code == 2 and "not --probe small-heater" in err


def test_without_pyarrow_a_parquet_export_is_refused_before_connecting(capsys, tmp_path, monkeypatch):
    import host.records

    def missing():
        raise RecordError("Parquet files need pyarrow (pip install 'thermotouch[parquet]')")

    monkeypatch.setattr(host.records, "_parquet", missing)
    code, _, err = run(capsys, "history", "--port", tmp_path / "no-such-port", "--export", tmp_path / "h.parquet")
    assert code == 2 and "pip install 'thermotouch[parquet]'" in err and not (tmp_path / "h.parquet").exists()


@pytest.mark.hil
def test_a_measured_touch_estimates_the_same_from_its_parquet_export(capsys, tmp_path):
    w = tmp_path / "w"
    assert run(capsys, "measure", *SIM, "--workdir", w)[0] == 0
    answers = []
    for fmt in ("csv", "parquet"):
        f = tmp_path / f"m1.{fmt}"
        assert run(capsys, "history", *SIM, "--workdir", w, "--export-series", 1, f)[0] == 0
        code, out, err = run(capsys, "estimate", "--csv", f, "--json")
        assert code == 0, err
        answers.append(json.loads(out))
    assert answers[0]["effusivity_W_s05_m2K"] == answers[1]["effusivity_W_s05_m2K"] > 0
