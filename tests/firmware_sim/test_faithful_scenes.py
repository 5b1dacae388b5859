"""Scenes that choose their world and probe: the new keys, their errors, the shipped faithful and
small-heater scenes (the unchanged daemon on each of them: tests/host/test_round_trip.py).

Keys: ``[board] world`` / ``probe``, ``[as_built]`` (never told to the device), and per-touch
``[touch] contact_resistance_m2K_W``, ``object_temperature_C`` / ``object_offset_K``,
``contact_lead_s``.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib

import numpy as np
import pytest

from edge.physics.geometry import PROBES
from firmware_sim.clock import VirtualClock
from firmware_sim.rz.probe_world import FaithfulWorld
from firmware_sim.run import config_for_scene
from firmware_sim.scene.files import SHIPPED_DIR, read_scene, scene_names
from firmware_sim.scene.model import AsBuiltSpec, SceneError
from firmware_sim.scene.parser import parse_scene
from firmware_sim.simulator import load_scene
from firmware_sim.world import ScheduleDrive, ThermalWorld
from tests.firmware_sim.test_scene import BASE, edit
from tests.support.daemons import assert_heater_safe, sim_daemon
from tests.support.faithful import DEVICE_DT_s, world_step

pytestmark = [pytest.mark.hil, pytest.mark.slow]

PAPER_NINE = ("glass_12V", "glass_15V", "glass_18V", "pmma_8V", "pmma_15V", "pmma_20V",
              "alu_15V", "alu_20V", "alu_25V")
FAITHFUL = ("glass_15V_faithful", "pmma_15V_faithful", "alu_20V_faithful")

FULL = edit(edit(BASE, "ads1115 = 0x48\n", 'ads1115 = 0x48\nworld = "faithful"\nprobe = "small-heater"\n'),
            "length_s = 2.0\n", """length_s = 3.0
contact_lead_s = 1.0
contact_resistance_m2K_W = 1e-4
object_offset_K = -1.5

