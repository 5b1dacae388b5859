import math

import numpy as np
import pytest

from tests.support.daemons import FakeEstimator, assert_heater_safe, make_sequence
from edge.service.config import Config
from edge.physics.probe import HEATER_AREA_m2, volumetric_heat_W_m3
from edge.measure.sequence import MeasurementParams
from edge.measure.signal import quality_flags, resample_uniform
from firmware_sim.rigs.daemon_rig import heater_on_intervals

pytestmark = pytest.mark.hil


def test_resample_grid_and_anchor():
    t = np.array([-0.3, -0.1, 0.02, 0.12, 0.22, 0.32, 0.42, 0.52])
    T = np.where(t < 0, 20.0, 20.0 + 2 * np.sqrt(np.clip(t, 0, None)))
    q = np.where(t < 0, 5.0, 1005.0)
    g, dT, qg = resample_uniform(t, T, q, 20.0, 5.0, 10.0, 0.5)
    assert np.allclose(g, [0.1, 0.2, 0.3, 0.4, 0.5])
    assert np.allclose(qg, 1000.0)  # offset removed, no overshoot from the switch-on step
    assert np.allclose(dT, 2 * np.sqrt(g), atol=0.05)
    with pytest.raises(ValueError, match="at least 2"):
        resample_uniform(t[:3], T[:3], q[:3], 20.0, 5.0, 10.0, 0.5)


def test_normal_measurement_on_glass():
    rig, heater, seq, params = make_sequence(effusivity=1400.0)
    est = seq.estimator.context.method
    out = seq.run(params)
    assert out.status == "ok" and out.reason is None, out.error
    assert out.flags == ["uncalibrated"]   # estimated without a calibration: said (issue #33)
    assert out.T0_C == pytest.approx(25.0, abs=0.07) and out.q_offset_W_m2 == pytest.approx(0.0, abs=20)
    # The estimator got a uniform grid at the sample rate, flux near P/A, and the heater's q_v.
    t, dT, q, power_W, method = est.calls[0]
    dt = 1.0 / params.sample_rate_Hz   # the rig's MCP9600: 12.5 Hz, the cap of the configured rate
    assert np.allclose(np.diff(t), dt) and t[0] == pytest.approx(dt)
    assert np.mean(q) == pytest.approx(params.power_W / HEATER_AREA_m2, rel=0.02)
    assert power_W == params.power_W and method == "default"   # power in W, no q_v round trip (issue #33)
    assert out.result["effusivity_W_s05_m2K"] == pytest.approx(1400.0, rel=0.15)
    assert est.heater_on_at_call == [False]
    assert out.raw_t_s.size == out.raw_T_C.size == out.raw_q_W_m2.size > 20
    inv = assert_heater_safe(rig.parts, Config().heater.max_on_time_s)
    assert inv["n_intervals"] == 1 and inv["longest_on_s"] == pytest.approx(params.contact_time_s, abs=0.01)
    assert out.heater_on_s == pytest.approx(inv["total_on_s"], abs=1e-6)
    assert out.model_sha256 == "f" * 64
    seq.close()


def test_cooldown_between_touches_is_enforced_on_the_board_clock():
    rig, heater, seq, params = make_sequence()
    seq.run(params)
    seq.run(params)
    (a0, a1), (b0, b1) = heater_on_intervals(rig.parts)
    assert b0 - a1 >= params.cooldown_s
    assert_heater_safe(rig.parts, 10.0)
    seq.close()


def test_no_contact_is_flagged():
    rig, heater, seq, params = make_sequence(contact=False)
    out = seq.run(params)
    assert "no_contact" in out.flags
    assert_heater_safe(rig.parts, 10.0)
    seq.close()


