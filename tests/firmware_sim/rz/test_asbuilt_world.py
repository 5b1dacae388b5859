"""The faithful world reads the probe as built: square footprint, thermocouple radius, substrate, leads."""

from __future__ import annotations

import numpy as np
import pytest

from firmware_sim.clock import VirtualClock
from firmware_sim.rz.configs import geometry_for_probe
from firmware_sim.rz.footprint import SquareSensor
from firmware_sim.rz.probe_world import AsBuilt, FaithfulWorld
from firmware_sim.scene.files import read_scene
from firmware_sim.world import ScheduleDrive

pytestmark = pytest.mark.slow  # faithful-world simulations of as-built probes, a second or more each

T = np.array([1.0, 1.5, 2.5])   # heating from 0.5 s (the scenes' touch starts at 0.5 s)
DT = 0.04


def run(scene: str, probe: str, ab: AsBuilt = AsBuilt(), **geo) -> tuple[FaithfulWorld, dict]:
    clk = VirtualClock()
    clk.advance(3.0)
    w = FaithfulWorld(read_scene(scene), clk, ScheduleDrive([0.5, 2.5], [1.0, 0.0]), as_built=ab,
                      geometry=geometry_for_probe(probe, **geo), dt_s=DT)
    return w, w.series(T)


@pytest.fixture(scope="module")
def small():
    return run("glass_15V_small", "small-heater")[1]


def test_centred_square_on_the_paper_probes_uniform_flux_reads_as_its_disk():
    """The paper probe's sensor lies in the heater's uniform flux: square and equal-area disk agree."""
    _, disk = run("glass_15V", "paper")
    _, square = run("glass_15V", "paper", AsBuilt(sensor=SquareSensor()))
    np.testing.assert_allclose(square["q_sensor"], disk["q_sensor"], rtol=1e-9)
    np.testing.assert_allclose(square["T_tc"], disk["T_tc"], rtol=1e-12)   # radial faces differ, nothing else


def test_small_heater_reads_its_square_not_the_disk(small):
    _, disk = run("glass_15V_small", "small-heater", sensor_square=None)
    # The square's corners reach 7.1 mm, past the disk's 5.6-mm rim, where the edge's spread is weaker.
    ratio = small["q_sensor"] / disk["q_sensor"]
    assert np.all(ratio < 0.995) and np.all(ratio > 0.95), ratio


def test_the_sensitivity_map_and_offset_obey_the_fields_symmetry(small):
    # A gradient across a centred square weights +x and -x alike: an axisymmetric field reads the same.
    _, grad = run("glass_15V_small", "small-heater", AsBuilt(sensor=SquareSensor(gradient_x=0.05)))
    np.testing.assert_allclose(grad["q_sensor"], small["q_sensor"], rtol=1e-12)
    # An offset along x or along y is the same footprint turned by 90 degrees about the axis.
    _, ox = run("glass_15V_small", "small-heater", AsBuilt(sensor=SquareSensor(offset_x_m=0.4e-3)))
    _, oy = run("glass_15V_small", "small-heater", AsBuilt(sensor=SquareSensor(offset_y_m=0.4e-3)))
    np.testing.assert_allclose(ox["q_sensor"], oy["q_sensor"], rtol=1e-12)
    # Off centre, part of the square leaves the heated disk: it reads ~1 % less per 0.4 mm.
    assert np.all(ox["q_sensor"] < 0.995 * small["q_sensor"])
    # With the offset, the gradient now matters: sensitivity higher on the far (cooler) side reads less.
    _, og = run("glass_15V_small", "small-heater", AsBuilt(sensor=SquareSensor(offset_x_m=0.4e-3, gradient_x=0.05)))
    assert np.all(og["q_sensor"] < ox["q_sensor"])


def test_thermocouple_off_the_axis_reads_the_profile_there(small):
    _, off = run("glass_15V_small", "small-heater", AsBuilt(thermocouple_r_m=2.0e-3))
    rise_axis, rise_off = small["T_tc"] - 25.0, off["T_tc"] - 25.0
    # 2 mm off the axis of a 5-mm heater: the rise is lower, more so as the edge's deficit spreads in.
    assert np.all(rise_off < rise_axis) and np.all(rise_off > 0.9 * rise_axis)
    assert (rise_off / rise_axis)[-1] < (rise_off / rise_axis)[0]


