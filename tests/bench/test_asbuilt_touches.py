"""bench/_asbuilt_touches: a record cut to a shorter heating, and the cache of raw records, round-trip exactly."""

import numpy as np
import pytest

from edge.estimation.record import TouchRecord


@pytest.fixture(scope="module")
def A():
    import _asbuilt_touches  # bench/ is on the path: tests/bench/conftest.py

    return _asbuilt_touches


def _rec(dts=True):
    t = np.arange(-1.0, 2.0 + 1e-9, 0.05)
    kw = {"T_dt_s": np.full(t.size, 0.01), "q_dt_s": np.full(t.size, 0.02)} if dts else {}
    return TouchRecord(probe="paper", t_s=t, T_C=25 + np.clip(t, 0, None), q_W_m2=np.where(t > 0, 900.0, 0.0),
                       power_W=8.0, heater_on_s=2.0, sample_rate_Hz=20.0, baseline_s=1.0, **kw)


def test_a_cut_record_is_the_first_seconds_of_the_touch(A):
    r = _rec()
    c = A.truncated(r, 1.0)
    assert c.heater_on_s == 1.0 and c.t_s[-1] == pytest.approx(1.0) and c.T_dt_s.size == c.t_s.size
    np.testing.assert_array_equal(c.T_C, r.T_C[:c.t_s.size])
    assert A.truncated(r, 2.0) is r


def test_the_cache_round_trips_records_and_gaps(A, tmp_path):
    recs = [_rec(), None, _rec(dts=False)]
    meta = [{"name": "a"}, {"name": "b"}, {"name": "c"}]
    A.save_records(tmp_path / "c.npz", recs, meta, {"sim_s": 1.5})
    got, m, info = A.load_records(tmp_path / "c.npz")
    assert got[1] is None and m == meta and info == {"sim_s": 1.5}
    for a, b in ((recs[0], got[0]), (recs[2], got[2])):
        assert a.header() == b.header()
        np.testing.assert_array_equal(a.T_C, b.T_C)
    assert got[2].T_dt_s is None and got[0].q_dt_s is not None


def test_a_specimen_keeps_its_objects_e_and_alpha_within_the_spread(A):
    from edge.recognition import KnownObject
    o = KnownObject.from_properties("pmma", "polymer", 0.19, 1180, 1420, 0.05)
    rng = np.random.default_rng(0)
    sp = [A.specimen(o, rng) for _ in range(400)]
    ln_e = np.log([s.effusivity_W_s05_m2K / o.e_W_s05_m2K for s in sp])
    ln_a = np.log([s.alpha_m2_s / o.alpha_m2_s for s in sp])
    assert abs(ln_e.mean()) < 0.01 and 0.04 < ln_e.std() < 0.06 and 0.04 < ln_a.std() < 0.06


def test_the_bayes_rates_noise_is_the_simulated_scenes(A):
    """The attainable u is computed with the noise the simulated touches carry, read from their scene."""
    import math

    from edge.hw.chips import TYPE_K_SEEBECK_V_per_K

    sT, sq, dt = A.scene_noise("paper", "precision")
    sc = A.hand_scene("paper", A.Solid(k_W_mK=0.2, rho_kg_m3=1190.0, c_J_kgK=1470.0), None, 0, rc_m2K_W=0.0,
                      offset_K=0.0, lead_s=0.0, heat_s=1.0)
    v = sc.sensors.ads122c04_noise_rms_V
    assert v > 0 and sT == pytest.approx(v / TYPE_K_SEEBECK_V_per_K, rel=1e-3)   # the 24-bit step is negligible
    assert sq == pytest.approx(v / sc.sensors.flux_sensitivity_V_per_W_m2, rel=1e-3) and dt == pytest.approx(0.02)
    rT, rq, rdt = A.scene_noise("paper", "reference")
    # The reference board: the MCP9600's 16-bit step and the ADS1115's 14 W/m^2 step dominate, at 12.5 Hz.
    assert rT > 10 * sT and rq > 10 * sq and rdt == pytest.approx(0.08)
    assert rT > 0.197 / math.sqrt(12.0)
