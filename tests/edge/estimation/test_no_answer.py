"""A touch flagged ``no_signal`` or ``no_contact`` gets no answer (ISSUE #34 item 3), on every path.

On main a calibrated device answered 14 020 +- 910 on a touch it flagged ``no_signal`` (the 1-D
method's e), and the calibrated chain's e was promoted on a touch the seam flagged ``no_contact``:
whatever a method fitted, such a touch has nothing to answer.
"""

from __future__ import annotations

import dataclasses

import pytest

from edge.estimation.seam import NO_ANSWER, SeamContext, estimate_touch
from edge.service.config import Config
from edge.status import Flag
from tests.support.calibrations import sample_calibration


@pytest.fixture(scope="module")
def estimator():
    from edge.estimation.estimate import Estimator, pipeline_golden_check
    from edge.model.bundle import load_bundle
    from thermotouch_models import DEFAULT_BUNDLE

    return Estimator.from_bundle(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))


@pytest.fixture(scope="module")
def pmma_record():
    from edge.estimation.record import TouchRecord
    from edge.physics.materials import load_materials
    from firmware_sim.rigs.contact_record import ContactTouch
    from tests.support.records import recorded_touch

    touch = ContactTouch(load_materials().get("pmma").solid, 1e-5, 0.0, lead_s=1.0, heat_s=3.0)
    r = recorded_touch(touch, seed=3)   # the seam contract's faithful touch, simulated once a session
    return TouchRecord(probe="paper", t_s=r["t_s"], T_C=r["T_C"], q_W_m2=r["q_W_m2"], power_W=5.0,
                       heater_on_s=touch.heat_s, sample_rate_Hz=1.0 / float(r["t_s"][1] - r["t_s"][0]),
                       baseline_s=0.5, arm_s=touch.pre_s + touch.lead_s)


def _assert_no_answer(d: dict) -> None:
    assert NO_ANSWER & {Flag(f) for f in d["flags"]}
    for key in ("effusivity_W_s05_m2K", "k_W_mK", "alpha_m2_s"):
        assert d[key] is None and d[key + "_u"] is None, key
    assert d["determined"] == [] and d["from_prior"] == [] and d["object"] == "unknown"


@pytest.mark.parametrize("flag", ["no_signal", "no_contact"])
def test_a_method_answer_flagged_so_is_withheld(estimator, pmma_record, flag):
    def method(t_s, dT_K, q_W_m2, power_W, method):   # a head's estimator that fitted e anyway
        return {"method": "default", "effusivity_W_s05_m2K": 14020.0, "effusivity_W_s05_m2K_u": 910.0,
                "k_W_mK": 100.0, "k_W_mK_u": 10.0, "alpha_m2_s": 4e-5, "alpha_m2_s_u": 4e-6, "flags": [flag]}

    d = estimate_touch(pmma_record, SeamContext(estimator=estimator, method=method)).to_dict()
    _assert_no_answer(d)


def test_no_contact_withholds_the_uncalibrated_answer_and_the_calibrated_chain_supersedes_it(estimator, pmma_record):
    # The same record judged against a no-contact threshold above pmma's e: the 1-D judgement flags it.
    strict = dataclasses.replace(Config().measurement, no_contact_e_W_s05_m2K=5000.0)
    d = estimate_touch(pmma_record, SeamContext(estimator=estimator, thresholds=strict)).to_dict()
    assert "no_contact" in d["flags"] and "uncalibrated" in d["flags"]
    _assert_no_answer(d)
    # The calibrated chain found the contact in the record and fitted it: its answer stands, unflagged.
    d = estimate_touch(pmma_record, SeamContext(estimator=estimator, calibration=sample_calibration(),
                                                thresholds=strict)).to_dict()
    assert d["method"] == "sensor_chain" and d["effusivity_W_s05_m2K"] is not None
    assert not NO_ANSWER & {Flag(f) for f in d["flags"]}
