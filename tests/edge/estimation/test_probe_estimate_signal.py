"""The small-heater estimate's signal checks: no_signal vs an unresolved rise."""

import numpy as np

from edge.estimation.probe_estimate import _signal_check
from edge.status import Flag

STEP_K = 0.197   # a 16-bit MCP9600's step


def test_no_heat_at_either_sensor_is_no_signal():
    assert _signal_check(np.zeros(20), np.full(20, 3.0), STEP_K) == Flag.NO_SIGNAL


def test_flux_with_a_rise_below_two_thermometer_steps_is_insufficient_not_no_signal():
    # A metal on the small heater: ~900 W/m^2 through the sensor, the rise under one 0.2-K step.
    T = np.r_[np.zeros(10), np.full(10, STEP_K)]
    assert _signal_check(T, np.full(20, 900.0), STEP_K) == Flag.INSUFFICIENT_SIGNAL


def test_a_resolved_rise_with_flux_passes():
    assert _signal_check(np.linspace(0.0, 1.0, 20), np.full(20, 900.0), STEP_K) is None
    assert _signal_check(np.linspace(0.0, 0.05, 20), np.full(20, 900.0), 0.0) is None   # 24-bit: no step
