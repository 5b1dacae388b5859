"""bench/asbuilt_small_bench.py without simulating: its held-out specimens, cache keys and the compare line."""

from __future__ import annotations

import math

import numpy as np
import pytest


@pytest.fixture(scope="module")
def B():
    import asbuilt_small_bench

    return asbuilt_small_bench


def test_every_held_out_touch_is_its_own_specimen_spread_around_the_library(B):
    lib = B.solid("granite")
    a, b = B.held_out_specimen("granite", 3, 7), B.held_out_specimen("granite", 3, 7)
    assert (a.k_W_mK, a.alpha_m2_s) == (b.k_W_mK, b.alpha_m2_s)          # seeded: the cache's key reproduces it
    draws = [B.held_out_specimen("granite", p, j) for p in range(1, 9) for j in range(40)]
    assert len({d.k_W_mK for d in draws}) == len(draws)                   # a fresh specimen every touch
    ln_e = np.array([math.log(d.effusivity_W_s05_m2K / lib.effusivity_W_s05_m2K) for d in draws])
    ln_a = np.array([math.log(d.alpha_m2_s / lib.alpha_m2_s) for d in draws])
    for x in (ln_e, ln_a):   # 5 % lognormal, centred on the library's value (320 draws)
        assert abs(x.mean()) < 0.01 and 0.04 < x.std() < 0.06
    assert abs(np.corrcoef(ln_e, ln_a)[0, 1]) < 0.2                      # independent
    # ... and the touch's scene holds the specimen, not the library's solid.
    sc = B.touch_scene("granite", 3, 11, R_c=1e-5, offset_K=0.5, lead_s=1.0, specimen_solid=a)
    assert sc.object.solid == a and sc.object.label == "granite"
    assert B.touch_scene("granite", 3, 11, R_c=1e-5, offset_K=0.5, lead_s=1.0).object.solid == lib


def test_scored_against_the_specimen_and_spread_touches_never_reuse_library_touches(B):
    s = B.held_out_specimen("copper", 1, 0)
    d = {"effusivity_W_s05_m2K": s.effusivity_W_s05_m2K * 1.02, "effusivity_W_s05_m2K_u": 0.01 * s.effusivity_W_s05_m2K,
         "k_W_mK": s.k_W_mK, "k_W_mK_u": 0.1, "alpha_m2_s": None, "alpha_m2_s_u": None, "flags": [], "determined": ["e"]}
    sc = B.score(d, s)
    assert sc["err_e"] == pytest.approx(0.02) and sc["cov_e"] is False and sc["err_k"] == 0.0 and sc["cov_k"]
    assert sc["err_alpha"] is None and sc["cov_alpha"] is None
    assert B.cache_path("d1_copper_0").name.startswith(f"v{B.BENCH_VERSION}_") and B.BENCH_VERSION >= 2
    assert B.cache_path("d1_ref_pmma_0").name.startswith(f"v{B.REFERENCE_VERSION}_")


def test_the_other_runs_line_names_its_switches_and_numbers(B):
    s = {"touches": 47, "determined_k_alpha": 0.68, "answered_e": 1.0,
         "k": {"median_abs_err": 0.043, "cov95": 0.94, "n": 47}, "alpha": {"median_abs_err": 0.064, "cov95": 1.0, "n": 47},
         "e": {"median_abs_err": 0.015, "cov95": 0.91, "n": 47}}
    other = {"config": {"k_alpha_posterior": False, "remeasure_floor": True},
             "summary": {"calibrated/5s/rc_le_3e-5": s, "calibrated/5s/all": dict(s, touches=160)}}
    line = B.compare_line(other)
    assert line.startswith("`--no-posterior` on the same cache")
    assert "(47 touches) k 4.3 %, α 6.4 %, e 1.5 %, 95 % coverage k / α / e 94 / 100 / 91 %" in line
    assert "all 160:" in line
    assert B._switches({}) == "the defaults"
