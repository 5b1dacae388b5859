"""Tests of bench/: the scripts import each other as top-level modules (they run as ``python bench/x.py``),
so while these tests run bench/ is on the import path -- put there in this one place."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"


@pytest.fixture(scope="package", autouse=True)
def bench_on_path():
    """bench/ first on ``sys.path`` for the package's tests (before their module fixtures import a script)."""
    sys.path.insert(0, str(BENCH))
    try:
        yield BENCH
    finally:
        sys.path.remove(str(BENCH))
