"""The thermal world: exact physics, phases, faults and what the chips see."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from edge.physics import forward, typek
from edge.physics.solids import Solid
from firmware_sim.clock import VirtualClock
from firmware_sim.scene.files import read_scene
from firmware_sim.scene.model import Fault
from firmware_sim.wiring import pin_value
from firmware_sim.world import AIR, OPEN_TC_INPUT_V, ScheduleDrive, ThermalWorld


def world(scene, drive=None, now=20.0):
    clock = VirtualClock()
    clock.advance(now)  # the whole record is in the past (cacheable)
    return ThermalWorld(scene, clock, drive)


def touch_step(scene, duration=2.0, duty=1.0):
    ts = scene.touch.start_s
    return ScheduleDrive([ts, ts + duration], [duty, 0.0])


@pytest.mark.parametrize("name", ["glass_12V", "pmma_20V", "alu_15V"])
def test_touch_matches_edge_forward_exact(name):
    sc = read_scene(name)
    w = world(sc, touch_step(sc))
    ts = sc.touch.start_s
    t = np.linspace(0.005, 2.0, 60)
    tr = w.truth(ts + t)
    ref = forward.simulate(sc.object.solid, sc.q_v_W_m3(), 2.0, t_s=t, thickness_m=sc.object.thickness_m,
                           back=sc.object.back, scheme="exact", stack=sc.stack)
    T0 = sc.environment.initial_temperature_C
    np.testing.assert_allclose(tr.surface_C - T0, ref.T_f_K, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(tr.thermocouple_C, tr.surface_C)  # tau = 0 in the paper scenes
    np.testing.assert_allclose(tr.q_f_W_m2, ref.q_f_W_m2, rtol=1e-8, atol=1e-9)
    assert tr.contact.all()
    # ... and the grid model agrees to its own accuracy (a different method).
    grid = forward.simulate(sc.object.solid, sc.q_v_W_m3(), 2.0, t_s=t, thickness_m=sc.object.thickness_m,
                            back=sc.object.back, stack=sc.stack)
    assert np.max(np.abs(grid.T_f_K - (tr.surface_C - T0))) < 2e-3 * ref.T_f_K.max()


@pytest.mark.parametrize("back, thickness, rc", [("fixed", 0.004, 0.0), ("infinite", None, 0.0),
                                                 ("insulated", 0.003, 5e-4)])
def test_thickness_back_and_contact_resistance_follow_the_scene(back, thickness, rc):
    sc = read_scene("pmma_15V")
    sc = dataclasses.replace(sc, object=dataclasses.replace(sc.object, back=back, thickness_m=thickness),
                             contact_resistance_m2K_W=rc)
    w = world(sc, touch_step(sc))
    t = np.linspace(0.01, 2.0, 30)
    tr = w.truth(sc.touch.start_s + t)
    ref = forward.simulate(sc.object.solid, sc.q_v_W_m3(), 2.0, t_s=t, thickness_m=thickness, back=back,
                           scheme="exact", stack=sc.stack, contact_resistance_m2K_W=rc)
    np.testing.assert_allclose(tr.surface_C - 25.0, ref.T_f_K, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(tr.q_f_W_m2, ref.q_f_W_m2, rtol=1e-8, atol=1e-9)


def test_pwm_duty_and_supply_scale_linearly():
    sc = read_scene("glass_15V")
    full = world(sc, touch_step(sc, duty=1.0)).truth([1.5, 2.0])
    half = world(sc, touch_step(sc, duty=0.5)).truth([1.5, 2.0])
    np.testing.assert_allclose(half.surface_C - 25.0, 0.5 * (full.surface_C - 25.0), rtol=1e-12)
    sag = dataclasses.replace(sc, faults=(Fault("supply_sag", 0.0, None, {"factor": 0.5}),))
    sagged = world(sag, touch_step(sag)).truth([1.5, 2.0])
    np.testing.assert_allclose(sagged.q_f_W_m2, 0.25 * full.q_f_W_m2, rtol=1e-12)


def test_stepped_power_is_superposed():
    sc = read_scene("pmma_15V")
    ts = sc.touch.start_s
    w = world(sc, ScheduleDrive([ts, ts + 0.7, ts + 1.3], [1.0, 0.4, 0.0]))
    t = np.linspace(0.01, 2.0, 40)
    tr = w.truth(ts + t)
    q = sc.q_v_W_m3()
    ref = forward.simulate(sc.object.solid, [q, 0.4 * q, 0.0], 2.0, q_v_times_s=[0.0, 0.7, 1.3], t_s=t,
                           thickness_m=sc.object.thickness_m, back=sc.object.back, scheme="exact", stack=sc.stack)
    np.testing.assert_allclose(tr.surface_C - 25.0, ref.T_f_K, rtol=1e-9, atol=1e-12)
    sched = w.power_schedule(ts + 2.0)
    np.testing.assert_allclose(sched.t_start_s, [0.0, ts, ts + 0.7, ts + 1.3])
    np.testing.assert_allclose(sched.q_v_W_m3, [0.0, q, 0.4 * q, 0.0])


def test_probe_in_air_before_the_touch_and_heater_off_is_ambient():
    sc = read_scene("glass_15V")
    sc = dataclasses.replace(sc, environment=dataclasses.replace(sc.environment, ambient_temperature_C=21.0,
                                                                 initial_temperature_C=21.0))
    w = world(sc, None)
    for t in (0.0, 0.2, 0.49, 1.0, 5.0):
        st = w.state(t)
        assert st.surface_C == 21.0 and st.thermocouple_C == 21.0 and st.q_f_W_m2 == 0.0
    assert not w.state(0.49).contact and w.state(0.5).contact and not w.state(3.0).contact


def test_heating_in_air_conserves_energy_and_carries_into_the_touch():
    sc = read_scene("pmma_15V")  # touch 0.5..3.0
    q = sc.q_v_W_m3()
    w = world(sc, ScheduleDrive([0.1, 0.4], [1.0, 0.0]))  # 0.3 s of heating in air
    stack = sc.stack
    e_in = q * stack.heater_thickness_m * 0.3                     # J/m^2 released
    rho_c_L = stack.material.rho_c_J_m3K * stack.total_thickness_m
    before = w.state(0.5 - 1e-9)
    # Still air takes almost nothing: the probe's mean excess is ~ e_in / (rho c L).
    assert before.q_f_W_m2 < 0.01 * q * stack.heater_thickness_m
    t_mean, y = w._start_state(w.phases(), 1)
    assert t_mean - 25.0 == pytest.approx(e_in / rho_c_L, rel=0.02)
    assert y == pytest.approx(before.thermocouple_C, abs=1e-6)
    assert y < t_mean  # heated from the top: the bottom lags the mean
    # On contact the warm probe gives its heat to the PMMA: flux positive, surface cools.
    on = w.truth([0.5 + 1e-3, 0.6, 1.5, 2.9])
    assert np.all(on.q_f_W_m2 > 0)
    assert np.all(np.diff(on.surface_C) < 0)
    assert 25.0 < on.surface_C[-1] < t_mean


def test_contact_of_different_temperatures_starts_at_the_effusivity_mean():
    sc = read_scene("glass_15V")
    sc = dataclasses.replace(sc, environment=dataclasses.replace(sc.environment, ambient_temperature_C=30.0,
                                                                 initial_temperature_C=20.0))
    w = world(sc, None)
    e_p = sc.stack.material.effusivity_W_s05_m2K
    e_o = sc.object.solid.effusivity_W_s05_m2K
    expect = (e_p * 30.0 + e_o * 20.0) / (e_p + e_o)
    assert w.state(0.5 + 1e-6).surface_C == pytest.approx(expect, abs=0.01)
    assert w.state(0.5).surface_C == pytest.approx(expect, abs=0.01)  # the instant of contact
    later = w.state(2.5).surface_C
    assert 20.0 < later < expect  # the probe's heat drains into the object


def test_thermocouple_lag_is_a_first_order_filter():
    sc = read_scene("pmma_20V")
    tau = 0.05
    sc = dataclasses.replace(sc, sensors=dataclasses.replace(sc.sensors, thermocouple_time_constant_s=tau))
    w = world(sc, touch_step(sc))
    ts = sc.touch.start_s
    dt = 2e-4
    tt = ts + np.arange(1, 5001) * dt
    T = w.truth(tt).surface_C - 25.0
    # tau y' + y = T, integrated exactly for piecewise-linear T between samples.
    y = np.zeros_like(T)
    a = math.exp(-dt / tau)
    prev_T = prev_y = 0.0
    for i, Ti in enumerate(T):
        m = (Ti - prev_T) / dt
        prev_y = Ti - m * tau + (prev_y - prev_T + m * tau) * a
        y[i] = prev_y
        prev_T = Ti
    check = tt[[500, 2000, 4999]]
    got = w.truth(check).thermocouple_C - 25.0
    np.testing.assert_allclose(got, y[[500, 2000, 4999]], rtol=2e-3)
    assert np.all(got < w.truth(check).surface_C - 25.0)  # lag: reads low while heating


def test_no_contact_fault_leaves_flux_near_zero_and_heats_the_probe():
    sc = read_scene("pmma_15V_no_contact")
    w = world(sc, touch_step(sc))
    ref = world(read_scene("pmma_15V"), touch_step(read_scene("pmma_15V")))
    t = sc.touch.start_s + np.array([0.5, 1.0, 2.0])
    air, touch = w.truth(t), ref.truth(t)
    assert not air.contact.any()
    assert np.all(np.abs(air.q_f_W_m2) < 0.02 * touch.q_f_W_m2)
    assert np.all(air.surface_C > touch.surface_C)
    q_heater = sc.heater.max_power_W / sc.stack.heater_area_m2
    assert abs(w.flux_voltage_V(t[-1])) < 0.02 * 0.56e-6 * q_heater


def test_heater_faults_override_the_drive():
    sc = read_scene("glass_15V")
    stuck = dataclasses.replace(sc, faults=(Fault("heater_stuck_on", 1.0, 1.5, {"duty": 1.0}),))
    w = world(stuck, None)
    assert w.heater_power_W(1.2) == pytest.approx(4.5) and w.heater_power_W(1.6) == 0.0
    assert w.state(1.5).surface_C > 25.1
    dead = dataclasses.replace(sc, faults=(Fault("heater_dead", 0.0, None, {}),))
    w = world(dead, touch_step(dead))
    assert w.heater_power_W(1.0) == 0.0 and w.state(2.0).surface_C == 25.0
    sag = dataclasses.replace(sc, faults=(Fault("supply_sag", 1.0, None, {"voltage_V": 12.0}),))
    w = world(sag, touch_step(sag))
    assert w.supply_voltage_at(0.9) == 15.0 and w.supply_voltage_at(1.0) == 12.0
    assert w.heater_power_W(1.2) == pytest.approx(12.0**2 / 50.0)


def test_flux_sensor_clips_to_its_range_and_saturation_fault():
    sc = read_scene("alu_25V")
    hot = dataclasses.replace(sc, heater=dataclasses.replace(sc.heater, supply_voltage_V=60.0))
    w = world(hot, touch_step(hot))
    t = hot.touch.start_s + 1.5
    assert w.state(t).q_f_W_m2 > 10_000.0
    assert w.flux_voltage_V(t) == pytest.approx(0.56e-6 * 10_000.0)
    sat = dataclasses.replace(sc, faults=(Fault("flux_saturation", 1.0, 1.2, {"voltage_V": 0.3}),))
    w = world(sat, touch_step(sat))
    assert w.flux_voltage_V(1.1) == 0.3
    assert w.flux_voltage_V(1.3) == pytest.approx(0.56e-6 * w.state(1.3).q_f_W_m2)
    assert pin_value(w, "ads1115", "AIN0_AIN1", 1.1) == 0.3 and pin_value(w, "ads1115", "AIN2_GND", 1.1) == 0.0


def test_thermocouple_emf_and_open_circuit():
    sc = read_scene("glass_18V")
    sc = dataclasses.replace(sc, faults=(Fault("open_thermocouple", 1.0, 1.5, {}),))
    w = world(sc, touch_step(sc))
    t = 2.0
    T = w.thermocouple_C(t)
    emf = (typek.emf_mV(T) - typek.emf_mV(25.0)) * 1e-3
    assert w.thermocouple_emf_V(t) == pytest.approx(emf, rel=1e-12)
    assert pin_value(w, "ads122c04", "AIN1_AIN0", t) == pytest.approx(-emf, rel=1e-12)
    assert pin_value(w, "ads122c04", "AIN2_AIN3", t) == pytest.approx(w.flux_voltage_V(t))
    assert w.thermocouple_open(1.2) and not w.thermocouple_open(1.5)
    assert w.thermocouple_emf_V(1.2) == OPEN_TC_INPUT_V


def test_past_values_are_cached_and_future_faults_only():
    sc = read_scene("glass_15V")
    clock = VirtualClock()
    w = ThermalWorld(sc, clock, touch_step(sc))
    clock.advance(1.0)
    a = w.state(0.9)
    assert w.state(0.9) is a              # cached: the past is fixed
    b = w.state(1.0)
    assert w.state(1.0) is not b          # "now" may still change
    with pytest.raises(ValueError, match="in the past"):
        w.add_fault(Fault("no_contact", 0.5, None, {}))
    w.add_fault(Fault("no_contact", 1.2, 1.4, {}))
    assert [(p.start_s, p.contact) for p in w.phases()] == [(0.0, False), (0.5, True), (1.2, False),
                                                             (1.4, True), (3.0, False)]
    with pytest.raises(ValueError, match="t_s"):
        w.state(-1.0)


def test_air_is_still_air():
    assert isinstance(AIR, Solid) and 0.02 < AIR.k_W_mK < 0.03 and 1.0 < AIR.rho_kg_m3 < 1.3


def test_a_second_touch_is_a_fresh_contact():
    sc = read_scene("glass_15V")  # first touch 0.5..3.0 without heating
    clock = VirtualClock()
    w = ThermalWorld(sc, clock, ScheduleDrive([10.0, 12.0], [1.0, 0.0]))
    with pytest.raises(ValueError, match="overlaps"):
        w.add_touch(2.0, 1.0)
    w.add_touch(10.0, 3.0)
    clock.advance(20.0)
    with pytest.raises(ValueError, match="past"):
        w.add_touch(15.0, 1.0)
    assert w.touches == ((0.5, 3.0), (10.0, 13.0))
    assert [p.contact for p in w.phases()] == [False, True, False, True, False]
    t = np.linspace(0.01, 2.0, 20)
    ref = forward.simulate(sc.object.solid, sc.q_v_W_m3(), 2.0, t_s=t, thickness_m=0.02, back="insulated",
                           scheme="exact", stack=sc.stack)
    np.testing.assert_allclose(w.truth(10.0 + t).surface_C - 25.0, ref.T_f_K, rtol=1e-9, atol=1e-12)
