"""Run the daemon on the sim rig in this process's main thread, as thermotouch-edge does.

Usage: python daemon_proc.py TMPDIR

Prints the host-side port on the first line, ``HEATING`` when the fifth heating
read starts (that read waits in wall time until the heater is cut, so a
signal sent on ``HEATING`` always arrives mid-heating), and at exit one JSON
line with the heater invariant (from the simulated hardware) and the stored
records; the exit status is the one ``thermotouch-edge`` would return.

Like ``thermotouch-edge`` it handles every catchable signal, drives the
heater off at exit, and speaks systemd's notify protocol when
``NOTIFY_SOCKET`` is set. The simulated GPIO line states and PWM tree live
in ``TMPDIR/gpio`` and ``TMPDIR/pwm``
(:func:`firmware_sim.gpiod.state.read_line`), readable after this process
is killed.
"""

import json
import sys
import threading
import time
from pathlib import Path

# This checkout's edge and firmware_sim, not whichever one the venv has installed, and the test helpers.
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import serial  # noqa: E402

from tests.support.daemons import FakeEstimator, HookedSensors, sim_config  # noqa: E402
from edge.service.daemon import Daemon  # noqa: E402
from edge.service.main import install_signal_handlers  # noqa: E402
from firmware_sim.rigs.daemon_rig import heater_invariant, make_rig  # noqa: E402
from firmware_sim.ptylink import NullModem  # noqa: E402


def main() -> int:
    tmp = Path(sys.argv[1])
    rig = make_rig(gpio_state_dir=tmp / "gpio", pwm_root=tmp / "pwm")
    cfg = sim_config(tmp)
    stop = threading.Event()
    built = {}
    handlers = install_signal_handlers(stop, heater_off=lambda: built["daemon"].heater.off())
    nm = NullModem()
    port = serial.Serial(nm.device_port, timeout=0.05)
    built["daemon"] = daemon = Daemon(cfg, rig.board, estimator=FakeEstimator(), stop_event=stop)
    daemon.notifier.ready()

    heating_reads = []

    def hook(n, heater_on):
        if heater_on:
            heating_reads.append(n)
        if len(heating_reads) == 5 and heater_on:
            print("HEATING", flush=True)
            t_end = time.monotonic() + 20.0
            while rig.parts.chip.level(rig.parts.heater_enable_offset) == 1 and time.monotonic() < t_end:
                time.sleep(0.005)

    daemon.sensors = HookedSensors(daemon.sensors, daemon.heater, hook)
    print(nm.host_port, flush=True)
    try:
        daemon.serve(port, stop)
    finally:
        daemon.close()
    inv = heater_invariant(rig.parts, cfg.heater.max_on_time_s)
    from edge.storage.history import History

    with History(cfg.paths.history_db) as h:
        _, items = h.page(0, 10)
    print(json.dumps({"invariant": inv, "records": items, "history_closed": daemon.history.closed}), flush=True)
    port.close()
    nm.close()
    return handlers.exit_status()


if __name__ == "__main__":
    sys.exit(main())
