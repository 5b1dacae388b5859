"""edge.calibration.fit: the probe's chain from reference touches.

(1) Self-consistency: touches made by the 1-D chain itself with a known as-built chain (flux scale,
sensing depth, bead lag off the datasheet) are fitted back, and a held-out solid is then measured
better than with the datasheet chain.  (2) The independent FaithfulWorld (1-D limit, an as-built
probe) with the references' own physics: the calibrated probe measures an unseen glass within its
stated uncertainty, where the datasheet probe is off by more than the calibrated one.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from edge.calibration.fit import ReferenceTouch, clear_fit_memo, fit_calibration
from edge.calibration.model import CalibrationError, ProbeCalibration
from edge.estimation.chain_estimate import estimate_from_contact
from edge.estimation.sensor_chain import SensorChainCalibration, simulate_chain

#: The fits are slow; the refusals before any fit run in the fast tier too.

DT = 0.05
TRUE = SensorChainCalibration(sensing_thickness_m=0.43e-3, tc_tau_s=0.06, flux_scale=1 / 1.04)
E = {"pmma": 558.0, "pyroceram": 2892.0, "aisi_304": 7493.0, "glass": 1450.0}


def _touch(e, rc, off, seed, chain=TRUE, noise=True):
    """Air 0.5 s, contact, heater on 1 s later for 6 s; the reading q over the nominal sensitivity."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 7.0, DT)
    q_true = np.where(t > 1.0, 2500.0, 0.0) * (1 - np.exp(-np.clip(t - 1.0, 0, None) / 0.3))
    q_read = q_true / chain.flux_scale
    T = simulate_chain(t, q_read, e_W_s05_m2K=e, R_c_m2K_W=rc, T_obj0_C=25.0 + off, T_probe0_C=25.0,
                       calibration=chain)
    # The sample at the contact instant is the last one in air (as the FaithfulWorld and a converter
    # that sampled just before see it): air from -0.5 s to the contact, then the chain.
    n_air = 10
    t_all = np.concatenate([np.arange(-n_air, 1) * DT, t[1:]]) - 1.0
    T_all = np.concatenate([np.full(n_air + 1, 25.0), T[1:]])
    q_all = np.concatenate([np.zeros(n_air + 1), q_read[1:]])
    if noise:
        T_all = T_all + 0.005 * rng.standard_normal(T_all.size)
        q_all = q_all + 0.3 * rng.standard_normal(q_all.size)
    return t_all, T_all, q_all


def _refs():
    out = []
    # Objects at the probe's temperature: simulate_chain has no storage term for a contact step (its
    # inputs start at 0 at contact), so a step would make the synthetic record inconsistent with itself.
    for i, (name, rc, off) in enumerate((("pmma", 0.0, 0.0), ("pyroceram", 1e-5, 0.0), ("aisi_304", 0.0, 0.0))):
        t, T, q = _touch(E[name], rc, off, seed=i)
        out.append(ReferenceTouch(name, E[name], t, T, q))
    return out


@pytest.mark.slow
def test_fit_recovers_the_as_built_chain_and_beats_the_datasheet_on_an_unseen_solid():
    cal = fit_calibration(_refs(), created_utc="test")
    assert cal.calibrated and cal.probe == "paper"
    th_true = np.array([math.log(TRUE.flux_scale), math.log(TRUE.sensing_thickness_m), TRUE.tc_tau_s,
                        math.log(TRUE.k_W_mK)])
    # Within 3 of its stated standard uncertainties (and the sensitivity within 1.5 %).
    assert np.all(np.abs(cal.theta - th_true) <= 3 * cal.u_theta + 1e-9), (cal.theta, th_true, cal.u_theta)
    assert abs(cal.theta[0] - th_true[0]) < 0.015
    t, T, q = _touch(E["glass"], 2e-5, 0.0, seed=9)
    # The chain's own (1-D) geometry: an infinite heater.
    d_cal = estimate_from_contact(t, T, q, cal, heater_radius_m=math.inf)
    d_nom = estimate_from_contact(t, T, q, heater_radius_m=math.inf)
    err_cal = d_cal["effusivity_W_s05_m2K"] / E["glass"] - 1
    err_nom = d_nom["effusivity_W_s05_m2K"] / E["glass"] - 1
    assert abs(err_cal) < 0.005 and abs(err_cal) < abs(err_nom)
    assert abs(err_cal) * E["glass"] <= 2 * d_cal["effusivity_W_s05_m2K_u"]
    assert "uncalibrated" in d_nom["flags"] and "uncalibrated" not in d_cal["flags"]
    # The datasheet probe states its ignorance: its u covers its error.
    assert abs(err_nom) * E["glass"] <= 2 * d_nom["effusivity_W_s05_m2K_u"]
    assert d_cal["calibration_sha256"] == cal.sha256


