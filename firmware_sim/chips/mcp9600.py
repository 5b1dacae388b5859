"""Register-level model of the MCP9600 thermocouple converter (DS20005426).

What it emulates (datasheet sections in brackets):

* Register pointer protocol: a write sets the pointer (first byte) and, with
  more bytes, writes the register MSB first; a read returns the pointed
  register MSB first [4.1, Fig. 4-3]. Reads longer than the register repeat
  its bytes (unspecified on the real chip).
* T_H 0x00, T_delta 0x01, T_C 0x02 in 0.0625 °C two's complement [5.1];
  T_C quantised to 0.0625 or 0.25 °C per DEVICE_CONFIG bit 7 [Table 5-2].
* Raw ADC 0x03: 24-bit sign-extended, in 2 µV (18-bit) units; lower ADC
  resolutions zero the low bits (quantised to the resolution) [5.1.4].
* STATUS 0x04: burst complete (bit 7), T_H update (bit 6) -- set by the chip,
  cleared by writing 0 -- and input range (bit 4, read-only) [Reg. 5-6].
* THERMOCOUPLE_CONFIG 0x05 (type, filter) and DEVICE_CONFIG 0x06 (cold-junction
  resolution, ADC resolution 18/16/14/12 bit with 320/80/20/5 ms conversions,
  burst samples, normal/shutdown/burst modes) [5.2.2, 5.2.3].
* Device ID 0x40 and revision at 0x20 [Reg. 5-12].

How the hot junction is computed: the thermocouple EMF is
``E(T_hot) - E(T_cold_true)`` (NIST type K); the chip's ADC samples it at the
centre of each conversion window, adds noise, quantises to the ADC LSB; then
(``cjc_method="nist"``, default) ``T_H = T(E_adc + E(T_C))``, or
(``"sum"``) ``T_H = T(E_adc) + T_C`` -- the literal reading of Fig. 5-2 --
and ``T_delta = T_H - T_C`` so that the datasheet identity T_H = T_delta + T_C
holds bit-exactly. The digital filter is modelled as the first-order IIR
``y += (x - y) / 2**n`` for filter coefficient n (approximation of 5.2.2).

Only type K is emulated; other TYPE codes are stored but converted as K.

Open thermocouple: the input floats to the rail, the EMF leaves the type's
range, STATUS.INPUT_RANGE is set and T_H / T_delta keep their last in-range
values (so only the status bit tells), the raw ADC register shows positive
full scale.

Frozen converter (``converter_frozen``, :mod:`firmware_sim.chips.freeze`): no conversion
completes -- T_H, T_delta, T_C, the raw ADC register and STATUS (its T_H update flag included)
keep what they held -- while the interface answers as usual.
"""

from __future__ import annotations

import functools
import math
from types import MappingProxyType
from typing import Any, Callable, Mapping

import numpy as np

from edge.physics import typek
from firmware_sim.chips.freeze import Freezable
from edge.hw.regmaps.mcp9600 import (
    COLD_JUNCTION_TIME_s,
    CONVERSION_TIME_s,
    DEVICE_ID,
    RAW_ADC_LSB_V,
    REGISTERS,
)

_EPS = 1e-9
_MAX_BACKLOG = 64          # conversions replayed after a long idle gap (filter settles)
_RAW_FS = (1 << 17) - 1    # 18-bit positive full scale in 2 µV units


def _temp_code(t_C: float, lsb_C: float = 0.0625) -> int:
    """Two's-complement 16-bit register code, truncated to ``lsb_C``."""
    q = math.floor(t_C / lsb_C + 1e-9) * lsb_C
    code = int(round(q / 0.0625))
    code = max(-0x8000, min(0x7FFF, code))
    return code & 0xFFFF



@functools.lru_cache(maxsize=64)
def _device_config(value: int) -> Mapping[str, Any]:
    """DEVICE_CONFIG's fields for ``value`` (asked several times on every bus access; read only)."""
    return MappingProxyType(REGISTERS.DEVICE_CONFIG.decode(value))

