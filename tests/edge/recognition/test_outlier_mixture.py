"""The likelihood's outlier component: ε = 0 is the Gaussian bit for bit; directives; its shape (ISSUE #37)."""

import math

import numpy as np
import pytest

from edge.recognition import KnownObject, ObjectSet, ObjectSetError

OBJS = tuple(KnownObject(f"o{i}", "polymer", 300.0 * math.exp(0.25 * i)) for i in range(6))
TOUCHES = [(300.0 * math.exp(x), u) for x in (-0.3, 0.0, 0.12, 0.4, 0.9, 1.6, 3.0) for u in (0.03, 0.1)]


def test_zero_weight_is_the_gaussian_bit_for_bit():
    plain = ObjectSet(OBJS, temperature=1.3, z_crit=2.2)
    zero = ObjectSet(OBJS, temperature=1.3, z_crit=2.2, outlier_weight=0.0, outlier_ln=1.5)
    for e, u in TOUCHES:
        assert zero.classify(e, u).to_dict() == plain.classify(e, u).to_dict()
    x, u = np.log([e for e, _ in TOUCHES]), np.array([u for _, u in TOUCHES])
    q, h, _ = plain.log_terms(x, u)
    out = zero.outlier_terms(x, u)[:2]
    assert np.array_equal(zero.posteriors(q, h, outlier=out), plain.posteriors(q, h))
    # A set without an outlier component writes the CSV it wrote before (no outlier directives).
    assert "outlier" not in plain.to_csv_text()


def test_outlier_directives_round_trip_per_contact_time_and_are_checked():
    table = {0.5: {"temperature": 0.9, "outlier_weight": 0.1, "outlier_ln": 0.7}}
    s = ObjectSet(OBJS, outlier_weight=0.02, outlier_ln=1.0, contact_calibration=table)
    text = s.to_csv_text()
    assert "#@ outlier_weight@0.5s = 0.1" in text and "#@ outlier_weight = 0.02" in text
    back = ObjectSet.from_csv_text(text)
    assert back.contact_calibration == table and (back.outlier_weight, back.outlier_ln) == (0.02, 1.0)
    at = back.at_contact(0.6)
    assert (at.outlier_weight, at.outlier_ln, at.temperature) == (0.1, 0.7, 0.9)
    with pytest.raises(ObjectSetError, match="outlier_weight"):
        ObjectSet.from_csv_text(text.replace("#@ outlier_weight = 0.02", "#@ outlier_weight = 0.9"))


def test_the_mixture_tempers_a_far_touch_and_keeps_the_open_set_test():
    plain = ObjectSet(OBJS, temperature=1.0)
    mix = plain.with_calibration(outlier_weight=0.1, outlier_ln=0.7)
    # Beside an object the core dominates: near the Gaussian's answer (ε of the mass is broad).
    near = 300.0 * math.exp(0.02)
    assert mix.classify(near, 0.05).object_posterior == pytest.approx(plain.classify(near, 0.05).object_posterior,
                                                                      abs=0.05)
    # 0.5 in ln e beyond the last object (9 of its sds): the Gaussian is sure of it, the mixture is not.
    far = 300.0 * math.exp(0.25 * 5 + 0.5)
    q, h, _ = plain.log_terms(math.log(far), 0.02)
    pg = plain.posteriors(q, h)   # closed-set: the Gaussian gives the open-set mass to "unknown" here
    pm = mix.posteriors(q, h, outlier=mix.outlier_terms(math.log(far), 0.02)[:2])
    assert np.argmax(pg) == np.argmax(pm) == 5 and pg.max() > 0.99 > 0.9 > pm.max()
    # The broad component keeps far touches with the objects rather than the flat "unknown" background.
    assert mix.classify(far, 0.02).unknown_posterior < plain.classify(far, 0.02).unknown_posterior
    # The open-set test is the core's: same z, same acceptance.
    for e, u in TOUCHES:
        a, b = plain.classify(e, u), mix.classify(e, u)
        assert (a.z_min, a.accepted, a.nearest) == (b.z_min, b.accepted, b.nearest)
