"""Daemon configuration: a TOML file, validated key by key, plus runtime overrides.

The file has one table per section; every key is optional and defaults to the
value in :data:`SCHEMA`. Unknown sections or keys, wrong types and values out
of range are refused with a :class:`ConfigError` whose ``key`` is the dotted
name (``"heater.power_W"``). See ``edge/service/thermotouch-edge.example.toml`` for a
commented example of every key.

Sections
--------
board
    Which board factory (``kind``: ``"rpi"`` or a registered one such as
    ``"sim"``), which probe head is mounted (``probe``: a name in
    :data:`edge.physics.geometry.PROBES`; it decides the estimator's model)
    and where its devices are (I2C bus, GPIO chip and offsets, PWM
    root/chip/channel).
sensors
    Which chips are fitted, their addresses and settings: the thermocouple
    converter (``thermocouple``) and the heat-flux ADC (``flux_adc``), each a
    chip of :data:`edge.hw.chips.CHIPS` that can play that role, every chip's
    ``<chip>_<key>`` settings (from the same registry), the flux sensor's
    sensitivity, the I2C retry bound.
heater
    Supply voltage and film resistance (the power model ``P = d V^2/R``), the
    default power, and the two safety limits: ``max_on_time_s`` and
    ``over_temperature_C``.
measurement
    Baseline duration, contact (heating) time, sample rate, minimum rest
    between touches, and the quality-flag thresholds.
serial
    Port and baud rate of the host link.
paths
    Model store root, factory bundle, history database, runtime-override file.
estimation
    Estimation method passed to the estimator.
watchdog
    An optional hardware watchdog device (``/dev/watchdog``), pet together
    with systemd's software watchdog.
logging
    Log level.
limits
    What the device can hold: its RAM (``ram_bytes``), from which the model
    bundle bounds are derived (:func:`edge.model.bundle.limits_for_ram`).
security
    Who may update the device: the directory of trusted public key files
    (``trusted_keys_dir``) and whether unsigned updates are accepted
    (``allow_unsigned``, false on a real device; :mod:`edge.security.policy`).
    Neither is settable over the link: whoever holds the link is exactly who
    must not be able to loosen them.

Runtime settings
----------------
The keys in :data:`RUNTIME_KEYS` may be changed over the serial link
(CONFIG_SET). Safety limits are *not* among them: they can only be changed
in the file on the device. Overrides are validated like the file, checked
together with the file's values (e.g. ``heater.power_W`` against the
supply's maximum), and persisted atomically as JSON in
``paths.runtime_overrides`` by :class:`RuntimeOverrides`.
"""

from __future__ import annotations

import copy
import json
import logging
import os
import tomllib
from dataclasses import dataclass, field, fields, make_dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Iterable, Mapping

from edge.estimation.estimate import METHODS
from edge.hw.chips import CHIPS, DEFAULT_CHIPS, FLUX, THERMOCOUPLE, names_for
from edge.schema import Field, SchemaError, check_value, type_name
from edge.storage import durable
from edge.physics.geometry import PROBES
from edge.physics.probe import FLUX_SENSITIVITY_V_per_W_m2, heater_power_W

__all__ = [
    "ConfigError",
    "setting",
    "SECTIONS",
    "SCHEMA",
    "RUNTIME_KEYS",
    "HARD_MAX_ON_TIME_s",
    "HARD_MAX_TEMPERATURE_C",
    "Config",
    "load_config",
    "RuntimeOverrides",
]

log = logging.getLogger("thermotouch.edge")

#: No configuration may let the heater stay on longer than this (s).
HARD_MAX_ON_TIME_s = 30.0
#: No configuration may set the over-temperature cut above this (°C).
HARD_MAX_TEMPERATURE_C = 150.0


class ConfigError(ValueError):
    """A configuration value is wrong; ``key`` is its dotted name (or None)."""

    def __init__(self, key: str | None, message: str) -> None:
        self.key = key
        super().__init__(f"{key}: {message}" if key else message)