def test_noisy_and_saturated_and_estimator_flags():
    # Flux noise well above noise_q_W_m2 in the baseline.
    rig, heater, seq, params = make_sequence(flux_noise_V=200e-6, seed=4)
    out = seq.run(params)
    assert "noisy" in out.flags
    seq.close()
    # A flux sensor 1000x more sensitive than configured clips the ADC.
    rig, heater, seq, params = make_sequence(sensitivity_V_per_W_m2=0.56e-3)
    out = seq.run(params)
    assert "saturated" in out.flags
    seq.close()
    rig, heater, seq, params = make_sequence(estimator=FakeEstimator(flags=["outside_training_range"]))
    out = seq.run(params)
    assert out.status == "ok" and out.flags == ["outside_training_range", "uncalibrated"]
    seq.close()


def test_unstable_baseline_is_flagged_when_the_sample_drifts():
    rig, heater, seq, params = make_sequence()
    # The sample is still cooling from a long earlier heating when the baseline starts.
    heater.on_power(5.0)
    rig.clock.advance(8.0)
    heater.off()
    rig.clock.advance(0.5)
    out = seq.run(params)
    assert "unstable_baseline" in out.flags
    seq.close()


def test_quality_flags_function_thresholds():
    th = Config().measurement
    t = np.linspace(-0.5, -0.1, 5)
    flat = np.full(5, 25.0)
    # contact_e: the effusivity the heating record shows (edge.measure.signal.contact_effusivity).
    assert quality_flags(t, flat, np.zeros(5), np.full(10, 1500.0), 560.0, False, th) == []
    drift = 25.0 + np.linspace(0, 0.5, 5)
    assert quality_flags(t, drift, np.zeros(5), np.full(10, 1500.0), 560.0, False, th) == ["unstable_baseline"]
    assert quality_flags(t, flat, np.zeros(5), np.full(10, 10.0), 5.5, True, th) == ["no_contact", "saturated"]
    assert quality_flags(t, flat, np.zeros(5), np.full(10, 10.0), 30.0, False, th) == []  # the lightest foam
    assert quality_flags(t, flat, np.zeros(5), np.full(10, 10.0), None, False, th) == []  # rise not resolved


def test_params_are_validated():
    with pytest.raises(ValueError, match="power_W"):
        MeasurementParams(power_W=0.0, contact_time_s=1, baseline_s=1, sample_rate_Hz=10, cooldown_s=0)
    with pytest.raises(ValueError, match="sample_rate_Hz"):
        MeasurementParams(power_W=1.0, contact_time_s=1, baseline_s=1, sample_rate_Hz=math.nan, cooldown_s=0)


def test_request_longer_than_the_limit_is_clamped():
    cfg = Config({"heater": {"max_on_time_s": 3.0}, "measurement": {"contact_time_s": 2.0}})
    rig, heater, seq, params = make_sequence(cfg=cfg)
    long = MeasurementParams(power_W=5.0, contact_time_s=20.0, baseline_s=0.5, sample_rate_Hz=10, cooldown_s=0)
    out = seq.run(long)
    inv = assert_heater_safe(rig.parts, 3.0)
    assert inv["longest_on_s"] < 3.0 - 0.02 and out.status == "ok"  # clamped below the watchdog's guard
    seq.close()


def test_a_flag_the_estimate_superseded_does_not_return_in_the_record():
    # The calibrated chain that fitted the contact the 1-D check missed drops "no_contact" from its
    # answer (edge.estimation.seam); the record's flags, the conditioning's merged with the answer's,
    # must not bring it back (the demo's answered glass touch read "no_contact").
    import dataclasses

    from edge.status import Flag

    rig, heater, seq, params = make_sequence(contact=False)
    hook = seq.estimator

    def superseding(touch, decision):
        est = hook(touch, decision)
        assert Flag.NO_CONTACT in est.flags
        return dataclasses.replace(est, flags=tuple(f for f in est.flags if f != Flag.NO_CONTACT),
                                   details={**est.details, "sensor_chain": {"superseded_flags": ["no_contact"]}})

    seq.estimator = superseding
    out = seq.run(params)
    assert out.status == "ok" and "no_contact" not in out.flags and "uncalibrated" in out.flags
    assert_heater_safe(rig.parts, 10.0)
    seq.close()
