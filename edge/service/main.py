"""The daemon's process: ``thermotouch-edge --config FILE``.

Start-up order matters: the configuration is parsed, then the real heater is
driven OFF through its enable line and PWM (:func:`force_heater_off`, no I2C
needed), the board is built and the :class:`~edge.service.daemon.Daemon`
constructed (which drives the heater off again before anything else), and
only then is the serial port opened. Every catchable signal whose default
would end the process sets the stop event (:func:`install_signal_handlers`);
the daemon, then the board are closed, and interpreter exit (``atexit``)
drives the heater off once more.

What cannot be caught -- SIGKILL, the OOM killer, a crash in C, a frozen
process -- is left to the hardware: the heater's enable line is requested
biased towards inactive, so the kernel's release of the dead process's
lines lets it fall inactive (:meth:`edge.hw.board.GpioLine.request_fail_safe_output`);
a frozen daemon stops petting systemd's watchdog (``Type=notify``,
``WatchdogSec=``, :mod:`edge.service.notify`), which kills it; and the unit's
``ExecStopPost=... --heater-off`` drives the heater off again.

:func:`run_daemon` runs the same daemon on a given board and an open
pyserial-like port (the simulator and the tests run it in a thread).
"""

from __future__ import annotations

import argparse
import atexit
import logging
import signal
import sys
import threading
from typing import Any, Callable, Iterable

import serial

from edge.hw.board import Board, force_rpi_heater_off, make_board
from edge.estimation.seam import MethodFn
from edge.service.config import Config, ConfigError, load_config
from edge.service.daemon import FIRMWARE_VERSION, Daemon
from edge.service.notify import Notifier

__all__ = ["board_from_config", "run_daemon", "STOP_SIGNALS", "SignalHandlers", "install_signal_handlers",
           "force_heater_off", "main"]

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
               estimator: MethodFn | None = None, ready: Callable[[Daemon], None] | None = None,
               **kwargs: Any) -> None:
    """Run a daemon on ``board`` answering ``serial_port`` until ``stop_event`` is set.

    Blocking; run it in a thread for the simulator (see
    :class:`firmware_sim.daemon_thread.DaemonThread`). ``ready(daemon)`` is
    called once the daemon answers. The heater is off and the history closed
    when this returns, whatever happened.
    """
    daemon = Daemon(config, board, estimator=estimator, stop_event=stop_event, **kwargs)
    try:
        daemon.serve(serial_port, stop_event, ready=ready)
    finally:
        daemon.close()


#: Never handled: uncatchable (KILL, STOP); synchronous faults, after which a Python handler
#: would return to the faulting instruction (SEGV, BUS, FPE, ILL: faulthandler's, and the
#: hardware fail-safe's); and those whose default does not end the process (CHLD, CONT, URG,
#: WINCH). Job control (TSTP, TTIN, TTOU) would freeze a daemon that may be heating: ignored.
_NOT_HANDLED = frozenset({"SIGKILL", "SIGSTOP", "SIGSEGV", "SIGBUS", "SIGFPE", "SIGILL",
                          "SIGCHLD", "SIGCONT", "SIGURG", "SIGWINCH"})
_JOB_CONTROL = ("SIGTSTP", "SIGTTIN", "SIGTTOU")


def _name(signum: int) -> str:
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"SIGRTMIN+{signum - signal.SIGRTMIN}" if hasattr(signal, "SIGRTMIN") else f"signal {signum}"


#: Every signal that ends the process by default and can be caught: HUP, INT, QUIT, TRAP,
#: ABRT, USR1, USR2, PIPE, ALRM, TERM, STKFLT, XCPU, XFSZ, VTALRM, PROF, IO, PWR, SYS and the
#: real-time signals (the platform's list, from :func:`signal.valid_signals`).
STOP_SIGNALS: tuple[int, ...] = tuple(sorted(
    int(s) for s in signal.valid_signals()
    if _name(int(s)) not in _NOT_HANDLED and _name(int(s)) not in _JOB_CONTROL))


class SignalHandlers:
    """What :func:`install_signal_handlers` installed: the signals received, and a way to undo it."""

    def __init__(self) -> None:
        #: Signal numbers received, in order.
        self.received: list[int] = []
        self._old: dict[int, Any] = {}
        self._at_exit: Callable[[], None] | None = None

    def exit_status(self) -> int:
        """0 after SIGTERM/SIGINT (an asked-for stop) or none; 128 + n after any other signal n.

        A stop by any other signal is not a clean one: a non-zero status makes
        systemd (``Restart=on-failure``) start the daemon again.
        """
        if not self.received or self.received[0] in (signal.SIGTERM, signal.SIGINT):
            return 0
        return 128 + self.received[0]

    def restore(self) -> None:
        """Put the previous handlers back and drop the ``atexit`` heater-off (tests)."""
        for s, h in self._old.items():
            try:
                signal.signal(s, h)
            except (OSError, ValueError, TypeError):
                pass
        self._old.clear()
        if self._at_exit is not None:
            atexit.unregister(self._at_exit)
            self._at_exit = None