def setting(kind: str, default: Any, doc: str, *, runtime: bool = False, **bounds: Any) -> Any:
    """A configuration key: a dataclass field whose metadata holds its schema.

    ``runtime`` keys may be changed over the link (CONFIG_SET); the others only
    in the file on the device. A runtime string must list its ``choices``: a
    value set from afar is checked against what the device can do, never
    taken as free text.
    """
    if kind == "str":
        bounds.setdefault("hi", 4096)  # a path or a name; anything longer is a mistake
        if runtime and not bounds.get("choices"):  # a schema bug, caught at import
            raise ValueError("a runtime-settable string needs its choices")
    return field(
        default=default, metadata={"schema": Field(kind, default, doc, **bounds), "runtime": runtime}
    )


@dataclass(frozen=True)
class BoardConfig:
    """The ``[board]`` section."""

    kind: str = setting("str", "rpi", "board factory name: 'rpi', or 'sim' when the simulator registered it")
    # Not runtime: the probe head is hardware; changing it over the link would let a host make the
    # device interpret its records with the wrong geometry.
    probe: str = setting("str", "paper", "probe head mounted on the board (its geometry decides the estimator: "
                         "'paper' = 55 x 60 mm heater, 1-D; 'small-heater' = 5 mm-radius disk, axisymmetric fit)",
                         choices=tuple(PROBES))
    i2c_bus: int | str = setting("int_or_str", 1, "I2C bus number or device path", lo=0)
    gpio_chip: str = setting("str", "/dev/gpiochip0", "GPIO character device")
    heater_enable_offset: int = setting("int", 17, "heater-enable line offset", lo=0, hi=1023)
    heater_active_low: bool = setting("bool", False, "heater enable is active low")
    trigger_offset: int = setting("int", 27, "trigger-button line offset", lo=0, hi=1023)
    trigger_active_low: bool = setting("bool", True, "button pulls the line low when pressed")
    pwm_root: str = setting("str", "/sys/class/pwm", "sysfs PWM class directory")
    pwm_chip: int = setting("int", 0, "PWM chip number", lo=0, hi=64)
    pwm_channel: int = setting("int", 0, "PWM channel number", lo=0, hi=64)


def _chip_fields() -> list[tuple[str, type, Any]]:
    """The ``[sensors]`` keys of every registry chip: its address, then its own settings."""
    out: list[tuple[str, type, Any]] = []
    for spec in CHIPS.values():
        out.append((spec.setting_key("address"), int,
                    setting("int", spec.default_address, f"{spec.part} I2C address",
                            lo=min(spec.addresses), hi=max(spec.addresses))))
        for st in spec.settings:
            out.append((spec.setting_key(st.key), Any, setting(st.kind, st.default, st.doc, **st.bounds)))
    return out


#: The ``[sensors]`` section: which registry chip plays each role, every chip's settings
#: (:data:`edge.hw.chips.CHIPS`), the flux sensor's sensitivity and the I2C retry bound.
SensorsConfig = make_dataclass("SensorsConfig", [
    ("thermocouple", str, setting("str", DEFAULT_CHIPS[THERMOCOUPLE], "thermocouple converter",
                                  choices=names_for(THERMOCOUPLE))),
    ("flux_adc", str, setting("str", DEFAULT_CHIPS[FLUX], "heat-flux sensor ADC", choices=names_for(FLUX))),
    *_chip_fields(),
    ("flux_sensitivity_V_per_W_m2", float, setting(
        "float", FLUX_SENSITIVITY_V_per_W_m2, "heat-flux sensor sensitivity, V per W/m^2", lo=1e-9, hi=1e-3)),
    ("i2c_attempts", int, setting("int", 4, "tries per I2C transaction before a sensor fault", lo=1, hi=20)),
], frozen=True)
SensorsConfig.__module__ = __name__
SensorsConfig.__doc__ = "The ``[sensors]`` section (its chip keys come from :data:`edge.hw.chips.CHIPS`)."


