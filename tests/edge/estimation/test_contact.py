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


def _heated(e_under, *, seed=0, q_W_m2=800.0, t0=-3.0, t1=2.0):
    """A probe whose heater goes on at 0 over what lies under it (effusivity ``e_under``), no step before.

    The face's rise under a constant flux into a half-space: 2 q sqrt(t) / (e sqrt(pi)).
    """
    rng = np.random.default_rng(seed)
    t = np.arange(t0, t1 + 1e-9, DT)
    on = np.clip(t, 0.0, None)
    T = 25.0 + 2.0 * q_W_m2 * np.sqrt(on) / (e_under * np.sqrt(np.pi))
    q = np.where(t > 0, q_W_m2, 0.0)
    return t, T + 0.01 * rng.standard_normal(t.size), q + 0.5 * rng.standard_normal(t.size)


def test_how_the_contact_was_found_is_said():
    t, T, q = _record(-1.5, -1.0, -300.0)
    assert find_contact(t, T, q).how == "temperature"
    t, T, q = _record(-1.5, 0.0, 40.0)
    assert find_contact(t, T, q).how == "flux"


def test_no_step_a_touching_probe_is_found_by_the_heaters_response():
    # Object at the probe's temperature (ISSUE #37's copper case): nothing steps; the heater heats a solid.
    for e in (40.0, 600.0, 30000.0):
        c = find_contact(*_heated(e, q_W_m2=800.0 if e < 1e4 else 20000.0))
        assert c.how == "heater_response" and not c.detected and c.recorded_in_air
        assert c.t_s == pytest.approx(0.0, abs=DT)


def test_no_step_a_probe_in_air_is_refused():
    # Still air (e 5.5): the heater's flux is not a touching probe's -- no contact, said clearly.
    c = find_contact(*_heated(5.5, q_W_m2=20.0))
    assert c.how == "none" and not c.detected


def test_the_users_trigger_sets_the_origin_when_nothing_steps():
    t, T, q = _heated(600.0)
    c = find_contact(t, T, q, trigger_t_s=-1.2)
    assert c.how == "trigger" and c.detected
    assert -1.2 - DT - 1e-9 <= c.t_s <= -1.2 + 1e-9
    # A trigger after heater-on or before the record is not a contact instant: the heater's response decides.
    assert find_contact(t, T, q, trigger_t_s=0.5).how == "heater_response"
    assert find_contact(t, T, q, trigger_t_s=-10.0).how == "heater_response"
    # A step wins over the trigger.
    t, T, q = _record(-1.5, -1.0, -300.0)
    assert find_contact(t, T, q, trigger_t_s=-2.5).how == "temperature"
