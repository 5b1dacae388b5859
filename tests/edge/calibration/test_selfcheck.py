"""edge.calibration.selfcheck: the leave-one-reference-out chi^2 check and the model-form floor."""

from __future__ import annotations

import math

import pytest

from edge.calibration.fit import check_reference
from edge.calibration.model import CalibrationError
from edge.calibration.selfcheck import Miss, chi2_quantile, leave_one_out, model_form_floor

#: chi^2 quantiles at p = 0.99 (tables).
EXACT = {1: 6.635, 2: 9.210, 3: 11.345, 6: 16.812, 20: 37.566}


@pytest.mark.parametrize("dof", sorted(EXACT))
def test_the_acceptance_is_the_99_percent_chi2_quantile(dof):
    assert chi2_quantile(dof) == pytest.approx(EXACT[dof], rel=0.008)


def test_the_floor_is_zero_only_when_every_touch_lands_within_its_u():
    inside = [Miss("a", 100.0, 101.0, 0.02), Miss("b", 200.0, 197.0, 0.02)]
    assert model_form_floor(inside, chi2_quantile(2)) == 0.0
    # One miss beyond its u, but chi^2 still passes: the rms excess.
    one = [Miss("a", 100.0, 103.0, 0.02), Miss("b", 200.0, 200.0, 0.02)]
    f = model_form_floor(one, chi2_quantile(2))
    assert f == pytest.approx(math.sqrt((math.log(1.03) - 0.02) ** 2 / 2), rel=1e-9) and f > 0
    # A miss chi^2 refuses: at least the floor that makes it pass (here the rms excess is larger).
    far = [Miss("a", 100.0, 150.0, 0.02), Miss("b", 200.0, 200.0, 0.02)]
    f = model_form_floor(far, chi2_quantile(2))
    chi2 = sum(m.ln_miss ** 2 / (m.u_rel ** 2 + f * f) for m in far)
    assert chi2 <= chi2_quantile(2) and f == pytest.approx(math.sqrt((math.log(1.5) - 0.02) ** 2 / 2))
    # Many small misses: the cover floor exceeds the rms excess and chi^2 lands on the limit.
    many = [Miss(str(i), 100.0, 100.0 * math.exp(0.05 * (-1) ** i), 0.02) for i in range(20)]
    f = model_form_floor(many, chi2_quantile(20))
    chi2 = sum(m.ln_miss ** 2 / (m.u_rel ** 2 + f * f) for m in many)
    assert chi2 == pytest.approx(chi2_quantile(20), rel=1e-6) and f > 0.03


def test_each_reference_is_re_measured_by_the_calibration_fitted_without_it():
    names = ["pmma", "pmma", "glass", "steel"]
    e_ref = [558.0, 558.0, 1490.0, 7493.0]
    fitted_without = []

    def fit_without(name):
        fitted_without.append(name)
        if name == "steel":
            raise CalibrationError("nothing left to fit")   # a ValueError: the touch is unanswered
        return {"without": name}

    def remeasure(cal, j):
        assert cal["without"] == names[j]   # never re-measured by a calibration that saw it
        return (e_ref[j] * (1.5 if names[j] == "glass" else 1.0), 0.01 * e_ref[j])

    check = leave_one_out(names, e_ref, [0.03] * 4, fit_without, remeasure)
    assert sorted(fitted_without) == ["glass", "pmma", "steel"]
    assert not check.passed and math.isinf(check.chi2)
    assert check.worst.name == "steel" and check.floor == pytest.approx(math.sqrt((math.log(1.5) - math.hypot(0.01 / 1.5, 0.03)) ** 2 / 3))
    assert check.to_dict()["chi2"] is None and len(check.to_dict()["misses"]) == 4
    line = check.line()
    assert "\n" not in line and "self-check failed" in line


def test_a_reference_far_outside_the_probes_tolerance_is_refused_as_swapped():
    check_reference("pmma", 558.0, 700.0, 20.0)                # x1.25: the datasheet probe's tolerance
    check_reference("copper", 37000.0, 90000.0, 0.5 * 90000)   # an unresolved metal: its own u widens it
    check_reference("pmma", 558.0, None, None)                 # nothing read: the fit's to refuse
    with pytest.raises(CalibrationError, match="reference pmma: the touch reads e 7500"):
        check_reference("pmma", 558.0, 7500.0, 150.0)


@pytest.mark.slow  # three simulated reference touches and a calibration fit
def test_a_calibration_on_references_at_the_probes_temperature_does_not_overflow():
    # Once "OverflowError: math range error": an object at the probe's own temperature shows no contact
    # step; with 3 s of contact before heating the fit's normal equations were nearly singular and an
    # undamped trial step sent ln(flux_scale) past exp's range.
    from edge.calibration.fit import ReferenceTouch, fit_calibration
    from edge.physics.materials import load_materials
    from firmware_sim.rigs.contact_record import ContactTouch
    from firmware_sim.rz.probe_world import AsBuilt
    from tests.support.records import recorded_touch

    as_built = AsBuilt(sensing_thickness_m=0.424e-3, flux_sensitivity_V_per_W_m2=0.56e-6 * 1.04,
                       thermocouple_time_constant_s=0.06)
    lib = load_materials()
    touches = []
    for name in ("pmma", "pyroceram", "aisi_304"):
        s = lib.get(name).solid
        r = recorded_touch(ContactTouch(s, 0.0, 0.0, lead_s=3.0, heat_s=2.0), as_built=as_built, seed=1)
        touches.append(ReferenceTouch(name, s.effusivity_W_s05_m2K, r["t_s"], r["T_C"], r["q_W_m2"]))
    cal = fit_calibration(touches, created_utc="2026-11-27T00:00:00Z")
    assert all(math.isfinite(x) for x in cal.theta) and 0.8 <= cal.flux_scale <= 1.25