@dataclass(frozen=True)
class HeaterConfig:
    """The ``[heater]`` section."""

    supply_voltage_V: float = setting(
        "float", 15.0, "heater supply voltage, V", lo=0.0, hi=48.0, lo_open=True
    )
    resistance_ohm: float = setting(
        "float", 44.0, "heater film resistance, ohm", lo=0.0, hi=1e4, lo_open=True
    )
    power_W: float = setting(
        "float", 5.0, "default heating power, W (<= V^2/R)", lo=0.0, hi=50.0, lo_open=True, runtime=True
    )
    max_on_time_s: float = setting(
        "float",
        10.0,
        "SAFETY: longest the heater may stay on, s",
        lo=0.0,
        hi=HARD_MAX_ON_TIME_s,
        lo_open=True,
    )
    over_temperature_C: float = setting(
        "float",
        80.0,
        "SAFETY: heater is cut above this thermocouple reading, °C",
        lo=0.0,
        hi=HARD_MAX_TEMPERATURE_C,
        lo_open=True,
    )
    pwm_period_ns: int = setting("int", 1_000_000, "PWM period, ns", lo=1000, hi=1_000_000_000)
    # Heater-fault detection (edge.measure.signal.heat_while_off / no_heat_while_on). Defaults
    # from the default sensors' noise: the ADS1115 at +-0.256 V reads 7.8 uV = 14 W/m^2 steps
    # on a 0.56 uV/(W/m^2) sensor, and a baseline passes the noise check with a flux scatter up
    # to measurement.noise_q_W_m2 = 50 W/m^2, so the mean of its >= 5 samples is within
    # ~22 W/m^2: 150 W/m^2 (about 10 steps, > 6 sigma) is heat, not noise -- and is a tenth of
    # the flux of full power (15 V on 44 ohm over 55 x 60 mm: 1550 W/m^2). The MCP9600 at 16
    # bits reads in 0.197 K steps and a baseline passes with a temperature scatter up to
    # measurement.noise_T_K = 0.1 K: a rise of 0.5 K (2.5 steps, 5 sigma) is real.
    fault_flux_W_m2: float = setting(
        "float", 150.0, "SAFETY: heater fault when this flux (W/m^2) flows with the heater off "
        "(and the temperature rises fault_rise_K), or is missing with it on", lo=0.0, hi=1e5, lo_open=True
    )
    fault_rise_K: float = setting(
        "float", 0.5, "SAFETY: temperature rise (K) that, with fault_flux_W_m2, marks heat (see there)",
        lo=0.0, hi=50.0, lo_open=True
    )
    # The duty limit beside the per-touch limit: runtime settings (cooldown_s = 0, a tiny baseline)
    # reached 99.8 % duty for 36 s, until the over-temperature cut (ISSUE #35 §6). Not a runtime key.
    max_duty: float = setting(
        "float", 0.5, "SAFETY: largest share of any duty_window_s the heater may be on (the sequence "
        "waits before a touch that would exceed it)", lo=0.0, hi=1.0, lo_open=True
    )
    duty_window_s: float = setting(
        "float", 60.0, "SAFETY: the sliding window of max_duty, s (>= max_on_time_s)", lo=1.0, hi=3600.0
    )


