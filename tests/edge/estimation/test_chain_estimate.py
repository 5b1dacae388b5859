"""edge.estimation.chain_estimate on FaithfulWorld records: from contact, flagged honestly.

The world is the independent (r, z) finite-volume probe (paper geometry), the record is what the
precision board reads, from 1 s in air before contact.
"""

from __future__ import annotations

import numpy as np
import pytest

from edge.estimation.chain_estimate import estimate_from_contact, uniform_record
from edge.physics.materials import load_materials
from firmware_sim.rigs.contact_record import ContactTouch, record_touch

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def lib():
    return load_materials()


@pytest.mark.parametrize("name", ["pmma", "borofloat_33"])
def test_a_touch_from_contact_is_within_its_stated_uncertainty(lib, name):
    r = record_touch(ContactTouch(lib.get(name).solid, 3e-5, -2.0, lead_s=1.5, heat_s=3.0), seed=3)
    d = estimate_from_contact(r["t_s"], r["T_C"], r["q_W_m2"])
    e = d["effusivity_W_s05_m2K"]
    assert abs(e - r["e_true"]) <= 1.96 * d["effusivity_W_s05_m2K_u"]
    assert d["contact_detected"] and d["contact_t_s"] == pytest.approx(-1.5, abs=0.06)
    assert d["object_temperature0"] == pytest.approx(r["T_obj0_C"], abs=3 * d["object_temperature0_u"] + 0.02)
    assert d["flags"] == ["uncalibrated"] and "e" in d["determined"]


@pytest.mark.parametrize("name", ["pmma", "aisi_304"])
def test_a_probe_lifted_while_heating_is_refused(lib, name):
    r = record_touch(ContactTouch(lib.get(name).solid, 1e-5, -1.0, lead_s=1.0, heat_s=2.0, lift_s=1.0), seed=1)
    d = estimate_from_contact(r["t_s"], r["T_C"], r["q_W_m2"])
    assert "contact_lost" in d["flags"] and d["effusivity_W_s05_m2K"] is None
    assert 1.0 <= d["contact_lost_t_s"] <= 1.5


def test_a_record_that_starts_in_contact_is_flagged_and_widened(lib):
    r = record_touch(ContactTouch(lib.get("borofloat_33").solid, 1e-5, -2.0, lead_s=2.0, heat_s=3.0), seed=4)
    keep = r["t_s"] >= -1.0          # the record starts 1 s after contact
    full = estimate_from_contact(r["t_s"], r["T_C"], r["q_W_m2"])
    late = estimate_from_contact(r["t_s"][keep], r["T_C"][keep], r["q_W_m2"][keep])
    assert "contact_not_recorded" in late["flags"] and "contact_not_recorded" not in full["flags"]
    assert late["u_e_parts"]["contact"] > 0
    # Widened enough to cover what starting mid-transient costs.
    assert abs(late["effusivity_W_s05_m2K"] - r["e_true"]) <= 1.96 * late["effusivity_W_s05_m2K_u"]


def test_uniform_record_resamples_jitter_and_refuses_gaps():
    rng = np.random.default_rng(0)
    t = np.arange(0, 2, 0.05) + rng.uniform(-0.004, 0.004, 40)
    tu, x = uniform_record(t, 2 * t)
    assert np.allclose(np.diff(tu), np.diff(tu)[0]) and np.allclose(x, 2 * tu)
    tg = np.concatenate([t[:10], t[12:]])
    with pytest.raises(ValueError, match="gap"):
        uniform_record(tg, tg)
    with pytest.raises(ValueError, match="increase"):
        uniform_record(t[::-1], t)


class _Fit:
    """What lateral_profile reads of a chain fit."""

    def __init__(self, e, rms, n=1000):
        self.e_W_s05_m2K, self.rms_residual_K, self.n_fitted, self.residual_inflation = e, rms, n, 1.0


def test_lateral_profile_finds_the_records_alpha_and_states_its_curvature():
    import math

    from edge.estimation.chain_estimate import alpha_prior, lateral_profile

    e0, la_true, sigma, kappa, n = 16000.0, math.log(6e-5), 0.004, 0.1, 1000

    def fit_disk(alpha):
        d = math.log(alpha) - la_true
        # e falls as more lateral loss is credited; the residual grows away from the true alpha.
        return _Fit(e0 * math.exp(-0.4 * d), sigma * math.sqrt(1.0 + kappa * d * d), n)

    p = lateral_profile(fit_disk, e0 * 1.3, sigma)
    assert p.profiled
    # The record's curvature: rss / sigma^2 = n (1 + kappa d^2) -> u(ln alpha) = 1 / sqrt(n kappa) = 0.1.
    assert p.u_ln_alpha == pytest.approx(0.1, rel=0.05)
    # The prior (sd ~0.6) pulls the optimum by a few per cent of its distance only.
    m, _ = alpha_prior(e0)
    assert abs(p.ln_alpha - la_true) <= 0.06 * abs(m - la_true) + 0.02
    assert p.slope == pytest.approx(-0.4, abs=0.01)
    assert p.u_ln_e == pytest.approx(0.4 * p.u_ln_alpha, rel=1e-6)


