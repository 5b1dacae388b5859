import json
from pathlib import Path

import pytest

from edge.service.config import (
    HARD_MAX_ON_TIME_s,
    RUNTIME_KEYS,
    SCHEMA,
    Config,
    ConfigError,
    RuntimeOverrides,
    load_config,
)

EXAMPLE = Path(__file__).resolve().parents[3] / "edge" / "service" / "thermotouch-edge.example.toml"


def _write(tmp_path, text):
    p = tmp_path / "edge.toml"
    p.write_text(text)
    return p


def test_example_file_documents_every_key_with_its_default():
    cfg = load_config(EXAMPLE)
    assert cfg == Config()
    text = EXAMPLE.read_text()
    for section, keys in SCHEMA.items():
        assert f"[{section}]" in text
        for name in keys:
            assert f"\n{name} = " in text, f"{section}.{name} missing from the example"


def test_values_and_hex_addresses_are_read(tmp_path):
    p = _write(tmp_path, "[sensors]\nmcp9600_address = 0x61\n[heater]\npower_W = 2\n")
    cfg = load_config(p)
    assert cfg.sensors.mcp9600_address == 0x61
    assert cfg.heater.power_W == 2.0 and isinstance(cfg.heater.power_W, float)
    assert cfg.get("heater.power_W") == 2.0
    assert cfg.flat()["sensors.mcp9600_address"] == 0x61


@pytest.mark.parametrize("text, key, match", [
    ("[heaters]\npower_W = 1\n", "heaters", "unknown section"),
    ("[heater]\npowr_W = 1\n", "heater.powr_W", "unknown key"),
    ("[heater]\npower_W = 'high'\n", "heater.power_W", "must be a number"),
    ("[heater]\npower_W = true\n", "heater.power_W", "must be a number"),
    ("[board]\npwm_chip = 1.5\n", "board.pwm_chip", "must be an integer"),
    ("[measurement]\ntrigger_button = 1\n", "measurement.trigger_button", "must be a boolean"),
    ("[heater]\npower_W = -1\n", "heater.power_W", "must be >"),
    ("[heater]\nmax_on_time_s = 100\n", "heater.max_on_time_s", f"<= {HARD_MAX_ON_TIME_s:g}"),
    ("[heater]\nover_temperature_C = 400\n", "heater.over_temperature_C", "<= 150"),
    ("[sensors]\nthermocouple = 'max31855'\n", "sensors.thermocouple", "must be one of"),
    ("[sensors]\nmcp9600_address = 0x70\n", "sensors.mcp9600_address", "<= 103"),
    ("[serial]\nbaud = 12345\n", "serial.baud", "must be one of"),
    ("[heater]\npower_W = nan\n", "heater.power_W", "finite"),
    ("heater = 3\n", "heater", "must be a table"),
    ("[heater]\npower_W = 20\n", "heater.power_W", "exceeds the supply"),
    ("[measurement]\ncontact_time_s = 12\n", "measurement.contact_time_s", "below heater.max_on_time_s"),
])
def test_bad_values_name_the_key(tmp_path, text, key, match):
    with pytest.raises(ConfigError, match=match) as ei:
        load_config(_write(tmp_path, text))
    assert ei.value.key == key
    assert str(ei.value).startswith(key)


def test_bad_toml_and_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(_write(tmp_path, "[heater\n"))
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "nope.toml")


def test_runtime_updates_are_validated_and_safety_keys_refused():
    cfg = Config()
    new = cfg.with_updates({"heater.power_W": 1.5, "measurement.sample_rate_Hz": 20})
    assert new.heater.power_W == 1.5 and new.measurement.sample_rate_Hz == 20.0
    assert cfg.heater.power_W == 5.0  # the original is unchanged
    for key in ("heater.max_on_time_s", "heater.over_temperature_C", "board.kind", "paths.history_db"):
        assert key not in RUNTIME_KEYS
        with pytest.raises(ConfigError, match="cannot be changed at run time") as ei:
            cfg.with_updates({key: cfg.get(key)})
        assert ei.value.key == key
    with pytest.raises(ConfigError) as ei:
        cfg.with_updates({"measurement.contact_time_s": 10.0})
    assert ei.value.key == "measurement.contact_time_s"
    with pytest.raises(ConfigError) as ei:
        cfg.with_updates({"nosuch": 1})
    assert ei.value.key == "nosuch"
    with pytest.raises(ConfigError, match="must be a number"):
        cfg.with_updates({"heater.power_W": "2"})


def test_runtime_overrides_persist_and_bad_entries_are_skipped(tmp_path):
    base = Config()
    store = RuntimeOverrides(tmp_path / "sub" / "rt.json")
    cfg = base.with_updates({"heater.power_W": 2.5, "estimation.method": "paper"})
    store.save(cfg, base)
    saved = json.loads((tmp_path / "sub" / "rt.json").read_text())
    assert saved == {"heater.power_W": 2.5, "estimation.method": "paper"}
    again = RuntimeOverrides(tmp_path / "sub" / "rt.json").load(base)
    assert again == cfg
    # A value that became invalid, an unknown key and a safety key are dropped, the rest applies.
    (tmp_path / "sub" / "rt.json").write_text(json.dumps(
        {"heater.power_W": 99.0, "bogus.key": 1, "heater.max_on_time_s": 29, "measurement.baseline_s": 1.0}))
    ro = RuntimeOverrides(tmp_path / "sub" / "rt.json")
    got = ro.load(base)
    assert got.heater.power_W == base.heater.power_W and got.measurement.baseline_s == 1.0
    assert got.heater.max_on_time_s == base.heater.max_on_time_s
    assert len(ro.errors) == 3
    (tmp_path / "sub" / "rt.json").write_text("{not json")
    ro = RuntimeOverrides(tmp_path / "sub" / "rt.json")
    assert ro.load(base) == base and ro.errors


def test_no_leftover_temp_files_after_save(tmp_path):
    store = RuntimeOverrides(tmp_path / "rt.json")
    store.save(Config().with_updates({"heater.power_W": 1.0}), Config())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rt.json"]