@dataclass(frozen=True)
class MeasurementConfig:
    """The ``[measurement]`` section."""

    baseline_s: float = setting(
        "float",
        0.5,
        "baseline before heating (T0, flux offset), s",
        lo=0.0,
        hi=10.0,
        lo_open=True,
        runtime=True,
    )
    arm_s: float = setting(
        "float",
        0.0,
        "armed: sample in air up to this long for the touch, find the contact, heat settle_s after it "
        "(0 = off: the baseline is baseline_s and heating follows it)",
        lo=0.0,
        hi=600.0,
        runtime=True,
    )
    settle_s: float = setting(
        "float",
        1.0,
        "armed: time from the detected contact to heater-on, s",
        lo=0.0,
        hi=30.0,
        runtime=True,
    )
    contact_time_s: float = setting(
        "float",
        2.0,
        "heating (contact) time, s; < heater.max_on_time_s",
        lo=0.0,
        hi=HARD_MAX_ON_TIME_s,
        lo_open=True,
        runtime=True,
    )
    # 50 Hz: the paper probe's short windows need it (bench/asbuilt_calibrated_bench.py --attribute: at
    # 10 Hz the 1-s error on the as-built probe was 4-20 % with the true calibration, at 50 Hz 0.3-3 %).
    # A board whose converter is slower samples at its own pace (edge.hw.chips.max_sample_rate_Hz caps
    # every MEASURE: the reference board's MCP9600 at 12.5 Hz), the precision board at this.
    sample_rate_Hz: float = setting(
        "float", 50.0, "sampling and resampling rate, Hz (capped at what the fitted converters deliver)",
        lo=1.0, hi=200.0, runtime=True
    )
    cooldown_s: float = setting(
        "float",
        5.0,
        "minimum rest between a heater-off and the next heating, s",
        lo=0.0,
        hi=600.0,
        runtime=True,
    )
    no_contact_e_W_s05_m2K: float = setting(
        "float", 12.0, "flag no_contact when the effusivity the heating shows (flux vs rise) is below this, "
        "W s^0.5/(m^2 K): still air 5.5, the lightest foams 28", lo=0.0, hi=1000.0, runtime=True
    )
    decide_posterior: float = setting(
        "float", 0.95, "MEASURE until_decided: stop heating once the running answer's posterior reaches this",
        lo=0.5, hi=1.0, runtime=True
    )
    decide_min_s: float = setting(
        "float", 0.3, "MEASURE until_decided: heat at least this long before deciding, s", lo=0.0, hi=60.0,
        runtime=True
    )
    noise_T_K: float = setting(
        "float",
        0.1,
        "flag noisy when the baseline temperature std exceeds this, K",
        lo=0.0,
        hi=100.0,
        lo_open=True,
        runtime=True,
    )
    noise_q_W_m2: float = setting(
        "float",
        50.0,
        "flag noisy when the baseline flux std exceeds this, W/m^2",
        lo=0.0,
        hi=1e6,
        lo_open=True,
        runtime=True,
    )
    unstable_baseline_K: float = setting(
        "float",
        0.2,
        "flag unstable_baseline when T drifts more than this over the baseline, K",
        lo=0.0,
        hi=100.0,
        lo_open=True,
        runtime=True,
    )
    trigger_button: bool = setting("bool", True, "start a measurement when the trigger button is pressed")


@dataclass(frozen=True)
class SerialConfig:
    """The ``[serial]`` section."""

    port: str = setting("str", "/dev/ttyGS0", "serial device of the host link")
    baud: int = setting(
        "int",
        115200,
        "baud rate",
        choices=(9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600, 1000000),
    )


@dataclass(frozen=True)
class PathsConfig:
    """The ``[paths]`` section."""

    model_store: str = setting("str", "/var/lib/thermotouch/models", "model store root directory")
    factory_model: str = setting(
        "str", "", "factory bundle directory ('' = the bundle shipped with the package)"
    )
    history_db: str = setting("str", "/var/lib/thermotouch/history.sqlite3", "SQLite measurement history")
    object_sets: str = setting(
        "str", "", "object-set store directory ('' = 'objects' beside the model store)"
    )
    calibration: str = setting(
        "str", "", "probe calibration store directory ('' = 'calibration' beside the model store)"
    )
    runtime_overrides: str = setting(
        "str",
        "/var/lib/thermotouch/runtime.json",
        "where CONFIG_SET persists its values ('' = not persisted)",
    )


@dataclass(frozen=True)
class EstimationConfig:
    """The ``[estimation]`` section."""

    method: str = setting(
        "str", "default", "estimation method passed to the estimator", choices=METHODS, runtime=True
    )


@dataclass(frozen=True)
class WatchdogConfig:
    """The ``[watchdog]`` section."""

    device: str = setting(
        "str", "", "hardware watchdog device pet with systemd's watchdog, e.g. '/dev/watchdog' ('' = off)"
    )


