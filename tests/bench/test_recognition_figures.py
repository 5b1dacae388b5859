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
    """Objects far apart, wide u: every answer right and said so (closed-set); the joint confidence short by the background."""
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
    joint = sum(r["joint"] * r["n"] for r in rows) / n
    assert right > 0.98 and conf > right - 0.01                  # calibrated as printed (closed-set) ...
    assert joint < right - 0.02                                  # ... where the background folded in was under-confident
    assert b["unknown_share"] == pytest.approx(conf - joint, abs=0.02)   # ... by the background's mass
    for r in rows:
        assert r["joint"] + r["unknown"] <= 1.0 + 1e-9 and r["joint"] <= r["confidence"] + 1e-12
    top = [r for r in rows if r["lo"] >= 0.9]                    # the accepted answers: the object terms alone calibrated
    assert sum(r["n"] for r in top) > 0.95 * n
    assert all(r["confidence"] > 0.98 and r["runner_up"] < 0.01 and r["accuracy"] == 1.0 for r in top)
    assert b["groups"]["poor_fit"]["n"] == int(poor.sum()) and b["groups"]["stated_u"]["n"] == n - int(poor.sum())
    lines = breakdown_lines({"1.0": {"confidence_breakdown": b}})
    assert any(line.startswith("| poor_fit") for line in lines) and "1 s" in lines[1]


def test_reliability_is_judged_against_what_a_calibrated_answerer_shows_on_the_same_touches():
    from _recognition import reliability_judged, reliability_sampling

    rng = np.random.default_rng(3)
    conf = np.concatenate([rng.uniform(0.3, 0.5, 175), rng.uniform(0.5, 1.0, 4000)])
    ok = rng.random(conf.size) < conf   # calibrated answers
    big = reliability_sampling(conf[175:], ok[175:], draws=500)
    assert reliability_judged(big).startswith("met") and big["p_all_within"] > 0.9
    low = (conf < 0.5).nonzero()[0]
    # The low bin made 15 points over-confident: shown (p far below 5 %), NOT met.
    bad = ok.copy()
    bad[low] = rng.random(low.size) < conf[low] - 0.15
    s = reliability_sampling(conf, bad, draws=500)
    b0 = s["bins"][0]
    assert b0["n"] == 175 and abs(b0["sd"] - 0.037) < 0.005 and b0["p_as_far"] < 0.01
    assert reliability_judged(s).startswith("NOT met (0.00-0.50")
    # Six points off on 175 touches: what a calibrated answerer shows often -> consistent with calibration.
    mild = ok.copy()
    k = int(round((conf[low].mean() - 0.06) * low.size))
    mild[low] = np.arange(low.size) < k
    s = reliability_sampling(conf, mild, draws=500)
    assert 0.05 < s["bins"][0]["p_as_far"] < 0.3 and s["bins"][0]["p_off"] > 0.1
    assert reliability_judged(s).startswith("NOT met as written, consistent with calibration")
    # The bar as written is a gamble on a small bin: a calibrated answerer passes less often than on big ones.
    assert s["p_all_within"] < big["p_all_within"]
    # Bins under min_n are not judged.
    assert reliability_sampling(conf[:10], ok[:10], draws=50)["bins"] == []