[as_built]
sensing_thickness_factor = 1.03
sensing_k_factor = 0.97
flux_sensitivity_factor = 0.98
heater_resistance_factor = 1.02
thermocouple_time_constant_s = 0.02
heater_tcr_per_K = 1e-4
""")


# ----------------------------------------------------------------------------------------------
# Parsing


def test_defaults_are_the_ideal_world_on_the_paper_probe_built_as_nominal():
    s = parse_scene(BASE)
    assert (s.board.world, s.board.probe, s.as_built) == ("ideal", "paper", None)
    t = s.touch
    assert (t.contact_resistance_m2K_W, t.object_temperature_C, t.object_offset_K, t.contact_lead_s) == \
        (None, None, None, 0.0)
    # Without [touch] values the scene-wide ones hold; heating starts with the touch.
    assert s.touch_contact_resistance_m2K_W == 0.0 and s.object_temperature_C == 25.0
    assert t.heater_on_s == t.start_s


def test_new_keys_parse_and_resolve():
    s = parse_scene(FULL, source="full.toml")
    assert (s.board.world, s.board.probe) == ("faithful", "small-heater")
    assert s.as_built == AsBuiltSpec(1.03, 0.97, 0.98, 1.02, 0.02, 1e-4, 25.0)
    assert s.touch.contact_lead_s == 1.0 and s.touch.heater_on_s == 1.5
    assert s.touch_contact_resistance_m2K_W == 1e-4
    assert s.object_temperature_C == pytest.approx(24.0 - 1.5)   # the offset is from ambient (24 degC)
    s2 = parse_scene(edit(FULL, "object_offset_K = -1.5", "object_temperature_C = 30.0"))
    assert s2.object_temperature_C == 30.0
    # A [touch] contact resistance overrides the scene-wide one.
    s3 = parse_scene("contact_resistance_m2K_W = 5e-4\n" + FULL)
    assert s3.contact_resistance_m2K_W == 5e-4 and s3.touch_contact_resistance_m2K_W == 1e-4
    for probe in PROBES:
        assert parse_scene(edit(FULL, '"small-heater"', f'"{probe}"')).board.probe == probe


@pytest.mark.parametrize("old, new, key, words", [
    ('world = "faithful"', 'world = "exact"', "board.world", "must be one of"),
    ('probe = "small-heater"', 'probe = "tiny"', "board.probe", "must be one of"),
    ('world = "faithful"', 'world = "ideal"', "board.probe", 'needs world = "faithful"'),
    ("sensing_k_factor = 0.97", "sensing_k_factor = 97.0", "as_built.sensing_k_factor", "<= 2"),
    ("flux_sensitivity_factor = 0.98", "flux_sensitivity_factor = -0.98", "as_built.flux_sensitivity_factor",
     ">= 0.5"),
    ("thermocouple_time_constant_s = 0.02", "thermocouple_time_constant_s = -1.0",
     "as_built.thermocouple_time_constant_s", ">= 0"),
    ("heater_tcr_per_K = 1e-4", "heater_tcr_percent = 1e-4", "as_built.heater_tcr_percent", "unknown"),
    ("heater_tcr_per_K = 1e-4", 'heater_tcr_per_K = "small"', "as_built.heater_tcr_per_K", "must be a number"),
    ("object_offset_K = -1.5", "object_offset_K = -1.5\nobject_temperature_C = 22.0", "touch.object_offset_K",
     "not both"),
    ("object_offset_K = -1.5", "object_offset_K = -400.0", "touch.object_offset_K", ">= -200"),
    ("object_offset_K = -1.5", "object_temperature_C = -300.0", "touch.object_temperature_C", ">= -270"),
    ("contact_lead_s = 1.0", "contact_lead_s = 3.0", "touch.contact_lead_s", "must be < touch.length_s"),
    ("contact_lead_s = 1.0", "contact_lead_s = -0.4", "touch.contact_lead_s", "a late touch needs"),
    ("contact_lead_s = 1.0", "contact_lead_s = -11.0", "touch.contact_lead_s", ">= -10"),
    ("contact_resistance_m2K_W = 1e-4", "contact_resistance_m2K_W = -1e-4", "touch.contact_resistance_m2K_W",
     ">= 0"),
])
def test_bad_values_give_one_line_naming_file_table_and_key(old, new, key, words):
    with pytest.raises(SceneError) as info:
        parse_scene(edit(FULL, old, new), source="bad.toml")
    msg = str(info.value)
    assert msg.startswith(f"bad.toml: {key}: ") and words in msg and "\n" not in msg, msg
    assert info.value.key == key and info.value.file == "bad.toml"


def test_a_late_touch_has_the_heater_on_before_the_contact(tmp_path):
    s = parse_scene(edit(edit(FULL, "start_s = 0.5", "start_s = 1.0"), "contact_lead_s = 1.0", "contact_lead_s = -0.5"))
    assert s.touch.heater_on_s == 0.5 and s.touch.end_s == 4.0
    cfg = config_for_scene(s, tmp_path)
    # The small-heater probe heats as long as the touch allows (its profile asks 5 s), up to 0.3 s before the lift.
    assert cfg.measurement.baseline_s == 0.5 and cfg.measurement.contact_time_s == pytest.approx(3.2)
    paper = config_for_scene(dataclasses.replace(s, board=dataclasses.replace(s.board, probe="paper")), tmp_path)
    assert paper.measurement.baseline_s == 0.5 and paper.measurement.contact_time_s == 2.0


def test_as_built_needs_the_faithful_world():
    text = edit(FULL, 'world = "faithful"\nprobe = "small-heater"', 'world = "ideal"')
    with pytest.raises(SceneError, match=r'^bad\.toml: as_built: needs board\.world = "faithful"'):
        parse_scene(text, source="bad.toml")


def test_the_ideal_world_honours_the_touch_contact_resistance_and_object_temperature():
    text = edit(BASE, "length_s = 2.0\n", "length_s = 2.0\ncontact_resistance_m2K_W = 1e-3\n"
                                          "object_temperature_C = 20.0\n")
    s, s0 = parse_scene(text), parse_scene(BASE)
    clk = VirtualClock()
    clk.advance(10.0)
    drive = ScheduleDrive([0.5, 2.5], [1.0, 0.0])
    tr = ThermalWorld(s, clk, drive).truth([2.0])
    ref = ThermalWorld(dataclasses.replace(
        s0, contact_resistance_m2K_W=1e-3,
        environment=dataclasses.replace(s0.environment, initial_temperature_C=20.0)), clk, drive).truth([2.0])
    assert tr.thermocouple_C[0] == pytest.approx(ref.thermocouple_C[0], abs=1e-12)
    assert tr.q_f_W_m2[0] == pytest.approx(ref.q_f_W_m2[0], rel=1e-12)


# ----------------------------------------------------------------------------------------------
# Shipped scenes


def test_shipped_scenes_stay_on_the_ideal_world_unless_named_faithful_or_small():
    names = scene_names()
    for n in names:
        s = read_scene(n)
        faithful = n.endswith(("_faithful", "_small"))
        assert (s.board.world == "faithful") == faithful, n
        if not faithful:
            assert s.board.probe == "paper" and s.as_built is None
    # The simulator puts each on its world.
    for n, kind in (("glass_15V", ThermalWorld), ("glass_15V_faithful", FaithfulWorld), ("alu_25V_small", FaithfulWorld)):
        with load_scene(n) as sim:
            assert type(sim.world) is kind


@pytest.mark.parametrize("paper", PAPER_NINE)
def test_small_heater_scene_is_its_paper_scene_on_the_small_probe_at_the_same_areal_power(paper):
    small = tomllib.loads((SHIPPED_DIR / f"{paper}_small.toml").read_text())
    ref = tomllib.loads((SHIPPED_DIR / f"{paper}.toml").read_text())
    assert small.pop("name") == f"{paper}_small" and ref.pop("name") == paper
    assert small.pop("description").startswith(ref.pop("description"))
    assert small["board"].pop("world") == "faithful" and small["board"].pop("probe") == "small-heater"
    # The precision converter added to the paper's board (the small heater's rise is a few 0.2-K steps).
    assert small["board"].pop("ads122c04") == 0x40 and small["sensors"].pop("ads122c04_noise_rms_V") == 0.15e-6
    r_small, r_ref = small["heater"].pop("resistance_ohm"), ref["heater"].pop("resistance_ohm")
    assert small == ref   # everything else, key for key
    # Same supply, same areal power: R scales with the inverse of the heater area.
    ratio = (r_small / r_ref) * PROBES["small-heater"].heater_area_m2 / read_scene(paper).stack.heater_area_m2
    assert ratio == pytest.approx(1.0, rel=1e-4)
    sim = load_scene(f"{paper}_small")
    assert isinstance(sim.world, FaithfulWorld)
    assert sim.world.stack.heater_area_m2 == pytest.approx(PROBES["small-heater"].heater_area_m2, rel=1e-12)
    sim.close()


@pytest.mark.parametrize("name", FAITHFUL)
def test_faithful_scenes_touch_as_a_hand_does_with_a_probe_built_a_little_off(name):
    s = read_scene(name)
    assert s.board.world == "faithful" and s.board.probe == "paper"
    assert s.touch_contact_resistance_m2K_W == 1e-4
    assert 1.0 <= abs(s.object_temperature_C - s.environment.ambient_temperature_C) <= 2.0
    assert s.touch.contact_lead_s == 1.0 and s.touch.end_s - s.touch.heater_on_s >= 2.3
    a = s.as_built
    factors = (a.sensing_thickness_factor, a.sensing_k_factor, a.flux_sensitivity_factor,
               a.heater_resistance_factor)
    assert all(0.95 <= f <= 1.05 for f in factors) and sum(f != 1.0 for f in factors) >= 3
    assert a.thermocouple_time_constant_s != s.sensors.thermocouple_time_constant_s
    # The device is told the nominal probe and heats contact_lead_s after the contact.
    cfg = config_for_scene(s, "/nonexistent")
    assert cfg.sensors.flux_sensitivity_V_per_W_m2 == s.sensors.flux_sensitivity_V_per_W_m2
    assert cfg.heater.resistance_ohm == s.heater.resistance_ohm
    assert cfg.measurement.baseline_s == pytest.approx(s.touch.heater_on_s)
    assert cfg.measurement.contact_time_s == 2.0
    # ... while the world runs the probe as built.
    w = load_scene(name).world
    assert w.flux_sensitivity == pytest.approx(s.sensors.flux_sensitivity_V_per_W_m2 * a.flux_sensitivity_factor)
    assert w.R0 == pytest.approx(s.heater.resistance_ohm * a.heater_resistance_factor)
    assert w.stack.sensing_thickness_m == pytest.approx(s.stack.sensing_thickness_m * a.sensing_thickness_factor)
    assert w.tau == a.thermocouple_time_constant_s


# ----------------------------------------------------------------------------------------------
# The unchanged daemon on a faithful scene


@pytest.fixture
def device_world_step(faithful_world_test_step):
    """The simulated device's world marches at ``DEVICE_DT_s``: these tests assert what the daemon does
    (heating when and as long as configured, the film's energy, the contact found), none of which
    needs the world's 20-ms accuracy; the same scene's touch as tests/host/test_round_trip.py's, once
    per process (0.51 + 0.47 + 0.39 -> 0.42 + 0.37 + 0.24 CPU-s, the three alone)."""
    with world_step(DEVICE_DT_s):
        yield


def _measure_on(scene: str, tmp_path, **measure):
    with sim_daemon(scene, tmp_path) as (c, d, sim):
        rec = c.measure(**measure)
        series = c.series(rec["measurement_id"], "raw")
    return rec, series, d, sim


# The unchanged daemon on a faithful scene (a record; one heating, contact_lead_s after the touch began, as long
# as configured and safe; the as-built film's energy; the baseline's flux under a contact resistance) is checked on
# every faithful and small-heater scene by tests/host/test_round_trip.py, on the device run it round-trips
# (``_assert_the_daemon_ran_unchanged_on_the_faithful_world``): here it touched glass_15V_faithful and
# pmma_15V_small once more, usually in the other xdist worker, for 0.7 CPU-s.


def test_the_faithful_world_gives_the_chips_the_scenes_touch_timing():
    sim = load_scene("glass_15V_faithful")
    w, sc = sim.world, sim.scene
    assert not w.contact_at(sc.touch.start_s - 1e-6) and w.contact_at(sc.touch.start_s + 1e-6)
    # A colder object (1.5 K below the probe): the thermocouple falls towards it with the heater still
    # off (the thin probe layers take the object's temperature; the foam above holds some heat back).
    sim.advance_to(sc.touch.heater_on_s - 0.01)
    T = w.truth(np.array([sc.touch.start_s - 0.01, sc.touch.heater_on_s - 0.01])).thermocouple_C
    T_obj = sc.object_temperature_C
    assert T[0] == pytest.approx(25.0, abs=1e-6) and T_obj < T[1] < T_obj + 0.5 * (25.0 - T_obj)
    assert math.isclose(sim.heater_on_time_s(), 0.0)
    sim.close()


# ----------------------------------------------------------------------------------------------
# Armed: the device waits in air for the touch, finds the contact, heats settle_s after it


def _armed_on(scene: str, tmp_path, **measure):
    rec, series, _d, sim = _measure_on(scene, tmp_path, **measure)
    return rec, series, sim


@pytest.mark.usefixtures("device_world_step")
def test_armed_measurement_heats_settle_s_after_the_detected_contact(tmp_path):
    rec, series, sim = _armed_on("pmma_15V_faithful", tmp_path, arm_s=5.0, settle_s=0.6, contact_time_s=2.0)
    assert rec["status"] == "ok", rec
    touch = sim.scene.touch
    (a, b), = sim.heater_intervals()
    # Contact at start_s is seen within a sample or two (MCP9600: 80 ms), heating settle_s later.
    # The origin is the last sample in air: up to one sample period (0.1 s) before the touch.
    assert touch.start_s + 0.6 - 0.11 <= a <= touch.start_s + 0.6 + 0.25
    assert b - a == pytest.approx(2.0, abs=0.02)
    # The record keeps the samples in air and the contact; the chain finds the contact there.
    t = np.asarray(series["raw_t_s"])
    assert t.min() <= -(a - touch.start_s) - 0.2
    chain = rec["result"]["sensor_chain"]
    assert chain["contact_t_s"] == pytest.approx(touch.start_s - a, abs=0.2)
    assert_heater_safe(sim.parts, 10.0)
    sim.close()


@pytest.mark.usefixtures("device_world_step")
def test_armed_without_a_touch_ends_no_contact_with_the_heater_never_on(tmp_path):
    # pmma_15V_faithful's touch comes at 0.5 s; arming from ~0 for 0.3 s is over before it.
    rec, series, sim = _armed_on("pmma_15V_faithful", tmp_path, arm_s=0.3, settle_s=0.5)
    assert rec["status"] == "aborted" and rec["reason"] == "no_contact", rec
    assert sim.heater_intervals() == []
    sim.close()
