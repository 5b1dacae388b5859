"""HISTORY pages: as many records as fit, built in one pass (ISSUE #35 §8)."""

import json

import edge.service.requests as R
from edge.service.requests import REPLY_MARGIN, history_page


def _records(n, note=100):
    return [{"measurement_id": n - i, "status": "ok", "result": {"e": 1.0, "note": "x" * note}, "error": None}
            for i in range(n)]


def test_a_page_holds_every_record_that_fits_and_no_more():
    for max_payload in (700, 1024, 4096):
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
