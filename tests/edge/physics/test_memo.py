"""edge.physics.memo and the memos built on it: bounded, read-only, and the same numbers as computing afresh."""

from __future__ import annotations

import numpy as np
import pytest

from edge.physics.bessel import _MEMO as BESSEL_MEMO, bessel_j
from edge.physics.memo import BoundedMemo


def test_bounded_memo_evicts_the_least_recently_used_and_freezes_its_values():
    m = BoundedMemo(2)
    calls = []

    def make(v):
        calls.append(v)
        return np.full(3, float(v))

    a = m(("a",), lambda: make(1))
    m(("b",), lambda: make(2))
    assert m(("a",), lambda: make(9)) is a          # a hit: not recomputed
    m(("c",), lambda: make(3))                      # evicts b, the least recently used
    assert len(m) == 2 and m.get(("b",)) is None and m.get(("a",)) is a
    assert calls == [1, 2, 3]
    with pytest.raises(ValueError):
        a[0] = 5.0                                  # shared by every caller: read-only


def test_slab_kernels_of_a_shorter_grid_are_the_longer_grids_prefix_bit_for_bit():
    from edge.estimation.sensor_chain import _KERNELS, _slab_kernels

    args = (0.005, 0.43e-3, 0.2, 1.1e-7)
    _KERNELS.clear()
    short = [k.copy() for k in _slab_kernels(300, *args)]
    long_ = [k.copy() for k in _slab_kernels(900, *args)]      # extends the kept 300 by 600 times
    _KERNELS.clear()
    fresh = _slab_kernels(900, *args)
    for s, l, f in zip(short, long_, fresh):
        assert np.array_equal(l, f)
        assert np.array_equal(s, f[:300])


def test_bessel_memo_returns_the_computed_values_as_a_private_copy():
    x = np.linspace(0.0, 400.0, 777)
    BESSEL_MEMO.clear()
    first = bessel_j(1, x)
    first[0] = 123.0                                # the caller's copy: the kept values are untouched
    again = bessel_j(1, x)
    assert again[0] == 0.0
    assert np.array_equal(again[1:], first[1:])


def test_a_byte_capped_memo_keeps_at_most_its_bytes_and_always_the_newest():
    m = BoundedMemo(100, max_bytes=3 * 80)
    for i in range(5):
        m.put((i,), (np.full(10, float(i)), 1.5))        # 80 bytes of array per entry; the float adds none
    assert len(m) == 3 and m.nbytes == 240 and m.get((0,)) is None and m.get((4,))[0][0] == 4.0
    m.put((4,), (np.zeros(10), 0.0))                     # a replaced entry is counted once
    assert len(m) == 3 and m.nbytes == 240
    m.put(("big",), np.zeros(100))                       # larger than the cap: kept alone, not dropped
    assert len(m) == 1 and m.nbytes == 800
    m.clear()
    assert len(m) == 0 and m.nbytes == 0
