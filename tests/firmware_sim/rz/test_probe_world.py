"""Verification of FaithfulWorld: the chips' world time-stepped on the (r, z) model.

Each test can fail: the references are the exact 1-D ThermalWorld (the
estimator's idealisation, built from a scene), lumped and analytic limits
(effusivity shunt, lumped cooling, first-order lag), the contact-resistance
jump and the energy ledger across configuration switches.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from edge.physics import typek
from edge.physics.probe import PROBE_MATERIAL
from firmware_sim.clock import VirtualClock
from firmware_sim.rz.grid import PU_FOAM, Mesh
from firmware_sim.rz.probe_world import AsBuilt, FaithfulWorld, Geometry
from firmware_sim.scene.model import Fault
from firmware_sim.scene.files import read_scene
from firmware_sim.wiring import pin_value
from firmware_sim.world import ManualDrive, ScheduleDrive, ThermalWorld

pytestmark = pytest.mark.slow

#: The 1-D limit: no foam, no convection, heater and object far wider than the 2-s diffusion length.
ONE_D = Geometry(substrate=None, h_air_W_m2K=0.0, heater_radius_m=0.1, object_radius_m=0.15,
                 mesh=Mesh(max_dr_m=0.01))


def clock_at(now: float = 100.0) -> VirtualClock:
    c = VirtualClock()
    c.advance(now)  # the whole record is in the past
    return c


def scene(name="glass_15V", *, T_obj=None, T_amb=None, touch=None, rc=None, tau=None):
    sc = read_scene(name)
    env = sc.environment
    sc = dataclasses.replace(sc, environment=dataclasses.replace(
        env, initial_temperature_C=env.initial_temperature_C if T_obj is None else T_obj,
        ambient_temperature_C=env.ambient_temperature_C if T_amb is None else T_amb))
    if touch is not None:
        sc = dataclasses.replace(sc, touch=dataclasses.replace(sc.touch, start_s=touch[0], length_s=touch[1]))
    if rc is not None:
        sc = dataclasses.replace(sc, contact_resistance_m2K_W=rc)
    if tau is not None:
        sc = dataclasses.replace(sc, sensors=dataclasses.replace(sc.sensors, thermocouple_time_constant_s=tau))
    return sc


def heat(t0: float, length: float = 2.0, duty: float = 1.0) -> ScheduleDrive:
    return ScheduleDrive([t0, t0 + length], [duty, 0.0])


@pytest.fixture(scope="module")
def heated():
    """``heated(name, geometry)``: the scene's probe heated for 2 s from its touch's start, all in the past.

    One world per (scene, geometry) for the module: several tests read the same touch
    (``FaithfulWorld(scene(name), clock_at(), heat(touch start), geometry=...)``). Reading
    only marches it on (fixed steps, nothing provisional with the clock at 100 s), so the
    values at a time do not depend on which test asked first.
    """
    worlds = {}

    def get(name: str = "glass_15V", geometry: Geometry | None = None) -> FaithfulWorld:
        key = (name, "default" if geometry is None else id(geometry))
        if key not in worlds:
            sc = scene(name)
            worlds[key] = FaithfulWorld(sc, clock_at(), heat(sc.touch.start_s),
                                        geometry=Geometry() if geometry is None else geometry)
        return worlds[key]

    return get


# ----------------------------------------------------------------------------------------------
# (1) The 1-D limit and the real probe against the exact 1-D ThermalWorld


@pytest.mark.parametrize("name", ["glass_15V", "pmma_15V"])
def test_matches_1d_thermal_world_within_the_foam_shunt(name, heated):
    sc = scene(name)
    ts = sc.touch.start_s
    drive = heat(ts)
    clk = clock_at()
    t = ts + np.linspace(0.02, 2.0, 100)
    ref = ThermalWorld(sc, clk, drive).truth(t)
    dT_ref = ref.surface_C - sc.environment.initial_temperature_C
    # The 1-D limit of the (r, z) world: same physics as ThermalWorld, different method.
    lim = heated(name, ONE_D).truth(t)   # = FaithfulWorld(sc, clk, drive, geometry=ONE_D)
    assert np.max(np.abs(lim.thermocouple_C - ref.thermocouple_C)) < 5e-3 * dT_ref.max()
    assert np.max(np.abs(lim.q_f_W_m2 - ref.q_f_W_m2)) < 5e-3 * ref.q_f_W_m2.max()
    # The real probe (ideal as built, R_c = 0, object at the probe's temperature, the default 50-mm
    # object: wide against the 2-s diffusion length, the deficits below are those of a 100-mm one to
    # 4 digits, and it is the shared world the thermopile test reads):
    # 32-mm heater disk under 30 mm of PU foam, h = 5 W/m^2K on its faces. At the axis the
    # finite heater is invisible in 2 s (diffusion length ~2 mm << 32 mm); the foam above the
    # film is not: it takes the share e_f / (e_f + e_p) of the heater's flux (effusivities of
    # foam and probe layer; the film sees the probe layer below it for ~L^2/alpha = 1.7 s),
    # which is the tolerance: T and q low by at most that share (+0.5 % numerics), and by at
    # least half of it (so the foam is really there).
    real = heated(name).truth(t)   # = FaithfulWorld(sc, clk, drive)
    shunt = PU_FOAM.effusivity_W_s05_m2K / (PU_FOAM.effusivity_W_s05_m2K + PROBE_MATERIAL.effusivity_W_s05_m2K)
    assert 0.055 < shunt < 0.06
    late = t - ts >= 0.5
    for got, want in ((real.thermocouple_C - sc.environment.initial_temperature_C, dT_ref),
                      (real.q_f_W_m2, ref.q_f_W_m2)):
        deficit = 1.0 - got[late] / want[late]
        assert np.all(deficit < shunt + 5e-3), deficit.max()
        assert np.all(deficit > 0.5 * shunt), deficit.min()


# ----------------------------------------------------------------------------------------------
# (2) The thermopile inside its layer reads more than the face flux


@pytest.mark.parametrize("name, lo, hi", [("glass_15V", 0.2, 0.6), ("pmma_15V", 0.4, 1.0)])
def test_thermopile_reads_more_than_the_face_flux(name, lo, hi, heated):
    sc = scene(name)
    ts = sc.touch.start_s
    w = heated(name)   # = FaithfulWorld(sc, clock_at(), heat(ts))
    t = ts + np.linspace(0.05, 2.0, 40)
    s = w.series(t)
    excess = s["q_sensor"] / s["q_face"] - 1.0
    # Heat stored in the sensing layer as it warms: the flux falls with depth, so the depth
    # average exceeds the face value, less and less as the layer's profile settles.
    assert np.all(excess > 0)
    assert np.all(np.diff(excess) < 0)
    second = t - ts >= 1.0  # the second half of the touch: the 20-100 %
    assert lo < excess[second].min() and excess[second].max() < hi, excess[second]
    # The device sees the true sensitivity times the thermopile's flux.
    ab = AsBuilt(flux_sensitivity_V_per_W_m2=0.5e-6)
    w2 = FaithfulWorld(sc, clock_at(), heat(ts), as_built=ab)
    assert w2.flux_voltage_V(ts + 1.5) == pytest.approx(0.5e-6 * w.thermopile_W_m2(ts + 1.5), rel=1e-12)
    assert pin_value(w2, "ads1115", "AIN0_AIN1", ts + 1.5) == w2.flux_voltage_V(ts + 1.5)


# ----------------------------------------------------------------------------------------------
# (3) Contact resistance


def test_contact_resistance_adds_its_jump(heated):
    rc = 1e-3
    ts = 0.5
    t = ts + np.array([0.5, 1.0, 2.0])
    # The shared glass_15V worlds are the R_c = 0 references (the scene's own R_c, heated from 0.5 s).
    assert scene().contact_resistance_m2K_W == 0.0 and scene().touch.start_s == ts
    s0 = heated().series(t)   # = FaithfulWorld(scene(rc=0.0), clock_at(), heat(ts))
    s1 = FaithfulWorld(scene(rc=rc), clock_at(), heat(ts)).series(t)
    # The interface carries the jump R_c q between the thermocouple (probe side) and the object's face.
    jump = s1["T_tc"] - s1["T_obj_face"]
    np.testing.assert_allclose(jump, rc * s1["q_face"], rtol=0.01)
    np.testing.assert_allclose(s0["T_tc"] - s0["T_obj_face"], 0.0, atol=1e-9)
    # The thermocouple-object difference grows by R_c q; the object's face itself is a little
    # cooler (the resistance holds heat back in the probe), so T_tc rises by less than R_c q.
    rise = s1["T_tc"] - s0["T_tc"]
    assert np.all((rise > 0.5 * rc * s1["q_face"]) & (rise < rc * s1["q_face"]))
    # ... exactly as in the exact 1-D solution with the same R_c (1-D limit of the world).
    drive, clk = heat(ts), clock_at()
    for r in (0.0, rc):
        ref = ThermalWorld(scene(rc=r), clk, drive).truth(t)
        lim = (heated("glass_15V", ONE_D) if r == 0.0 else FaithfulWorld(scene(rc=r), clk, drive, geometry=ONE_D)).truth(t)
        assert np.max(np.abs(lim.thermocouple_C - ref.thermocouple_C)) < 5e-3 * (ref.thermocouple_C[-1] - 25.0)


# ----------------------------------------------------------------------------------------------
# (4) A colder object: the contact transient


def test_colder_object_transient_lasts_seconds_before_heater_on():
    sc = scene(T_obj=22.0, touch=(1.0, 4.0))     # probe at 25 degC in air, object 3 K colder
    w = FaithfulWorld(sc, clock_at(), heat(3.0))  # heater on 2 s after contact
    before = np.array([0.5, 0.99])
    assert np.allclose(w.truth(before).thermocouple_C, 25.0) and not w.truth(before).contact.any()
    t = 1.0 + np.linspace(0.005, 1.995, 80)
    s = w.series(t)
    assert np.all(s["q_face"] > 0) and np.all(s["q_sensor"] > 0)   # heat flows probe -> object
    e_p, e_o = PROBE_MATERIAL.effusivity_W_s05_m2K, sc.object.solid.effusivity_W_s05_m2K
    T_c = (25.0 * e_p + 22.0 * e_o) / (e_p + e_o)
    assert abs(s["T_tc"][0] - T_c) < 0.02 * 3.0   # contact temperature of two half-spaces
    # Still visible at heater-on: the sensor reads >10 % of what the heater will push, and the
    # thermocouple is still falling.
    q_heater = sc.heater.max_power_W / sc.stack.heater_area_m2
    assert s["q_sensor"][-1] > 0.1 * q_heater
    assert s["T_tc"][-1] < T_c - 0.1 and np.all(np.diff(s["T_tc"][t >= 1.5]) < 0)
    # The flux voltage the device sees before heater-on is positive.
    assert w.flux_voltage_V(2.5) > 0


# ----------------------------------------------------------------------------------------------
# (5) The probe in air relaxes to ambient


def test_probe_in_air_relaxes_with_the_lumped_time_constant():
    # Without foam the probe is a thin lumped plate (Biot h L / k = 0.02): both faces and the rim
    # lose h (T - T_amb), so T - T_amb decays as exp(-t / tau), tau = C / (h A).
    # Steps of 0.5 s: tau is ~50 s, so TR-BDF2's error is ~(dt/tau)^2 / 12 ~ 1e-5 (the fitted tau
    # moves by 5e-6 from 0.1-s steps; its 1.6 % offset from the lumped value is the plate's own).
    h = 10.0
    sc = scene(touch=(1000.0, 1.0))
    geo = Geometry(substrate=None, h_air_W_m2K=h)
    w = FaithfulWorld(sc, clock_at(200.0), heat(0.0, 2.0), geometry=geo, dt_s=0.5)
    a = math.sqrt(sc.stack.heater_area_m2 / math.pi)
    L = sc.stack.total_thickness_m
    C = PROBE_MATERIAL.rho_c_J_m3K * math.pi * a * a * L
    tau = C / (h * (2 * math.pi * a * a + 2 * math.pi * a * L))
    t = np.linspace(10.0, 60.0, 11)
    dT = w.truth(t).thermocouple_C - 25.0
    assert np.all(dT > 0) and np.all(np.diff(dT) < 0)
    slope = np.polyfit(t, np.log(dT), 1)[0]
    assert -1.0 / slope == pytest.approx(tau, rel=0.02)
    # With the foam the film's heat also soaks upwards: the sensing layer cools faster at
    # first, then the warm foam holds it above the lumped curve; it still heads for ambient.
    wf = FaithfulWorld(sc, clock_at(200.0), heat(0.0, 2.0), geometry=Geometry(h_air_W_m2K=h), dt_s=0.5)
    dTf = wf.truth(t).thermocouple_C - 25.0
    assert np.all(dTf > 0) and np.all(np.diff(dTf) < 0)
    led = wf.energy_ledger(60.0)
    assert led["e_lost"] > 0.05 * led["e_in"]


# ----------------------------------------------------------------------------------------------
# (6) Heater TCR at constant voltage


def test_heater_tcr_lowers_the_power_as_it_warms(heated):
    alpha = 3.9e-3
    sc = scene()
    ts = sc.touch.start_s
    V, R0 = sc.heater.supply_voltage_V, sc.heater.resistance_ohm
    ideal = heated()   # = FaithfulWorld(sc, clock_at(), heat(ts))
    w = FaithfulWorld(sc, clock_at(), heat(ts), as_built=AsBuilt(heater_tcr_per_K=alpha, heater_reference_C=25.0))
    t = ts + np.array([0.2, 1.0, 1.99])
    P = np.array([w.heater_power_W(x) for x in t])
    dT_h = w.series(t)["T_heater"] - 25.0
    assert np.all(np.diff(P) < 0) and np.all(dT_h > 0.5)
    deficit = V * V / R0 - P
    np.testing.assert_allclose(deficit, V * V / R0 * alpha * dT_h, rtol=0.03)
    assert ideal.heater_power_W(t[-1]) == pytest.approx(V * V / R0, rel=1e-12)
    # Less power, less temperature rise: by less than the final power deficit (it grew from 0).
    r = 1.0 - (w.truth(t).thermocouple_C - 25.0) / (ideal.truth(t).thermocouple_C - 25.0)
    assert np.all((r > 0.2 * alpha * dT_h) & (r < alpha * dT_h)), (r, alpha * dT_h)
    # The schedule and the ledger carry the real power.
    led = w.energy_ledger(ts + 2.0)
    sched = w.power_schedule(ts + 2.0)
    assert led["e_in"] == pytest.approx(sched.energy_density(ts + 2.0) * sc.stack.heater_area_m2
                                        * sc.stack.heater_thickness_m, rel=1e-9)
    assert led["e_in"] < 2.0 * V * V / R0


# ----------------------------------------------------------------------------------------------
# (7) Thermocouple bead lag


def test_thermocouple_lag_is_first_order_with_the_true_tau():
    tau = 0.15
    sc = scene(T_obj=22.0, touch=(1.0, 3.0), tau=0.0)   # the scene (nominal) says tau = 0
    w = FaithfulWorld(sc, clock_at(), None, as_built=AsBuilt(thermocouple_time_constant_s=tau))
    # Contact with a 3 K colder object: the junction's true temperature steps to the contact
    # temperature within a millisecond and then barely moves; the reading follows exp(-t / tau).
    t = 1.0 + np.linspace(0.05, 0.6, 12)
    tr = w.truth(t)
    err = tr.thermocouple_C - tr.surface_C
    assert np.all(err > 0)
    slope = np.polyfit(t, np.log(err), 1)[0]
    assert -1.0 / slope == pytest.approx(tau, rel=0.05)
    # ... and it is the first-order filter of the true temperature (exact integration here).
    dt = 1e-4   # finer than the start-up sub-steps (dt/16) that resolve the contact jump
    tt = np.arange(0.9, 1.6, dt)
    T = w.truth(tt).surface_C
    y = np.empty_like(T)
    y[0] = T[0]
    a = math.exp(-dt / tau)
    for i in range(1, T.size):
        m = (T[i] - T[i - 1]) / dt
        y[i] = T[i] - m * tau + (y[i - 1] - T[i - 1] + m * tau) * a
    np.testing.assert_allclose(w.truth(tt).thermocouple_C, y, atol=2e-3)
    emf = (typek.emf_mV(w.thermocouple_C(1.1)) - typek.emf_mV(25.0)) * 1e-3
    assert w.thermocouple_emf_V(1.1) == pytest.approx(emf, rel=1e-12)


# ----------------------------------------------------------------------------------------------
# (8) Energy ledger across switches; several touches per session


def test_energy_ledger_closes_across_touches_lifts_and_gaps():
    sc = scene(T_obj=22.0, touch=(1.0, 1.5), rc=2e-4)
    clk = VirtualClock()
    drive = ScheduleDrive([0.2, 0.6, 1.5, 2.0, 4.2, 5.2], [1.0, 0.0, 0.5, 0.0, 1.0, 0.0])
    # 80-ms steps: the ledger closes to round-off at any step (each step books the scheme's own
    # quadrature of the heat in and lost, and steps end at every drive, touch and fault switch), so the
    # suite's 20 ms would only quadruple the march.
    w = FaithfulWorld(sc, clk, drive, dt_s=0.08)
    w.add_touch(4.0, 2.0, contact_resistance_m2K_W=1e-3, object_temperature_C=28.0)
    w.add_fault(Fault("no_contact", 4.5, 4.7, {}))
    clk.advance(8.0)
    assert [(p.start_s, p.touch is not None) for p in w.phases()] == [
        (0.0, False), (1.0, True), (2.5, False), (4.0, True), (4.5, False), (4.7, True), (6.0, False)]
    e_nominal = sc.heater.max_power_W * (0.4 + 0.5 * 0.5 + 1.0)
    for t in (0.7, 1.0, 2.4, 2.5, 4.5, 4.7, 5.5, 6.0, 8.0):
        led = w.energy_ledger(t)
        assert abs(led["residual"]) < 1e-8 * e_nominal, (t, led)
    assert led["e_in"] == pytest.approx(e_nominal, rel=1e-12)
    assert 0 < led["e_lost"] < led["e_in"]
    # The second touch has its own resistance and its (warmer) object: the probe is heated by it.
    assert w.series([4.4])["q_face"][0] < 0 < w.series([1.4])["q_face"][0]
    # After the gap the same object returns (it kept its heat): no new contact jump of its sign.
    assert w.contact_at(4.8) and not w.contact_at(4.6)


# ----------------------------------------------------------------------------------------------
# Drop-in: the clock, the drive changing "now", faults


def test_provisional_steps_follow_the_drive_and_faults():
    sc = scene()
    clk = VirtualClock()
    live = ManualDrive()  # only what has been commanded so far, like the board
    w = FaithfulWorld(sc, clk, live)
    got = []
    for k in range(1, 301):   # a device polling every 7 ms, switching at odd instants
        now = clk.advance(0.007)
        if abs(now - 0.803) < 0.0035:
            live.set(now, 1.0)
        if abs(now - 2.103) < 0.0035:
            live.set(now, 0.4)
        if abs(now - 1.5) < 0.0035:
            w.add_fault(Fault("supply_sag", now + 0.1, now + 0.3, {"factor": 0.8}))
        got.append((now, w.thermocouple_C(now), w.flux_voltage_V(now), w.thermocouple_C(now + 0.05)))
    got = np.array(got)
    # The same record computed after the fact, with everything known.
    ref = FaithfulWorld(dataclasses.replace(sc, faults=(w.faults[-1],)), clock_at(10.0),
                        ScheduleDrive(live.change_times(), [live.duty_at(t) for t in live.change_times()]))
    np.testing.assert_allclose(got[:, 1], ref.truth(got[:, 0]).thermocouple_C, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got[:, 2], [ref.flux_voltage_V(x) for x in got[:, 0]], rtol=0, atol=1e-15)
    assert ref.heater_power_W(1.7) == pytest.approx(0.64 * sc.heater.max_power_W)
    with pytest.raises(ValueError, match="past"):
        w.add_touch(1.0, 1.0)
    with pytest.raises(ValueError, match="overlaps"):
        w.add_touch(2.9, 1.0)


def test_drop_in_surface_matches_thermal_world():
    # Touch after touch (repeat_touches) included: test_probe_world_sessions.py.
    public = {n for n in dir(ThermalWorld) if not n.startswith("_")}
    assert public <= {n for n in dir(FaithfulWorld) if not n.startswith("_")}
    sc = scene()
    sat = dataclasses.replace(sc, faults=(Fault("flux_saturation", 1.0, 1.2, {"voltage_V": 0.3}),
                                         Fault("open_thermocouple", 2.0, 2.1, {})))
    w = FaithfulWorld(sat, clock_at(), heat(0.5))
    assert w.flux_voltage_V(1.1) == 0.3 and w.thermocouple_open(2.05) and not w.thermocouple_open(2.2)
    assert pin_value(w, "ads122c04", "AIN1_AIN0", 2.05) == -1.65
    assert pin_value(w, "ads122c04", "AIN3_AIN2", 1.5) == -w.flux_voltage_V(1.5)
    assert w.cold_junction_C(1.0) == 25.0 and w.state(1.0).contact and not w.state(3.0).contact
    with pytest.raises(ValueError, match="t_s"):
        w.state(-1.0)
