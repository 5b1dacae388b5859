"""contact_effusivity's Duhamel integrals, a block of rows at a time: the same numbers as one duhamel_m per sample."""

from __future__ import annotations

import numpy as np
import pytest

from edge.estimation import conditioning as C


def _one_by_one(t, dT, q, T_age_s):
    """contact_effusivity as it was written: one duhamel_m call per heating sample."""
    keep = t > 0
    t, dT, q = t[keep], dT[keep], q[keep]
    tT = t - T_age_s
    ok = tT > 0
    m = np.array([C.duhamel_m(x, t, q) for x in tT[ok]])
    d = dT[ok]
    return float(m @ d) / float(d @ d)


@pytest.mark.parametrize("block", [C._BLOCK_ELEMENTS, 7])
@pytest.mark.parametrize("seed", range(4))
def test_the_same_effusivity_bit_for_bit(monkeypatch, block, seed):
    monkeypatch.setattr(C, "_BLOCK_ELEMENTS", block)       # 7: blocks of one row and ragged last blocks
    rng = np.random.default_rng(seed)
    dt = (0.1, 0.05, 0.02, 1 / 860)[seed]
    t = np.sort(np.arange(-10, 150) * dt + rng.normal(0, 0.02 * dt, 160))
    dT = np.cumsum(rng.normal(0.01, 0.02, t.size))
    q = 1000.0 + rng.normal(0, 50, t.size)
    for age in (0.0, 0.5 * dt, 0.1):
        assert C.contact_effusivity(t, dT, q, age) == _one_by_one(t, dT, q, age)
    # A reading placed after the last flux sample (a negative age) takes the per-sample path, as before.
    assert C.contact_effusivity(t, dT, q, -0.05) == _one_by_one(t, dT, q, -0.05)


def test_each_row_is_duhamel_m():
    rng = np.random.default_rng(9)
    t = np.cumsum(rng.uniform(0.01, 0.1, 50))
    q = rng.normal(500, 100, t.size)
    x = t[3:] - 0.013
    assert list(C._duhamel_m_at(x, t, q)) == [C.duhamel_m(v, t, q) for v in x]
