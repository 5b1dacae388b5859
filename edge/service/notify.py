"""systemd's notify protocol (``Type=notify``, ``WatchdogSec=``) in pure Python.

:func:`sd_notify` sends one datagram of ``KEY=VALUE`` lines to the unix
socket named by ``$NOTIFY_SOCKET`` (a path, or ``@name`` for the abstract
namespace) and does nothing without it, so the daemon runs unchanged outside
systemd.

:class:`Notifier` adds the watchdog: systemd kills a ``WatchdogSec=``
service whose ``WATCHDOG=1`` messages stop for that long (SIGABRT, then
SIGKILL), and the kernel then releases the heater's enable line, which its
bias pulls inactive (:meth:`edge.hw.board.GpioLine.request_fail_safe_output`).
The daemon has two loops that can hang on their own -- the serve loop (main
thread) and the measurement loop (worker thread, the one that switches the
heater on) -- so each reports with :meth:`Notifier.beat` under its own name,
and ``WATCHDOG=1`` goes out only when *every* loop that is running has beaten
since the last one: a measurement stuck in a driver call stops the pets even
though the serve loop still answers STATUS. A loop that ends says so with
:meth:`Notifier.done`.
"""

from __future__ import annotations

import logging
import os
import socket
import threading
import time
from typing import Callable

__all__ = ["sd_notify", "watchdog_interval_s", "Notifier"]

log = logging.getLogger(__name__)


def _address(path: str) -> str | bytes:
    # "@name" is an abstract-namespace socket: a leading NUL byte on the wire.
    return b"\0" + path[1:].encode() if path.startswith("@") else path


def sd_notify(*fields: str, env: dict[str, str] | None = None) -> bool:
    """Send ``fields`` (e.g. ``"READY=1"``) to ``$NOTIFY_SOCKET``; False if not sent.

    Never raises: a service manager that went away must not stop the daemon.
    """
    path = (os.environ if env is None else env).get("NOTIFY_SOCKET", "")
    if not path or not fields:
        return False
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as s:
            s.sendto("\n".join(fields).encode(), _address(path))
        return True
    except OSError as e:
        log.debug("sd_notify(%s) to %s failed: %s", fields, path, e)
        return False


def watchdog_interval_s(env: dict[str, str] | None = None) -> float | None:
    """``WatchdogSec=`` in seconds from ``$WATCHDOG_USEC`` (None if unset, invalid or for another pid)."""
    env = os.environ if env is None else env
    try:
        usec = int(env.get("WATCHDOG_USEC", ""))
    except ValueError:
        return None
    pid = env.get("WATCHDOG_PID")
    if pid and pid != str(os.getpid()):
        return None
    return usec / 1e6 if usec > 0 else None


class Notifier:
    """READY/STOPPING/STATUS and gated watchdog pets (see the module docstring).

    Parameters
    ----------
    env : dict, optional
        Environment to read ``NOTIFY_SOCKET``/``WATCHDOG_USEC`` from (default ``os.environ``).
    clock : callable () -> float
        Wall-clock monotonic seconds (pets are about real time, never the board's clock).
    hw_watchdog : str
        Hardware watchdog device (``/dev/watchdog``) pet with the same gate, or "" for none
        (config ``watchdog.device``). Opening it starts it; :meth:`close` writes the magic
        ``V`` that stops it on a clean exit. If the daemon dies and is not restarted before
        the driver's timeout, the SoC resets and its GPIOs come up as inputs: heater off.
    """

    #: Pet period (s) for a hardware watchdog when systemd's is off; drivers time out after 10-60 s.
    HW_PET_INTERVAL_s = 1.0

    def __init__(self, env: dict[str, str] | None = None, *, clock: Callable[[], float] = time.monotonic,
                 hw_watchdog: str = "") -> None:
        self._env = dict(os.environ if env is None else env)
        self.enabled = bool(self._env.get("NOTIFY_SOCKET"))
        self.watchdog_s = watchdog_interval_s(self._env) if self.enabled else None
        self._hw_fd: int | None = None
        if hw_watchdog:
            self._hw_fd = os.open(hw_watchdog, os.O_WRONLY | os.O_CLOEXEC)
        # systemd's advice: pet at half WatchdogSec; a quarter leaves room for a slow loop turn.
        self.pet_interval_s = None if self.watchdog_s is None else self.watchdog_s / 4
        if self._hw_fd is not None:
            self.pet_interval_s = min(self.pet_interval_s or self.HW_PET_INTERVAL_s, self.HW_PET_INTERVAL_s)
        self._clock = clock
        self._lock = threading.Lock()
        self._beats: dict[str, float] = {}
        self._last_pet = -float("inf")
        #: WATCHDOG=1 messages sent.
        self.pets = 0

    def send(self, *fields: str) -> bool:
        """Send raw fields (no-op when not under a service manager)."""
        return self.enabled and sd_notify(*fields, env=self._env)

    def ready(self, status: str = "") -> bool:
        """``READY=1`` (start-up done: systemd's ``Type=notify`` start completes)."""
        return self.send("READY=1", *([f"STATUS={status}"] if status else []))

    def stopping(self) -> bool:
        """``STOPPING=1``."""
        return self.send("STOPPING=1")

    def beat(self, loop: str) -> None:
        """Loop ``loop`` is alive; pet the watchdog if every running loop has beaten since the last pet."""
        if self.pet_interval_s is None:
            return
        now = self._clock()
        with self._lock:
            self._beats[loop] = now
            if now - self._last_pet < self.pet_interval_s:
                return
            if any(t <= self._last_pet for t in self._beats.values()):
                return  # some running loop has not turned since the last pet: it may be stuck
            self._last_pet = now
            fd = self._hw_fd
        if fd is not None:
            try:
                os.write(fd, b"\0")
            except OSError as e:
                log.error("hardware watchdog: %s", e)
        if self.send("WATCHDOG=1"):
            self.pets += 1

    def done(self, loop: str) -> None:
        """Loop ``loop`` has ended normally: stop waiting for its beats."""
        with self._lock:
            self._beats.pop(loop, None)

    def close(self) -> None:
        """Clean stop: disarm the hardware watchdog (magic close) and close it (idempotent)."""
        with self._lock:
            fd, self._hw_fd = self._hw_fd, None
        if fd is not None:
            try:
                os.write(fd, b"V")
            finally:
                os.close(fd)
