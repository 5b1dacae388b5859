"""Every benchmark script imports against today's tree (a renamed module must not break a bench silently)."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

# Importing the benches imports scikit-learn and matplotlib: one worker pays for them (tests/support/schedule.py).
pytestmark = pytest.mark.shares_import("sklearn", "matplotlib")

BENCH = Path(__file__).resolve().parents[2] / "bench"
SCRIPTS = sorted(p.stem for p in BENCH.glob("*_bench.py"))


def test_there_are_benches():
    assert len(SCRIPTS) >= 10


@pytest.mark.parametrize("name", SCRIPTS)
def test_bench_imports_and_has_a_main(name):
    mod = importlib.import_module(name)
    assert callable(getattr(mod, "main", None)), f"bench/{name}.py has no main()"
    doc = mod.__doc__ or ""
    assert "Run:" in doc or "Usage" in doc, f"bench/{name}.py does not say how to run it"


def test_interleaved_rounds_alternate_the_cases():
    import _common

    order: list[str] = []
    res = _common.interleaved({"a": lambda: order.append("a") or 1, "b": lambda: order.append("b") or 2}, 3,
                              warmup=False)
    assert order == ["a", "b"] * 3
    assert res["a"]["n"] == 3 and res["a"]["result"] == 1 and res["b"]["result"] == 2
    assert res["a"]["min_s"] <= res["a"]["median_s"] <= res["a"]["max_s"]
    with pytest.raises(ValueError):
        _common.interleaved({"a": lambda: 1}, 0)


def test_results_name_the_machine_they_were_measured_on():
    import _common

    m = _common.machine()
    assert m["cpus"] >= 1 and m["cpu"] and m["numpy"]
    # The SIMD level decides NumPy's tanh/exp speed (scalar without AVX-512): it must be recorded.
    assert isinstance(m["simd"], list) and all(isinstance(s, str) for s in m["simd"])
    assert all(isinstance(b, str) and b for b in m["blas"])
