"""Drawn as-built probes (firmware_sim.asbuilt): reproducible, within their tolerances, never seen by the device."""

from __future__ import annotations

import ast
import dataclasses
import math
from pathlib import Path

import pytest

from edge.physics.geometry import PROBES
from firmware_sim.asbuilt import TOLERANCES, ZERO_LAG_DRAW_s, Nominal, as_built_for_scene, draw_as_built, draw_factors
from firmware_sim.rz.configs import AsBuilt, geometry_for_probe
from firmware_sim.rz.footprint import SquareSensor
from firmware_sim.scene.files import read_scene, scene_path
from firmware_sim.scene.model import SceneError
from firmware_sim.scene.parser import parse_scene

ROOT = Path(__file__).resolve().parents[2]
HEADS = sorted(PROBES)


@pytest.mark.parametrize("head", HEADS)
def test_a_seed_draws_one_probe_reproducibly(head):
    a, b = draw_as_built(head, 7), draw_as_built(head, 7)
    assert a == b
    assert draw_as_built(head, 8) != a
    other = HEADS[1 - HEADS.index(head)]
    assert draw_factors(other, 7) != draw_factors(head, 7)   # one stream per head and seed
    with pytest.raises(ValueError):
        draw_as_built(head, -1)
    with pytest.raises(KeyError):
        draw_as_built("no-such-head", 1)


@pytest.mark.parametrize("head", HEADS)
def test_draws_stay_within_their_tolerances_and_spread_over_them(head):
    draws = [draw_factors(head, s) for s in range(300)]
    for name, (kind, lo, hi) in TOLERANCES.items():
        xs = [d[name] for d in draws]
        assert all(lo <= x <= hi for x in xs), name
        # Not a constant: the draws use a good part of the range (the N2 ones mostly inside 2 sigma).
        span = (max(xs) - min(xs)) / (hi - lo)
        assert span > (0.7 if kind == "N2" else 0.9), (name, span)
    nom = Nominal.of(head)
    sub = PROBES[head].substrate
    for s in range(50):
        ab, d = draw_as_built(head, s), draws[s]
        assert ab.flux_sensitivity_V_per_W_m2 / nom.flux_sensitivity_V_per_W_m2 - 1 == pytest.approx(
            d["flux_sensitivity_rel"], abs=1e-12)
        assert abs(ab.sensing_thickness_m / nom.sensing_thickness_m - 1) <= 0.10 + 1e-12
        assert abs(ab.sensing_k_W_mK / nom.sensing_k_W_mK - 1) <= 0.10 + 1e-12
        assert abs(ab.substrate_k_W_mK / sub.k_W_mK - 1) <= 0.20 + 1e-12
        assert abs(ab.substrate_rho_c_J_m3K / (sub.rho_kg_m3 * sub.c_J_kgK) - 1) <= 0.15 + 1e-12
        assert abs(ab.heater_resistance_ohm / nom.heater_resistance_ohm - 1) <= 0.02 + 1e-12
        assert 0.001 <= ab.heater_tcr_per_K <= 0.004
        assert 0.0 <= ab.thermocouple_r_m <= 0.5e-3
        # A datasheet lag of 0 s draws the laminated bead's; a stated lag draws +-30 % around it.
        assert 0.0 <= ab.thermocouple_time_constant_s <= ZERO_LAG_DRAW_s
        sq = ab.sensor
        assert isinstance(sq, SquareSensor)
        assert abs(sq.side_x_m - 0.010) <= 0.2e-3 and abs(sq.side_y_m - 0.010) <= 0.2e-3
        assert abs(sq.offset_x_m) <= 0.5e-3 and abs(sq.offset_y_m) <= 0.5e-3
        assert abs(sq.gradient_x) <= 0.05 and abs(sq.gradient_y) <= 0.05


def test_a_stated_lag_is_drawn_around_its_value():
    sc = read_scene("glass_15V_faithful")   # [sensors] lag 10 ms
    taus = [draw_as_built("paper", s, sc).thermocouple_time_constant_s for s in range(100)]
    assert all(0.007 - 1e-12 <= t <= 0.013 + 1e-12 for t in taus)
    assert max(taus) - min(taus) > 0.005


