"""``unknown_min_odds`` (ISSUE #37): "unknown" only when the background is also the most probable hypothesis."""

import math

import numpy as np
import pytest

from edge.recognition import UNKNOWN, KnownObject, ObjectSet, ObjectSetError
from host.recognition import reliability

#: A wood cluster 0.05-0.11 apart in ln e (pine, rubber, MDF) and two objects clear of it, the 5 % spread.
OBJS = tuple(KnownObject(n, c, e) for n, c, e in (("pine", "wood", 322.5), ("rubber", "rubber", 360.7),
                                                   ("mdf", "wood", 377.9), ("glass", "glass", 1369.3),
                                                   ("steel", "alloy", 8194.5)))
Z_CRIT = 2.45   # what the as-built bench fits at 2 s for 99 % in-set acceptance


def test_a_touch_the_test_rejects_but_the_posterior_gives_to_an_object_names_that_object():
    s0 = ObjectSet(OBJS, z_crit=Z_CRIT)
    s1 = s0.with_calibration(unknown_min_odds=1.0)
    u = 0.015
    sd = math.hypot(0.05, u)
    x = 1369.3 * math.exp(2.7 * sd)             # a glass specimen from the spread's tail: beyond z_crit
    r0, r1 = s0.classify(x, u), s1.classify(x, u)
    assert r0.object == UNKNOWN and r0.object_posterior == r0.unknown_posterior < 0.5
    assert r1.object == "glass" and r1.accepted and r1.unknown_posterior == r0.unknown_posterior
    assert r1.object_posterior == r0.candidates[0][1]          # the printed posteriors are unchanged
    # Far from every object the background is the most probable hypothesis: "unknown" under both rules.
    far = 1369.3 * math.exp(6 * sd)
    assert s0.classify(far, u).object == s1.classify(far, u).object == UNKNOWN
    assert s1.classify(far, u).unknown_posterior > 0.5
    # A larger r asks more of the background; inside the test's region the rule changes nothing.
    assert s0.with_calibration(unknown_min_odds=1e6).classify(x, u).object == "glass"
    inside = 1369.3 * math.exp(1.0 * sd)
    assert s0.classify(inside, u).object == s1.classify(inside, u).object == "glass"


#: Objects clear of each other (more than 1 in ln e apart): every answer below 0.5 is the open-set test's.
CLEAR = tuple(KnownObject(n, c, e) for n, c, e in (("foam", "foam", 38.3), ("cardboard", "other", 116.8),
                                                    ("glass", "glass", 1369.3), ("steel", "alloy", 8194.5),
                                                    ("copper", "metal", 35849.1)))


def _answers(s, rng, n=1000, u=0.015):
    """In-set touches (fresh 5 % specimens, measured with their stated u): confidence and rightness as printed."""
    conf, ok = [], []
    for o in s.objects:
        x = math.log(o.e_W_s05_m2K) + rng.normal(0.0, 0.05, n) + rng.normal(0.0, u, n)
        for r in s.classify_many([math.exp(v) for v in x], u):   # classify, batched
            conf.append(r.object_posterior)
            ok.append(r.object == o.name)
    return np.array(conf), np.array(ok)


def test_the_low_bin_is_calibrated_only_when_unknown_needs_the_background_to_be_the_most_probable():
    s0 = ObjectSet(CLEAR, z_crit=Z_CRIT)
    (c0, k0), (c1, k1) = (_answers(s, np.random.default_rng(37)) for s in (s0, s0.with_calibration(unknown_min_odds=1.0)))
    low0 = reliability(c0, k0)["rows"][0]
    # The likelihood is the true one: the test alone answers the spread's tail "unknown" below 0.5, always wrong.
    assert low0["n"] >= 20 and low0["accuracy"] == 0.0 and low0["confidence"] > 0.1
    rows1 = [b for b in reliability(c1, k1)["rows"] if b["n"] >= 20]
    assert rows1 and all(abs(b["accuracy"] - b["confidence"]) <= 0.05 for b in rows1)
    assert k1.mean() > k0.mean() + 0.005


def test_the_rule_round_trips_per_contact_time_and_bad_values_are_one_clear_error():
    s = ObjectSet(OBJS)
    assert "unknown_min_odds" not in s.to_csv_text()        # files written before this field: unchanged
    t = ObjectSet(OBJS, unknown_min_odds=1.0, contact_calibration={1.0: {"unknown_min_odds": 2.0}})
    text = t.to_csv_text()
    assert "#@ unknown_min_odds = 1.0" in text and "#@ unknown_min_odds@1s = 2.0" in text
    back = ObjectSet.from_csv_text(text)
    assert back.unknown_min_odds == 1.0 and back.at_contact(1.1).unknown_min_odds == 2.0
    assert back.at_contact(None).unknown_min_odds == 1.0
    for bad, word in (("#@ unknown_min_odds = -1", "unknown_min_odds"), ("#@ unknown_min_odds@2s = x", "number")):
        with pytest.raises(ObjectSetError) as exc:
            ObjectSet.from_csv_text(bad + "\nname,class,e_W_s05_m2K\npine,wood,322.5\n")
        assert len(exc.value.issues) == 1 and exc.value.issues[0].line == 1 and word in str(exc.value)
    with pytest.raises(ValueError):
        ObjectSet(OBJS, unknown_min_odds=-0.5)
