"""The default sample rate: 50 Hz where the converters deliver it, their own rate elsewhere (issue #34 item 5)."""

from __future__ import annotations

import pytest

from edge.measure.profiles import PROFILES, probe_settings
from edge.service.config import Config
from edge.service.requests import max_sample_rate_Hz, measure_params

PRECISION = {"sensors": {"thermocouple": "ads122c04", "flux_adc": "ads122c04"}}


def test_the_configured_rate_is_50_hz_and_capped_like_a_request():
    ref, prec = Config(), Config(PRECISION)
    assert ref.measurement.sample_rate_Hz == prec.measurement.sample_rate_Hz == 50.0
    # The precision board (ADS122C04) samples the paper probe at the default; the reference board's
    # MCP9600 (a conversion per 80 ms at 16 bit) at its own 12.5 Hz, with or without a request.
    assert measure_params(prec, 10.0).sample_rate_Hz == 50.0
    assert measure_params(ref, 10.0).sample_rate_Hz == pytest.approx(max_sample_rate_Hz(ref.sensors)) == 12.5
    assert measure_params(ref, 10.0, sample_rate_Hz=100.0).sample_rate_Hz == pytest.approx(12.5)
    # A configured rate below the cap is kept as it is (a user's choice, e.g. 10 Hz).
    slow = Config({**PRECISION, "measurement": {"sample_rate_Hz": 10.0}})
    assert measure_params(slow, 10.0).sample_rate_Hz == 10.0
    assert measure_params(slow, 10.0, sample_rate_Hz=200.0).sample_rate_Hz == pytest.approx(
        min(200.0, max_sample_rate_Hz(slow.sensors)))


def test_profiles_keep_the_configured_rate_unless_they_need_their_own():
    # One source of the paper probe's rate: the configuration; a profile states one only when it needs it.
    assert PROFILES["standard"].sample_rate_Hz is None and PROFILES["precise"].sample_rate_Hz is None
    assert PROFILES["quick"].sample_rate_Hz == 50.0
    ref, prec = Config(), Config(PRECISION)
    assert probe_settings("paper", prec.sensors) is None
    small = probe_settings("small-heater", prec.sensors)
    assert small["sample_rate_Hz"] == 50.0 and small["contact_time_s"] == 5.0
    assert probe_settings("small-heater", ref.sensors)["sample_rate_Hz"] == pytest.approx(12.5)
