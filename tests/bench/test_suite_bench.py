"""bench/suite_bench.py: both tiers' figures, their targets and the load they were taken at reach the README block."""

from __future__ import annotations


import pytest


@pytest.fixture(scope="module")
def suite_bench():
    import suite_bench  # bench/ is on the path: tests/bench/conftest.py

    return suite_bench


def _run(tier, wall_s, load=0.4, n=100):
    return {"tier": tier, "wall_s": wall_s, "cpu_s": 2 * wall_s, "tests_s": 1.8 * wall_s, "n": n, "passed": n,
            "load_1min_at_start": load, "files": []}


def test_the_readme_block_gives_both_tiers_with_their_targets_and_the_load(suite_bench):
    runs = {"full": [_run("full", 57.6), _run("full", 59.4, load=0.9), _run("full", 58.2)],
            "fast": [_run("fast", 18.2, n=80), _run("fast", 17.6, n=80), _run("fast", 19.4, n=80)]}
    text = suite_bench.readme_text(runs, 2)
    full, fast, how = text.splitlines()
    assert full.startswith("Full suite (`python -m pytest -n 2`")
    assert "100 tests in 58 s of wall time [58–59] (target ≤ 60 s)" in full
    assert fast.startswith('Fast tier (`python -m pytest -n 2 -m "not slow"`')
    assert "80 tests in 18 s of wall time [18–19] (target ≤ 20 s)" in fast
    assert "Median of 3 runs" in how and "load average ≤ 0.9" in how and "2 workers" in how


def test_the_summary_says_whether_the_median_meets_the_target(suite_bench):
    over = suite_bench.summary("fast", [_run("fast", 19.0), _run("fast", 25.0), _run("fast", 21.0)])
    assert over["wall_s"] == 21.0 and over["target_wall_s"] == 20.0 and not over["meets_target"]
    assert over["wall_range_s"] == [19.0, 25.0] and over["command"] == 'python -m pytest -n 2 -m "not slow"'
    assert suite_bench.summary("full", [_run("full", 59.0)])["meets_target"]
    # The fast tier is the marker expression the pyproject's slow marker documents.
    assert suite_bench.TIER_MARKER == {"full": None, "fast": "not slow"}