@dataclass(frozen=True)
class LoggingConfig:
    """The ``[logging]`` section."""

    level: str = setting(
        "str", "INFO", "log level", choices=("DEBUG", "INFO", "WARNING", "ERROR"), runtime=True
    )


@dataclass(frozen=True)
class LimitsConfig:
    """The ``[limits]`` section."""

    ram_bytes: int = setting(
        "int", 512 * 1024 * 1024, "device RAM, bytes; model bundle bounds are derived from it",
        lo=64 * 1024 * 1024, hi=64 * 1024 ** 3,
    )


@dataclass(frozen=True)
class SecurityConfig:
    """The ``[security]`` section (file only: never settable over the link)."""

    trusted_keys_dir: str = setting(
        "str", "/etc/thermotouch/trusted_keys",
        "directory of trusted public key files (thermotouch keys new writes NAME.public.json); '' = none",
    )
    allow_unsigned: bool = setting(
        "bool", False, "accept model updates without a signature (development devices and simulators only)"
    )


#: Section name -> its typed, frozen dataclass; the schema is read off their fields.
SECTIONS: Mapping[str, type] = MappingProxyType(
    {
        "board": BoardConfig,
        "sensors": SensorsConfig,
        "heater": HeaterConfig,
        "measurement": MeasurementConfig,
        "serial": SerialConfig,
        "paths": PathsConfig,
        "estimation": EstimationConfig,
        "watchdog": WatchdogConfig,
        "logging": LoggingConfig,
        "limits": LimitsConfig,
        "security": SecurityConfig,
    }
)

#: Section -> key -> :class:`edge.schema.Field` (derived from :data:`SECTIONS`).
SCHEMA: Mapping[str, Mapping[str, Field]] = MappingProxyType(
    {
        name: MappingProxyType({f.name: f.metadata["schema"] for f in fields(cls)})
        for name, cls in SECTIONS.items()
    }
)

#: Dotted keys settable over the link (CONFIG_SET).
RUNTIME_KEYS: tuple[str, ...] = tuple(
    f"{s}.{f.name}" for s, cls in SECTIONS.items() for f in fields(cls) if f.metadata["runtime"]
)


#: Value types a deep copy returns as they are (:meth:`Config.to_dict`).
_IMMUTABLE_SCALARS = (str, int, float, bool, type(None))


def _check_value(key: str, spec: Field, value: Any) -> Any:
    """Validate one value; return it normalised (ints accepted for floats)."""
    try:
        return check_value(spec, value, key)
    except SchemaError as e:
        raise ConfigError(e.path, e.message) from None


def _lookup(key: str) -> Field:
    if not isinstance(key, str) or key.count(".") != 1:
        raise ConfigError(str(key), "unknown key (expected 'section.name')")
    section, name = key.split(".")
    if section not in SCHEMA:
        raise ConfigError(key, f"unknown section {section!r}; known: {sorted(SCHEMA)}")
    if name not in SCHEMA[section]:
        raise ConfigError(key, f"unknown key; {section} has {sorted(SCHEMA[section])}")
    return SCHEMA[section][name]


def _check_consistency(v: Mapping[str, Mapping[str, Any]]) -> None:
    """Cross-key rules; each error names the key that has to change."""
    h, m = v["heater"], v["measurement"]
    p_max = heater_power_W(1.0, h["supply_voltage_V"], h["resistance_ohm"])
    if h["power_W"] > p_max * (1 + 1e-12):
        raise ConfigError(
            "heater.power_W", f"{h['power_W']} W exceeds the supply's maximum V^2/R = {p_max:.4g} W"
        )
    if m["contact_time_s"] >= h["max_on_time_s"]:
        raise ConfigError(
            "measurement.contact_time_s",
            f"{m['contact_time_s']} s must be below heater.max_on_time_s = {h['max_on_time_s']} s",
        )
    if h["duty_window_s"] < h["max_on_time_s"]:
        raise ConfigError("heater.duty_window_s",
                          f"{h['duty_window_s']} s must be at least heater.max_on_time_s = {h['max_on_time_s']} s")
    if m["contact_time_s"] > h["max_duty"] * h["duty_window_s"]:
        raise ConfigError("measurement.contact_time_s", f"{m['contact_time_s']} s is more heating than "
                          f"heater.max_duty x duty_window_s = {h['max_duty'] * h['duty_window_s']:g} s allows")
    b = v["board"]
    if b["heater_enable_offset"] == b["trigger_offset"] and b["kind"] == "rpi":
        raise ConfigError("board.trigger_offset", "must differ from board.heater_enable_offset")
    if not v["paths"]["model_store"]:
        raise ConfigError("paths.model_store", "must not be empty")
    if not v["paths"]["history_db"]:
        raise ConfigError("paths.history_db", "must not be empty")


