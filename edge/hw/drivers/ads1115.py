"""ADS1115 16-bit delta-sigma ADC (TI SBAS444): driver (its register map is data in edge.hw.regmaps.ads1115).

On the probe it reads the heat-flux sensor differentially (AIN0-AIN1 by
default) at the ±0.256 V range: an FHF05-class sensor gives 0.56 µV per W/m²,
so ±10 kW/m² is ±5.6 mV, i.e. about ±717 codes of 7.8125 µV.

Saturation policy: a conversion code of 0x7FFF or 0x8000 means the input is at
or beyond full scale (datasheet 9.3.3, "Full-Scale Range"). With
``on_saturation="raise"`` (default) the read raises
``SensorFault(reason="saturated")``; with ``"flag"`` it returns the clipped
value and sets :attr:`ADS1115.saturated` (for callers that prefer to keep the
sample and mark it).

A frozen converter (ISSUE #35 §5): in single shot the chip's own "done"
indication is CONFIG.OS (0 while converting); a conversion not done within
three conversion times plus 10 ms raises ``SensorFault(reason="timeout")``
naming the chip (the probe reads the flux this way). In continuous mode the
chip has no new-data bit (OS reads 0 throughout; only the ALERT/RDY pin
pulses, which the probe does not wire), so :meth:`ADS1115.read_latest_code`
cannot tell a frozen converter from a steady input.
"""

from __future__ import annotations

import functools
import time
from typing import Callable

from edge.hw.drivers.i2c_base import I2CDevice
from edge.hw.registers import to_signed
from edge.hw.regmaps.ads1115 import (
    ADDRESSES,
    REGISTERS,
    CODE_MIN,
    CODE_MAX,
    fsr_for_code,
    code_to_volts,
)


# A single shot's register arithmetic depends only on the cached CONFIG and the input, the same every
# sample of a touch: memoised (the map stays the one statement of the bits).
@functools.lru_cache(maxsize=256)
def _single_shot(config: int, mux: str | None) -> tuple[int, int, float]:
    """(CONFIG kept, CONFIG written with OS=1, conversion time s) for a single shot of ``mux``."""
    cfg = config if mux is None else REGISTERS.CONFIG.encode(config, MUX=mux)
    cfg = REGISTERS.CONFIG.encode(cfg, MODE="single", OS=0)
    return cfg, REGISTERS.CONFIG.encode(cfg, OS=1), 1.0 / REGISTERS.CONFIG.get(cfg, "DR")


@functools.lru_cache(maxsize=256)
def _done(config: int) -> bool:
    return bool(REGISTERS.CONFIG.get(config, "OS"))    # OS reads 0 while converting


@functools.lru_cache(maxsize=256)
def _fsr_V(config: int) -> float:
    return fsr_for_code(REGISTERS.CONFIG.field("PGA").raw(config))