def test_lead_resistance_takes_its_share_of_the_supply():
    w0, _ = run("glass_15V_small", "small-heater")
    r_lead = 50.0
    w1, _ = run("glass_15V_small", "small-heater", AsBuilt(heater_lead_resistance_ohm=r_lead))
    R = w0.R0
    assert w1.heater_power_W(1.0) / w0.heater_power_W(1.0) == pytest.approx(R * R / (R + r_lead) ** 2, rel=1e-12)
    led = w1.energy_ledger(2.5)
    assert abs(led["residual"]) < 1e-8 * led["e_in"]


def test_a_denser_more_conducting_foam_takes_more_of_the_small_heaters_heat(small):
    denser = AsBuilt(substrate_k_W_mK=0.036, substrate_rho_c_J_m3K=40 * 1400 * 1.15)
    _, foam = run("glass_15V_small", "small-heater", denser)
    assert np.all(foam["q_sensor"] < 0.995 * small["q_sensor"])
    _, thin = run("glass_15V_small", "small-heater", AsBuilt(substrate_thickness_m=0.029))
    # 1 mm less foam changes nothing a 2-s touch sees (the heat does not reach its top).
    np.testing.assert_allclose(thin["q_sensor"], small["q_sensor"], rtol=1e-4)


#: The paper probe's shipped as-built scenes before the as-built world (commit 2f8bbf6, same march):
#: thermocouple (y), thermopile flux and heater power at 1.0, 2.0, 3.5 s; heating 1.5-3.5 s.
BEFORE = {
    "glass_15V_faithful": ([23.99705290247362, 24.022119476910593, 24.563587355364998],
                           [348.29945369804045, 796.2921742560575, 1076.616023264185], 4.4114909950903956),
    "alu_20V_faithful": ([23.174181762410804, 23.191950160722023, 23.41603548293803],
                         [649.2596554899355, 1584.933718358865, 2278.4327772631077], 8.162464131197348),
}


@pytest.mark.parametrize("name", sorted(BEFORE))
def test_the_paper_probes_shipped_scenes_are_unchanged(name):
    """Scenes that ask for nothing new (the paper probe reads its disk, no new keys) march as before."""
    clk = VirtualClock()
    clk.advance(4.0)
    w = FaithfulWorld.for_scene(read_scene(name), clk, ScheduleDrive([1.5, 3.5], [1.0, 0.0]), dt_s=0.04)
    s = w.series(np.array([1.0, 2.0, 3.5]))
    y, q, p = BEFORE[name]
    np.testing.assert_allclose(s["y"], y, rtol=1e-12)
    np.testing.assert_allclose(s["q_sensor"], q, rtol=1e-12)
    assert w.heater_power_W(2.0) == pytest.approx(p, rel=1e-12)


def test_a_junction_above_the_face_reads_the_layers_gradient():
    from edge.physics.probe import PROBE_MATERIAL
    _, face = run("glass_15V", "paper")
    k = PROBE_MATERIAL.k_W_mK
    for h, lo, hi in ((5e-6, 1 - 1e-9, 1 + 1e-9), (100e-6, 1.0, 1.25)):
        _, up = run("glass_15V", "paper", AsBuilt(thermocouple_height_m=h))
        ratio = (up["T_tc"] - face["T_tc"]) / (face["q_face"] * h / k)
        # Inside the last cell: exactly the face's gradient q / k.  Higher up: steeper while the layer
        # still stores heat (the flux grows towards the heater), relaxing to q / k as it settles.
        assert np.all((ratio >= lo) & (ratio <= hi)), (h, ratio)
        if h > 50e-6:
            assert np.all(np.diff(ratio) < 0), ratio
    with pytest.raises(ValueError, match="inside the sensing layer"):
        run("glass_15V", "paper", AsBuilt(thermocouple_height_m=0.5e-3))