def install_signal_handlers(stop_event: threading.Event, *, heater_off: Callable[[], None] | None = None,
                            wake: Callable[[], None] | None = None,
                            signals: Iterable[int] = STOP_SIGNALS) -> SignalHandlers:
    """Every catchable ending signal sets ``stop_event``; ``heater_off`` runs at exit (main thread only).

    Before, SIGHUP, SIGQUIT, SIGUSR1 or SIGALRM during a heating ended the
    process on the spot, leaving the enable line active and the PWM at full
    duty. Now every signal in ``signals`` (default :data:`STOP_SIGNALS`,
    which includes SIGPIPE: Python ignores it, but then a stop signal sent
    as SIGPIPE would pass unnoticed) stops the daemon in order; job-control
    stops (TSTP, TTIN, TTOU) are ignored.

    The handler only sets the event (and wakes the serve loop, below): the
    heater watchdog then cuts a running heating within its poll period, the
    sampling loop ends, the serve loop returns and :meth:`Daemon.close` runs.
    Switching the heater from inside the handler could interleave with a
    half-finished ``Heater.on``.
    ``heater_off`` is registered with :mod:`atexit`, for an exit that skips
    the daemon's own clean-up (an exception escaping ``main``, ``sys.exit``
    from a library); its errors are logged, never raised.
    ``wake`` is called by the signal that sets the event (once): the serve
    loop waits in a read of the port and would otherwise see the event only
    when that read times out (:meth:`~edge.service.daemon.Daemon.wake`); its
    errors are logged, never raised.

    Returns
    -------
    SignalHandlers
        The signals received (for the exit status) and ``restore()``.
    """
    h = SignalHandlers()

    def on_signal(signum: int, _frame: Any) -> None:
        h.received.append(signum)
        log.warning("signal %s: stopping (heater off)", _name(signum))
        first = not stop_event.is_set()
        stop_event.set()
        if first and wake is not None:  # once: a stopping loop needs no second wake-up
            try:
                wake()
            except Exception as e:  # noqa: BLE001 - the stop event is set; the loop sees it at its next poll
                log.error("waking the serve loop failed: %s", e)

    for s in signals:
        try:
            h._old[s] = signal.signal(s, on_signal)
        except (OSError, ValueError) as e:  # reserved by the C library or the platform
            log.debug("cannot handle %s: %s", _name(s), e)
    for name in _JOB_CONTROL:
        s = getattr(signal, name, None)
        if s is not None:
            h._old[s] = signal.signal(s, signal.SIG_IGN)
    if heater_off is not None:
        def at_exit() -> None:
            try:
                heater_off()
            except BaseException as e:  # noqa: BLE001 - exit goes on; say why the heater may be on
                log.critical("heater off at exit failed: %s", e)

        h._at_exit = at_exit
        atexit.register(at_exit)
    return h


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
    built: dict[str, Any] = {}

    def heater_off_at_exit() -> None:
        d = built.get("daemon")
        if d is not None and not d.heater.closed:
            d.heater.off()
        else:  # the line is free again: drive it like ExecStopPost does
            for f in force_heater_off(cfg):
                log.critical("at exit, cannot drive the heater off: %s", f)

    def wake_serve_loop() -> None:
        d = built.get("daemon")
        if d is not None:
            d.wake()

    handlers = install_signal_handlers(stop, heater_off=heater_off_at_exit, wake=wake_serve_loop)
    try:
        board = board_from_config(cfg)
    except Exception as e:
        log.critical("cannot build board %r: %s", cfg.board.kind, e)
        handlers.restore()
        return 1
    try:
        notifier = Notifier(hw_watchdog=cfg.watchdog.device)
        built["daemon"] = daemon = Daemon(cfg, board, stop_event=stop, notifier=notifier)
    except Exception as e:
        log.critical("start-up failed: %s", e)
        board.close()
        handlers.restore()
        return 1
    log.info("thermotouch-edge %s on board %s, serial %s", FIRMWARE_VERSION, board.name, cfg.serial.port)
    notifier.ready(f"serving {cfg.serial.port}")
    status = 0
    try:
        while not stop.is_set():
            try:
                with serial.Serial(cfg.serial.port, cfg.serial.baud, timeout=0.05, exclusive=True) as ser:
                    daemon.serve(ser, stop)
            except (serial.SerialException, OSError) as e:
                # The link can come and go (USB gadget unplugged): heater is off, retry (alive: pet).
                log.warning("serial port %s: %s; retrying", cfg.serial.port, e)
                notifier.beat("serve")
                stop.wait(1.0)
    except Exception:
        log.exception("daemon failed")
        status = 1
    finally:
        notifier.stopping()
        try:
            daemon.close()
        except Exception as e:
            log.critical("shutdown: %s", e)
            status = 1
        try:
            board.close()
        except Exception as e:
            log.error("closing the board: %s", e)
        notifier.close()
    # Shut down in order: the heater is off and its line released; the at-exit net is not needed.
    handlers.restore()
    log.info("stopped")
    return status or handlers.exit_status()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