def test_lateral_profile_leaves_alpha_at_the_prior_where_the_loss_is_negligible():
    from edge.estimation.chain_estimate import alpha_prior, lateral_profile

    calls = []

    def fit_disk(alpha):
        calls.append(alpha)
        return _Fit(1500.0 * (1.0 - 1e-4 * alpha / 1e-6), 0.004)   # a glass: e hardly moves with alpha

    p = lateral_profile(fit_disk, 1500.0, 0.004)
    m, sd = alpha_prior(p.fit.e_W_s05_m2K)
    assert not p.profiled and len(calls) == 2
    assert p.u_ln_alpha == pytest.approx(sd) and p.ln_alpha == pytest.approx(alpha_prior(1500.0)[0])
    assert abs(p.u_ln_e) < 1e-3


def test_lateral_profile_without_a_usable_fit_says_so():
    from edge.estimation.chain_estimate import lateral_profile

    assert lateral_profile(lambda alpha: _Fit(float("nan"), 0.004), 1500.0, 0.004) is None


def test_a_metal_touch_measures_alpha_and_k_within_their_stated_uncertainty(lib):
    """On aluminium the heat reaches the paper heater's edge within seconds: the touch pins alpha."""
    import math

    s = lib.get("aluminium_alloy").solid
    alpha_true = s.k_W_mK / s.rho_c_J_m3K
    r = record_touch(ContactTouch(s, 2e-5, -2.0, lead_s=1.5, heat_s=6.0), seed=2, noise=(0.004, 0.5))
    d = estimate_from_contact(r["t_s"], r["T_C"], r["q_W_m2"])
    assert abs(d["effusivity_W_s05_m2K"] - r["e_true"]) <= 1.96 * d["effusivity_W_s05_m2K_u"]
    assert {"alpha", "k"} <= set(d["determined"])
    assert abs(math.log(d["alpha_m2_s"] / alpha_true)) <= 1.96 * d["alpha_m2_s_u"] / d["alpha_m2_s"]
    assert abs(math.log(d["k_W_mK"] / s.k_W_mK)) <= 1.96 * d["k_W_mK_u"] / d["k_W_mK"]
    # ... and it is a measurement: alpha within 25 %, not the prior's spread (a factor ~1.8 at 1 sd).
    assert d["alpha_m2_s_u"] / d["alpha_m2_s"] < 0.25
    # The 1-D model would have read the lateral loss as a higher e.
    assert d["lateral_correction"] < -0.03


def test_a_glass_touch_does_not_claim_alpha(lib):
    r = record_touch(ContactTouch(lib.get("tempered_glass").solid, 2e-5, 1.0, lead_s=1.0, heat_s=3.0), seed=5)
    d = estimate_from_contact(r["t_s"], r["T_C"], r["q_W_m2"])
    assert "alpha" not in d["determined"] and "k" not in d["determined"]
    assert d["alpha_m2_s"] > 0 and d["u_e_parts"]["lateral"] < 0.01


def test_a_coarse_thermometers_step_is_in_the_noise_the_fit_is_judged_against():
    """A ramp read through 0.197-K steps (the 16-bit MCP9600) errs by step / sqrt 12 per sample, which air samples
    on one code do not show: without it the chain called every such touch poor_fit; with it, it answers, right."""
    from tests.support.seam_records import paper_record
    from tests.support.calibrations import sample_calibration

    rec = paper_record(570.0)
    assert rec.T_resolution_K == pytest.approx(0.197, abs=1e-3)
    cal = sample_calibration()
    blind = estimate_from_contact(rec.t_s, rec.T_C, rec.q_W_m2, cal)
    told = estimate_from_contact(rec.t_s, rec.T_C, rec.q_W_m2, cal, T_resolution_K=rec.T_resolution_K)
    assert "poor_fit" in blind["flags"] and "poor_fit" not in told["flags"]
    assert told["noise_T_K"] == pytest.approx(rec.T_resolution_K / 12 ** 0.5)
    assert abs(told["effusivity_W_s05_m2K"] / 570.0 - 1.0) < 2 * told["effusivity_W_s05_m2K_u"] / 570.0
    # A step below the measured noise changes nothing, bit for bit (the precision board's converter).
    fine = estimate_from_contact(rec.t_s, rec.T_C, rec.q_W_m2, cal, T_resolution_K=1e-6)
    assert fine["effusivity_W_s05_m2K"] == blind["effusivity_W_s05_m2K"] and fine["flags"] == blind["flags"]
    with pytest.raises(ValueError, match="T_resolution_K"):
        estimate_from_contact(rec.t_s, rec.T_C, rec.q_W_m2, cal, T_resolution_K=-0.1)
