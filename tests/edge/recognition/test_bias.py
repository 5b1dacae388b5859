"""The probe's fitted bias of ln e and the poor_fit width in an object set (ISSUE #37)."""

import math

import pytest

from edge.recognition import KnownObject, ObjectSet, ObjectSetError, recognition_fields
from edge.recognition.objects import BIAS_REF_E_W_s05_m2K

# a and b are 0.2 apart in ln e (e 0.2 vs 0.3 W/(m K) at equal rho c): four spreads.
OBJS = (KnownObject.from_properties("a", "polymer", 0.2, 1200, 1400, 0.05),
        KnownObject.from_properties("b", "polymer", 0.3, 1200, 1400, 0.05))
GAP = 0.5 * math.log(1.5)


def _est(e, u_rel=0.02, **kw):
    return {"effusivity_W_s05_m2K": e, "effusivity_W_s05_m2K_u": u_rel * e, **kw}


def test_a_set_with_a_bias_expects_each_object_to_read_shifted():
    e_a = OBJS[0].e_W_s05_m2K
    reads = e_a * math.exp(GAP)   # a probe reading a GAP high puts a touch of a on b's nominal e
    plain = ObjectSet(OBJS).classify(reads, 0.02)
    biased = ObjectSet(OBJS, bias_ln=GAP).classify(reads, 0.02)
    assert plain.object == "b" and biased.object == "a" and biased.object_posterior > 0.9
    # The slope: the bias at e_ref is bias_ln, and it changes by bias_slope per unit ln e.
    s = ObjectSet(OBJS, bias_ln=0.05, bias_slope=-0.02)
    assert s.bias_of(math.log(BIAS_REF_E_W_s05_m2K)) == pytest.approx(0.05)
    assert s.ln_e - s.ln_e_nominal == pytest.approx(0.05 - 0.02 * (s.ln_e_nominal - math.log(BIAS_REF_E_W_s05_m2K)))


def test_bias_directives_round_trip_per_contact_time_and_are_checked():
    table = {1.0: {"temperature": 1.2, "z_crit": 2.2, "bias_ln": 0.06, "bias_slope": -0.04, "poor_fit_ln": 0.25}}
    s = ObjectSet(OBJS, bias_ln=0.01, contact_calibration=table)
    text = s.to_csv_text()
    assert "#@ bias_ln@1s = 0.06" in text and "#@ poor_fit_ln@1s = 0.25" in text and "#@ bias_ln = 0.01" in text
    back = ObjectSet.from_csv_text(text)
    assert back.contact_calibration == table and back.bias_ln == 0.01
    at = back.at_contact(0.9)
    assert (at.bias_ln, at.bias_slope, at.poor_fit_ln) == (0.06, -0.04, 0.25)
    base = "name,class,k_W_mK,rho_kg_m3,c_J_kgK\na,polymer,0.2,1200,1400\n"
    for bad in ("#@ bias_ln@1s = 5", "#@ poor_fit_ln = -0.1", "#@ bias_slope@1s = x"):
        with pytest.raises(ObjectSetError):
            ObjectSet.from_csv_text(bad + "\n" + base)


def test_a_withheld_poor_fit_answer_names_an_object_only_where_the_set_says_how_far_to_trust_it():
    e_a = OBJS[0].e_W_s05_m2K
    withheld = {"effusivity_W_s05_m2K": None, "effusivity_W_s05_m2K_u": None,
                "flags": ["calibration_refused", "poor_fit"], "sensor_chain": {"effusivity_W_s05_m2K": e_a}}
    assert recognition_fields(ObjectSet(OBJS), withheld)["object"] is None            # no poor_fit_ln: nothing
    named = recognition_fields(ObjectSet(OBJS, poor_fit_ln=0.05), withheld)
    assert named["object"] == "a" and named["object_posterior"] > 0.5
    wide = recognition_fields(ObjectSet(OBJS, poor_fit_ln=1.0), withheld)
    assert wide["object_posterior"] < named["object_posterior"]                        # its width is the set's
    # Per contact time: the entry at the touch's heating time decides.
    s = ObjectSet(OBJS, contact_calibration={1.0: {"poor_fit_ln": 0.05}, 2.0: {"poor_fit_ln": 0.0}})
    assert recognition_fields(s, withheld, contact_time_s=1.0)["object"] == "a"
    assert recognition_fields(s, withheld, contact_time_s=2.0)["object"] is None
    # Not a poor fit, or no chain e: nothing to name by.
    for est in ({**withheld, "flags": ["calibration_refused"]}, {**withheld, "sensor_chain": {}},
                {**withheld, "sensor_chain": {"effusivity_W_s05_m2K": -1.0}}):
        assert recognition_fields(ObjectSet(OBJS, poor_fit_ln=0.05), est)["object"] is None
    # An answer with its own e is named from it, not from the chain's.
    own = _est(OBJS[1].e_W_s05_m2K, flags=["poor_fit"], sensor_chain={"effusivity_W_s05_m2K": e_a})
    assert recognition_fields(ObjectSet(OBJS, poor_fit_ln=0.05), own)["object"] == "b"