class MCP9600Emulator(Freezable):
    """Emulated MCP9600 (the driver is :class:`edge.hw.drivers.mcp9600.MCP9600`).

    Parameters
    ----------
    clock : SimClock
        Any mode of :mod:`firmware_sim.clock`: the model reads ``clock.now()``
        on each access and catches up, so it never relies on sleeps.
    hot_junction_C : callable t_s -> °C
        True temperature of the thermocouple's hot junction.
    cold_junction_C : callable t_s -> °C
        True temperature of the chip/terminals (cold junction).
    rng : numpy Generator or seed, optional
    emf_noise_rms_V : float
        Input-referred ADC noise per conversion.
    open_circuit : callable t_s -> bool, optional
        True while the thermocouple is disconnected (see also :meth:`set_open`).
    cjc_method : {"nist", "sum"}
    revision : int
        Revision byte of the DEVICE_ID register.
    """

    def __init__(self, clock, hot_junction_C: Callable[[float], float],
                 cold_junction_C: Callable[[float], float] = lambda t: 25.0, *,
                 rng=None, emf_noise_rms_V: float = 0.0,
                 open_circuit: Callable[[float], bool] | None = None,
                 cjc_method: str = "nist", revision: int = 0x11) -> None:
        if cjc_method not in ("nist", "sum"):
            raise ValueError(f"cjc_method must be 'nist' or 'sum', got {cjc_method!r}")
        if not emf_noise_rms_V >= 0:
            raise ValueError(f"emf_noise_rms_V must be >= 0, got {emf_noise_rms_V!r}")
        self.clock = clock
        self.hot_junction_C = hot_junction_C
        self.cold_junction_C = cold_junction_C
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.emf_noise_rms_V = float(emf_noise_rms_V)
        self.open_circuit = open_circuit
        self.cjc_method = cjc_method
        self._forced_open = False
        self.regs: dict[int, int] = REGISTERS.reset_values()
        self.regs[0x20] = (DEVICE_ID << 8) | (revision & 0xFF)
        self._pointer = 0x00
        self._filtered_C: float | None = None
        self._burst_left = 0
        t0 = clock.now()
        self.conversions = 0
        # The board is taken as powered up before the simulation starts: the
        # registers already hold one conversion of each junction taken at t0.
        self._convert_cold(t0)
        self._convert_hot(t0, 0.0)
        self._next_hot = t0 + self._t_hot()
        self._next_cold = t0 + self._t_cold()

    # -- configuration helpers ------------------------------------------------------
    def _dev(self, field: str):
        return _device_config(self.regs[0x06])[field]

    def _t_hot(self) -> float:
        return CONVERSION_TIME_s[self._dev("ADC_RESOLUTION")]

    def _t_cold(self) -> float:
        return COLD_JUNCTION_TIME_s[self._dev("COLD_JUNCTION_RESOLUTION")]

    def _running(self) -> bool:
        mode = self._dev("MODE")
        return mode == "normal" or (mode == "burst" and self._burst_left > 0)

    def set_open(self, is_open: bool) -> None:
        """Disconnect (True) or reconnect (False) the thermocouple."""
        self._forced_open = bool(is_open)

    def _is_open(self, t: float) -> bool:
        return self._forced_open or (self.open_circuit is not None and bool(self.open_circuit(t)))

    # -- conversions -----------------------------------------------------------------
    def _catch_up(self) -> None:
        now = self.clock.now() + _EPS
        if not self._running():
            return
        t_hot, t_cold = self._t_hot(), self._t_cold()
        if now - self._next_hot > _MAX_BACKLOG * t_hot:
            skip = math.floor((now - self._next_hot) / t_hot) - _MAX_BACKLOG
            self._next_hot += skip * t_hot
        if now - self._next_cold > 2 * t_cold:
            self._next_cold += (math.floor((now - self._next_cold) / t_cold) - 1) * t_cold
        while self._running():
            if self._next_cold <= now and self._next_cold <= self._next_hot:
                self._convert_cold(self._next_cold)
                self._next_cold += t_cold
            elif self._next_hot <= now:
                self._convert_hot(self._next_hot, t_hot)
                self._next_hot += t_hot
            else:
                break

    def _convert_cold(self, t: float) -> None:
        if self.frozen_at(t):
            return
        lsb = self._dev("COLD_JUNCTION_RESOLUTION")
        self.regs[0x02] = _temp_code(float(self.cold_junction_C(t)), lsb)

    def _convert_hot(self, t_end: float, t_conv: float) -> None:
        if self.frozen_at(t_end):
            return  # frozen: no result, no T_H update flag (a burst does not finish either)
        self.conversions += 1
        tm = t_end - 0.5 * t_conv
        status = self.regs[0x04] | 0x40          # T_H update
        res = self._dev("ADC_RESOLUTION")
        lsb_units = 1 << (18 - res)              # ADC LSB in 2 µV units
        tc_C = REGISTERS.TC.get(self.regs[0x02], "TEMP_C")
        in_range = False
        if self._is_open(tm):
            self.regs[0x03] = _RAW_FS & ~(lsb_units - 1)
        else:
            e_V = (typek.emf_mV(float(self.hot_junction_C(tm)))
                   - typek.emf_mV(float(self.cold_junction_C(tm)))) * 1e-3
            if self.emf_noise_rms_V:
                e_V += self.rng.normal(0.0, self.emf_noise_rms_V)
            code = int(round(e_V / (RAW_ADC_LSB_V * lsb_units))) * lsb_units
            code = max(-_RAW_FS - 1, min(_RAW_FS, code))
            self.regs[0x03] = code & 0xFFFFFF
            e_mV = code * RAW_ADC_LSB_V * 1e3
            try:
                # refine=True: the model is an ideal converter up to quantisation
                # (the real chip's own linearisation error is within its spec).
                if self.cjc_method == "nist":
                    th = typek.temperature_C(e_mV + typek.emf_mV(tc_C), refine=True)
                else:
                    th = typek.temperature_C(e_mV, refine=True) + tc_C
                in_range = typek.T_MIN_C <= th <= typek.T_MAX_C and abs(code) < _RAW_FS
            except ValueError:
                in_range = False
            if in_range:
                n = REGISTERS.THERMOCOUPLE_CONFIG.get(self.regs[0x05], "FILTER")
                if n == 0 or self._filtered_C is None:
                    self._filtered_C = th
                else:
                    self._filtered_C += (th - self._filtered_C) / (1 << n)
                th_code = _temp_code(self._filtered_C)
                self.regs[0x00] = th_code
                self.regs[0x01] = (th_code - self.regs[0x02]) & 0xFFFF
        status = (status | 0x10) if not in_range else (status & ~0x10)
        self.regs[0x04] = status
        if self._dev("MODE") == "burst":
            self._burst_left -= 1
            if self._burst_left <= 0:
                # Burst done: flag it and drop to shutdown (datasheet 5.2.3).
                self.regs[0x04] |= 0x80
                self.regs[0x06] = REGISTERS.DEVICE_CONFIG.encode(self.regs[0x06], MODE="shutdown")

    # -- I2C target --------------------------------------------------------------------
    def i2c_write(self, data: bytes) -> None:
        if not data:
            return
        self._catch_up()
        self._pointer = data[0]
        if len(data) == 1 or not REGISTERS.has_address(self._pointer):
            return
        reg = REGISTERS.at(self._pointer)
        if reg.read_only or len(data) < 1 + reg.width_bytes:
            return
        value = reg.from_bytes(data[1:1 + reg.width_bytes])
        if reg.address == 0x04:
            # Flags 7 and 6 are cleared by writing 0; writing 1 does not set them.
            self.regs[0x04] &= (value & 0xC0) | 0x3F
            return
        old_mode = self._dev("MODE")
        old_res = self._dev("ADC_RESOLUTION")
        old_cj = self._dev("COLD_JUNCTION_RESOLUTION")
        self.regs[reg.address] = value
        if reg.address == 0x06:
            now = self.clock.now()
            mode = self._dev("MODE")
            if mode == "burst":
                self._burst_left = self._dev("BURST_SAMPLES")
                self._next_hot = now + self._t_hot()
                self._next_cold = min(self._next_cold, now + self._t_cold()) \
                    if old_mode == "normal" else now + self._t_cold()
            elif mode == "normal" and (old_mode != "normal" or old_res != self._dev("ADC_RESOLUTION")):
                self._next_hot = now + self._t_hot()
                if old_mode != "normal":
                    self._next_cold = now + self._t_cold()
            if old_cj != self._dev("COLD_JUNCTION_RESOLUTION"):
                self._next_cold = now + self._t_cold()

    def i2c_read(self, n: int) -> bytes:
        self._catch_up()
        if not REGISTERS.has_address(self._pointer):
            return b"\xff" * n
        reg = REGISTERS.at(self._pointer)
        raw = reg.to_bytes(self.regs[reg.address])
        # The register repeats past its width (a driver's read is its width: no loop then).
        return raw if n == len(raw) else bytes(raw[i % len(raw)] for i in range(n))

    # -- convenience for tests / the world ----------------------------------------------
    def register(self, name: str) -> int:
        """Current value of register ``name`` (after catching up with the clock)."""
        self._catch_up()
        return self.regs[REGISTERS[name].address]
