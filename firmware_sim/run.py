"""``thermotouch sim SCENE.toml``: the edge daemon on a simulated probe behind a virtual serial cable.

:func:`run_sim` loads the scene, builds a daemon configuration that matches
the scene's board (chips and addresses, heater supply and resistance, flux
sensitivity, touch timing), opens a :class:`~firmware_sim.ptylink.NullModem`,
prints the host-side port path as the first line of output and runs the
daemon until stopped (SIGTERM/SIGINT when run from the main thread, or the
given stop event). Virtual time only advances while the daemon measures, so
a host that sends MEASURE right away meets the scene's touch.

The edge daemon itself never imports this package; the simulator hands it a
board.
"""

from __future__ import annotations

import argparse
import logging
import shutil
import sys
import tempfile
import threading
from pathlib import Path
from typing import Any, Callable, Mapping

import serial

from edge.estimation.seam import MethodFn
from edge.hw.chips import CHIPS, FLUX, ROLES, THERMOCOUPLE, names_for
from edge.measure.profiles import probe_profile, probe_settings
from edge.service.config import Config
from edge.service.main import install_signal_handlers, run_daemon
from firmware_sim.ptylink import NullModem
from firmware_sim.simulator import load_scene

__all__ = ["config_for_scene", "run_sim", "main"]

log = logging.getLogger("thermotouch.sim")


def _reader_for(role: str, fitted: Mapping[str, int]) -> str:
    """The fitted chip that reads ``role``: one that reads both sensors wins whenever fitted.

    That is the 24-bit ADS122C04: a metal rises ~0.1 K in 2 s, below what the MCP9600 resolves (an
    MCP9600 fitted beside it is only a cold-junction alternative), and its flux reading has 24 bits
    against the ADS1115's 14 W/m^2 steps, a few per cent of the small heater's flux.
    """
    able = [name for name in names_for(role) if name in fitted]
    both = [name for name in able if set(ROLES) <= set(CHIPS[name].roles)]
    return (both or able)[0]


def config_for_scene(scene: Any, workdir: str | Path, overrides: Mapping[str, Mapping[str, Any]] | None = None
                     ) -> Config:
    """A daemon :class:`~edge.service.config.Config` matching ``scene`` (a firmware_sim Scene).

    Heating runs at full duty (the paper applies a fixed voltage); the
    baseline lasts until the scene's heater-on time (the touch's start plus
    ``[touch] contact_lead_s``) and the heating ends before the touch does.
    The configuration carries the nominal probe (``[heater]``, ``[sensors]``),
    never the scene's ``[as_built]`` deviations. ``overrides`` are extra ``{section: {key: value}}``.

    A simulated probe is a development device: it accepts unsigned model
    updates (``security.allow_unsigned``), so ``thermotouch demo`` and
    ``flash --sim`` work without a key, and it trusts the public key files in
    ``WORKDIR/trusted_keys`` (signed updates are checked as on a real probe:
    a bad or untrusted signature, or a signed downgrade without ``--force``,
    is refused).
    """
    w = Path(workdir)
    b, s, t = scene.board, scene.sensors, scene.touch
    sensors: dict[str, Any] = {"flux_sensitivity_V_per_W_m2": s.flux_sensitivity_V_per_W_m2}
    # The chips the scene fits, at their addresses; each role read by a fitted chip that can play it.
    fitted = {name: b.address_of(name) for name in CHIPS if b.address_of(name) is not None}
    sensors["thermocouple"] = _reader_for(THERMOCOUPLE, fitted)
    sensors["flux_adc"] = _reader_for(FLUX, fitted)
    sensors.update({CHIPS[name].setting_key("address"): address for name, address in fitted.items()})
    # Heating begins [touch] contact_lead_s after the touch does (0: as it does) and ends before the lift.
    on = t.heater_on_s
    baseline = min(on, 10.0) if on >= 0.2 else 0.5
    contact = max(0.5, min(2.0, t.end_s - on - 0.3))
    values: dict[str, dict[str, Any]] = {
        # The device is told which probe head is mounted (hardware it knows), never how it deviates.
        "board": {"kind": "sim", "probe": b.probe},
        "sensors": sensors,
        "heater": {"supply_voltage_V": scene.heater.supply_voltage_V, "resistance_ohm": scene.heater.resistance_ohm,
                   "power_W": scene.heater.max_power_W},
        "measurement": {"baseline_s": baseline, "contact_time_s": contact, "trigger_button": False},
        "paths": {"model_store": str(w / "models"), "history_db": str(w / "history.sqlite3"),
                  "runtime_overrides": str(w / "runtime.json")},
        "security": {"allow_unsigned": True, "trusted_keys_dir": str(w / "trusted_keys")},
    }
    for section, table in (overrides or {}).items():
        values.setdefault(section, {}).update(table)
    if probe_profile(b.probe) is not None:
        # A probe head with its own profile (the small-heater probe: 5 s at 50 Hz to resolve k and
        # alpha) heats as long as the scene's touch allows, sampled as fast as its converters convert.
        # What the caller overrode stays.
        sens = Config({"sensors": values["sensors"]}).sensors
        got = probe_settings(b.probe, sens, max(0.5, t.end_s - on - 0.3))
        m = (overrides or {}).get("measurement", {})
        for key, v in (got or {}).items():
            if key not in m:
                values["measurement"][key] = v
    return Config(values, source=f"scene {scene.name}")


