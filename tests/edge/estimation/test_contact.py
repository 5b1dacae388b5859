"""edge.estimation.contact: the contact instant from a record that starts in air."""

from __future__ import annotations

import numpy as np
import pytest

from edge.estimation.contact import find_contact

DT = 0.05


def _record(t_contact, dT_contact, q_contact, *, drift_K_s=0.0, seed=0, t0=-3.0, t1=2.0):
    rng = np.random.default_rng(seed)
    t = np.arange(t0, t1 + 1e-9, DT)
    after = t > t_contact
    T = 25.0 + drift_K_s * (t - t0) + np.where(after, dT_contact * (1 - np.exp(-(t - t_contact) / 0.2)), 0.0)
    q = np.where(after, q_contact / np.sqrt(np.clip(t - t_contact, DT, None)), 0.0)
    q = q + np.where(t > 0, 800.0, 0.0)   # heater on at 0
    return t, T + 0.01 * rng.standard_normal(t.size), q + 0.5 * rng.standard_normal(t.size)


@pytest.mark.parametrize("dT,qc", [(-1.0, -300.0), (0.5, 150.0), (0.0, 40.0), (-0.2, -60.0)])
def test_a_step_in_flux_or_temperature_is_the_contact(dT, qc):
    t, T, q = _record(-1.5, dT, qc)
    c = find_contact(t, T, q)
    assert c.detected and c.recorded_in_air
    # The origin is the last sample in air: within one sample before the true instant.
    assert -1.5 - DT - 1e-9 <= c.t_s <= -1.5 + 1e-9
    assert 0.005 < c.noise_T_K < 0.02 and 0.3 < c.noise_q_W_m2 < 0.8


def test_an_object_at_the_probes_temperature_gives_heater_on_as_origin():
    t, T, q = _record(-1.5, 0.0, 0.0)
    c = find_contact(t, T, q)
    assert not c.detected and c.recorded_in_air
    assert c.t_s == pytest.approx(0.0, abs=1e-9)


def test_a_probe_cooling_in_air_is_not_a_touch():
    # 0.05 K/s of drift (a probe just lifted off a warm object) over 3 s: 0.15 K, above the floor.
    t, T, q = _record(10.0, 0.0, 0.0, drift_K_s=-0.05)
    assert not find_contact(t, T, q).detected


def test_a_record_that_starts_in_contact_says_so():
    t, T, q = _record(-5.0, -1.0, -300.0)
    c = find_contact(t, T, q)
    assert not c.recorded_in_air and not c.detected
    t2 = np.arange(0.0, 2.0, DT)
    c2 = find_contact(t2, np.full(t2.size, 25.0), np.full(t2.size, 800.0))
    assert not c2.recorded_in_air and c2.index == 0


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="1-D"):
        find_contact(np.zeros(5), np.zeros(4), np.zeros(5))


def test_a_coarse_converters_lsb_flips_are_not_a_touch_but_a_real_contact_is():
    # The reference board: 0.0625 K thermocouple steps, 14 W/m^2 flux steps, noise below one step.
    t, T, q = _record(-1.5, -1.0, -300.0)
    Tq, qq = np.floor(T / 0.0625) * 0.0625, np.round(q / 14.0) * 14.0
    c = find_contact(t, Tq, qq)
    assert c.detected and -1.5 - DT - 1e-9 <= c.t_s <= -1.5 + 1e-9
    t, T, q = _record(10.0, 0.0, 0.0)
    assert not find_contact(t, np.floor((T + 0.03) / 0.0625) * 0.0625, np.round(q / 14.0) * 14.0).detected
