"""SimBus: an smbus2-compatible I2C bus that talks to emulated chips.

It offers smbus2.SMBus's method set and signatures, so the edge drivers (and
any third-party smbus2 code) run unchanged against the chip models in
``firmware_sim.chips``. Behaviour follows a Linux i2c-dev adapter:

* SMBus word data is little-endian on the wire (low byte first):
  ``read_word_data`` returns ``first_byte | second_byte << 8``. The chips here
  send their registers MSB first, so a driver using word calls must swap.
* ``read_i2c_block_data``/``write_i2c_block_data``/``write_block_data`` refuse
  more than 32 bytes with ValueError before any I/O, as smbus2 does.
* ``i2c_rdwr(*msgs)`` takes ``smbus2.i2c_msg`` objects and fills read buffers
  in place, so ``list(msg)`` / ``bytes(msg)`` work afterwards.
* An address nobody answers raises ``OSError`` with ``nack_errno``. On the
  Raspberry Pi the controller driver (i2c-bcm2835) reports a NACK as EREMOTEIO
  (121, "Remote I/O error") for both SMBus calls and ``i2c_rdwr`` -- the SMBus
  ioctl is emulated through the same ``master_xfer`` -- hence the default.
  Adapters following Documentation/i2c/fault-codes.rst report ENXIO instead:
  pass ``nack_errno=errno.ENXIO`` to emulate those.
* A transfer that times out (bus held low, a chip stretching forever) raises
  ETIMEDOUT, like i2c-bcm2835's "i2c transfer timed out".

Chips attach by 7-bit address and implement :class:`I2CTarget`: a write
transaction delivers the bytes after the address, a read transaction asks for
``n`` bytes. A combined transfer (repeated start) is a sequence of those.

Fault injection (all windows in virtual seconds on ``clock``):
:meth:`nack`, :meth:`stuck`, :meth:`flaky`, :meth:`clear_faults`.

Time: a clock with ``bus_transaction(n_bytes, n_segments)`` (a
:class:`firmware_sim.clock.BusClock`) is told about every transaction after it
ends -- a failed one (NACK, stuck bus) counts as its address byte only -- and
advances by the transaction's wire time. ``bit_rate_Hz`` instead makes each
successful transaction ``clock.sleep`` its wire time (on a wall clock that
really takes the time).
"""

from __future__ import annotations

import ctypes
import errno as _errno
import os
import threading
from collections import Counter, deque
from dataclasses import dataclass
from typing import Protocol, Sequence

import numpy as np

from firmware_sim.clock import i2c_transaction_time_s

__all__ = ["SimBus", "I2CTarget", "I2C_SMBUS_BLOCK_MAX"]

I2C_SMBUS_BLOCK_MAX = 32
I2C_M_RD = 0x0001


class I2CTarget(Protocol):
    """What a chip model implements to sit on a :class:`SimBus`."""

    def i2c_write(self, data: bytes) -> None:
        """A write transaction: ``data`` are the bytes after the address byte."""

    def i2c_read(self, n: int) -> bytes:
        """A read transaction of ``n`` bytes."""


@dataclass
class _Fault:
    kind: str                    # "nack", "stuck", "flaky"
    address: int | None          # None: every address
    from_s: float
    until_s: float | None
    err: int
    probability: float = 1.0
    reads_only: bool = False

    def active(self, t: float, address: int) -> bool:
        if self.address is not None and self.address != address:
            return False
        return t >= self.from_s and (self.until_s is None or t < self.until_s)


def _oserror(err: int) -> OSError:
    return OSError(err, os.strerror(err))


