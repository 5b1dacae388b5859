"""bench/_window_consistency.py: the figures its diagnosis rests on (CAL44, ISSUE #37)."""

from __future__ import annotations

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def W(bench_on_path):
    import _window_consistency

    return _window_consistency


def test_delta_is_short_minus_full_per_material_sorted_by_ln_e(W):
    refs = [("aisi_304", {"1.0": 9.0, "full": 8.9}), ("pmma", {"1.0": 6.31, "full": 6.34}),
            ("pmma", {"1.0": 6.37, "full": 6.34}), ("pyroceram", {"1.0": math.nan, "full": 8.0})]
    le, d = W.predicted_offsets(refs, 1.0)
    assert le.tolist() == pytest.approx([6.34, 8.9])          # pyroceram's short window gave no answer
    assert d.tolist() == pytest.approx([0.0, 0.1])            # pmma's two touches averaged


def test_split_separates_a_probe_level_from_the_scatter_about_it(W):
    rng = np.random.default_rng(1)
    level = {p: rng.normal(0.0, 0.03) for p in range(40)}
    rows = [{"probe": p, "contact_s": 1.0, "name": "oak", "e_true": 400.0,
             "e": 400.0 * math.exp(level[p] + rng.normal(0.0, 0.01)), "u_ln_e": 0.02}
            for p in range(40) for _ in range(30)]
    s = W.split(rows, set(range(40)), 1.0, "oak")
    assert s["within"] == pytest.approx(0.01, rel=0.1)
    assert s["between"] == pytest.approx(np.std(list(level.values()), ddof=1), abs=0.003)
    assert s["rms_z"] == pytest.approx(math.sqrt(0.03**2 + 0.01**2) / 0.02, rel=0.25)
    assert W.split(rows, {0, 1}, 1.0, "oak")["n"] == 60      # only the probes asked for


def test_r2_of_an_exact_linear_dependence_is_one_and_of_noise_small(W):
    rng = np.random.default_rng(2)
    x = rng.normal(size=(200, 2))
    r2, b = W._r2(1.5 * x[:, 0] - 0.5 * x[:, 1] + 0.2, x)
    assert r2 == pytest.approx(1.0) and b.tolist() == pytest.approx([1.5, -0.5])
    assert W._r2(rng.normal(size=200), x)[0] < 0.1
