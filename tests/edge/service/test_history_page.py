"""HISTORY pages: as many records as fit, built in one pass (ISSUE #35 §8)."""

import json

import edge.service.requests as R
from edge.service.requests import REPLY_MARGIN, history_page


def _records(n, note=100):
    return [{"measurement_id": n - i, "status": "ok", "result": {"effusivity_W_s05_m2K": 1.0, "material": "x" * note},
             "error": None} for i in range(n)]


def test_a_page_holds_every_record_that_fits_and_no_more():
    for max_payload in (1024, 2048, 4096):
        page = history_page(0, 100, _records(100), max_payload)
        n = len(page["items"])
        assert n >= 2
        assert len(json.dumps(page)) + REPLY_MARGIN <= max_payload
        one_more = history_page(0, 100, _records(100)[:n + 1], 10**9)
        assert len(json.dumps(one_more)) + REPLY_MARGIN > max_payload  # the next record would not fit
        assert [r["measurement_id"] for r in page["items"]] == list(range(100, 100 - n, -1))


def test_each_record_is_encoded_a_bounded_number_of_times(monkeypatch):
    calls = []
    real = R.json.dumps
    monkeypatch.setattr(R.json, "dumps", lambda *a, **k: calls.append(1) or real(*a, **k))
    items = _records(100, note=3000)  # one or two per 4-kB reply: before, 100 encodings of shrinking pages
    page = history_page(0, 100, items, 4096)
    assert 1 <= len(page["items"]) <= 2
    assert len(calls) <= 3 * len(page["items"]) + 4


def test_a_page_lists_the_answers_summary_several_records_to_a_reply():
    """A whole answer is ~2 kB (candidates, decision, sensor chain): a 4-kB page held one record (§8)."""
    answer = {"effusivity_W_s05_m2K": 1491.0, "effusivity_W_s05_m2K_u": 107.0, "k_W_mK": 1.18, "k_W_mK_u": 0.34,
              "alpha_m2_s": 6.2e-7, "alpha_m2_s_u": 3.3e-7, "material": "borofloat_33", "object": "window",
              "class": "glass/ceramic/stone", "flags": ["uncalibrated"], "method": "default",
              "model_sha256": "8" * 64, "calibration_sha256": None,
              "candidates": [{"name": f"c{i}", "posterior": 0.1} for i in range(8)],
              "decision": {"source": "thick_body", "note": "d" * 300}, "sensor_chain": {"fit": "s" * 500},
              "u_e_parts": {"fit": 0.01, "calibration": 0.02}}
    records = [{"measurement_id": 20 - i, "status": "ok", "flags": ["uncalibrated"], "result": dict(answer),
                "started_utc": "2026-11-27T13:46:40.352+00:00"} for i in range(20)]
    assert len(json.dumps(records[0])) > 1500
    page = history_page(0, 20, records, 4096)
    assert len(page["items"]) >= 4
    first = page["items"][0]["result"]
    assert first["effusivity_W_s05_m2K"] == 1491.0 and first["object"] == "window" and first["flags"] == ["uncalibrated"]
    assert not {"candidates", "decision", "sensor_chain", "u_e_parts"} & set(first)
    assert records[0]["result"]["candidates"]  # the stored record itself is not changed