class Config:
    """A validated configuration (immutable; changes give a new object).

    Sections are attributes holding read-only namespaces::

        cfg.heater.power_W, cfg.measurement.sample_rate_Hz

    Parameters
    ----------
    values : mapping of section -> mapping of key -> value, optional
        Values overriding the defaults (e.g. the parsed TOML). Validated.
    source : str, optional
        Where the values came from (for messages).
    """

    def __init__(self, values: Mapping[str, Any] | None = None, *, source: str = "<defaults>") -> None:
        self.source = source
        merged: dict[str, dict[str, Any]] = {
            s: {k: spec.default for k, spec in keys.items()} for s, keys in SCHEMA.items()
        }
        values = {} if values is None else values
        if not isinstance(values, Mapping):
            raise ConfigError(None, f"configuration must be a table, got {type_name(values)}")
        for section, table in values.items():
            if section not in SCHEMA:
                raise ConfigError(str(section), f"unknown section; known: {sorted(SCHEMA)}")
            if not isinstance(table, Mapping):
                raise ConfigError(str(section), f"must be a table, got {type_name(table)}")
            for name, value in table.items():
                key = f"{section}.{name}"
                spec = _lookup(key)
                merged[section][name] = _check_value(key, spec, value)
        _check_consistency(merged)
        self._values = merged

    # -- access ------------------------------------------------------------------
    def __getattr__(self, section: str) -> Any:
        """The section as its typed, frozen dataclass (e.g. ``cfg.heater`` is a :class:`HeaterConfig`)."""
        values = self.__dict__.get("_values")
        if values is None or section not in values:
            raise AttributeError(section)
        return SECTIONS[section](**values[section])

    def get(self, key: str) -> Any:
        """Value of dotted ``key`` (ConfigError if unknown)."""
        _lookup(key)
        section, name = key.split(".")
        return self._values[section][name]

    def to_dict(self) -> dict[str, dict[str, Any]]:
        """Deep copy as ``{section: {key: value}}``."""
        # Table by table: every schema kind is a scalar, which a deep copy returns as it is; only anything
        # else goes through copy.deepcopy (one memo, so shared objects stay shared, as in one deepcopy of the
        # whole). The same dict as ``copy.deepcopy(self._values)`` at a tenth of its cost: a daemon's start
        # applies its stored overrides through it, one key at a time.
        memo: dict[int, Any] = {}
        return {s: {k: v if type(v) in _IMMUTABLE_SCALARS else copy.deepcopy(v, memo) for k, v in t.items()}
                for s, t in self._values.items()}

    def flat(self, keys: Iterable[str] | None = None) -> dict[str, Any]:
        """``{"section.key": value}`` for all keys or the given ones."""
        if keys is None:
            return {f"{s}.{k}": v for s, t in self._values.items() for k, v in t.items()}
        return {k: self.get(k) for k in keys}

    def runtime(self) -> dict[str, Any]:
        """The runtime-settable subset, flat."""
        return self.flat(RUNTIME_KEYS)

    def with_updates(self, updates: Mapping[str, Any], *, runtime_only: bool = True) -> Config:
        """A new Config with dotted-key ``updates`` applied and everything re-validated.

        Raises
        ------
        ConfigError
            Unknown key, a key not settable at run time (``runtime_only``),
            wrong type, out of range, or inconsistent with other keys.
        """
        if not isinstance(updates, Mapping):
            raise ConfigError(None, "updates must be a mapping of 'section.key' to values")
        values = self.to_dict()
        for key, value in updates.items():
            spec = _lookup(key)
            if runtime_only and key not in RUNTIME_KEYS:
                raise ConfigError(key, "cannot be changed at run time (edit the configuration file)")
            section, name = key.split(".")
            values[section][name] = _check_value(key, spec, value)
        return Config._checked(values, self.source)

    @classmethod
    def _checked(cls, values: dict[str, dict[str, Any]], source: str) -> Config:
        """A Config of complete ``values`` whose every value has passed its check (the cross-key rules not yet).

        What ``Config(values)`` gives for them: checking a checked value again returns it unchanged (every
        kind normalises to itself), so only the cross-key rules, which an update may break, run again.
        """
        _check_consistency(values)
        cfg = cls.__new__(cls)
        cfg.source = source
        cfg._values = values
        return cfg

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Config) and other._values == self._values

    def __repr__(self) -> str:
        return f"<Config from {self.source}>"


