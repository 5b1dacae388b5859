"""Resampling places lagging temperature readings at the time they were taken."""

import numpy as np
import pytest

from edge.measure.signal import resample_uniform


def test_converter_lag_is_removed_and_nothing_is_extrapolated():
    rate, age = 10.0, 0.08
    t = np.arange(-0.5, 2.0 + 1e-9, 0.1)  # read times since heater-on
    true_T = lambda tt: 25.0 + 0.5 * np.clip(tt, 0, None) ** 1.5
    T_read = true_T(t - age)  # each reading shows the temperature one conversion earlier
    q = np.where(t >= 0, 800.0, 0.0)
    g, dT, qg = resample_uniform(t, T_read, q, 25.0, 0.0, rate, 2.0, T_age_s=age)
    assert g[-1] <= 2.0 - age + 1e-9, "the grid must stop at the last placed reading"
    np.testing.assert_allclose(dT, true_T(g) - 25.0, atol=2e-3)
    _, dT_naive, _ = resample_uniform(t, T_read, q, 25.0, 0.0, rate, 2.0)
    assert np.max(np.abs(dT_naive[: g.size] - (true_T(g) - 25.0))) > 0.03


def test_lag_longer_than_the_record_is_refused():
    t = np.array([0.05, 0.1])
    with pytest.raises(ValueError, match="after heater-on"):
        resample_uniform(t, [25.0, 25.1], [1.0, 1.0], 25.0, 0.0, 10.0, 0.1, T_age_s=0.5)