def _with_as_built(name: str, table: str) -> str:
    """The shipped scene's TOML with its ``[as_built]`` table replaced by (or, without one, given) ``table``."""
    text = scene_path(name).read_text()
    head, sep, _ = text.partition("\n[as_built]\n")
    if not sep:
        head = text.partition("\n[touch]\n")[0]
    _, _, touch = text.partition("\n[touch]\n")
    return f"{head}\n[as_built]\n{table}\n\n[touch]\n{touch}"


@pytest.mark.parametrize("name", ["glass_15V_faithful", "glass_12V_small"])
def test_a_scene_asks_for_a_drawn_probe(name):
    sc = parse_scene(_with_as_built(name, "draw_seed = 5"))
    assert sc.as_built.draw_seed == 5
    assert as_built_for_scene(sc) == draw_as_built(sc.board.probe, 5, sc)
    # The draw deviates from the scene's own nominal values (its [heater] resistance, ...).
    assert as_built_for_scene(sc).heater_resistance_ohm == pytest.approx(sc.heater.resistance_ohm, rel=0.02)
    with pytest.raises(SceneError, match="draw_seed"):
        parse_scene(_with_as_built(name, "draw_seed = 5\nsensing_k_factor = 1.1"))


def test_explicit_as_built_keys_reach_the_world():
    sc = parse_scene(_with_as_built("glass_15V_faithful", "sensor_square = true\nsensor_offset_x_m = 0.3e-3\n"
                                    "substrate_k_factor = 1.2\nthermocouple_r_m = 0.4e-3\n"
                                    "thermocouple_height_m = 2e-5\n"
                                    "heater_lead_resistance_ohm = 0.2"))
    ab = as_built_for_scene(sc)
    assert ab.sensor == SquareSensor(offset_x_m=0.3e-3)
    assert ab.substrate_k_W_mK == pytest.approx(PROBES["paper"].substrate.k_W_mK * 1.2)
    assert ab.substrate_rho_c_J_m3K is None and ab.substrate_thickness_m is None
    geo = ab.apply_to(geometry_for_probe("paper"))
    assert geo.sensor_square == ab.sensor and geo.thermocouple_r_m == 0.4e-3 and geo.thermocouple_height_m == 2e-5
    assert geo.substrate.k_W_mK == pytest.approx(0.036) and geo.substrate.rho_kg_m3 * geo.substrate.c_J_kgK == \
        pytest.approx(40.0 * 1400.0)
    with pytest.raises(SceneError, match="sensor_square"):
        parse_scene(_with_as_built("glass_15V_faithful", "sensor_offset_x_m = 0.3e-3"))


def test_nominal_scenes_build_the_nominal_world():
    """No [as_built] keys beyond the old ones: the world's geometry is the probe's, untouched."""
    for name in ("glass_15V_faithful", "alu_20V_faithful", "glass_12V_small"):
        sc = read_scene(name)
        geo = geometry_for_probe(sc.board.probe)
        assert as_built_for_scene(sc).apply_to(geo) == geo
    assert AsBuilt().apply_to(geometry_for_probe("paper")).sensor_square is None      # the disk
    assert geometry_for_probe("small-heater").sensor_square == SquareSensor()         # the real square


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names)
    return out


def test_the_device_and_its_host_tools_never_see_the_draws():
    """Nothing under edge/ or host/ imports firmware_sim.asbuilt (nor names it, e.g. in an importlib string)."""
    files = [p for d in ("edge", "host") for p in (ROOT / d).rglob("*.py")]
    assert len(files) > 50
    for p in files:
        text = p.read_text()
        assert "firmware_sim.asbuilt" not in text and "draw_as_built" not in text, p
        # Every spelling of an import of the module (``from firmware_sim import asbuilt`` too) has "asbuilt" in
        # its text: only such files need parsing (the parse of every file was most of this test's 0.7 s).
        if "asbuilt" in text:
            assert not any(m == "firmware_sim.asbuilt" or m.startswith("firmware_sim.asbuilt.")
                           for m in _imports(p)), p


def test_as_built_is_frozen_and_checked():
    ab = draw_as_built("small-heater", 3)
    with pytest.raises(dataclasses.FrozenInstanceError):
        ab.heater_tcr_per_K = 0.0
    with pytest.raises(ValueError):
        AsBuilt(substrate_k_W_mK=-1.0)
    with pytest.raises(ValueError):
        AsBuilt(heater_lead_resistance_ohm=math.nan)