def run_sim(scene_path: str | Path, stop_event: threading.Event | None = None,
            print_port: Callable[[str], None] = print, *, estimator: MethodFn | None = None,
            workdir: str | Path | None = None, overrides: Mapping[str, Mapping[str, Any]] | None = None,
            on_ready: Callable[[Any, Any], None] | None = None) -> int:
    """Run the daemon on the scene's simulator behind a NullModem until stopped.

    Parameters
    ----------
    scene_path : str or path
        Scene file or shipped scene name.
    stop_event : threading.Event, optional
        Stops the daemon when set. If None and called from the main thread,
        SIGTERM and SIGINT stop it.
    print_port : callable
        Receives the host-side port path first (default: ``print``, flushed).
    estimator : callable, optional
        The probe head's estimator on the uniform grid (tests, benches); default: the model store's bundle
        through the registry (:mod:`edge.estimation.methods`). The answer is always the seam's.
    workdir : path, optional
        Model store, history and runtime settings (default: a temporary
        directory removed at exit).
    on_ready : callable (daemon, simulator), optional
        Called once the daemon answers (tests use it).

    Returns
    -------
    int
        Exit status (0 on a clean stop).
    """
    stop = stop_event if stop_event is not None else threading.Event()
    if stop_event is None and threading.current_thread() is threading.main_thread():
        install_signal_handlers(stop)
    sim = load_scene(scene_path)
    sim.repeat_touches()  # touch after touch, unless the scene says [touch] repeat = false
    tmp = None
    if workdir is None:
        tmp = tempfile.mkdtemp(prefix="thermotouch-sim-")
        workdir = tmp
    try:
        cfg = config_for_scene(sim.scene, workdir, overrides)
        with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
            if print_port is print:
                print(nm.host_port, flush=True)
            else:
                print_port(nm.host_port)
            ready = (lambda d: on_ready(d, sim)) if on_ready is not None else None
            run_daemon(cfg, sim.board(), port, stop, estimator=estimator, ready=ready)
        return 0
    finally:
        sim.close()
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def main(argv: list[str] | None = None) -> int:
    """``python -m firmware_sim.run SCENE``: see :func:`run_sim`."""
    p = argparse.ArgumentParser(prog="thermotouch-sim", description=__doc__.splitlines()[0])
    p.add_argument("scene", help="scene file or shipped scene name")
    p.add_argument("--workdir", help="keep model store and history here")
    a = p.parse_args(argv)
    logging.basicConfig(stream=sys.stderr, level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    return run_sim(a.scene, workdir=a.workdir)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
