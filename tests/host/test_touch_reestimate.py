"""The host's re-estimate of a stored touch (host/touch.py) goes through the one estimate path."""

from __future__ import annotations

import pytest

from edge.estimation.seam import SeamContext, estimate_touch
from host.touch import reestimate, touch_record
from tests.support.cli import rounded as _rounded


@pytest.fixture(scope="module")
def bundle():
    from edge.estimation.estimate import pipeline_golden_check
    from edge.model.bundle import load_bundle
    from thermotouch_models import DEFAULT_BUNDLE

    return load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check)


@pytest.fixture(scope="module")
def touch():
    from tests.support.daemons import make_sequence

    _, _, seq, params = make_sequence(effusivity=1400.0)
    try:
        out = seq.run(params)
    finally:
        seq.close()
    return out


def test_a_series_with_the_devices_header_is_re_estimated_as_the_device_does(bundle, touch):
    from edge.estimation.estimate import Estimator

    rec = touch.touch
    series = {"raw_t_s": rec.t_s, "raw_T_C": rec.T_C, "raw_q_W_m2": rec.q_W_m2, "touch_header": rec.header(),
              "raw_T_dt_s": rec.T_dt_s, "raw_q_dt_s": rec.q_dt_s}   # the read times: part of the record
    assert rec.T_dt_s is not None and touch_record({}, series).header() == rec.header()
    fits = reestimate(bundle, series, methods=("default",))
    want = estimate_touch(rec, SeamContext(estimator=Estimator.from_bundle(bundle)))
    # Equal (to the last bit or two: two runs of the same path may differ there, see test_estimator.py).
    assert _rounded(fits["default"].to_dict()) == _rounded(want.to_dict())
    assert fits["default"].fit_T_K is not None and fits["default"].t_model_s is not None   # the plot's curve


def test_a_series_without_a_header_is_fitted_on_the_devices_grid(bundle, touch):
    record = {"result": {"probe": "paper"}, "power_W": touch.power_W}
    series = {"raw_t_s": touch.raw_t_s, "raw_T_C": touch.raw_T_C, "raw_q_W_m2": touch.raw_q_W_m2,
              "grid_t_s": touch.grid_t_s, "grid_dT_K": touch.grid_dT_K, "grid_q_W_m2": touch.grid_q_W_m2}
    fits = reestimate(bundle, series, methods=("default", "paper"), record=record)
    assert set(fits) == {"default", "paper"}
    # The device's method on the device's grid: the same e as the seam's method step gave on the device.
    seam = estimate_touch(touch.touch, SeamContext(estimator=_estimator(bundle)))
    assert fits["default"].effusivity_W_s05_m2K == pytest.approx(seam.to_dict()["effusivity_W_s05_m2K"], rel=1e-12)
    assert reestimate(None, series) == {} and reestimate(bundle, {"raw_t_s": None}) == {}


def _estimator(bundle):
    from edge.estimation.estimate import Estimator

    return Estimator.from_bundle(bundle)
