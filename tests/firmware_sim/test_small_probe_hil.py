"""The small-heater probe end to end on the simulator: the device's sequence and estimator on emulated chips.

The touch is the shipped ``glass_15V_small`` scene (tempered glass, the
paper's areal power on the 5-mm heater, faithful (r, z) world, the
precision converter ADS122C04 reading the thermocouple and the flux; the
reference board's 0.2-K thermometer steps are most of the small heater's
rise), with the daemon's configuration for that scene
(:func:`firmware_sim.run.config_for_scene`: the probe's profile, 50 Hz, as
long as the scene's touch allows).  These tests are hil-marked by
``tests/firmware_sim/conftest.py``.
"""

from __future__ import annotations

import dataclasses
import math

import pytest

from edge.estimation.estimate import Estimator
from firmware_sim.rigs.sequence_rig import OneBundleStore, sequence_touch
from firmware_sim.scene.files import read_scene

pytestmark = pytest.mark.slow

#: The paper's 50-ohm heater (glass_15V): the same experiment on the paper's probe.
PAPER_HEATER_OHM = 50.0


@pytest.fixture(scope="module")
def store():
    from thermotouch_models import DEFAULT_BUNDLE

    from edge.estimation.estimate import pipeline_golden_check
    from edge.model.bundle import load_bundle

    return OneBundleStore(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))


def _glass_scene(probe: str):
    """The shipped scene (precision converter fitted), or the same touch on the paper's probe and heater."""
    sc = read_scene("glass_15V_small")
    if probe == "small-heater":
        return sc
    return dataclasses.replace(sc, board=dataclasses.replace(sc.board, probe=probe),
                               heater=dataclasses.replace(sc.heater, resistance_ohm=PAPER_HEATER_OHM))


def _touch(sc, store, tmp_path, overrides=None):
    """One touch through the device's sequence and the daemon's estimator; (outcome, config)."""
    out, cfg, invariant = sequence_touch(sc, store, str(tmp_path), overrides)
    assert invariant["ok"]
    return out, cfg


def test_small_heater_touch_on_glass_determines_k_and_alpha_within_its_stated_uncertainty(store, tmp_path):
    sc = _glass_scene("small-heater")
    out, cfg = _touch(sc, store, tmp_path)
    # The probe's profile on the precision converter: 50 Hz, the longest heating the 2.5-s touch allows.
    assert cfg.measurement.sample_rate_Hz == 50.0
    assert cfg.measurement.contact_time_s == pytest.approx(sc.touch.end_s - sc.touch.heater_on_s - 0.3)
    assert out.status == "ok", (out.reason, out.error)
    r = out.result
    assert r["probe"] == "small-heater" and r["determined"] == ["e", "k", "alpha"] and not r["from_prior"]
    s = sc.object.solid
    for key, true in (("k_W_mK", s.k_W_mK), ("alpha_m2_s", s.alpha_m2_s)):
        u = r[f"{key}_u"]
        assert u / r[key] < 0.30, key                          # determined, not a guess
        assert abs(r[key] - true) <= 2.0 * u, (key, r[key], true, u)   # within the stated 95 % interval


def test_paper_probe_on_the_same_glass_reports_k_and_alpha_from_the_prior(store, tmp_path):
    out, _ = _touch(_glass_scene("paper"), store, tmp_path)
    assert out.status == "ok", (out.reason, out.error)
    r = out.result
    # The paper's probe is one-dimensional at its sensors: e from the touch, k and alpha from the library
    # prior given e (k = e^2 / rho c, alpha = e^2 / (rho c)^2), exactly -- nothing of k or alpha was measured.
    e, u_e = r["effusivity_W_s05_m2K"], r["effusivity_W_s05_m2K_u"]
    # Every answer says what the touch determined (issue #33: one Estimate, the same keys on every path).
    assert r["determined"] == ["e"] and r["from_prior"] == ["k", "alpha"] and r["method"] == "default"
    assert r["determined_by"] == {"e": "data", "k": "prior", "alpha": "prior"}
    ln_rc, _, _ = Estimator.from_bundle(store.bundle).library.prior_rho_c(e, u_e / e)
    rc = math.exp(ln_rc)
    assert r["k_W_mK"] == pytest.approx(e * e / rc, rel=1e-9)
    assert r["alpha_m2_s"] == pytest.approx(e * e / (rc * rc), rel=1e-9)
    assert r["k_W_mK_u"] / r["k_W_mK"] > 0.05          # the prior's spread, not a touch's precision


def test_small_heater_probe_in_air_is_flagged_no_contact_not_a_material(store, tmp_path):
    # The 1-D no_contact test reads ~340 here (the flux sensor sees the probe's own sensing layer spread
    # the heat); the fit's object effusivity is what tells air (2-3) from a solid.
    sc = _glass_scene("small-heater")
    sc = dataclasses.replace(sc, touch=dataclasses.replace(sc.touch, start_s=30.0))   # touch after the measurement
    out, _ = _touch(sc, store, tmp_path, {"measurement": {"contact_time_s": 1.0, "baseline_s": 0.5}})
    assert out.status == "ok", (out.reason, out.error)
    assert "no_contact" in out.flags
    assert out.result["k_W_mK"] is None and out.result["determined"] == []
