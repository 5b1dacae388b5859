"""An answer the installed calibration did not make says so (ISSUE #34: answers that look calibrated but are not)."""

import pytest

from edge.estimation.seam import SeamContext, estimate_touch
from edge.recognition import ObjectSet
from edge.service.config import Config
from tests.edge.estimation.test_seam_contract import estimator, records  # noqa: F401 - the shared fixtures
from tests.support.calibrations import sample_calibration


@pytest.mark.parametrize("rec_name", ["paper/faithful_pmma", "paper/glass", "paper/pmma", "paper/air"])
def test_calibration_refused_exactly_when_the_chain_did_not_answer(estimator, records, rec_name):  # noqa: F811
    record = records[rec_name]
    ctx = SeamContext(estimator=estimator, calibration=sample_calibration(probe="paper"),
                      object_set=ObjectSet.from_library(), object_set_name="library",
                      thresholds=Config().measurement)
    d = estimate_touch(record, ctx).to_dict()
    chain_answered = d["method"] == "sensor_chain"
    assert ("calibration_refused" in d["flags"]) is (not chain_answered)
    assert "uncalibrated" not in d["flags"]  # a calibration is installed; it was refused, not missing
    if not chain_answered:  # the reason is on the record
        chain = d["sensor_chain"]
        assert chain.get("error") or chain.get("flags"), chain


def test_the_faithful_touch_is_answered_by_the_chain_and_a_1d_touch_is_refused(estimator, records):  # noqa: F811
    ctx = SeamContext(estimator=estimator, calibration=sample_calibration(probe="paper"),
                      object_set=ObjectSet.from_library(), object_set_name="library", thresholds=Config().measurement)
    assert estimate_touch(records["paper/faithful_pmma"], ctx).method == "sensor_chain"
    assert "calibration_refused" in estimate_touch(records["paper/glass"], ctx).to_dict()["flags"]