class ADS1115(I2CDevice):
    """Driver for one ADS1115.

    Parameters
    ----------
    bus : smbus2-compatible bus
    address : int
        0x48..0x4B.
    on_saturation : {"raise", "flag"}
        See module docstring.
    attempts, backoff_s, sleep, clock
        Retry policy; ``sleep`` is also used to wait for conversions.
    """

    CHIP = "ads1115"
    ADDRESSES = ADDRESSES

    def __init__(self, bus, address: int = 0x48, *, on_saturation: str = "raise",
                 attempts: int = 4, backoff_s: float = 0.002,
                 sleep: Callable[[float], None] = time.sleep,
                 clock: Callable[[], float] | None = None) -> None:
        super().__init__(bus, address, attempts=attempts, backoff_s=backoff_s, sleep=sleep, clock=clock)
        if on_saturation not in ("raise", "flag"):
            raise ValueError(f"on_saturation must be 'raise' or 'flag', got {on_saturation!r}")
        self.on_saturation = on_saturation
        self.saturated = False
        self._config = REGISTERS.CONFIG.encode(REGISTERS.CONFIG.reset, OS=0)  # cached, OS cleared

    # -- registers -------------------------------------------------------------
    def read_register(self, name: str) -> int:
        reg = REGISTERS[name]
        return reg.from_bytes(self._read_block(reg.address, 2))

    def write_register(self, name: str, value: int) -> None:
        reg = REGISTERS[name]
        if reg.read_only:
            raise ValueError(f"register {name} is read-only")
        self._write_block(reg.address, reg.to_bytes(value & 0xFFFF))

    def read_config(self) -> dict:
        return REGISTERS.CONFIG.decode(self.read_register("CONFIG"))

    def configure(self, *, mux: str = "AIN0_AIN1", fsr_V: float = 0.256, data_rate_sps: int = 128,
                  mode: str = "single", comp_mode: str = "traditional", comp_pol: str = "active_low",
                  comp_lat: str = "nonlatching", comp_que="disable") -> None:
        """Write CONFIG (without starting a conversion in single-shot mode)."""
        self._config = REGISTERS.CONFIG.encode(
            0, OS=0, MUX=mux, PGA=fsr_V, MODE=mode, DR=data_rate_sps, COMP_MODE=comp_mode,
            COMP_POL=comp_pol, COMP_LAT=comp_lat, COMP_QUE=comp_que)
        self.write_register("CONFIG", self._config)

    def enable_conversion_ready_pin(self) -> None:
        """Use ALERT/RDY as conversion-ready: Hi_thresh MSB=1, Lo_thresh MSB=0,
        COMP_QUE != disable (datasheet 9.3.8)."""
        self.write_register("HI_THRESH", REGISTERS.HI_THRESH.encode(0, CODE=CODE_MIN))  # MSB set
        self.write_register("LO_THRESH", REGISTERS.LO_THRESH.encode(0, CODE=0))  # MSB clear
        self._config = REGISTERS.CONFIG.encode(self._config, COMP_QUE=1)
        self.write_register("CONFIG", self._config)

    @property
    def fsr_V(self) -> float:
        return _fsr_V(self._config)

    @property
    def data_rate_sps(self) -> int:
        return REGISTERS.CONFIG.get(self._config, "DR")

    # -- conversions -------------------------------------------------------------
    def _check(self, code: int) -> int:
        self.saturated = code in (CODE_MAX, CODE_MIN)
        if self.saturated and self.on_saturation == "raise":
            raise self.fault("saturated", f"code 0x{code & 0xFFFF:04x} at ±{self.fsr_V} V full scale")
        return code

    def read_single_shot_code(self, mux: str | None = None, timeout_s: float | None = None) -> int:
        """Start one conversion (OS=1), wait 1/DR, poll OS, read the code."""
        cfg, start, t_conv = _single_shot(self._config, mux)
        self._config = cfg
        if timeout_s is None:
            timeout_s = 3.0 * t_conv + 0.01
        self.write_register("CONFIG", start)
        self.sleep(t_conv)
        waited = t_conv
        while not _done(self.read_register("CONFIG")):  # OS reads 0 while converting
            if waited >= timeout_s:
                raise self.fault("timeout", f"converter stuck: single shot not done (CONFIG.OS) after "
                                            f"{timeout_s:.4f} s, one takes {t_conv:.4f} s")
            step = t_conv / 10.0
            self.sleep(step)
            waited += step
        return self._check(to_signed(self.read_register("CONVERSION"), 16))

    def read_single_shot_V(self, mux: str | None = None, timeout_s: float | None = None) -> float:
        """One single-shot conversion in volts."""
        return code_to_volts(self.read_single_shot_code(mux, timeout_s), self.fsr_V)

    def start_continuous(self, mux: str | None = None) -> None:
        """Switch to continuous conversion (new result every 1/DR)."""
        cfg = self._config if mux is None else REGISTERS.CONFIG.encode(self._config, MUX=mux)
        self._config = REGISTERS.CONFIG.encode(cfg, MODE="continuous", OS=0)
        self.write_register("CONFIG", self._config)

    def stop_continuous(self) -> None:
        """Back to single-shot mode (the ADC powers down after the current conversion)."""
        self._config = REGISTERS.CONFIG.encode(self._config, MODE="single", OS=0)
        self.write_register("CONFIG", self._config)

    def read_latest_code(self) -> int:
        """Latest conversion register (continuous mode)."""
        return self._check(to_signed(self.read_register("CONVERSION"), 16))

    def read_latest_V(self) -> float:
        return code_to_volts(self.read_latest_code(), self.fsr_V)
