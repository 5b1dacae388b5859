"""Posteriors calibrated per contact time (ISSUE #37): the set's table, its CSV directives, its use."""

import math

import pytest

from edge.recognition import KnownObject, ObjectSet, ObjectSetError, recognition_fields

OBJS = (KnownObject.from_properties("a", "polymer", 0.2, 1200, 1400, 0.05),
        KnownObject.from_properties("b", "polymer", 0.3, 1200, 1400, 0.05))
TABLE = {0.5: {"temperature": 4.0, "z_crit": 3.0}, 2.0: {"temperature": 1.0, "z_crit": 2.0}}


def test_at_contact_picks_the_nearest_entry_in_ln_t():
    s = ObjectSet(OBJS, temperature=2.0, z_crit=2.5, contact_calibration=TABLE)
    assert s.at_contact(0.6).temperature == 4.0 and s.at_contact(0.6).z_crit == 3.0
    assert s.at_contact(1.5).temperature == 1.0
    assert s.at_contact(None) is s
    assert ObjectSet(OBJS, temperature=2.0).at_contact(1.0).temperature == 2.0   # no table: the scalars


def test_classify_estimate_uses_the_contact_times_calibration():
    s = ObjectSet(OBJS, contact_calibration=TABLE)
    e = OBJS[0].e_W_s05_m2K
    est = {"effusivity_W_s05_m2K": e, "effusivity_W_s05_m2K_u": 0.05 * e}
    short = s.classify_estimate(est, contact_time_s=0.5)
    long = s.classify_estimate(est, contact_time_s=2.0)
    # A larger temperature widens every object: the nearest one is less certain.
    assert short.object == long.object == "a"
    assert short.object_posterior < long.object_posterior
    f = recognition_fields(s, est, contact_time_s=0.5)
    assert math.isclose(f["object_posterior"], short.object_posterior)


def test_csv_round_trip_and_refusals():
    s = ObjectSet(OBJS, contact_calibration=TABLE)
    text = s.to_csv_text()
    assert "#@ temperature@0.5s = 4.0" in text and "#@ z_crit@2s = 2.0" in text
    back = ObjectSet.from_csv_text(text)
    assert back.contact_calibration == {0.5: TABLE[0.5], 2.0: TABLE[2.0]}
    assert back.with_object(OBJS[0]).contact_calibration == back.contact_calibration
    base = "name,class,k_W_mK,rho_kg_m3,c_J_kgK\na,polymer,0.2,1200,1400\n"
    for bad in ("#@ temperature@0s = 1.0", "#@ temperature@1s = -1", "#@ spread@1s = 1.0", "#@ z_crit@1s = x"):
        with pytest.raises(ObjectSetError):
            ObjectSet.from_csv_text(bad + "\n" + base)
    with pytest.raises(ValueError):
        ObjectSet(OBJS, contact_calibration={0.0: {"temperature": 1.0}})


def test_an_answer_the_calibration_refused_is_named_with_a_broad_u():
    s = ObjectSet(OBJS)
    e = OBJS[0].e_W_s05_m2K
    est = {"effusivity_W_s05_m2K": e, "effusivity_W_s05_m2K_u": 0.01 * e, "flags": ["calibration_refused"]}
    f, g = recognition_fields(s, est), recognition_fields(s, {**est, "flags": []})
    assert g["object"] == "a" and g["object_posterior"] > 0.9
    # a and b lie 0.4 in ln e apart: with u(ln e) = 1 the answer cannot choose between them.
    assert f["object_posterior"] < 0.6 and f["candidates"]
