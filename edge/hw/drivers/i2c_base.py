"""Shared plumbing for the I2C chip drivers: bounded retries -> SensorFault.

Drivers take any smbus2-compatible bus object (``smbus2.SMBus`` on the Pi,
``firmware_sim.bus.SimBus`` in the simulator). Transient bus errors are common
on the Raspberry Pi (its I2C controller mishandles clock stretching and then
reports errno 121, EREMOTEIO), so every transaction is retried a bounded number
of times with a short, growing back-off before giving up with a SensorFault
that names the chip.
"""

from __future__ import annotations

import errno
import time
from typing import Callable, TypeVar

from edge.hw.faults import SensorFault

T = TypeVar("T")

_TIMEOUT_ERRNOS = {errno.ETIMEDOUT}


def _clock_of(sleep: Callable[[float], None]) -> Callable[[], float] | None:
    """The monotonic clock ``sleep`` waits on, when it can be told (see :class:`I2CDevice`)."""
    if sleep is time.sleep:
        return time.monotonic
    owner = getattr(sleep, "__self__", None)
    return getattr(owner, "monotonic", None) if owner is not None else None


class I2CDevice:
    """Base class: one chip at one address on one bus.

    Parameters
    ----------
    bus : smbus2-compatible object
        Must provide the smbus2 methods the subclass uses.
    address : int
        7-bit I2C address.
    attempts : int
        Total tries per transaction (>= 1) before raising SensorFault.
    backoff_s : float
        Sleep before the first retry; doubles on each further retry.
    sleep : callable
        ``sleep(seconds)``; pass ``clock.sleep`` in the simulator.
    clock : callable, optional
        ``clock() -> s``, monotonic (the board clock's ``monotonic`` in the simulator): how long a
        converter has gone without a new result (:meth:`MCP9600.read_hot_junction_C`). None: the
        clock ``sleep`` belongs to (``time.monotonic`` for ``time.sleep``, ``c.monotonic`` for a
        clock's ``c.sleep``), so that time is never measured on one clock and waited on another;
        without one, nothing is timed.
    """

    CHIP = "i2c"
    ADDRESSES: tuple[int, ...] = tuple(range(0x08, 0x78))

    def __init__(self, bus, address: int, *, attempts: int = 4, backoff_s: float = 0.002,
                 sleep: Callable[[float], None] = time.sleep,
                 clock: Callable[[], float] | None = None) -> None:
        if not isinstance(address, int) or address not in self.ADDRESSES:
            raise ValueError(
                f"address must be one of {[hex(a) for a in self.ADDRESSES]} for {self.CHIP}, "
                f"got {address!r}")
        if not isinstance(attempts, int) or attempts < 1:
            raise ValueError(f"attempts must be an integer >= 1, got {attempts!r}")
        if not backoff_s >= 0.0:
            raise ValueError(f"backoff_s must be >= 0, got {backoff_s!r}")
        self.bus = bus
        self.address = address
        self.attempts = attempts
        self.backoff_s = float(backoff_s)
        self.sleep = sleep
        self.clock = clock if clock is not None else _clock_of(sleep)
        #: transactions that needed at least one retry / errors seen (for diagnostics)
        self.retries = 0

    @property
    def name(self) -> str:
        """Sensor name used in faults, e.g. ``"mcp9600@0x60"``."""
        return f"{self.CHIP}@0x{self.address:02x}"

    def fault(self, reason: str, detail: str = "") -> SensorFault:
        return SensorFault(self.name, reason, detail)

    def _retry(self, what: str, fn: Callable[[], T]) -> T:
        """Run bus transaction ``fn`` with bounded retries; OSError -> SensorFault."""
        try:
            return fn()     # the first try, outside the loop: every transaction of every sample passes here
        except OSError as exc:
            last: OSError | None = exc
        delay = self.backoff_s
        for _ in range(1, self.attempts):
            self.retries += 1
            if delay > 0:
                self.sleep(delay)
            delay *= 2.0
            try:
                return fn()
            except OSError as exc:
                last = exc
        reason = "timeout" if last is not None and last.errno in _TIMEOUT_ERRNOS else "i2c"
        raise self.fault(reason, f"{what} failed after {self.attempts} attempts: "
                                 f"[errno {getattr(last, 'errno', None)}] {last}") from last

    # Generic helpers built on smbus2 calls that every adapter supports.
    def _read_block(self, register: int, n: int) -> bytes:
        return bytes(self._retry(
            f"read 0x{register:02x}[{n}]",
            lambda: self.bus.read_i2c_block_data(self.address, register, n)))

    def _write_block(self, register: int, data: bytes) -> None:
        self._retry(f"write 0x{register:02x}",
                    lambda: self.bus.write_i2c_block_data(self.address, register, list(data)))
