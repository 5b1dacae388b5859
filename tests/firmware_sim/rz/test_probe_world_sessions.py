"""FaithfulWorld sessions and probes: touch after touch, and the small-heater geometry.

References: the same session with its touches placed by hand after the fact
(the live, provisional march must agree with it), the energy ledger, the
electrical power ``V^2 / R`` over the small film, and the exact 1-D
ThermalWorld in the large-heater limit.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from edge.physics.geometry import PROBES
from firmware_sim.clock import VirtualClock
from firmware_sim.rz.grid import Mesh
from firmware_sim.rz.probe_world import FaithfulWorld, geometry_for_probe
from firmware_sim.scene.files import read_scene
from firmware_sim.simulator import load_scene
from firmware_sim.world import REPEAT_RELEASE_S, ManualDrive, ScheduleDrive, ThermalWorld

pytestmark = pytest.mark.slow

DT = 0.02    # coarse steps keep each test well under 3 s; the physics checked here does not need finer
TICK = 0.01
#: Heatings of the session (on, off): one in the scene's touch, one in the first repeat touch.
HEAT = ((0.3, 1.0), (2.3, 3.0))


def repeat_scene(name="glass_15V"):
    sc = read_scene(name)
    return dataclasses.replace(sc, touch=dataclasses.replace(sc.touch, start_s=0.2, length_s=1.2, repeat=True,
                                                             repeat_gap_s=0.6))


def live_session(sc, t_end=3.6):
    """Read the world at "now" every tick while a drive learns the heater commands as they happen."""
    clk, drive = VirtualClock(), ManualDrive()
    w = FaithfulWorld(sc, clk, drive, dt_s=DT)
    edges = {round(t, 9): d for on, off in HEAT for t, d in ((on, 1.0), (off, 0.0))}
    got = []
    for _ in range(int(round(t_end / TICK))):
        now = clk.advance(TICK)
        if round(now, 9) in edges:
            drive.set(now, edges[round(now, 9)])
        got.append((now, w.thermocouple_C(now), w.flux_voltage_V(now)))
    return w, drive, np.array(got)


def test_touch_after_touch_carries_the_probes_heat_through_the_air_gap():
    sc = repeat_scene()
    w, drive, got = live_session(sc)
    # The scene's touch, the repeat touch closed REPEAT_RELEASE_S after its heating, the next one open.
    (a1, b1), (a2, b2), (a3, b3) = w.touches
    assert (a1, b1) == (0.2, 1.4)
    assert a2 == pytest.approx(b1 + 0.6) and b2 == pytest.approx(HEAT[1][1] + REPEAT_RELEASE_S)
    assert a3 == pytest.approx(b2 + 0.6) and b3 > 1e5

    # The same record computed after the fact, with the touches placed by hand: the live march
    # (provisional steps, the open touch closed by the heating) must agree with it.
    clk = VirtualClock()
    ref = FaithfulWorld(dataclasses.replace(sc, touch=dataclasses.replace(sc.touch, repeat=False)), clk,
                        ScheduleDrive(drive.change_times(), [drive.duty_at(t) for t in drive.change_times()]),
                        dt_s=DT)
    ref.add_touch(a2, b2 - a2)
    ref.add_touch(a3, 10.0)
    clk.advance(10.0)
    np.testing.assert_allclose(got[:, 1], ref.truth(got[:, 0]).thermocouple_C, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got[:, 2], [ref.flux_voltage_V(x) for x in got[:, 0]], rtol=0, atol=1e-15)

    # In the air gap the probe drifts back: it loses heat to the air (ledger) and the film cools.
    gap = np.linspace(b1 + 0.05, a2 - 0.02, 8)
    s = w.series(gap)
    assert np.all(np.diff(s["e_stored"]) < 0) and np.all(np.diff(s["e_lost"]) > 0)
    assert np.all(np.diff(s["T_heater"]) < 0) and np.all(s["T_heater"] > 25.0)
    # The second touch starts from the first's residual heat: the probe is still warm when it lands
    # and pushes heat into the fresh spot before its heater goes on; the first touch started cold.
    before1, before2 = HEAT[0][0] - 0.02, HEAT[1][0] - 0.02
    T_land = w.series([a2 - 1e-3])["T_tc"][0]
    assert T_land > 25.3
    q1, q2 = (w.thermopile_W_m2(x) for x in (before1, before2))
    assert abs(q1) < 1.0 and q2 > 50.0
    led = w.energy_ledger(3.6)
    assert abs(led["residual"]) < 1e-8 * led["e_in"]


def test_touches_placed_by_hand_take_over_from_touch_after_touch():
    sc = repeat_scene()
    clk = VirtualClock()
    w = FaithfulWorld(sc, clk, ManualDrive(), dt_s=DT)
    assert len(w.touches) == 2           # the scene's and the open repeat touch
    w.add_touch(5.0, 1.0, contact_resistance_m2K_W=1e-3, object_temperature_C=30.0)
    assert w.touches == ((0.2, 1.4), (5.0, 6.0))
    assert w.touch_specs[1].object_temperature_C == 30.0
    w.repeat_touches()
    assert len(w.touches) == 3 and w.touches[2][0] == pytest.approx(6.0 + sc.touch.repeat_gap_s)


def test_a_sim_session_on_a_faithful_scene_repeats_touches():
    sim = load_scene("glass_15V_faithful")
    sim.repeat_touches()
    (_, b1), (a2, b2) = sim.world.touches
    assert a2 == pytest.approx(b1 + sim.scene.touch.repeat_gap_s) and b2 > 1e5
    sim.close()


# ----------------------------------------------------------------------------------------------
# The small-heater probe


def small_scene(name="glass_15V_small"):
    return read_scene(name)


def test_small_heater_energy_closes_and_the_film_dissipates_V2_over_R():
    sc = small_scene()
    clk = VirtualClock()
    on, off = 0.5, 2.0
    # 80-ms steps: what is asserted is exact at any step (the ledger books each step's own quadrature, the
    # power and its density are the drive's), so the module's DT would only quadruple the march.
    w = FaithfulWorld.for_scene(sc, clk, ScheduleDrive([on, off], [1.0, 0.0]), dt_s=0.08)
    clk.advance(3.0)
    P = sc.heater.supply_voltage_V ** 2 / sc.heater.resistance_ohm
    assert w.heater_power_W(1.0) == pytest.approx(P, rel=1e-12)
    for t in (0.4, 1.0, 2.0, 2.5, 3.0):   # in air before the touch, heating, switch-off, cooling, the lift
        led = w.energy_ledger(t)
        assert abs(led["residual"]) < 1e-8 * P * (off - on), (t, led)
    assert led["e_in"] == pytest.approx(P * (off - on), rel=1e-9)
    # All of it went into the small film: the power density is P over the probe's own film.
    probe = PROBES["small-heater"]
    assert w.q_v_at(1.0) == pytest.approx(P / probe.heater_volume_m3, rel=1e-12)
    sched = w.power_schedule(3.0)
    assert sched.energy_density(3.0) * probe.heater_volume_m3 == pytest.approx(P * (off - on), rel=1e-12)


def test_small_heater_edge_reaches_the_axis_of_a_metal_but_not_of_glass():
    # Same areal power as the paper heater, same object. The 5-mm disk's edge reaches the axis
    # only where the diffusion length sqrt(alpha t) approaches it: ~1 mm in glass after 2 s (the
    # axis cannot tell the heaters apart), ~10 mm in aluminium (the rise falls far behind: the
    # length scale that makes k and alpha identifiable). The 10 x 10 mm thermopile overhangs the
    # disk: it reads the heated fraction of its area, pi (5 mm)^2 / (10 mm)^2 -- to 1.2 % on glass
    # through its real square, whose corners lie farther out than the equal-area disk's rim and
    # catch less of the heat the sensing layer spreads past the heater's edge.
    probe = PROBES["small-heater"]
    frac = probe.heater_area_m2 / probe.sensor_area_m2
    t = np.array([0.7, 1.0, 1.5, 2.0])   # heating from 0.5 s
    ratios = {}
    for name in ("glass_15V", "alu_20V"):
        clk = VirtualClock()
        drive = ScheduleDrive([0.5, 2.5], [1.0, 0.0])
        # 40-ms steps: both probes march alike, and the ratios below are far from their bounds.
        small = FaithfulWorld.for_scene(read_scene(f"{name}_small"), clk, drive, dt_s=2 * DT)
        paper = FaithfulWorld.for_scene(read_scene(name), clk, drive, dt_s=2 * DT)
        clk.advance(2.0)
        s, p = small.series(t), paper.series(t)
        ratios[name] = (s["T_tc"] - 25.0) / (p["T_tc"] - 25.0), s["q_sensor"] / p["q_sensor"]
    T_glass, q_glass = ratios["glass_15V"]
    T_alu, q_alu = ratios["alu_20V"]
    np.testing.assert_allclose(T_glass, 1.0, atol=1e-3)
    np.testing.assert_allclose(q_glass, frac, rtol=0.015)
    assert np.all(np.diff(q_glass) < 0)   # the spread past the edge grows with time: less of it reaches the corners
    assert np.all(np.diff(T_alu) < 0) and T_alu[-1] < 0.7, T_alu
    np.testing.assert_allclose(q_alu, frac, rtol=0.02)


def test_small_heater_large_heater_limit_matches_the_1d_world():
    # The small-heater probe's geometry with its heater widened to 100 mm (same areal power, no
    # foam, no convection, a wide object) is the 1-D stack again: it must match the exact 1-D
    # ThermalWorld within the tolerance of the paper probe's 1-D limit (test_probe_world.py).
    sc = read_scene("glass_15V")
    wide = PROBES["small-heater"].with_heater_radius(0.1)
    geo = geometry_for_probe(wide, substrate=None, h_air_W_m2K=0.0, object_radius_m=0.15,
                             mesh=Mesh(max_dr_m=0.01))
    assert geo.heater_area_m2 == pytest.approx(math.pi * 0.01)
    ts = sc.touch.start_s
    drive = ScheduleDrive([ts, ts + 2.0], [1.0, 0.0])
    clk = VirtualClock()
    t = ts + np.linspace(0.02, 2.0, 60)
    ref = ThermalWorld(sc, clk, drive)
    lim = FaithfulWorld(sc, clk, drive, geometry=geo)
    clk.advance(10.0)
    r, f = ref.truth(t), lim.truth(t)
    # Both are linear in the heater's areal power: compare at the same areal power.
    scale = geo.heater_area_m2 / sc.stack.heater_area_m2
    dT_ref = r.thermocouple_C - 25.0
    assert np.max(np.abs((f.thermocouple_C - 25.0) * scale - dT_ref)) < 5e-3 * dT_ref.max()
    assert np.max(np.abs(f.q_f_W_m2 * scale - r.q_f_W_m2)) < 5e-3 * r.q_f_W_m2.max()
