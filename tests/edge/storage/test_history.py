import json
import sqlite3
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from edge.storage.history import SCHEMA_VERSION, History, HistoryError, touch_header


def _rec(i, **kw):
    t = np.linspace(-0.5, 2.0, 26)
    rec = {"status": "ok", "flags": ["noisy"] if i % 2 else [], "result": {"e": 1000.0 + i},
           "config": {"heater": {"power_W": 5.0}}, "power_W": 5.0, "contact_time_s": 2.0,
           "raw_t_s": t, "raw_T_C": 25 + 0.1 * i + t**2, "raw_q_W_m2": np.full(26, 1500.0 + i),
           "model_sha256": "a" * 64, "started_utc": "2026-01-01T00:00:00Z"}
    rec.update(kw)
    return rec


def test_roundtrip_keeps_series_bit_exact(tmp_path):
    with History(tmp_path / "h.db") as h:
        rng = np.random.default_rng(3)
        t = np.sort(rng.random(50))
        mid = h.add(_rec(0, raw_t_s=t, raw_T_C=rng.normal(size=50), raw_q_W_m2=rng.normal(size=50),
                         grid_dT_K=rng.normal(size=20)))
        got = h.get(mid, series=True)
        assert np.array_equal(got["raw_t_s"], t) and got["raw_t_s"].dtype == np.float64
        assert got["grid_dT_K"].shape == (20,) and got["grid_t_s"] is None
        assert got["n_samples"] == 50 and got["result"] == {"e": 1000.0}
        assert got["config"] == {"heater": {"power_W": 5.0}}
        summary = h.get(mid)
        assert "raw_t_s" not in summary and summary["measurement_id"] == mid
        assert h.get(mid + 1) is None


def test_paging_is_newest_first(tmp_path):
    with History(tmp_path / "h.db") as h:
        ids = [h.add(_rec(i)) for i in range(7)]
        total, page = h.page(0, 3)
        assert total == 7 and [r["measurement_id"] for r in page] == ids[::-1][:3]
        total, page = h.page(6, 3)
        assert [r["measurement_id"] for r in page] == [ids[0]]
        assert h.page(7, 3) == (7, [])
        assert h.latest_id() == ids[-1] and h.count() == 7
        with pytest.raises(ValueError, match="offset"):
            h.page(-1, 3)
        with pytest.raises(ValueError, match="limit"):
            h.page(0, 0)


def test_durable_settings_and_commit_visible_to_another_connection(tmp_path):
    path = tmp_path / "h.db"
    with History(path) as h:
        assert h._db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert h._db.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
        mid = h.add(_rec(1))
        # Committed when add() returns: a separate connection sees it at once.
        other = sqlite3.connect(path)
        assert other.execute("SELECT status FROM measurements WHERE id=?", (mid,)).fetchone() == ("ok",)
        other.close()


def test_records_survive_a_process_killed_without_close(tmp_path):
    path = tmp_path / "h.db"
    code = textwrap.dedent(f"""
        import os, numpy as np
        from edge.storage.history import History
        h = History({str(path)!r})
        for i in range(3):
            h.add({{"status": "ok", "raw_t_s": np.arange(4.0), "raw_T_C": np.ones(4), "raw_q_W_m2": np.ones(4)}})
        os._exit(0)  # no close, no checkpoint
    """)
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
    with History(path) as h:
        assert h.count() == 3
        assert np.array_equal(h.get(3, series=True)["raw_t_s"], np.arange(4.0))


@pytest.mark.parametrize("bad, match", [
    ({"status": "great"}, "status"),
    ({"bogus": 1}, "unknown keys"),
    ({"flags": [1]}, "flags"),
    ({"result": {"e": float("nan")}}, "JSON"),
    ({"raw_T_C": np.ones(3)}, "raw_T_C has 3"),
    ({"raw_t_s": np.ones((2, 2))}, "1-D"),
])
def test_bad_records_are_refused(tmp_path, bad, match):
    with History(tmp_path / "h.db") as h:
        with pytest.raises(ValueError, match=match):
            h.add(_rec(0, **bad))
        assert h.count() == 0


def test_nonfinite_scalars_become_null_and_closed_db_raises(tmp_path):
    h = History(tmp_path / "h.db")
    mid = h.add(_rec(0, T0_C=float("nan"), error="x"))
    assert h.get(mid)["T0_C"] is None and h.get(mid)["error"] == "x"
    h.close()
    h.close()
    with pytest.raises(HistoryError, match="closed"):
        h.count()


def test_unknown_schema_version_is_refused(tmp_path):
    path = tmp_path / "h.db"
    db = sqlite3.connect(path)
    db.execute("PRAGMA user_version=99")
    db.close()
    with pytest.raises(HistoryError, match="schema version 99"):
        History(path)


