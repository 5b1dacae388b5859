"""host/malloc.py: the training's large arrays stay on the heap inside the block."""

import resource

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


@pytest.mark.skipif(not available(), reason="the C library has no mallopt (not glibc)")
def test_freed_large_blocks_are_reused_inside_the_block():
    # Faults are counted in the kernel's page size, 4 KiB or 2 MiB (transparent huge pages): compare.
    before = _faults_over(4)                       # each array faulted in afresh
    with large_blocks_on_heap() as on:
        assert on
        _faults_over(1)                            # the heap grows once
        inside = _faults_over(4)                   # and its pages are reused
    assert before >= 4 and inside * 4 < before, (before, inside)


@pytest.mark.parametrize("bad", [0, -1, 2**31])
def test_a_threshold_out_of_range_is_refused_before_anything_changes(bad):
    with pytest.raises(ValueError, match="threshold_bytes"):
        with large_blocks_on_heap(bad):
            pass