class SimBus:
    """smbus2.SMBus look-alike dispatching to emulated chips.

    Parameters
    ----------
    bus : int or str, optional
        Accepted for signature compatibility with ``smbus2.SMBus(bus)``; ignored.
    force : bool
        Accepted like smbus2's ``force``; has no effect.
    clock : SimClock, optional
        Time base for fault windows and transfer durations
        (:mod:`firmware_sim.clock`); a BusClock is ticked by each transaction.
    nack_errno : int
        errno for an unanswered address (default EREMOTEIO, the Pi's).
    rng : numpy.random.Generator or int, optional
        Randomness for :meth:`flaky` faults (seeded for reproducibility).
    bit_rate_Hz : float, optional
        If given, each transaction sleeps ``clock`` for its duration on the
        wire (9 bit-times per byte incl. address, plus start/stop;
        :func:`firmware_sim.clock.i2c_transaction_time_s`). Not with a
        BusClock, which counts wire time itself.
    """

    def __init__(self, bus=None, force: bool = False, *, clock=None,
                 nack_errno: int = _errno.EREMOTEIO, rng=None,
                 bit_rate_Hz: float | None = None) -> None:
        if bit_rate_Hz is not None and not bit_rate_Hz > 0:
            raise ValueError(f"bit_rate_Hz must be > 0, got {bit_rate_Hz!r}")
        if bit_rate_Hz is not None and clock is None:
            raise ValueError("bit_rate_Hz needs a clock")
        if bit_rate_Hz is not None and callable(getattr(clock, "bus_transaction", None)):
            raise ValueError("bit_rate_Hz cannot be combined with a bus clock, which counts "
                             "wire time itself (give the BusClock the bit rate)")
        self.clock = clock
        self.nack_errno = nack_errno
        self.bit_rate_Hz = bit_rate_Hz
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.force = force
        self.address = None
        self._pec = 0
        self._devices: dict[int, I2CTarget] = {}
        self._faults: list[_Fault] = []
        self._lock = threading.RLock()
        self._open = True
        self._tick_clock: object = object()     # the clock _tick was looked up on (none yet)
        self._tick = None
        self.bus_id = bus
        #: counts of "ok", "nack", "stuck", "flaky" transactions
        self.stats: Counter = Counter()
        #: recent transactions: (t_s, address, description, outcome)
        self.log: deque = deque(maxlen=2000)

    # -- devices -----------------------------------------------------------------
    def attach(self, address: int, device: I2CTarget) -> I2CTarget:
        """Put ``device`` on the bus at 7-bit ``address``; returns the device."""
        self._check_addr(address)
        if address in self._devices:
            raise ValueError(f"address 0x{address:02x} already has a device attached")
        if not (hasattr(device, "i2c_write") and hasattr(device, "i2c_read")):
            raise TypeError("device must implement i2c_write(data) and i2c_read(n)")
        self._devices[address] = device
        return device

    def detach(self, address: int) -> None:
        self._devices.pop(address, None)

    @property
    def devices(self) -> dict[int, I2CTarget]:
        return dict(self._devices)

    # -- faults --------------------------------------------------------------------
    def nack(self, address: int, from_s: float = 0.0, until_s: float | None = None) -> None:
        """``address`` stops acknowledging (as if unplugged) in [from_s, until_s)."""
        self._check_addr(address)
        self._faults.append(_Fault("nack", address, from_s, until_s, self.nack_errno))

    def stuck(self, from_s: float = 0.0, until_s: float | None = None,
              err: int = _errno.ETIMEDOUT) -> None:
        """Whole bus stuck (SDA/SCL held low): every transaction fails with ``err``."""
        self._faults.append(_Fault("stuck", None, from_s, until_s, err))

    def flaky(self, probability: float, address: int | None = None, *,
              err: int = _errno.EREMOTEIO, reads_only: bool = False,
              from_s: float = 0.0, until_s: float | None = None) -> None:
        """Each matching transaction fails with probability ``probability``.

        Emulates the Pi's clock-stretching trouble (EREMOTEIO); with
        ``reads_only`` only transfers containing a read are hit (the MCP9600
        stretches while preparing read data).
        """
        if not 0.0 <= probability <= 1.0:
            raise ValueError(f"probability must be in [0, 1], got {probability!r}")
        if address is not None:
            self._check_addr(address)
        self._faults.append(_Fault("flaky", address, from_s, until_s, err, probability, reads_only))

    def clear_faults(self) -> None:
        self._faults.clear()

    # -- core ------------------------------------------------------------------------
    @staticmethod
    def _check_addr(address: int) -> None:
        if not isinstance(address, int) or not 0 <= address <= 0x7F:
            raise ValueError(f"address must be a 7-bit integer 0..0x7f, got {address!r}")

    def _now(self) -> float:
        return self.clock.now() if self.clock is not None else 0.0

    def _transfer(self, address: int, segments: Sequence[tuple[str, object]], what: str) -> list[bytes]:
        """One bus transaction (START ... STOP) of write ("w", bytes) and read
        ("r", n) segments to one address; returns the read results."""
        clock = self.clock
        if clock is not self._tick_clock:   # looked up once per clock (a failed getattr costs a caught exception)
            self._tick_clock, self._tick = clock, getattr(clock, "bus_transaction", None)
        tick = self._tick
        try:
            out, nbytes = self._exchange(address, segments, what)
        except OSError as e:
            if tick is not None and e.errno not in (_errno.EBADF, _errno.EINVAL):
                tick(1, 1)          # the address byte went out, then NACK / bus error
            raise
        if self.bit_rate_Hz is not None:
            self.clock.sleep(i2c_transaction_time_s(nbytes, len(segments), self.bit_rate_Hz))
        if tick is not None:
            tick(max(nbytes, 1), max(len(segments), 1))
        return out

    def _exchange(self, address: int, segments: Sequence[tuple[str, object]],
                  what: str) -> tuple[list[bytes], int]:
        """:meth:`_transfer` without timing; returns (read results, bytes on the wire)."""
        with self._lock:
            if not self._open:
                raise _oserror(_errno.EBADF)
            if not isinstance(address, int) or not 0 <= address <= 0x7F:
                raise _oserror(_errno.EINVAL)
            t = self.clock.now() if self.clock is not None else 0.0
            faults = self._faults
            for f in faults:
                if not f.active(t, address):
                    continue
                if f.kind == "stuck":
                    self._record(t, address, what, "stuck")
                    raise _oserror(f.err)
                if f.kind == "nack":
                    self._record(t, address, what, "nack")
                    raise _oserror(f.err)
            dev = self._devices.get(address)
            if dev is None:
                self._record(t, address, what, "nack")
                raise _oserror(self.nack_errno)
            if faults:
                has_read = any(kind == "r" for kind, _ in segments)
                for f in faults:
                    if f.kind == "flaky" and f.active(t, address) and (has_read or not f.reads_only):
                        if self.rng.random() < f.probability:
                            self._record(t, address, what, "flaky")
                            raise _oserror(f.err)
            out: list[bytes] = []
            nbytes = 0
            for kind, arg in segments:
                if kind == "w":
                    data = bytes(arg)
                    dev.i2c_write(data)
                    nbytes += 1 + len(data)
                else:
                    n = int(arg)
                    data = bytes(dev.i2c_read(n))
                    if len(data) != n:
                        raise RuntimeError(f"device at 0x{address:02x} returned {len(data)} bytes, asked {n}")
                    out.append(data)
                    nbytes += 1 + n
            # _record, inline: every transaction of every simulated sample ends here.
            self.stats["ok"] += 1
            self.log.append((t, address, what, "ok"))
        return out, nbytes

    def _record(self, t: float, address: int, what: str, outcome: str) -> None:
        self.stats[outcome] += 1
        self.log.append((t, address, what, outcome))

    @staticmethod
    def _byte(value: int, name: str) -> int:
        if not isinstance(value, int) or not 0 <= value <= 0xFF:
            raise ValueError(f"{name} must be a byte 0..255, got {value!r}")
        return value

    def _use(self, i2c_addr: int, force) -> None:
        self.address = i2c_addr

    # -- smbus2 API --------------------------------------------------------------------
    def __enter__(self) -> "SimBus":
        return self

    def __exit__(self, exc_type, exc_val, exc_tb) -> None:
        self.close()

    def open(self, bus) -> None:
        if not isinstance(bus, (int, str)):
            raise TypeError("Unexpected type(bus)={}".format(type(bus)))
        self.bus_id = bus
        self._open = True

    def close(self) -> None:
        self._open = False
        self._pec = 0
        self.address = None

    @property
    def closed(self) -> bool:
        return not self._open

    def _get_pec(self) -> int:
        return self._pec

    def enable_pec(self, enable: bool = True) -> None:
        # Accepted for compatibility; PEC bytes are not emulated.
        self._pec = int(enable)

    pec = property(_get_pec, enable_pec)

    def write_quick(self, i2c_addr: int, force=None) -> None:
        self._use(i2c_addr, force)
        self._transfer(i2c_addr, [], "quick")

    def read_byte(self, i2c_addr: int, force=None) -> int:
        self._use(i2c_addr, force)
        return self._transfer(i2c_addr, [("r", 1)], "read_byte")[0][0]

    def write_byte(self, i2c_addr: int, value: int, force=None) -> None:
        self._use(i2c_addr, force)
        self._transfer(i2c_addr, [("w", [self._byte(value, "value")])], "write_byte")

    def read_byte_data(self, i2c_addr: int, register: int, force=None) -> int:
        self._use(i2c_addr, force)
        reg = self._byte(register, "register")
        return self._transfer(i2c_addr, [("w", [reg]), ("r", 1)], f"read_byte_data 0x{reg:02x}")[0][0]

    def write_byte_data(self, i2c_addr: int, register: int, value: int, force=None) -> None:
        self._use(i2c_addr, force)
        reg = self._byte(register, "register")
        self._transfer(i2c_addr, [("w", [reg, self._byte(value, "value")])], f"write_byte_data 0x{reg:02x}")

    def read_word_data(self, i2c_addr: int, register: int, force=None) -> int:
        self._use(i2c_addr, force)
        reg = self._byte(register, "register")
        lo, hi = self._transfer(i2c_addr, [("w", [reg]), ("r", 2)], f"read_word_data 0x{reg:02x}")[0]
        return lo | (hi << 8)

    def write_word_data(self, i2c_addr: int, register: int, value: int, force=None) -> None:
        self._use(i2c_addr, force)
        reg = self._byte(register, "register")
        if not isinstance(value, int) or not 0 <= value <= 0xFFFF:
            raise ValueError(f"value must be a word 0..65535, got {value!r}")
        self._transfer(i2c_addr, [("w", [reg, value & 0xFF, value >> 8])], f"write_word_data 0x{reg:02x}")

    def process_call(self, i2c_addr: int, register: int, value: int, force=None) -> int:
        self._use(i2c_addr, force)
        reg = self._byte(register, "register")
        if not isinstance(value, int) or not 0 <= value <= 0xFFFF:
            raise ValueError(f"value must be a word 0..65535, got {value!r}")
        lo, hi = self._transfer(i2c_addr, [("w", [reg, value & 0xFF, value >> 8]), ("r", 2)],
                                f"process_call 0x{reg:02x}")[0]
        return lo | (hi << 8)

    def read_block_data(self, i2c_addr: int, register: int, force=None) -> list[int]:
        """SMBus block read: the device's first byte is the count (1..32)."""
        self._use(i2c_addr, force)
        reg = self._byte(register, "register")
        data = self._transfer(i2c_addr, [("w", [reg]), ("r", 1 + I2C_SMBUS_BLOCK_MAX)],
                              f"read_block_data 0x{reg:02x}")[0]
        count = data[0]
        if not 1 <= count <= I2C_SMBUS_BLOCK_MAX:
            raise _oserror(_errno.EPROTO)  # the kernel rejects invalid block lengths
        return list(data[1:1 + count])

    def write_block_data(self, i2c_addr: int, register: int, data, force=None) -> None:
        length = len(data)
        if length > I2C_SMBUS_BLOCK_MAX:
            raise ValueError("Data length cannot exceed %d bytes" % I2C_SMBUS_BLOCK_MAX)
        self._use(i2c_addr, force)
        reg = self._byte(register, "register")
        payload = [reg, length] + [self._byte(b, "data byte") for b in data]
        self._transfer(i2c_addr, [("w", payload)], f"write_block_data 0x{reg:02x}")

    def block_process_call(self, i2c_addr: int, register: int, data, force=None) -> list[int]:
        """Write a counted block, read a counted block back (SMBus 2.0)."""
        length = len(data)
        if length > I2C_SMBUS_BLOCK_MAX:
            raise ValueError("Data length cannot exceed %d bytes" % I2C_SMBUS_BLOCK_MAX)
        self._use(i2c_addr, force)
        reg = self._byte(register, "register")
        payload = [reg, length] + [self._byte(b, "data byte") for b in data]
        back = self._transfer(i2c_addr, [("w", payload), ("r", 1 + I2C_SMBUS_BLOCK_MAX)],
                              f"block_process_call 0x{reg:02x}")[0]
        count = back[0]
        if not 1 <= count <= I2C_SMBUS_BLOCK_MAX:
            raise _oserror(_errno.EPROTO)
        return list(back[1:1 + count])

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int, force=None) -> list[int]:
        if length > I2C_SMBUS_BLOCK_MAX:
            raise ValueError("Desired block length over %d bytes" % I2C_SMBUS_BLOCK_MAX)
        if length < 0:
            raise ValueError(f"length must be >= 0, got {length!r}")
        self._use(i2c_addr, force)
        reg = self._byte(register, "register")
        return list(self._transfer(i2c_addr, [("w", [reg]), ("r", length)],
                                   f"read_i2c_block_data 0x{reg:02x}[{length}]")[0])

    def write_i2c_block_data(self, i2c_addr: int, register: int, data, force=None) -> None:
        length = len(data)
        if length > I2C_SMBUS_BLOCK_MAX:
            raise ValueError("Data length cannot exceed %d bytes" % I2C_SMBUS_BLOCK_MAX)
        self._use(i2c_addr, force)
        reg = self._byte(register, "register")
        payload = [reg] + [self._byte(b, "data byte") for b in data]
        self._transfer(i2c_addr, [("w", payload)], f"write_i2c_block_data 0x{reg:02x}[{length}]")

    def i2c_rdwr(self, *i2c_msgs) -> None:
        """Combined transfer: messages separated by repeated starts, one STOP.

        Messages to different addresses are split into per-address transfers
        in order (each address must acknowledge).
        """
        if not i2c_msgs:
            raise _oserror(_errno.EINVAL)
        groups: list[tuple[int, list]] = []
        for msg in i2c_msgs:
            try:
                addr, _, _, _ = msg.addr, msg.flags, msg.len, msg.buf
            except AttributeError:
                raise TypeError(f"i2c_rdwr expects smbus2.i2c_msg objects, got {type(msg).__name__}") from None
            if not groups or groups[-1][0] != addr:
                groups.append((addr, []))
            groups[-1][1].append(msg)
        for addr, msgs in groups:
            segs = [("r", m.len) if m.flags & I2C_M_RD else ("w", ctypes.string_at(m.buf, m.len))
                    for m in msgs]
            what = " ".join([f"{'R' if kind == 'r' else 'W'}{m.len}" for (kind, _), m in zip(segs, msgs)])
            results = iter(self._transfer(addr, segs, "i2c_rdwr " + what))
            for (kind, _), m in zip(segs, msgs):
                if kind == "r":
                    ctypes.memmove(m.buf, next(results), m.len)
