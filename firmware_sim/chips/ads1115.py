"""Register-level model of the ADS1115 16-bit ADC (TI SBAS444).

Emulated (datasheet sections in brackets):

* Pointer register: first byte written selects CONVERSION 0x00, CONFIG 0x01,
  LO_THRESH 0x02, HI_THRESH 0x03; two more bytes write the register MSB first;
  reads return the pointed register MSB first [9.5.1-9.5.3]. Reset values
  CONFIG 0x8583, LO_THRESH 0x8000, HI_THRESH 0x7FFF [9.6].
* Single-shot: writing OS=1 while idle starts one conversion; OS reads 0 while
  converting and 1 when done; the device then powers down [9.4.2.1].
* Continuous: a new result every 1/DR; writing CONFIG restarts the conversion
  so the next result reflects the new settings [9.4.2.2].
* Conversion time 1/DR on the virtual clock; the input is sampled at the centre
  of the conversion window (a delta-sigma averages over it; the centre has the
  same group delay).
* PGA full-scale ranges and clipping to 0x7FFF / 0x8000 [9.3.3, Table 3].
* Comparator and ALERT/RDY [9.3.7, 9.3.8]: traditional (with hysteresis
  LO..HI) and window modes, latching/non-latching, the COMP_QUE count, and the
  conversion-ready function (HI_THRESH MSB=1, LO_THRESH MSB=0). The pin is an
  attribute: :attr:`alert_asserted` (logical) and :attr:`alert_pin_high`
  (electrical, honouring COMP_POL). In continuous conversion-ready mode the
  real pin pulses for ~8 µs per conversion; :attr:`rdy_pulses` counts them.
* Frozen converter (``converter_frozen``, :mod:`firmware_sim.chips.freeze`): a single shot
  does not finish while frozen (OS reads 0; it finishes when the freeze ends), and in continuous
  mode the conversion register stops changing (no conversion-ready pulses either).
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from firmware_sim.chips.freeze import Freezable
from edge.hw.regmaps.ads1115 import CODE_MAX, CODE_MIN, PGA_FSR_V, REGISTERS

_EPS = 1e-9
_MAX_BACKLOG = 64
_CFG = REGISTERS.CONFIG
_MUX_LABELS = {v: k for k, v in _CFG.field("MUX").enum.items()}
_DR_SPS = {v: k for k, v in _CFG.field("DR").enum.items()}


class ADS1115Emulator(Freezable):
    """Emulated ADS1115 (the driver is :class:`edge.hw.drivers.ads1115.ADS1115`).

    Parameters
    ----------
    clock : SimClock
        Any mode of :mod:`firmware_sim.clock`: the model reads ``clock.now()``
        on each access and catches up, so it never relies on sleeps.
    inputs : callable (mux_label, t_s) -> volts
        Input voltage for a multiplexer setting, e.g. ``"AIN0_AIN1"`` (see
        ``edge.hw.regmaps.ads1115.MUX``).
    noise_rms_V : float
        Input-referred noise added to each conversion.
    rng : numpy Generator or seed, optional
    """

    def __init__(self, clock, inputs: Callable[[str, float], float], *,
                 noise_rms_V: float = 0.0, rng=None) -> None:
        if not noise_rms_V >= 0:
            raise ValueError(f"noise_rms_V must be >= 0, got {noise_rms_V!r}")
        self.clock = clock
        self.inputs = inputs
        self.noise_rms_V = float(noise_rms_V)
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.regs = REGISTERS.reset_values()
        self.regs[0x00] = 0
        self.regs[0x01] &= 0x7FFF       # stored without OS; OS is computed on read
        self._pointer = 0
        self._converting = False
        self._t_end = 0.0
        self._queue = 0
        self._alert = False
        self.rdy_pulses = 0
        self.conversions = 0

    # -- helpers ----------------------------------------------------------------
    @property
    def continuous(self) -> bool:
        return not (self.regs[0x01] & 0x0100)

    def _t_conv(self) -> float:
        return 1.0 / _DR_SPS[(self.regs[0x01] >> 5) & 0x7]

    @property
    def alert_asserted(self) -> bool:
        """Logical state of the ALERT/RDY function (after catching up with the clock)."""
        self._catch_up()
        return self._alert

    @property
    def alert_pin_high(self) -> bool:
        """Electrical level of ALERT/RDY (open drain, pulled up when inactive)."""
        self._catch_up()
        active_high = bool(self.regs[0x01] & 0x0008)
        return self._alert if active_high else not self._alert

    def _catch_up(self) -> None:
        now = self.clock.now() + _EPS
        if not self._converting:
            return
        if self.continuous:
            t = self._t_conv()
            if now - self._t_end > _MAX_BACKLOG * t:
                self._t_end += (math.floor((now - self._t_end) / t) - _MAX_BACKLOG) * t
            while self._t_end <= now:
                if not self.frozen_at(self._t_end):
                    self._convert(self._t_end, t)
                self._t_end += t
            return
        if self.frozen_at(self._t_end):
            self._t_end = self.thaw_s(self._t_end)  # a frozen single shot ends when the freeze does
        if self._t_end <= now:
            self._convert(self._t_end, self._t_conv())
            self._converting = False

    def _convert(self, t_end: float, t_conv: float) -> None:
        cfg = self.regs[0x01]
        mux = _MUX_LABELS[(cfg >> 12) & 0x7]
        fsr = PGA_FSR_V[(cfg >> 9) & 0x7]
        v = float(self.inputs(mux, t_end - 0.5 * t_conv))
        if self.noise_rms_V:
            v += self.rng.normal(0.0, self.noise_rms_V)
        code = max(CODE_MIN, min(CODE_MAX, int(round(v * 32768.0 / fsr))))
        self.regs[0x00] = code & 0xFFFF
        self.conversions += 1
        self._comparator(code)

    def _comparator(self, code: int) -> None:
        cfg = self.regs[0x01]
        que = cfg & 0x3
        if que == 3:                       # comparator disabled: pin high-Z
            self._alert = False
            self._queue = 0
            return
        hi = self.regs[0x03] - 0x10000 if self.regs[0x03] & 0x8000 else self.regs[0x03]
        lo = self.regs[0x02] - 0x10000 if self.regs[0x02] & 0x8000 else self.regs[0x02]
        if self.regs[0x03] & 0x8000 and not self.regs[0x02] & 0x8000:
            # Conversion-ready mode (9.3.8).
            self._alert = True
            self.rdy_pulses += 1
            return
        window = bool(cfg & 0x0010)
        latching = bool(cfg & 0x0004)
        beyond = code > hi or (window and code < lo)
        self._queue = self._queue + 1 if beyond else 0
        if self._queue >= (1, 2, 4)[que]:
            self._alert = True
        elif not latching:
            inside = (lo <= code <= hi) if window else (code < lo)
            if inside:
                self._alert = False

    # -- I2C target -------------------------------------------------------------------
    def i2c_write(self, data: bytes) -> None:
        if not data:
            return
        self._catch_up()
        self._pointer = data[0] & 0x03
        if len(data) < 3 or self._pointer == 0x00:
            return
        value = (data[1] << 8) | data[2]
        now = self.clock.now()
        if self._pointer != 0x01:
            self.regs[self._pointer] = value
            return
        start = bool(value & 0x8000)
        self.regs[0x01] = value & 0x7FFF
        if self.continuous:
            self._converting = True
            self._t_end = now + self._t_conv()
        elif start and not self._converting:
            self._converting = True
            self._t_end = now + self._t_conv()
            if self.regs[0x03] & 0x8000 and not self.regs[0x02] & 0x8000:
                self._alert = False     # RDY deasserts when a conversion starts
        elif self._converting and not start:
            # Switched from continuous to single-shot: finish the running conversion, then stop.
            pass

    def i2c_read(self, n: int) -> bytes:
        self._catch_up()
        value = self.regs[self._pointer]
        if self._pointer == 0x01:
            value |= 0x0000 if (self._converting or self.continuous) else 0x8000
        elif self._pointer == 0x00 and self.regs[0x01] & 0x0004 and self.regs[0x01] & 0x3 != 3:
            self._alert = False          # latched alert clears on a conversion read
        raw = value.to_bytes(2, "big")
        # The register repeats past its two bytes (a driver's read is two: no loop then).
        return raw if n == 2 else bytes(raw[i % 2] for i in range(n))

    def register(self, name: str) -> int:
        """Register value as the chip would send it (OS computed for CONFIG)."""
        self._catch_up()
        reg = REGISTERS[name]
        v = self.regs[reg.address]
        if reg.address == 0x01:
            v |= 0x0000 if (self._converting or self.continuous) else 0x8000
        return v
