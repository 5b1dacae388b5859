"""host/malloc.py: the training's large arrays stay on the heap inside the block."""

import json
import resource
import subprocess
import sys

import numpy as np
import pytest

from host.malloc import available, large_blocks_on_heap

BLOCK_BYTES = 48 * 1024 * 1024           # above glibc's 32 MiB ceiling: always a fresh mapping by default


def _faults_over(n: int) -> int:
    """Minor page faults of allocating, filling and freeing ``n`` large arrays one after another."""
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(n):
        a = np.empty(BLOCK_BYTES // 8)
        a.fill(1.0)
        del a
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before


def _measure() -> None:
    """In a fresh interpreter: faults of four large arrays outside and inside the block (JSON on stdout)."""
    # Faults are counted in the kernel's page size, 4 KiB or 2 MiB (transparent huge pages): compare.
    before = _faults_over(4)                       # each array faulted in afresh
    with large_blocks_on_heap() as on:
        _faults_over(1)                            # the heap grows once
        inside = _faults_over(4)                   # and its pages are reused
    print(json.dumps({"on": on, "before": before, "inside": inside}))


@pytest.mark.slow  # a fresh interpreter that faults in large arrays: 0.45 s; the argument checks stay fast
@pytest.mark.skipif(not available(), reason="the C library has no mallopt (not glibc)")
def test_freed_large_blocks_are_reused_inside_the_block():
    # A fresh process: malloc's thresholds are process state, and a test worker that already trained a
    # network (or ran this block) no longer starts from glibc's defaults -- the "before" arrays then
    # faulted 0 times and the comparison said nothing.
    out = subprocess.run([sys.executable, "-c", "from tests.host.test_malloc import _measure; _measure()"],
                         capture_output=True, text=True, timeout=120, check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert r["on"]
    assert r["before"] >= 4 and r["inside"] * 4 < r["before"], r


@pytest.mark.parametrize("bad", [0, -1, 2**31])
def test_a_threshold_out_of_range_is_refused_before_anything_changes(bad):
    with pytest.raises(ValueError, match="threshold_bytes"):
        with large_blocks_on_heap(bad):
            pass
