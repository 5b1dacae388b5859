import sqlite3
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from edge.storage.history import History, HistoryError


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
