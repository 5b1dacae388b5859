"""bench/asbuilt_calibrated_bench.py's decomposition of the stated u(e) and of the error (ISSUE #34 item 5)."""

from __future__ import annotations

import math

import pytest


@pytest.fixture(scope="module")
def bench():
    import asbuilt_calibrated_bench  # bench/ is on the path: tests/bench/conftest.py

    return asbuilt_calibrated_bench


def _row(probe, err, cls="glass", **kw):
    return {"head": "paper", "probe": probe, "solid": "x", "class": cls, "window_s": 2.0, "R_c": 1e-5,
            "e": 1000.0 * (1 + err), "e_true": 1000.0, "u_e": 10.0, "err": err, "method": "sensor_chain",
            "flags": [], "attainable_u_rel": 0.003, "attainable_u_rel_no_nuisance": 0.002,
            "u_e_fit_noise": 0.002, "u_e_fit_noise_nuisance_known": 0.001,
            "u_e_parts": {"fit": 0.004, "calibration": 0.012, "floor": 0.004, "contact": 0.0, "lateral": 0.0}} | kw


def test_a_probes_common_offset_is_the_calibrations_share_and_is_taken_out(bench):
    # Probe 1 reads everything 2 % high, probe 2 1 % low; the touches scatter 0.1-0.3 % about that.
    rows = [_row(1, math.expm1(0.02 + d)) for d in (-0.003, 0.0, 0.001)]
    rows += [_row(2, math.expm1(-0.01 + d)) for d in (0.002, 0.0, -0.001)]
    s = bench.summarise(rows, [{"head": "paper", "refused": None, "calibration": None}])
    parts = s["paper"]["windows"]["2"]["all"]["u_parts"]
    assert parts["error"] == pytest.approx(0.0151, abs=2e-3)
    assert parts["error_within_probe"] == pytest.approx(0.001, abs=5e-4)
    # The attainable u with the calibration's parts added is their quadrature sum.
    assert parts["attainable_with_calibration"] == pytest.approx(math.sqrt(0.003**2 + 0.012**2 + 0.004**2))
    assert parts["residual_factor"] == pytest.approx(2.0)
    text = bench.decomposition_table(s, windows=("2",))
    assert "| paper | 2 s | glass |" in text and "1.30 %" in text