def test_touch_header_and_read_times_round_trip(tmp_path):
    header = {"probe": "paper", "power_W": 5.0, "heater_on_s": 2.0, "sample_rate_Hz": 10.0, "baseline_s": 0.5,
              "method": "default", "T_age_s": 0.04, "T_resolution_K": 0.0625, "saturated": False, "arm_s": 0.0,
              "contact_detected_s": None}
    rng = np.random.default_rng(5)
    dT, dq = rng.normal(size=26) * 1e-3, rng.normal(size=26) * 1e-3
    with History(tmp_path / "h.db") as h:
        mid = h.add(_rec(0, touch_header=header, raw_T_dt_s=dT, raw_q_dt_s=dq))
        old = h.add(_rec(1))
        got = h.get(mid, series=True)
        assert got["touch_header"] == header and touch_header(got) == header
        assert np.array_equal(got["raw_T_dt_s"], dT) and np.array_equal(got["raw_q_dt_s"], dq)
        # A summary (HISTORY, RESULT, MEASURE replies) stays as it was.
        assert "touch_header" not in h.get(mid) and "raw_T_dt_s" not in h.get(mid)
        plain = h.get(old, series=True)
        assert plain["touch_header"] is None and plain["raw_T_dt_s"] is None
        with pytest.raises(ValueError, match="raw_q_dt_s has 3"):
            h.add(_rec(2, raw_q_dt_s=np.ones(3)))
        with pytest.raises(ValueError, match="touch_header"):
            h.add(_rec(2, touch_header=["paper"]))
        with pytest.raises(ValueError, match="JSON"):
            h.add(_rec(2, touch_header={"power_W": float("inf")}))
        assert h.count() == 2


#: Version 1's table, as the software before the touch record's columns created it.
_V1_DDL = """CREATE TABLE measurements (
    id INTEGER PRIMARY KEY AUTOINCREMENT, created_utc TEXT NOT NULL, started_utc TEXT, status TEXT NOT NULL,
    reason TEXT, error TEXT, flags TEXT NOT NULL, result TEXT, model_sha256 TEXT, power_W REAL,
    contact_time_s REAL, heater_on_s REAL, T0_C REAL, q_offset_W_m2 REAL, sample_rate_Hz REAL,
    config TEXT NOT NULL, n_samples INTEGER NOT NULL, raw_t_s BLOB, raw_T_C BLOB, raw_q_W_m2 BLOB,
    grid_t_s BLOB, grid_dT_K BLOB, grid_q_W_m2 BLOB)"""


def test_version_1_database_is_migrated_and_loses_nothing(tmp_path):
    path = tmp_path / "h.db"
    t = np.linspace(-0.5, 2.0, 26)
    db = sqlite3.connect(path)
    db.execute(_V1_DDL)
    cfg = {"board": {"probe": "small-heater"}, "measurement": {"baseline_s": 0.7},
           "estimation": {"method": "paper"}}
    db.execute("INSERT INTO measurements (created_utc, started_utc, status, flags, result, model_sha256, power_W, "
               "contact_time_s, heater_on_s, sample_rate_Hz, config, n_samples, raw_t_s, raw_T_C, raw_q_W_m2) "
               "VALUES ('2026-01-01', '2026-01-01T00:00:00Z', 'ok', '[\"saturated\"]', '{\"e\":1.0}', ?, 4.5, "
               "2.0, 2.01, 12.5, ?, 26, ?, ?, ?)",
               ("b" * 64, json.dumps(cfg), t.astype("<f8").tobytes(), (25 + t).astype("<f8").tobytes(),
                np.full(26, 9.0).astype("<f8").tobytes()))
    db.execute("INSERT INTO measurements (created_utc, status, flags, config, n_samples) "
               "VALUES ('2026-01-02', 'failed', '[]', '{}', 0)")
    db.execute("PRAGMA user_version=1")
    db.commit()
    db.close()
    with History(path) as h:
        assert h._db.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION == 2
        old = h.get(1, series=True)
        assert old["result"] == {"e": 1.0} and old["flags"] == ["saturated"] and old["power_W"] == 4.5
        assert np.array_equal(old["raw_t_s"], t) and np.array_equal(old["raw_T_C"], 25 + t)
        assert old["touch_header"] is None and old["raw_T_dt_s"] is None and old["raw_q_dt_s"] is None
        assert touch_header(old) == {"probe": "small-heater", "power_W": 4.5, "heater_on_s": 2.01,
                                     "sample_rate_Hz": 12.5, "baseline_s": 0.7, "method": "paper",
                                     "saturated": True, "header_rebuilt": True}
        assert touch_header(h.get(2, series=True)) is None  # nothing was sampled
        # A record that starts well before its baseline was armed: only its last baseline_s is the baseline.
        armed = dict(old, raw_t_s=np.linspace(-5.0, 2.0, 26))
        assert touch_header(armed)["arm_s"] == 5.0 and "arm_s" not in touch_header(old)
        # New rows take the new columns; ids go on.
        assert h.add(_rec(0, touch_header={"probe": "paper"})) == 3
        assert h.get(3, series=True)["touch_header"] == {"probe": "paper"}
    with History(path) as h:  # opening a migrated database again changes nothing
        assert h.count() == 3 and h.get(1, series=True)["power_W"] == 4.5


def test_series_page_carries_the_header_first_and_gives_way_to_a_sample_in_a_small_frame():
    """SERIES (edge.service.requests.series_page) sends the stored header on the raw series' first page."""
    from edge.service.requests import series_page

    rec = _rec(0, touch_header={"probe": "paper", "power_W": 5.0, "note": "x" * 300})
    page = series_page(rec, 1, "raw", 0, None, 4096)
    assert page["header"]["note"] == "x" * 300 and page["header"]["power_W"] == 5.0 and len(page["t_s"]) == 26
    assert "header" not in series_page(rec, 1, "raw", 5, None, 4096)   # the first page only
    small = series_page(rec, 1, "raw", 0, None, 300)   # no room for the header and a sample
    assert "header" not in small and len(small["t_s"]) >= 1
