"""tests/support/cpu_times.py: each test's CPU seconds, by tier, summed per file."""

from __future__ import annotations

import pytest

pytest_plugins = ["pytester"]

BUSY = '''
import pytest

def _spin(n):
    return sum(i * i for i in range(n))

@pytest.mark.slow
def test_busy():
    assert _spin(300_000) > 0

def test_idle():
    assert True
'''


def test_each_test_gets_its_own_cpu_seconds_and_tier_and_the_files_are_summed(pytester):
    from tests.support.cpu_times import main, per_file, startup

    pytester.makepyfile(test_a=BUSY, test_b="def test_other():\n    assert True\n")
    pytester.makeini("[pytest]\nmarkers =\n    slow: slow\n")
    prefix = pytester.path / "cpu"
    result = pytester.runpytest_inprocess("-p", "tests.support.cpu_times", f"--cpu-times={prefix}",
                                          "-p", "no:cacheprovider")
    result.assert_outcomes(passed=3)
    # One file, named for the process (``main``, or the xdist worker whose environment the run inherited).
    (written,) = pytester.path.glob("cpu.*.tsv")
    rows = {ln.split("\t")[0]: ln.split("\t")[1:] for ln in written.read_text().splitlines()}
    assert float(rows["#process"][1]) > float(rows["#startup"][1]) > 0
    assert startup(str(prefix)) == {written.name[len("cpu."):-len(".tsv")]: float(rows["#startup"][1])}
    assert rows["test_a.py::test_busy"][0] == "slow" and rows["test_a.py::test_idle"][0] == "fast"
    busy, idle = float(rows["test_a.py::test_busy"][1]), float(rows["test_a.py::test_idle"][1])
    assert busy > idle >= 0   # 300 000 squares against an assert: CPU time, whatever the machine's load
    both, fast = per_file(str(prefix)), per_file(str(prefix), "fast")
    assert set(both) == {"test_a.py", "test_b.py"} and both["test_a.py"] == pytest.approx(busy + idle)
    assert fast["test_a.py"] == idle
    assert main([str(prefix), "--tier", "slow"]) == 0 and main([]) == 2
