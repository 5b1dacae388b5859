"""The chip registry: one place per chip, read by configuration, make_sensors and the instrument models."""

from __future__ import annotations

import inspect
from types import SimpleNamespace

import pytest

from edge.hw import chips
from edge.hw.chips import BOARDS, CHIPS, DEFAULT_CHIPS, FLUX, ROLES, THERMOCOUPLE, names_for
from edge.hw.regmaps import ads122c04 as ads122c04_map
from edge.measure.instrument import INSTRUMENTS
from edge.measure.sensors import make_sensors
from edge.service.config import SCHEMA, Config, ConfigError
from edge.service.requests import max_sample_rate_Hz
from firmware_sim.scene.files import scene_variant
from firmware_sim.simulator import load_scene


def test_each_chip_entry_agrees_with_its_driver_and_register_map():
    for name, spec in CHIPS.items():
        assert spec.driver.CHIP == name
        assert tuple(spec.driver.ADDRESSES) == spec.addresses == tuple(spec.regmap.ADDRESSES)
        assert inspect.signature(spec.driver).parameters["address"].default == spec.default_address
        assert set(spec.roles) <= set(ROLES) and spec.roles


def test_roles_and_boards_name_registry_chips_that_can_play_them():
    assert names_for(THERMOCOUPLE) == ("mcp9600", "ads122c04")
    assert names_for(FLUX) == ("ads1115", "ads122c04")
    for board in BOARDS.values():
        for role, name in board.items():
            assert name in names_for(role)
    assert DEFAULT_CHIPS is BOARDS["reference"]
    with pytest.raises(ValueError, match="unknown role"):
        names_for("pressure")
    with pytest.raises(ValueError, match="known:"):
        chips.chip("max31855")


def test_the_sensors_config_section_is_built_from_the_registry():
    s = SCHEMA["sensors"]
    assert s["thermocouple"].choices == names_for(THERMOCOUPLE) and s["flux_adc"].choices == names_for(FLUX)
    assert s["thermocouple"].default == DEFAULT_CHIPS[THERMOCOUPLE] and s["flux_adc"].default == DEFAULT_CHIPS[FLUX]
    for spec in CHIPS.values():
        addr = s[spec.setting_key("address")]
        assert (addr.default, addr.lo, addr.hi) == (spec.default_address, min(spec.addresses), max(spec.addresses))
        for st in spec.settings:
            assert s[spec.setting_key(st.key)].default == st.default
    with pytest.raises(ConfigError, match="sensors.flux_adc"):
        Config({"sensors": {"flux_adc": "mcp9600"}})        # a thermocouple converter cannot read the flux


def test_instrument_models_are_the_boards_chip_noise_models():
    assert set(INSTRUMENTS) == {b[THERMOCOUPLE] for b in BOARDS.values()}
    for board in BOARDS.values():
        inst = INSTRUMENTS[board[THERMOCOUPLE]]
        T, q = CHIPS[board[THERMOCOUPLE]].models[THERMOCOUPLE], CHIPS[board[FLUX]].models[FLUX]
        assert (inst.T_rate_Hz, inst.T_lsb_K, inst.T_noise_K) == (T.rate_Hz, T.lsb, T.noise)
        assert (inst.q_rate_Hz, inst.q_lsb_W_m2, inst.q_noise_W_m2) == (q.rate_Hz, q.lsb, q.noise)


def test_resolution_and_sample_rate_limit_per_thermocouple_chip():
    reference, precision = Config().sensors, Config({"sensors": {"thermocouple": "ads122c04"}}).sensors
    assert max_sample_rate_Hz(reference) == pytest.approx(12.5)          # 16 bit: 80-ms conversions
    assert chips.thermocouple_resolution_K(reference) == pytest.approx(8e-6 / chips.TYPE_K_SEEBECK_V_per_K)
    per_sample = 2 * ads122c04_map.conversion_time_s(6, False, True) + 2e-3
    assert max_sample_rate_Hz(precision) == pytest.approx(min(200.0, 1.0 / per_sample))
    assert chips.thermocouple_resolution_K(precision) == pytest.approx(
        2.048 / 128 / 2 ** 23 / chips.TYPE_K_SEEBECK_V_per_K)


@pytest.fixture(scope="module")
def all_chips_scene(tmp_path_factory):
    """glass_15V on a board that carries every registry chip at its default address."""
    board = {name: spec.default_address for name, spec in CHIPS.items()} | {"stack": "0.42"}
    return scene_variant("glass_15V", tmp_path_factory.mktemp("scenes"), suffix="_all_chips", board=board)


@pytest.mark.parametrize("thermocouple", names_for(THERMOCOUPLE))
@pytest.mark.parametrize("flux", names_for(FLUX))
def test_make_sensors_reads_every_role_pairing_of_the_registry(all_chips_scene, thermocouple, flux):
    with load_scene(all_chips_scene) as sim:
        board = sim.board()
        cfg = Config({"sensors": {"thermocouple": thermocouple, "flux_adc": flux}}).sensors
        sensors = make_sensors(board, cfg)
        assert sensors.description == f"thermocouple={thermocouple} flux={flux}"
        sim.advance(0.4)                                  # in air, before the touch: ambient, no flux
        r = sensors.read()
        assert r.T_C == pytest.approx(25.0, abs=0.25) and abs(r.q_W_m2) < 50.0 and not r.saturated
        assert sensors.T_resolution_K == chips.thermocouple_resolution_K(cfg)


def test_make_sensors_opens_a_chip_playing_both_roles_once():
    with load_scene("alu_20V_ads122c04") as sim:
        writes = []
        bus = sim.board().i2c
        orig = bus.write_byte

        def spy(addr, value, *a, **kw):
            writes.append((addr, value))
            return orig(addr, value, *a, **kw)

        bus.write_byte = spy
        cfg = Config({"sensors": {"thermocouple": "ads122c04", "flux_adc": "ads122c04"}}).sensors
        make_sensors(sim.board(), cfg)
        resets = [w for w in writes if w == (CHIPS["ads122c04"].default_address, ads122c04_map.CMD_RESET)]
        assert len(resets) == 1


def test_make_sensors_refuses_a_chip_that_cannot_play_the_role():
    with load_scene("glass_15V") as sim:
        cfg = SimpleNamespace(**Config().sensors.__dict__)
        cfg.flux_adc = "mcp9600"                          # past the configuration's own check
        with pytest.raises(ValueError, match="cannot read the flux"):
            make_sensors(sim.board(), cfg)
