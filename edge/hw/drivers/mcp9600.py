"""MCP9600 thermocouple EMF-to-temperature converter (Microchip DS20005426).

Driver for any smbus2-compatible bus; the register map is data in edge.hw.regmaps (datasheet section 5) plus a driver for any
smbus2-compatible bus.

Why reads go through ``i2c_rdwr`` in two transactions
-----------------------------------------------------
The MCP9600 stretches SCL while it fetches register data after the read
address byte (datasheet Fig. 4-3, "MCP9600 Clock Stretching"). The Raspberry
Pi's BCM283x I2C controller does not honour clock stretching reliably; the
symptom is ``OSError: [Errno 121] Remote I/O error`` (EREMOTEIO) or, rarely, a
corrupted byte. The datasheet's own read sequence sets the register pointer
with a write terminated by STOP and then reads in a *separate* transaction;
that is what ``transport="split"`` (the default) does with two ``i2c_rdwr``
calls. Keeping the pointer write out of the stretched read means a failed read
costs one short transaction, and the whole pointer-then-read pair is retried a
bounded number of times before a SensorFault is raised. ``"combined"`` (one
``i2c_rdwr`` with a repeated start) and ``"smbus"`` (``read_i2c_block_data``)
are available for adapters where they work better. Lowering the bus clock
(``dtparam=i2c_baudrate=10000``) further reduces errors on a Pi.

A frozen converter (ISSUE #35 §5)
---------------------------------
In normal (continuous) mode the chip sets STATUS.TH_UPDATE at the end of
every hot-junction conversion. :meth:`MCP9600.read_hot_junction_C` reads
STATUS anyway (for the open-input bit); when the flag is set it clears it
(one write), and when it is not it checks how long ago it last cleared it: a
conversion must have ended within :data:`STALE_FACTOR` conversion times plus
:data:`STALE_MARGIN_s` of the clear (one lost to the clear itself is
followed by the next within one conversion time). Past that the converter is
stuck and the read raises ``SensorFault(reason="timeout")`` naming the chip.
An unchanged *temperature* is no fault: a touch on metal legitimately moves
the hot junction by less than one LSB (0.0625 °C) -- only the chip's own
"new data" flag is believed.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Callable, Mapping

from edge.hw.drivers.i2c_base import I2CDevice
from edge.hw.registers import Register

try:  # smbus2 is a run-time dependency of edge; keep the import soft for docs builds
    from smbus2 import i2c_msg
except ImportError:  # pragma: no cover
    i2c_msg = None
from edge.hw.regmaps.mcp9600 import (
    DEVICE_ID,
    ADDRESSES,
    CONVERSION_TIME_s,
    RAW_ADC_LSB_V,
    REGISTERS,
)

#: A conversion is overdue after this many conversion times since the update flag was cleared
#: (the datasheet's conversion times are typical; the chip's oscillator is specified to a few %).
STALE_FACTOR = 1.5
#: ... plus this much (s): the I2C traffic between the flag's clear and the check.
STALE_MARGIN_s = 0.02


@dataclass(frozen=True)
class MCP9600Reading:
    """One set of temperature registers (°C) and the status flags."""

    hot_C: float
    delta_C: float
    cold_C: float
    status: dict


@functools.lru_cache(maxsize=256)
def _status(value: int) -> Mapping[str, Any]:
    """STATUS's fields for ``value`` (read every sample; the same few values all touch)."""
    return MappingProxyType(REGISTERS.STATUS.decode(value))


