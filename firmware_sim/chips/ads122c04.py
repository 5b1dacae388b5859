"""Register-level model of the ADS122C04 24-bit ADC (TI SBAS751).

Emulated (datasheet sections in brackets):

* Command interface [8.5.3, Table 16]: RESET 0000011x, START/SYNC 0000100x,
  POWERDOWN 0000001x, RDATA 0001xxxx, RREG 0010rrxx, WREG 0100rrxx (+ data
  byte). A read transaction returns the response of the last RDATA/RREG.
* Configuration registers 0..3 (reset 0x00) [8.6]: MUX, GAIN, PGA_BYPASS; DR,
  MODE (normal/turbo), CM (single-shot/continuous), VREF, TS; DRDY (read-only,
  set on a new result, cleared when the result is read with RDATA), DCNT, CRC,
  BCS, IDAC; I1MUX/I2MUX.
* Conversion timing from Table 12 (single-shot from START to DRDY; continuous
  between results) on the virtual clock; the input is sampled at the centre of
  the conversion window.
* 24-bit two's-complement result, LSB = 2·VREF / GAIN / 2^24, clipped to
  0x7FFFFF / 0x800000 [8.5.1]; VREF internal 2.048 V, external or AVDD.
* Internal temperature sensor (TS=1): 14-bit result, 0.03125 °C/LSB,
  left-justified in the 24-bit word, low 10 bits zero [8.3.10, Table 13].
* System monitors: (VREFP-VREFN)/4, (AVDD-AVSS)/4, shorted inputs [8.3.9].
* Data counter (DCNT) and data-integrity bytes (inverted data / CRC-16).
* Frozen converter (``converter_frozen``, :mod:`firmware_sim.chips.freeze`): no conversion
  completes, DRDY is never set; a START after the freeze ends converts again.
"""

from __future__ import annotations

import functools
import math
from typing import Callable

import numpy as np

from firmware_sim.chips.freeze import Freezable
from edge.hw.regmaps.ads122c04 import (
    CODE_MAX,
    CODE_MIN,
    INTERNAL_VREF_V,
    MUX,
    REGISTERS,
    TEMP_LSB_C,
    conversion_time_s,
    rdata_frame,
)

_EPS = 1e-9
_MAX_BACKLOG = 64
_MUX_LABELS = {v: k for k, v in MUX.items()}


@functools.lru_cache(maxsize=None)
def _times_for(config1: int) -> tuple[float, float]:
    """(single-shot, continuous) conversion times for a CONFIG1 value (asked on every bus access)."""
    dr = min((config1 >> 5) & 0x7, 6)
    turbo = bool(config1 & 0x10)
    return conversion_time_s(dr, turbo, True), conversion_time_s(dr, turbo, False)


@functools.lru_cache(maxsize=None)
def _crc_mode(config2: int) -> str:
    """RDATA's integrity bytes for a CONFIG2 value ("off" for the reserved code too)."""
    mode = REGISTERS.CONFIG2.get(config2, "CRC")
    return mode if mode in ("inverted", "crc16") else "off"