def test_one_reference_material_is_not_enough():
    refs = [r for r in _refs() if r.name == "pmma"] * 2
    with pytest.raises(CalibrationError, match="at least two"):
        fit_calibration(refs)


def test_touches_that_disagree_on_a_references_value_are_refused():
    a, b, c = _refs()
    bad = ReferenceTouch("pmma", 600.0, b.t_s, b.T_C, b.q_W_m2)
    with pytest.raises(CalibrationError, match="disagree"):
        fit_calibration([a, bad, c])


@pytest.mark.slow
def test_the_nominal_prior_keeps_an_unresolvable_parameter_at_its_datasheet_spread():
    # Two polymers-only references (no metal): the bead lag is barely seen; its u stays near the prior's.
    refs = []
    for i, (name, e) in enumerate((("pmma", 558.0), ("hdpe", 800.0))):
        t, T, q = _touch(e, 0.0, 0.0, seed=20 + i, noise=True)
        refs.append(ReferenceTouch(name, e, t, T, q))
    cal = fit_calibration(refs)
    prior = ProbeCalibration.nominal()
    assert cal.u_theta[2] <= prior.u_theta[2] * 1.0001
    assert np.all(np.isfinite(cal.covariance))


def _noisy_refs(noise_T_K: float, seed0: int):
    """Two touches per reference with a noisy thermocouple (the reference board's MCP9600 reads ~25 mK)."""
    out = []
    for i, (name, rc) in enumerate((("pmma", 0.0), ("pmma", 1e-5), ("pyroceram", 1e-5), ("pyroceram", 0.0),
                                     ("aisi_304", 0.0), ("aisi_304", 1e-5))):
        t, T, q = _touch(E[name], rc, 0.0, seed=seed0 + i, noise=False)
        rng = np.random.default_rng(seed0 + 100 + i)
        out.append(ReferenceTouch(name, E[name], t, T + noise_T_K * rng.standard_normal(T.size),
                                  q + 0.3 * rng.standard_normal(q.size)))
    return out


@pytest.mark.slow
def test_the_noise_bias_correction_undoes_most_of_the_depth_pull_of_a_noisy_thermocouple():
    # A noisy thermocouple pulls the fitted sensing depth low (errors in variables through the storage
    # term); the correction measures that pull on the chain's own records and undoes most of it.  The
    # yardstick is the same touches without noise (these short references leave the depth to +-4 %).
    clean = fit_calibration(_noisy_refs(0.0, 300), noise_bias_draws=0)
    refs = _noisy_refs(0.03, 300)
    raw = fit_calibration(refs, noise_bias_draws=0)
    # Off by default (edge.calibration.fit.NOISE_BIAS_DRAWS).  Two antithetic pairs, the fewest that give the
    # correction's scatter a covariance: they undo 79 % of the pull here (three: 69 %) at 3/4 of the fit's CPU.
    cal = fit_calibration(refs, noise_bias_draws=2)
    pull_raw, pull_cal = raw.theta[1] - clean.theta[1], cal.theta[1] - clean.theta[1]
    assert pull_raw < -cal.u_theta[1], (pull_raw, cal.u_theta[1])      # the pull is there, beyond 1 u
    assert abs(pull_cal) < 0.5 * abs(pull_raw), (pull_cal, pull_raw)
    # The correction's own scatter is in the covariance: no parameter claims less than before.
    assert np.all(cal.u_theta >= raw.u_theta * (1 - 1e-12))