class MCP9600(I2CDevice):
    """Driver for one MCP9600.

    Parameters
    ----------
    bus : smbus2-compatible bus
    address : int
        0x60..0x67.
    transport : {"split", "combined", "smbus"}
        How registers are read (see module docstring).
    attempts, backoff_s, sleep, clock
        Retry policy (see :class:`edge.hw.drivers.i2c_base.I2CDevice`).
    """

    CHIP = "mcp9600"
    ADDRESSES = ADDRESSES

    def __init__(self, bus, address: int = 0x60, *, transport: str = "split",
                 attempts: int = 4, backoff_s: float = 0.002,
                 sleep: Callable[[float], None] = time.sleep,
                 clock: Callable[[], float] | None = None) -> None:
        super().__init__(bus, address, attempts=attempts, backoff_s=backoff_s, sleep=sleep, clock=clock)
        if transport not in ("split", "combined", "smbus"):
            raise ValueError(f"transport must be 'split', 'combined' or 'smbus', got {transport!r}")
        if transport != "smbus" and (i2c_msg is None or not hasattr(bus, "i2c_rdwr")):
            raise ValueError(f"transport={transport!r} needs smbus2.i2c_msg and bus.i2c_rdwr")
        self.transport = transport
        self.adc_resolution_bits = 18
        self.cold_junction_resolution_C = 0.0625
        #: The chip's mode as configured ("normal" at power-on: converts continuously).
        self.mode = "normal"
        #: When the T_H update flag was last cleared by :meth:`read_hot_junction_C` (None: not yet).
        self._cleared_at_s: float | None = None

    # -- raw register access ------------------------------------------------
    def _read_reg(self, reg: Register) -> int:
        n = reg.width_bytes

        def xfer() -> bytes:
            if self.transport == "smbus":
                return bytes(self.bus.read_i2c_block_data(self.address, reg.address, n))
            wr = i2c_msg.write(self.address, [reg.address])
            rd = i2c_msg.read(self.address, n)
            if self.transport == "combined":
                self.bus.i2c_rdwr(wr, rd)
            else:
                self.bus.i2c_rdwr(wr)
                self.bus.i2c_rdwr(rd)
            return bytes(rd)

        return reg.from_bytes(self._retry(f"read {reg.name}", xfer))

    def _write_reg(self, reg: Register, value: int) -> None:
        data = list(reg.to_bytes(value))
        self._retry(f"write {reg.name}",
                    lambda: self.bus.write_i2c_block_data(self.address, reg.address, data))

    def read_register(self, name: str) -> int:
        """Raw value of register ``name`` (see :data:`REGISTERS`)."""
        return self._read_reg(REGISTERS[name])

    def write_register(self, name: str, value: int) -> None:
        reg = REGISTERS[name]
        if reg.read_only:
            raise ValueError(f"register {name} is read-only")
        self._write_reg(reg, value)

    # -- identity and configuration ------------------------------------------
    def probe(self) -> tuple[int, int]:
        """Check the device ID (0x40); return ``(device_id, revision)``."""
        raw = self._read_reg(REGISTERS.DEVICE_ID)
        dev_id, rev = REGISTERS.DEVICE_ID.get(raw, "ID"), REGISTERS.DEVICE_ID.get(raw, "REVISION")
        if dev_id != DEVICE_ID:
            raise self.fault("not_found", f"device ID 0x{dev_id:02x}, expected 0x{DEVICE_ID:02x}")
        return dev_id, rev

    def configure(self, *, thermocouple_type: str = "K", filter_coefficient: int = 0,
                  adc_resolution_bits: int = 18, cold_junction_resolution_C: float = 0.0625,
                  mode: str = "normal", burst_samples: int = 1) -> None:
        """Write the sensor and device configuration registers.

        ``filter_coefficient`` 0 (off) .. 7 (strongest); keep 0 for fast
        transients. ``mode``: "normal" (continuous), "shutdown" or "burst".
        """
        tc = REGISTERS.THERMOCOUPLE_CONFIG.encode(0, TYPE=thermocouple_type, FILTER=filter_coefficient)
        dc = REGISTERS.DEVICE_CONFIG.encode(
            0, COLD_JUNCTION_RESOLUTION=cold_junction_resolution_C,
            ADC_RESOLUTION=adc_resolution_bits, BURST_SAMPLES=burst_samples, MODE=mode)
        self._write_reg(REGISTERS.THERMOCOUPLE_CONFIG, tc)
        self._write_reg(REGISTERS.DEVICE_CONFIG, dc)
        self.adc_resolution_bits = adc_resolution_bits
        self.cold_junction_resolution_C = cold_junction_resolution_C
        self.mode = mode
        self._cleared_at_s = None  # new settings restart the conversions: watch afresh

    def read_config(self) -> dict:
        out = REGISTERS.THERMOCOUPLE_CONFIG.decode(self._read_reg(REGISTERS.THERMOCOUPLE_CONFIG))
        out.update(REGISTERS.DEVICE_CONFIG.decode(self._read_reg(REGISTERS.DEVICE_CONFIG)))
        return out

    @property
    def conversion_time_s(self) -> float:
        """Typical hot-junction conversion time at the configured resolution."""
        return CONVERSION_TIME_s[self.adc_resolution_bits]

    # -- status ----------------------------------------------------------------
    def read_status(self) -> dict:
        return dict(_status(self._read_reg(REGISTERS.STATUS)))   # a copy: the caller's to keep

    def clear_flags(self) -> None:
        """Clear the TH-update and burst-complete flags (write 0 to them)."""
        self._write_reg(REGISTERS.STATUS, 0x00)

    def _check_range(self, status: dict) -> None:
        if status["INPUT_RANGE"]:
            raise self.fault("open_thermocouple",
                             "STATUS.INPUT_RANGE set: EMF outside the type's range "
                             "(open or disconnected thermocouple)")

    def wait_for_update(self, timeout_s: float | None = None, poll_s: float | None = None) -> dict:
        """Clear TH_UPDATE, then poll until the next conversion sets it.

        Returns the status dict; raises SensorFault(reason="timeout") if no
        conversion completes within ``timeout_s`` (default 3 conversion times).
        """
        if timeout_s is None:
            timeout_s = 3.0 * self.conversion_time_s
        if poll_s is None:
            poll_s = self.conversion_time_s / 8.0
        self.clear_flags()
        waited = 0.0
        while True:
            status = self.read_status()
            if status["TH_UPDATE"] or status["BURST_COMPLETE"]:
                return status
            if waited >= timeout_s:
                raise self.fault("timeout", f"no conversion within {timeout_s:.3f} s")
            self.sleep(poll_s)
            waited += poll_s

    def start_burst(self, samples: int = 1) -> None:
        """Start a burst of ``samples`` conversions (the chip shuts down after)."""
        dc_reg = REGISTERS.DEVICE_CONFIG
        dc = dc_reg.encode(self._read_reg(dc_reg), BURST_SAMPLES=samples, MODE="burst")
        self.clear_flags()
        self._write_reg(dc_reg, dc)

    # -- temperatures ------------------------------------------------------------
    def _temp(self, name: str) -> float:
        return REGISTERS[name].get(self._read_reg(REGISTERS[name]), "TEMP_C")

    @property
    def stale_after_s(self) -> float:
        """Longest time (s) from clearing the T_H update flag to the next conversion of a working chip."""
        return STALE_FACTOR * self.conversion_time_s + STALE_MARGIN_s

    def _check_fresh(self, status: dict) -> None:
        """Normal mode: a new conversion must arrive within :attr:`stale_after_s` (see the module docstring)."""
        if self.mode != "normal" or self.clock is None:
            return  # shutdown / burst: no conversions are due (no clock: nothing can be timed)
        if status["TH_UPDATE"] or self._cleared_at_s is None:
            self.clear_flags()
            self._cleared_at_s = self.clock()
            return
        waited = self.clock() - self._cleared_at_s
        if waited > self.stale_after_s:
            raise self.fault("timeout", f"converter stuck: no new hot-junction conversion (STATUS.TH_UPDATE) for "
                                        f"{waited:.3f} s, one is due every {self.conversion_time_s:.3f} s")

    def read_hot_junction_C(self, check_status: bool = True) -> float:
        """Hot-junction (thermocouple) temperature, 0.0625 °C resolution.

        Raises SensorFault(reason="open_thermocouple") when the chip flags its
        input out of range, and SensorFault(reason="timeout") when no new
        conversion arrived in time (a frozen converter; module docstring).
        ``check_status=False`` skips that status read and both checks.
        """
        if check_status:
            status = self.read_status()
            self._check_range(status)
            self._check_fresh(status)
        return self._temp("TH")

    def read_delta_C(self) -> float:
        """Junction delta temperature T_H - T_C (°C)."""
        return self._temp("TDELTA")

    def read_cold_junction_C(self) -> float:
        """Cold-junction (die) temperature (°C)."""
        return self._temp("TC")

    def read_raw_adc(self) -> int:
        """Raw ADC register, sign-extended (18-bit units of 2 µV)."""
        return REGISTERS.RAW_ADC.get(self._read_reg(REGISTERS.RAW_ADC), "CODE")

    def read_raw_emf_V(self) -> float:
        """Thermocouple EMF in volts from the raw ADC register."""
        return self.read_raw_adc() * RAW_ADC_LSB_V

    def read(self) -> MCP9600Reading:
        """Status, hot, delta and cold junction in one call (raises on open input)."""
        status = self.read_status()
        self._check_range(status)
        return MCP9600Reading(self._temp("TH"), self._temp("TDELTA"), self._temp("TC"), status)
