"""The edge daemon in a background thread: how the tests and the bench run it.

The device runs the daemon in its main thread (``thermotouch-edge``,
:func:`edge.service.main.main`); this convenience lives with the simulator
because only simulated set-ups need a daemon beside other work in the same
process.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from edge.hw.board import Board
from edge.service.config import Config
from edge.service.daemon import Daemon
from edge.service.main import run_daemon

__all__ = ["DaemonThread"]

log = logging.getLogger("thermotouch.edge")


class DaemonThread:
    """:func:`edge.service.main.run_daemon` in a background thread; ``daemon`` is available after start().

    Use as a context manager: leaving it sets the stop event and joins.

    Parameters
    ----------
    config : Config
    board : Board
    serial_port : pyserial-like
        The daemon's end of the serial line.
    **kwargs
        Passed to :class:`~edge.service.daemon.Daemon` (``estimator``, ``history`` ...).
    """

    def __init__(self, config: Config, board: Board, serial_port: Any, **kwargs: Any) -> None:
        self.stop_event = threading.Event()
        self.daemon: Daemon | None = None
        self.error: BaseException | None = None
        self._ready = threading.Event()
        self._args = (config, board, serial_port)
        self._kwargs = kwargs
        self.thread = threading.Thread(target=self._run, name="thermotouch-edge", daemon=True)

    def _run(self) -> None:
        def ready(d: Daemon) -> None:
            self.daemon = d
            self._ready.set()

        try:
            run_daemon(*self._args, self.stop_event, ready=ready, **self._kwargs)
        except BaseException as e:  # reported to the starter
            self.error = e
            log.exception("daemon thread ended with an error")
        finally:
            self._ready.set()

    def start(self, timeout_s: float = 10.0) -> Daemon:
        """Start and wait until the daemon answers; re-raise a start-up error."""
        self.thread.start()
        self._ready.wait(timeout_s)
        if self.daemon is None:
            raise RuntimeError(f"daemon did not start: {self.error!r}") from self.error
        return self.daemon

    def stop(self, timeout_s: float = 10.0) -> None:
        """Set the stop event and wait for the thread."""
        self.stop_event.set()
        if self.daemon is not None:
            self.daemon.wake()  # no read timeout to wait out
        self.thread.join(timeout_s)

    def __enter__(self) -> DaemonThread:
        self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()
