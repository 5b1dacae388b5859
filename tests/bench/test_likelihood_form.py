"""The likelihood-form checks (bench/_likelihood_form.py): dispersion per object, a u-dependent k, a bin's gap."""

from __future__ import annotations

import math

import numpy as np

from edge.recognition import KnownObject, ObjectSet

#: A wood cluster (0.06 apart) beside two far objects, each with the 5 % specimen spread.
OSET = ObjectSet([KnownObject(f"o{i}", "polymer", 300.0 * math.exp(0.06 * i)) for i in range(4)]
                 + [KnownObject("metal", "metal", 20000.0), KnownObject("foam", "polymer", 40.0)])


def _touches(rng, n, g_true=0.0, tail=0.0):
    """Specimens with the spread, read with sd ``u (u/0.05)^g_true`` (u 2 % or 15 %); a share ``tail`` 0.15 off."""
    ti = rng.integers(0, len(OSET), n)
    xt = OSET.ln_e_nominal[ti] + rng.normal(0.0, 0.05, n)
    u = np.where(rng.random(n) < 0.5, 0.02, 0.15)
    x = xt + rng.normal(0.0, 1.0, n) * u * (u / 0.05) ** g_true
    bad = rng.random(n) < tail
    x[bad] += rng.normal(0.0, 0.15, int(bad.sum()))
    return x, u, ti, xt


def test_a_right_width_reads_rms_z_one_and_a_heavy_tail_reads_kurtosis():
    from _likelihood_form import object_dispersion

    rng = np.random.default_rng(3)
    x, u, ti, xt = _touches(rng, 12000)
    for d in object_dispersion(OSET, x, u, ti, xt):
        assert 0.93 < d["rms_z"] < 1.07 and 0.9 < d["robust_z_meas"] < 1.1 and abs(d["kurtosis"]) < 0.5
    # The stated u twice the scatter: z reads 1/2 for the measurement; a share of touches 0.15 off reads as kurtosis.
    x, u, ti, xt = _touches(rng, 12000)
    half = object_dispersion(OSET.with_calibration(u_var_scale=4.0), x, u, ti, xt)
    assert all(0.4 < d["robust_z_meas"] < 0.6 and d["rms_z"] < 0.9 for d in half)
    x, u, ti, xt = _touches(rng, 12000, tail=0.2)
    assert min(d["kurtosis"] for d in object_dispersion(OSET, x, u, ti, xt)) > 0.5


def test_the_u_power_profile_has_its_minimum_at_the_power_the_touches_were_drawn_with():
    from _likelihood_form import u_power_profile

    rng = np.random.default_rng(5)
    for g_true, best in ((0.0, 0.0), (0.3, 0.3)):
        x, u, ti, _ = _touches(rng, 6000, g_true=g_true)
        prof = u_power_profile(OSET, x, u, ti, powers=(-0.3, 0.0, 0.3))
        assert min(prof, key=lambda g: prof[g][0]) == best and prof[0.0][0] == 0.0


def test_the_bin_gap_of_calibrated_answers_holds_zero_and_a_biased_bin_does_not():
    from _likelihood_form import bin_gap

    rng = np.random.default_rng(7)
    probe = np.repeat(np.arange(40), 50)
    conf = rng.uniform(0.3, 0.6, probe.size)
    fair = bin_gap(probe, conf, rng.random(probe.size) < conf)
    lo, hi = fair["interval_probes"]
    assert lo < 0.0 < hi and fair["n"] == int((conf < 0.5).sum())
    low = bin_gap(probe, conf, rng.random(probe.size) < conf - 0.15)
    assert low["interval_probes"][1] < 0.0 and abs(low["gap"] + 0.15) < 0.04
    assert bin_gap(probe, np.full(probe.size, 0.9), np.ones(probe.size, bool)) is None
