"""Scene files: schema, shipped scenes and errors that name their key."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from firmware_sim.scene.files import read_scene, scene_names, scene_path
from firmware_sim.scene.model import FAULT_KINDS, Fault, SceneError
from firmware_sim.scene.parser import library_material, parse_scene, validate_fault

PAPER = {
    "glass": ((1.097, 2458.4, 809.0), (12, 15, 18)),
    "pmma": ((0.185, 1178.35, 1429.0), (8, 15, 20)),
    "alu": ((120.4, 2651.5, 873.0), (15, 20, 25)),
}

BASE = """
name = "t"
seed = 4

[object]
k_W_mK = 1.0
rho_kg_m3 = 2000.0
c_J_kgK = 800.0
thickness_m = 0.02
back = "insulated"

[environment]
initial_temperature_C = 25.0
ambient_temperature_C = 24.0

[heater]
supply_voltage_V = 15.0
resistance_ohm = 50.0

[board]
mcp9600 = 0x60
ads1115 = 0x48

[touch]
start_s = 0.5
length_s = 2.0
"""


def edit(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


def error_of(text: str, source: str = "bad.toml") -> SceneError:
    with pytest.raises(SceneError) as info:
        parse_scene(text, source=source)
    return info.value


def test_minimal_scene_parses_with_defaults():
    s = parse_scene(BASE, source="x.toml")
    assert s.name == "t" and s.seed == 4
    assert s.object.solid.k_W_mK == 1.0 and s.object.back == "insulated" and s.object.thickness_m == 0.02
    assert s.environment.initial_temperature_C == 25.0 and s.environment.ambient_temperature_C == 24.0
    assert s.board.mcp9600 == 0x60 and s.board.ads1115 == 0x48 and s.board.ads122c04 is None
    assert s.board.stack_name == "0.42"
    assert s.sensors.flux_sensitivity_V_per_W_m2 == pytest.approx(0.56e-6)
    assert s.sensors.flux_range_W_m2 == 10_000.0 and s.sensors.thermocouple_time_constant_s == 0.0
    assert s.touch.end_s == pytest.approx(2.5) and s.touch.press_trigger
    assert s.contact_resistance_m2K_W == 0.0 and s.faults == ()
    # q_v = V^2/R / (area * heater thickness)
    assert s.q_v_W_m3() == pytest.approx(15.0**2 / 50.0 / (0.055 * 0.060 * 20e-6))


def test_shipped_scenes_include_the_nine_paper_experiments():
    names = scene_names()
    for key, ((k, rho, c), volts) in PAPER.items():
        for v in volts:
            s = read_scene(f"{key}_{v}V")
            assert (s.object.solid.k_W_mK, s.object.solid.rho_kg_m3, s.object.solid.c_J_kgK) == (k, rho, c)
            assert s.heater.supply_voltage_V == v and s.heater.resistance_ohm == 50.0
            assert s.object.back == "insulated" and s.object.thickness_m == 0.02
            assert s.touch.length_s >= 2.0
            assert f"{key}_{v}V" in names
    assert len(names) >= 12
    for n in names:  # every shipped scene is valid
        read_scene(n)


def test_example_scenes_cover_precision_adc_faults_and_no_contact():
    prec = read_scene("alu_20V_ads122c04")
    assert prec.board.ads122c04 == 0x40 and prec.object.material == "aluminium_alloy"
    kinds = {f.kind for f in read_scene("glass_15V_faults").faults}
    assert {"open_thermocouple", "flux_saturation", "supply_sag", "i2c_nack"} <= kinds
    assert [f.kind for f in read_scene("pmma_15V_no_contact").faults] == ["no_contact"]


def test_material_name_resolves_from_the_library_csv():
    s = parse_scene(edit(BASE, "k_W_mK = 1.0\nrho_kg_m3 = 2000.0\nc_J_kgK = 800.0", 'material = "pmma"'))
    assert (s.object.solid.k_W_mK, s.object.solid.rho_kg_m3, s.object.solid.c_J_kgK) == (0.185, 1178.35, 1429.0)
    assert s.object.material == "pmma" and s.object.label == "pmma"
    assert library_material("tempered_glass") == (1.097, 2458.4, 809.0)


def test_material_lookup_can_be_supplied():
    text = edit(BASE, "k_W_mK = 1.0\nrho_kg_m3 = 2000.0\nc_J_kgK = 800.0", 'material = "unobtainium"')
    s = parse_scene(text, material_lookup={"unobtainium": (3.0, 4000.0, 500.0)}.__getitem__)
    assert s.object.solid.k_W_mK == 3.0


def test_material_library_is_read_without_importing_host():
    code = ("import sys; from firmware_sim.scene.parser import library_material; "
            "library_material('pmma'); print('host' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_infinite_back_needs_no_thickness():
    s = parse_scene(edit(BASE, 'thickness_m = 0.02\nback = "insulated"', 'back = "infinite"'))
    assert s.object.thickness_m is None and s.object.back == "infinite"


@pytest.mark.parametrize("text, key, words", [
    ("colour = 'red'\n" + BASE, "colour", "unknown key"),
    (edit(BASE, "back = ", "colour = 1\nback = "), "object.colour", "unknown key"),
    (edit(BASE, "length_s = 2.0", "length_s = 2.0\nduration_s = 3.0"), "touch.duration_s", "unknown key"),
    (edit(BASE, 'back = "insulated"', ""), "object.back", "missing"),
    (edit(BASE, "resistance_ohm = 50.0", ""), "heater.resistance_ohm", "missing"),
    (edit(BASE, 'back = "insulated"', 'back = "fixed"').replace("thickness_m = 0.02\n", ""),
     "object.thickness_m", "missing"),
    (BASE.split("[touch]")[0], "touch", "missing"),
    (edit(BASE, "k_W_mK = 1.0\n", ""), "object.k_W_mK", "missing"),
    (edit(BASE, "k_W_mK = 1.0\nrho_kg_m3 = 2000.0\nc_J_kgK = 800.0", ""), "object.material", "missing"),
    (edit(BASE, "k_W_mK = 1.0", "k_W_mK = -1.0"), "object.k_W_mK", "> 0"),
    (edit(BASE, "rho_kg_m3 = 2000.0", "rho_kg_m3 = 0"), "object.rho_kg_m3", "> 0"),
    (edit(BASE, "thickness_m = 0.02", "thickness_m = -0.02"), "object.thickness_m", "> 0"),
    (edit(BASE, "resistance_ohm = 50.0", "resistance_ohm = 0.0"), "heater.resistance_ohm", "> 0"),
    (edit(BASE, "initial_temperature_C = 25.0", "initial_temperature_C = -300.0"),
     "environment.initial_temperature_C", ">="),
    (edit(BASE, "length_s = 2.0", "length_s = 0"), "touch.length_s", "> 0"),
    (edit(BASE, "seed = 4", "seed = -1"), "seed", ">= 0"),
    (edit(BASE, "seed = 4", "seed = 4\ncontact_resistance_m2K_W = -1e-4"), "contact_resistance_m2K_W", ">= 0"),
    (edit(BASE, "supply_voltage_V = 15.0", 'supply_voltage_V = "15"'), "heater.supply_voltage_V", "number"),
    (edit(BASE, "supply_voltage_V = 15.0", "supply_voltage_V = true"), "heater.supply_voltage_V", "number"),
    (edit(BASE, "seed = 4", "seed = 4.5"), "seed", "integer"),
    (edit(BASE, 'back = "insulated"', 'back = "open"'), "object.back", "one of"),
    (edit(BASE, "k_W_mK = 1.0", 'material = "pmma"\nk_W_mK = 1.0'), "object.k_W_mK", "not both"),
    (edit(BASE, "k_W_mK = 1.0\nrho_kg_m3 = 2000.0\nc_J_kgK = 800.0", 'material = "nope"'),
     "object.material", "unknown material"),
    (edit(BASE, "mcp9600 = 0x60", "mcp9600 = 0x70"), "board.mcp9600", "address"),
    (edit(BASE, "mcp9600 = 0x60", "mcp9600 = 0x60\nads122c04 = 0x48"), "board.ads122c04", "already used"),
    (edit(BASE, "ads1115 = 0x48", ""), "board.ads1115", "flux"),
    (edit(BASE, "mcp9600 = 0x60", ""), "board.mcp9600", "thermocouple"),
    (edit(BASE, "ads1115 = 0x48", 'ads1115 = 0x48\nstack = "0.5"'), "board.stack", "one of"),
    (BASE + "[sensors]\nads1115_noise_rms_V = -1e-6\n", "sensors.ads1115_noise_rms_V", ">= 0"),
    (BASE + "[sensors]\nflux_sensitivity_V_per_W_m2 = 0\n", "sensors.flux_sensitivity_V_per_W_m2", "> 0"),
    (BASE + "[sensors]\nnoise = 1\n", "sensors.noise", "unknown key"),
    (BASE + '[[faults]]\nkind = "meteor"\n', "faults[0].kind", "one of"),
    (BASE + '[[faults]]\nkind = "no_contact"\nat_s = 1.0\nuntil_s = 0.5\n', "faults[0].until_s", "> 1"),
    (BASE + '[[faults]]\nkind = "heater_dead"\nwhen = 1\n', "faults[0].when", "unknown key"),
    (BASE + '[[faults]]\nkind = "heater_dead"\n[[faults]]\nkind = "supply_sag"\nparams = { factor = 1.5 }\n',
     "faults[1].params.factor", "<= 1"),
    (BASE + '[[faults]]\nkind = "supply_sag"\nparams = { factor = 0.5, voltage_V = 3.0 }\n',
     "faults[0].params.factor", "exactly one"),
    (BASE + '[[faults]]\nkind = "heater_stuck_on"\nparams = { duty = 0 }\n', "faults[0].params.duty", "> 0"),
    (BASE + '[[faults]]\nkind = "i2c_nack"\nparams = { chip = "ads122c04" }\n',
     "faults[0].params.chip", "not fitted"),
    (BASE + '[[faults]]\nkind = "open_thermocouple"\nparams = { level = 1 }\n',
     "faults[0].params.level", "unknown key"),
])
def test_errors_name_the_key_and_the_file(text, key, words):
    e = error_of(text)
    assert e.key == key
    assert e.file == "bad.toml"
    msg = str(e)
    assert msg.startswith(f"bad.toml: {key}: "), msg
    assert words in msg, msg
    assert isinstance(e, ValueError)


def test_bad_toml_is_a_scene_error_with_the_position():
    e = error_of(BASE + "\n[heater\n")
    assert e.key == "" and "not valid TOML" in str(e) and "line" in str(e)
    assert str(e).startswith("bad.toml: ")


def test_read_scene_reports_the_file_name(tmp_path):
    p = tmp_path / "my_scene.toml"
    p.write_text(edit(BASE, "k_W_mK = 1.0", "k_W_mK = -3.0"))
    with pytest.raises(SceneError, match=r"^my_scene\.toml: object\.k_W_mK: "):
        read_scene(p)
    p.write_text(BASE.replace('name = "t"\n', ""))
    assert read_scene(str(p)).name == "my_scene"  # default name: file stem


def test_unknown_scene_name_lists_the_shipped_ones():
    with pytest.raises(FileNotFoundError, match="glass_15V"):
        scene_path("glass_99V")
    assert scene_path("glass_15V").name == "glass_15V.toml"


def test_validate_fault_from_code():
    f = validate_fault("supply_sag", 1.0, 2.0, {"factor": 0.7})
    assert f == Fault("supply_sag", 1.0, 2.0, {"factor": 0.7})
    assert f.active(1.0) and f.active(1.999) and not f.active(2.0) and not f.active(0.5)
    assert validate_fault("flux_saturation").params["voltage_V"] == pytest.approx(0.3)
    with pytest.raises(SceneError, match=r"fault\.params\.duty"):
        validate_fault("heater_stuck_on", params={"duty": 2.0})
    assert set(FAULT_KINDS) == {"i2c_nack", "bus_stuck", "open_thermocouple", "flux_saturation",
                                "heater_stuck_on", "heater_dead", "supply_sag", "no_contact", "converter_frozen"}


def test_scene_text_in_readme_example_parses():
    text = textwrap.dedent("""
        [object]
        material = "tempered_glass"
        thickness_m = 0.02
        back = "insulated"
        [environment]
        initial_temperature_C = 25.0
        ambient_temperature_C = 25.0
        [heater]
        supply_voltage_V = 15.0
        resistance_ohm = 50.0
        [board]
        ads122c04 = 0x40
        [touch]
        start_s = 0.0
        length_s = 2.0
        [[faults]]
        kind = "i2c_nack"
        at_s = 1.0
        until_s = 1.1
        params = { address = 0x40 }
    """)
    s = parse_scene(text, source="readme.toml")
    assert s.name == "readme" and s.board.ads122c04 == 0x40 and s.faults[0].params == {"address": 0x40}


def test_a_fitted_ads122c04_reads_the_thermocouple_in_every_shipped_scene(tmp_path):
    # The precision ADC is there for the thermocouple (a metal rises ~0.1 K in 2 s); an MCP9600 fitted
    # beside it (alu_20V_ads122c04) must not take the thermocouple over.
    from firmware_sim.run import config_for_scene
    from firmware_sim.scene.files import read_scene, scene_names

    checked = 0
    for name in scene_names():
        scene = read_scene(name)
        cfg = config_for_scene(scene, tmp_path / name)
        if scene.board.ads122c04 is not None:
            assert cfg.sensors.thermocouple == "ads122c04", name
            checked += 1
        elif scene.board.mcp9600 is not None:
            assert cfg.sensors.thermocouple == "mcp9600", name
    assert checked >= 1