@pytest.mark.slow
def test_noise_free_records_come_back_unbiased_with_or_without_the_noise_bias_correction():
    # ISSUE #34 item 6: on records the chain describes and no noise, neither the fit nor the correction
    # may move the answer: both calibrations agree to 1e-3 in every parameter and re-measure every
    # reference within 0.5 %.  And the default path applies no correction.
    import edge.calibration.fit as fit_mod

    refs = []
    for i, (name, rc) in enumerate((("pmma", 0.0), ("pmma", 1e-5), ("pyroceram", 1e-5), ("pyroceram", 0.0),
                                     ("aisi_304", 0.0), ("aisi_304", 1e-5))):
        t, T, q = _touch(E[name], rc, 0.0, seed=i, noise=False)
        refs.append(ReferenceTouch(name, E[name], t, T, q))
    plain = fit_calibration(refs, created_utc="t")
    # One antithetic pair: the correction runs whole (the chain's clean copies refitted, then with noise);
    # on these records it moves theta by 1.43e-4 with one pair and 1.49e-4 with three, at 60 % of the CPU.
    corrected = fit_calibration(refs, created_utc="t", noise_bias_draws=1)
    assert fit_mod.NOISE_BIAS_DRAWS == 0 and plain.sha256 == fit_calibration(refs, created_utc="t",
                                                                            noise_bias_draws=0).sha256
    assert np.all(np.abs(corrected.theta - plain.theta) < 1e-3), corrected.theta - plain.theta
    for cal in (plain, corrected):
        assert all(abs(x) < 0.005 for r in cal.references for x in r.rel_errors), cal.references


@pytest.mark.slow
def test_a_calibration_is_reproducible_and_the_correction_is_optional():
    # Seeded noise: the same touches give the same calibration, byte for byte (one pair is enough to see it).
    refs = _refs()
    # Without the correction (before the memo is cleared: test_fit_recovers_... kept this very fit).
    plain = fit_calibration(refs, created_utc="t", noise_bias_draws=0)
    a = fit_calibration(refs, created_utc="t", noise_bias_draws=1)
    # The second fit computed afresh, not taken from the fits kept (edge.calibration.fit._FITS) ...
    clear_fit_memo()
    b = fit_calibration(refs, created_utc="t", noise_bias_draws=1)
    assert a.sha256 == b.sha256
    # ... and a kept fit answers with the same calibration (another stamp, another file).
    assert fit_calibration(refs, created_utc="t", noise_bias_draws=1).sha256 == a.sha256
    assert fit_calibration(refs, created_utc="u", noise_bias_draws=1).created_utc == "u"
    assert plain.sha256 != a.sha256
    for bad in (-1, 1.5, "3", True):
        with pytest.raises(ValueError, match="noise_bias_draws"):
            fit_calibration(refs, noise_bias_draws=bad)


@pytest.mark.slow
def test_a_failing_noise_bias_correction_is_a_calibration_error(monkeypatch):
    import edge.calibration.fit as fit_mod

    def broken(*_a, **_k):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(fit_mod, "simulate_chain", broken)
    with pytest.raises(CalibrationError, match="noise-bias correction failed"):
        fit_calibration(_refs(), noise_bias_draws=1)


@pytest.mark.slow
def test_a_reference_the_fitted_chain_cannot_re_measure_is_refused_by_name(monkeypatch):
    # A 2-s walk-through touch on the faithful world re-measured to e = inf +- inf: the floor was NaN and the
    # calibration was refused as "u_rel_floor: must be in [0, 1], got nan", naming nothing a user could act on.
    import dataclasses

    import edge.calibration.fit as fit_mod

    real = fit_mod.fit_sensor_chain
    remeasured = []

    def no_answer_on_the_second_reference(t, T, q, **kw):
        r = real(t, T, q, **kw)
        if "contact_frac" in kw:    # the re-measure of each reference touch with the fitted chain, in order
            remeasured.append(r)
            if len(remeasured) == 2:
                return dataclasses.replace(r, e_W_s05_m2K=math.inf, u_e_W_s05_m2K=math.inf)
        return r

    monkeypatch.setattr(fit_mod, "fit_sensor_chain", no_answer_on_the_second_reference)
    with pytest.raises(CalibrationError, match=r"reference pyroceram: re-measured .* no finite e"):
        fit_calibration(_refs(), noise_bias_draws=0)
