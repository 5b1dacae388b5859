"""Through the seam: a touch whose chain fitted poorly keeps its e withheld, and names an object only
where the active set carries a fitted poor_fit_ln (ISSUE #37; the refusal itself is ISSUE #34's)."""

from edge.estimation.seam import SeamContext, estimate_touch
from edge.recognition import ObjectSet
from edge.service.config import Config
from tests.support.calibrations import sample_calibration


def test_a_poor_fit_touch_is_named_from_the_chains_e_by_a_set_that_carries_poor_fit_ln(estimator,
                                                                                         monkeypatch):
    import edge.estimation.chain_estimate as chain_estimate
    from edge.estimation.record import TouchRecord
    from edge.physics.materials import load_materials
    from firmware_sim.rigs.contact_record import ContactTouch
    from tests.support.records import recorded_touch

    touch = ContactTouch(load_materials().get("pmma").solid, 1e-5, 2.0, lead_s=1.0, heat_s=3.0)   # object 2 K off
    r = recorded_touch(touch, seed=3)   # test_seam_refused's and test_poor_fit_seam's touch, once a session
    record = TouchRecord(probe="paper", t_s=r["t_s"], T_C=r["T_C"], q_W_m2=r["q_W_m2"], power_W=5.0,
                         heater_on_s=touch.heat_s, sample_rate_Hz=1.0 / float(r["t_s"][1] - r["t_s"][0]),
                         baseline_s=0.5, arm_s=touch.pre_s + touch.lead_s)
    monkeypatch.setattr(chain_estimate, "POOR_FIT", 0.0)   # every fit called poor: the seam withholds e
    library = ObjectSet.from_library()

    def answer(objs):
        ctx = SeamContext(estimator=estimator, calibration=sample_calibration(probe="paper"), object_set=objs,
                          object_set_name="library", thresholds=Config().measurement)
        return estimate_touch(record, ctx).to_dict()

    plain = answer(library)
    assert plain["effusivity_W_s05_m2K"] is None and plain["object"] == "unknown"   # ISSUE #34 unchanged
    chain_e = plain["sensor_chain"]["effusivity_W_s05_m2K"]
    assert chain_e and chain_e > 0
    named = answer(library.with_calibration(poor_fit_ln=0.3))
    assert named["effusivity_W_s05_m2K"] is None and "poor_fit" in named["flags"]   # still no number
    assert named["object"] != "unknown" and named["object_posterior"] is not None and named["candidates"]
    # The name is the one the chain's e points to, at that width.
    direct = library.with_calibration(poor_fit_ln=0.3).classify(chain_e, 0.3)
    assert named["object"] == direct.object