class ADS122C04Emulator(Freezable):
    """Emulated ADS122C04 (the driver is :class:`edge.hw.drivers.ads122c04.ADS122C04`).

    Parameters
    ----------
    clock : SimClock
        Any mode of :mod:`firmware_sim.clock`: the model reads ``clock.now()``
        on each access and catches up, so it never relies on sleeps.
    inputs : callable (mux_label, t_s) -> volts
        Differential input for AIN multiplexer settings such as "AIN0_AIN1"
        or "AIN2_AVSS" (see ``edge.hw.regmaps.ads122c04.MUX``).
    temperature_C : callable t_s -> °C
        Die temperature seen by the internal sensor.
    noise_rms_V : float
        Input-referred noise per conversion (before the gain).
    rng : numpy Generator or seed, optional
    avdd_V, ext_vref_V : float
        Supply and external reference (for VREF settings and monitors).
    """

    def __init__(self, clock, inputs: Callable[[str, float], float], *,
                 temperature_C: Callable[[float], float] = lambda t: 25.0,
                 noise_rms_V: float = 0.0, rng=None, avdd_V: float = 3.3,
                 ext_vref_V: float = 2.5) -> None:
        if not noise_rms_V >= 0:
            raise ValueError(f"noise_rms_V must be >= 0, got {noise_rms_V!r}")
        self.clock = clock
        self.inputs = inputs
        self.temperature_C = temperature_C
        self.noise_rms_V = float(noise_rms_V)
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.avdd_V = float(avdd_V)
        self.ext_vref_V = float(ext_vref_V)
        self.conversions = 0
        self._reset()

    def _reset(self) -> None:
        self.regs = [reg.reset for reg in REGISTERS]    # CONFIG0..3, all 0x00 after reset
        self.data = 0
        self.counter = 0
        self._running = False          # converting (single-shot pending or continuous)
        self._t_end = 0.0
        self._response = b""

    # -- conversions ------------------------------------------------------------------
    @property
    def drdy(self) -> bool:
        return bool(self.regs[2] & 0x80)

    def _continuous(self) -> bool:
        return bool(self.regs[1] & 0x08)

    def _times(self) -> tuple[float, float]:
        return _times_for(self.regs[1])

    def _start(self, now: float) -> None:
        self._running = True
        self._t_end = now + self._times()[0]

    def _catch_up(self) -> None:
        if not self._running:
            return
        now = self.clock.now() + _EPS
        t_single, t_cont = self._times()
        if not self._continuous():
            if self._t_end <= now:
                if not self.frozen_at(self._t_end):  # frozen: the result is lost, DRDY never set
                    self._convert(self._t_end, t_single)
                self._running = False   # single-shot: power down after the result
            return
        if now - self._t_end > _MAX_BACKLOG * t_cont:
            self._t_end += (math.floor((now - self._t_end) / t_cont) - _MAX_BACKLOG) * t_cont
        while self._t_end <= now:
            if not self.frozen_at(self._t_end):
                self._convert(self._t_end, t_cont)
            self._t_end += t_cont

    def _vref(self) -> float:
        sel = (self.regs[1] >> 1) & 0x3
        return INTERNAL_VREF_V if sel == 0 else (self.ext_vref_V if sel == 1 else self.avdd_V)

    def _convert(self, t_end: float, t_conv: float) -> None:
        tm = t_end - 0.5 * t_conv
        if self.regs[1] & 0x01:        # temperature sensor mode ignores CONFIG0 and VREF
            t14 = math.floor(float(self.temperature_C(tm)) / TEMP_LSB_C)
            t14 = max(-(1 << 13), min((1 << 13) - 1, t14))
            code = (t14 & 0x3FFF) << 10
            code = code - (1 << 24) if code & 0x800000 else code
        else:
            mux = _MUX_LABELS.get(self.regs[0] >> 4)
            gain = 1 << ((self.regs[0] >> 1) & 0x7)
            if mux == "REFP_REFN_DIV4":
                v = self.ext_vref_V / 4.0
            elif mux == "AVDD_AVSS_DIV4":
                v = self.avdd_V / 4.0
            elif mux == "SHORTED" or mux is None:
                v = 0.0
            else:
                v = float(self.inputs(mux, tm))
            if self.noise_rms_V:
                v += self.rng.normal(0.0, self.noise_rms_V)
            code = int(round(v * gain / self._vref() * (1 << 23)))
            code = max(CODE_MIN, min(CODE_MAX, code))
        self.data = code & 0xFFFFFF
        self.counter = (self.counter + 1) & 0xFF
        self.regs[2] |= 0x80
        self.conversions += 1

    # -- I2C target --------------------------------------------------------------------
    def i2c_write(self, data: bytes) -> None:
        self._catch_up()
        now = self.clock.now()
        i = 0
        while i < len(data):
            cmd = data[i]
            i += 1
            if cmd & 0xFE == 0x06:                       # RESET
                self._reset()
            elif cmd & 0xFE == 0x08:                     # START/SYNC
                self._start(now)
            elif cmd & 0xFE == 0x02:                     # POWERDOWN
                self._running = False
            elif cmd & 0xF0 == 0x10:                     # RDATA
                dcnt = bool(self.regs[2] & 0x40)
                crc_mode = _crc_mode(self.regs[2])
                self._response = rdata_frame(self.data, self.counter if dcnt else None, crc_mode)
                self.regs[2] &= 0x7F                     # result read: DRDY cleared
            elif cmd & 0xF0 == 0x20:                     # RREG
                self._response = bytes([self.regs[(cmd >> 2) & 0x3]])
            elif cmd & 0xF0 == 0x40:                     # WREG rr + data byte
                if i >= len(data):
                    return
                reg, value = (cmd >> 2) & 0x3, data[i]
                i += 1
                if reg == 2:
                    value = (value & 0x7F) | (self.regs[2] & 0x80)   # DRDY is read-only
                self.regs[reg] = value
                if self._running and self._continuous() and reg in (0, 1):
                    self._start(now)                     # new settings restart the conversion
            # other codes are reserved: ignored

    def i2c_read(self, n: int) -> bytes:
        self._catch_up()
        r = self._response or b"\xff"
        return r[:n] if n <= len(r) else (r * (n // len(r) + 1))[:n]   # the response repeats
