"""The daemon's process: ``thermotouch-edge --config FILE``.

Start-up order matters: the configuration is parsed, then the real heater is
driven OFF through its enable line and PWM (:func:`force_heater_off`, no I2C
needed), the board is built and the :class:`~edge.service.daemon.Daemon`
constructed (which drives the heater off again before anything else), and
only then is the serial port opened. SIGTERM and SIGINT set the stop event
(:func:`install_signal_handlers`); the daemon, then the board are closed.

:func:`run_daemon` runs the same daemon on a given board and an open
pyserial-like port (the simulator and the tests run it in a thread).
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from typing import Any, Callable

import serial

from edge.hw.board import Board, force_rpi_heater_off, make_board
from edge.measure.sequence import EstimatorFn
from edge.service.config import Config, ConfigError, load_config
from edge.service.daemon import FIRMWARE_VERSION, Daemon

__all__ = ["board_from_config", "run_daemon", "install_signal_handlers", "force_heater_off", "main"]

log = logging.getLogger("thermotouch.edge")


def board_from_config(cfg: Config) -> Board:
    """Build the board named by ``[board] kind`` with the ``[board]`` options."""
    b = cfg.board
    if b.kind == "rpi":
        return make_board("rpi", i2c_bus=b.i2c_bus, gpio_chip=b.gpio_chip,
                          heater_enable_offset=b.heater_enable_offset, heater_active_low=b.heater_active_low,
                          trigger_offset=b.trigger_offset, trigger_active_low=b.trigger_active_low,
                          pwm_root=b.pwm_root, pwm_chip=b.pwm_chip, pwm_channel=b.pwm_channel)
    return make_board(b.kind)


def run_daemon(config: Config, board: Board, serial_port: Any, stop_event: threading.Event, *,
               estimator: EstimatorFn | None = None, ready: Callable[[Daemon], None] | None = None,
               **kwargs: Any) -> None:
    """Run a daemon on ``board`` answering ``serial_port`` until ``stop_event`` is set.

    Blocking; run it in a thread for the simulator (see
    :class:`firmware_sim.daemon_thread.DaemonThread`). ``ready(daemon)`` is
    called once the daemon answers. The heater is off and the history closed
    when this returns, whatever happened.
    """
    daemon = Daemon(config, board, estimator=estimator, stop_event=stop_event, **kwargs)
    try:
        if ready is not None:
            ready(daemon)
        daemon.serve(serial_port, stop_event)
    finally:
        daemon.close()


def install_signal_handlers(stop_event: threading.Event) -> None:
    """SIGTERM and SIGINT set ``stop_event`` (call from the main thread).

    The handler only sets the event: the heater watchdog then cuts a running
    heating within its poll period, the sampling loop ends, the serve loop
    returns and :meth:`Daemon.close` runs. Switching the heater from inside
    the handler could interleave with a half-finished ``Heater.on``.
    """

    def on_signal(signum: int, _frame: Any) -> None:
        log.info("signal %s: stopping", signal.Signals(signum).name)
        stop_event.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)


def _parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="thermotouch-edge", description="ThermoTouch probe daemon")
    p.add_argument("--config", required=True, help="TOML configuration file")
    p.add_argument("--check-config", action="store_true", help="validate the configuration and exit")
    p.add_argument("--heater-off", action="store_true",
                   help="drive the heater off (enable line and PWM, no I2C needed) and exit; for ExecStopPost")
    return p.parse_args(argv)


def force_heater_off(cfg: Config) -> list[str]:
    """Drive the configured real heater off before (or without) building the board.

    Returns
    -------
    list of str
        What could not be driven off (empty on success).
    """
    b = cfg.board
    if b.kind != "rpi":
        return []  # simulated boards start with the heater off; Daemon() drives it off again
    return force_rpi_heater_off(gpio_chip=b.gpio_chip, heater_enable_offset=b.heater_enable_offset,
                                heater_active_low=b.heater_active_low, pwm_root=b.pwm_root,
                                pwm_chip=b.pwm_chip, pwm_channel=b.pwm_channel)


def main(argv: list[str] | None = None) -> int:
    """``thermotouch-edge --config FILE``: exit status 0 on a clean stop, 1 on failure, 2 on bad config."""
    args = _parse_args(argv)
    logging.basicConfig(stream=sys.stderr, level=logging.INFO,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        cfg = load_config(args.config)
    except ConfigError as e:
        print(f"thermotouch-edge: bad configuration: {e}", file=sys.stderr)
        return 2
    if args.check_config:
        print(f"{args.config}: OK", file=sys.stderr)
        return 0
    # Heater off before anything that can fail (I2C, model store, serial port).
    failures = force_heater_off(cfg)
    for f in failures:
        log.critical("cannot drive the heater off: %s", f)
    if args.heater_off:
        return 1 if failures else 0
    stop = threading.Event()
    install_signal_handlers(stop)
    try:
        board = board_from_config(cfg)
    except Exception as e:
        log.critical("cannot build board %r: %s", cfg.board.kind, e)
        return 1
    try:
        daemon = Daemon(cfg, board, stop_event=stop)
    except Exception as e:
        log.critical("start-up failed: %s", e)
        board.close()
        return 1
    log.info("thermotouch-edge %s on board %s, serial %s", FIRMWARE_VERSION, board.name, cfg.serial.port)
    status = 0
    try:
        while not stop.is_set():
            try:
                with serial.Serial(cfg.serial.port, cfg.serial.baud, timeout=0.05, exclusive=True) as ser:
                    daemon.serve(ser, stop)
            except (serial.SerialException, OSError) as e:
                # The link can come and go (USB gadget unplugged): heater is off, retry.
                log.warning("serial port %s: %s; retrying", cfg.serial.port, e)
                stop.wait(1.0)
    except Exception:
        log.exception("daemon failed")
        status = 1
    finally:
        try:
            daemon.close()
        except Exception as e:
            log.critical("shutdown: %s", e)
            status = 1
        try:
            board.close()
        except Exception as e:
            log.error("closing the board: %s", e)
    log.info("stopped")
    return status


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
