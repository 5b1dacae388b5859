"""host.calibration.check_record: ``calibrate --check`` judges the device's answer, and only a calibrated one."""

from __future__ import annotations

import pytest

from host.calibration import check_record

SHA = "ab" * 32


def _rec(e, u, flags=(), sha=SHA):
    return {"result": {"effusivity_W_s05_m2K": e, "effusivity_W_s05_m2K_u": u, "flags": list(flags),
                       "calibration_sha256": sha, "method": "sensor_chain"}}


def test_a_calibrated_answer_within_its_u_holds_and_one_outside_does_not():
    ok = check_record(_rec(565.0, 10.0), 558.0, 0.03)
    assert ok["holds"] is True and ok["deviation_rel"] == pytest.approx(565 / 558 - 1) and ok["calibration_sha256"] == SHA
    off = check_record(_rec(700.0, 7.0), 558.0, 0.03)
    assert off["holds"] is False and off["z"] > 1.96


@pytest.mark.parametrize("rec,why", [
    (_rec(1400.0, 90.0, flags=["no_signal"]), "no_signal"),
    (_rec(30.0, 3.0, flags=["no_contact"]), "no_contact"),
    (_rec(560.0, 10.0, flags=["uncalibrated"], sha=None), "uncalibrated"),
    (_rec(None, None), "no answer"),
])
def test_nothing_is_judged_without_a_calibrated_answer(rec, why):
    res = check_record(rec, 558.0, 0.03)
    assert res["holds"] is None and why in res["why"]


def test_the_wrong_object_is_not_a_reason_to_recalibrate():
    res = check_record(_rec(7400.0, 150.0), 558.0, 0.03)   # steel touched, pmma named
    assert res["holds"] is None and res["wrong_object"] is True and "not that reference" in res["why"]