def load_config(path: str | os.PathLike | None, *, overrides: Mapping[str, Any] | None = None) -> Config:
    """Read and validate a TOML configuration file (None = defaults only).

    ``overrides`` are dotted runtime keys applied on top (validated).

    Raises
    ------
    ConfigError
        Unreadable file, bad TOML (with line/column), or a bad key.
    """
    if path is None:
        cfg = Config()
    else:
        p = Path(path)
        try:
            raw = p.read_bytes()
        except OSError as e:
            raise ConfigError(None, f"cannot read configuration {p}: {e.strerror or e}") from e
        try:
            data = tomllib.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
            raise ConfigError(None, f"{p}: not valid TOML: {e}") from e
        cfg = Config(data, source=str(p))
    if overrides:
        cfg = cfg.with_updates(overrides)
    return cfg


class RuntimeOverrides:
    """Persisted CONFIG_SET values: a JSON object of dotted runtime keys.

    Written with write-temp / fsync / rename / fsync-dir, so a power cut
    leaves the old or the new set. A file that is unreadable or holds
    values that no longer validate is ignored key by key at load (reported
    in :attr:`errors`), never fatal: the file configuration still applies.

    Parameters
    ----------
    path : path-like or None
        File location; None keeps overrides in memory only.
    """

    def __init__(self, path: str | os.PathLike | None) -> None:
        self.path = Path(path) if path else None
        self.errors: list[str] = []

    def load(self, base: Config) -> Config:
        """Apply the stored overrides to ``base``; bad entries are skipped."""
        self.errors = []
        if self.path is None or not self.path.exists():
            return base
        try:
            data = json.loads(self.path.read_text("utf-8"))
            if not isinstance(data, dict):
                raise ValueError("not a JSON object")
        except (OSError, ValueError) as e:
            self.errors.append(f"{self.path}: {e}")
            return base
        cfg = base
        for key, value in data.items():
            try:
                cfg = cfg.with_updates({key: value})
            except ConfigError as e:
                self.errors.append(str(e))
        return cfg

    def clean_temporaries(self) -> None:
        """Remove temp files a crash left beside the overrides file (``.runtime.json.tmp<pid>``)."""
        if self.path is not None:
            for p in durable.remove_stray_temporaries(self.path):
                log.warning("removed stray temporary %s", p)

    def save(self, cfg: Config, base: Config) -> None:
        """Persist the runtime keys where ``cfg`` differs from ``base``."""
        if self.path is None:
            return
        diff = {k: v for k, v in cfg.runtime().items() if base.get(k) != v}
        self.path.parent.mkdir(parents=True, exist_ok=True)
        durable.atomic_write_file(self.path, json.dumps(diff, indent=1, sort_keys=True).encode("utf-8"))
