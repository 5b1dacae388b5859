"""The tactile bench's diagnosis figures (bench/_recognition.py): the ECE's sampling floor, the per-object table."""

from __future__ import annotations

import math

import numpy as np
import pytest


def test_the_ece_floor_is_what_a_calibrated_answerer_shows_and_falls_with_the_touches():
    from _recognition import ece_floor
    from host.recognition import reliability

    def floor(n):
        conf = np.full(n, 0.7)
        return ece_floor(reliability(conf, np.arange(n) % 10 < 7))["median"]

    small, big = floor(40), floor(4000)
    assert 0.03 < small < 0.1 and big < 0.01 and small > 3 * big   # ~ sqrt(p (1 - p) / n)
    # Simulated calibrated answers at 140 touches: their ECE sits near the floor, not near 0.
    rng = np.random.default_rng(1)
    conf = rng.uniform(0.3, 1.0, 140)
    eces = [reliability(conf, rng.random(140) < conf)["ece"] for _ in range(200)]
    rel = reliability(conf, rng.random(140) < conf)
    assert abs(np.median(eces) - ece_floor(rel)["median"]) < 0.025


def test_the_diagnosis_reports_a_bias_against_each_touchs_own_specimen():
    from _recognition import diagnosis
    from edge.recognition import KnownObject, ObjectSet
    from host.recognition import Touches, classify_touches

    s = ObjectSet([KnownObject("a", "polymer", 300.0), KnownObject("b", "polymer", 340.0),
                   KnownObject("c", "metal", 20000.0)])
    rng = np.random.default_rng(2)
    n = 300
    ti = rng.integers(0, 3, n)
    e_true = np.exp(s.ln_e[ti] + 0.05 * rng.standard_normal(n))
    e = e_true * math.exp(0.08) * np.exp(0.02 * rng.standard_normal(n))   # reads 8 % high
    t = Touches(ti, np.full(n, "x"), np.full(n, 1.0), e_true, e, np.full(n, 0.02), s.names)
    d = diagnosis(s, t, classify_touches(s, t))
    assert d["a"]["bias"] == pytest.approx(0.08, abs=0.01) and d["a"]["rms_z"] > 3
    assert d["a"]["confused_with"][0] == "b"            # a touch of a slides up onto b
    assert set(d["c"]["answers"]) <= {"c", "unknown"}    # far from the others: 8 % high only risks "unknown"
    assert sum(d["a"]["answers"].values()) == d["a"]["n"]


def test_the_debiased_ece_is_near_zero_for_calibrated_answers_and_the_gap_for_over_confident_ones():
    from _recognition import debiased_ece

    rng = np.random.default_rng(3)
    plug, deb, over = [], [], []
    for _ in range(300):
        conf = rng.uniform(0.3, 1.0, 300)
        plug.append(debiased_ece(conf, rng.random(300) < conf)["plug_in"])
        deb.append(debiased_ece(conf, rng.random(300) < conf)["debiased"])
        # Over-confident by 0.10 everywhere: right with probability confidence - 0.10.
        over.append(debiased_ece(conf, rng.random(300) < conf - 0.10)["debiased"])
    assert np.median(plug) > 0.03                     # the plug-in's upward bias at 300 touches
    assert abs(np.mean(deb)) < 0.01                   # the debiased estimate is centred on 0
    assert abs(np.mean(over) - 0.10) < 0.015          # ... and on the true gap when there is one
    assert np.mean(over) > np.mean(deb) + 0.07


def test_the_ece_interval_covers_the_truth_and_resamples_by_probe():
    from _recognition import ece_interval

    rng = np.random.default_rng(4)
    conf = rng.uniform(0.3, 1.0, 400)
    probe = np.arange(400) % 3
    calibrated = ece_interval(conf, rng.random(400) < conf, probe, draws=200)
    lo, hi = calibrated["interval"]["touches"]["debiased"]
    assert lo < 0.0 < hi and lo < calibrated["debiased"] < hi
    over = ece_interval(conf, rng.random(400) < conf - 0.15, probe, draws=200)
    lo, hi = over["interval"]["probes_and_touches"]["debiased"]
    assert lo < 0.15 < hi + 0.01 and lo > 0.06        # a 0.15 gap is told from 0.03 at 400 touches
    assert over["plug_in"] >= over["debiased"]


def test_the_breakdown_tells_the_background_mass_from_the_objects_terms():
    """Objects far apart, wide u: every answer right, its printed confidence short by the `unknown` mass alone."""
    from _confidence_breakdown import breakdown, breakdown_lines
    from edge.recognition import KnownObject, ObjectSet
    from host.recognition import Touches, classify_touches

    s = ObjectSet([KnownObject("foam", "foam", 40.0), KnownObject("steel", "alloy", 8000.0)])
    rng = np.random.default_rng(6)
    n = 200
    ti = rng.integers(0, 2, n)
    u = np.full(n, 0.6)                      # a short touch's wide u: the objects' density is low, the background's flat
    e = np.exp(s.ln_e[ti] + np.hypot(0.6, 0.05) * rng.standard_normal(n))
    poor = np.arange(n) % 4 == 0
    t = Touches(ti, np.full(n, "x"), np.full(n, 1.0), e, e, u, s.names, poor_fit=poor)
    s = s.with_calibration(poor_fit_ln=0.6)  # poor_fit touches named at the same width: the groups compare alike
    recs = classify_touches(s, t)
    b = breakdown(s, t, recs)
    rows = [r for r in b["groups"]["all"]["rows"] if r["n"]]
    right = sum(r["accuracy"] * r["n"] for r in rows) / n
    conf = sum(r["confidence"] * r["n"] for r in rows) / n
    assert right > 0.98 and conf < right - 0.02                  # under-confident as printed ...
    assert b["unknown_share"] == pytest.approx(right - conf, abs=0.02)   # ... by the background's mass
    for r in rows:
        assert r["confidence"] + r["unknown"] + r["runner_up"] <= 1.0 + 1e-9
    top = [r for r in rows if r["lo"] >= 0.9]                    # the accepted answers: the object terms alone calibrated
    assert sum(r["n"] for r in top) > 0.95 * n
    assert all(r["closed_set"] > 0.98 and r["runner_up"] < 0.01 and r["accuracy"] == 1.0 for r in top)
    assert b["groups"]["poor_fit"]["n"] == int(poor.sum()) and b["groups"]["stated_u"]["n"] == n - int(poor.sum())
    lines = breakdown_lines({"1.0": {"confidence_breakdown": b}})
    assert any(line.startswith("| poor_fit") for line in lines) and "1 s" in lines[1]
