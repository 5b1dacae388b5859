"""ADS1115 16-bit delta-sigma ADC (TI SBAS444): register map and driver.

On the probe it reads the heat-flux sensor differentially (AIN0-AIN1 by
default) at the ±0.256 V range: an FHF05-class sensor gives 0.56 µV per W/m²,
so ±10 kW/m² is ±5.6 mV, i.e. about ±717 codes of 7.8125 µV.

Saturation policy: a conversion code of 0x7FFF or 0x8000 means the input is at
or beyond full scale (datasheet 9.3.3, "Full-Scale Range"). With
``on_saturation="raise"`` (default) the read raises
``SensorFault(reason="saturated")``; with ``"flag"`` it returns the clipped
value and sets :attr:`ADS1115.saturated` (for callers that prefer to keep the
sample and mark it).
"""

from __future__ import annotations

import time
from typing import Callable

from edge.hw.drivers.i2c_base import I2CDevice
from edge.hw.registers import BitField, Register, RegisterMap, to_signed

ADDRESSES = (0x48, 0x49, 0x4A, 0x4B)

MUX = {"AIN0_AIN1": 0, "AIN0_AIN3": 1, "AIN1_AIN3": 2, "AIN2_AIN3": 3,
       "AIN0_GND": 4, "AIN1_GND": 5, "AIN2_GND": 6, "AIN3_GND": 7}
#: PGA code -> full-scale range (V); codes 5, 6, 7 are all ±0.256 V (datasheet Table 8).
PGA_FSR_V = {0: 6.144, 1: 4.096, 2: 2.048, 3: 1.024, 4: 0.512, 5: 0.256, 6: 0.256, 7: 0.256}
DATA_RATES_SPS = {8: 0, 16: 1, 32: 2, 64: 3, 128: 4, 250: 5, 475: 6, 860: 7}
CODE_MAX, CODE_MIN = 0x7FFF, -0x8000

REGISTERS = RegisterMap("ads1115", [
    Register("CONVERSION", 0x00, 2, {"CODE": BitField(0xFFFF, signed=True)}, read_only=True),
    Register("CONFIG", 0x01, 2, {
        "OS": BitField(0x8000),
        "MUX": BitField(0x7000, enum=MUX),
        "PGA": BitField(0x0E00, enum={6.144: 0, 4.096: 1, 2.048: 2, 1.024: 3, 0.512: 4, 0.256: 5}),
        "MODE": BitField(0x0100, enum={"continuous": 0, "single": 1}),
        "DR": BitField(0x00E0, enum=DATA_RATES_SPS),
        "COMP_MODE": BitField(0x0010, enum={"traditional": 0, "window": 1}),
        "COMP_POL": BitField(0x0008, enum={"active_low": 0, "active_high": 1}),
        "COMP_LAT": BitField(0x0004, enum={"nonlatching": 0, "latching": 1}),
        "COMP_QUE": BitField(0x0003, enum={1: 0, 2: 1, 4: 2, "disable": 3}),
    }, reset=0x8583),
    Register("LO_THRESH", 0x02, 2, {"CODE": BitField(0xFFFF, signed=True)}, reset=0x8000),
    Register("HI_THRESH", 0x03, 2, {"CODE": BitField(0xFFFF, signed=True)}, reset=0x7FFF),
])


def fsr_for_code(pga_code: int) -> float:
    return PGA_FSR_V[pga_code & 0x7]


def code_to_volts(code: int, fsr_V: float) -> float:
    """Volts for a conversion code at full-scale range ``fsr_V`` (LSB = FSR / 2^15)."""
    return code * fsr_V / 32768.0


def volts_to_code(volts: float, fsr_V: float) -> int:
    """Ideal conversion code for ``volts`` (rounded, clipped to 0x8000..0x7FFF)."""
    code = int(round(volts * 32768.0 / fsr_V))
    return max(CODE_MIN, min(CODE_MAX, code))


class ADS1115(I2CDevice):
    """Driver for one ADS1115.

    Parameters
    ----------
    bus : smbus2-compatible bus
    address : int
        0x48..0x4B.
    on_saturation : {"raise", "flag"}
        See module docstring.
    attempts, backoff_s, sleep
        Retry policy; ``sleep`` is also used to wait for conversions.
    """

    CHIP = "ads1115"
    ADDRESSES = ADDRESSES

    def __init__(self, bus, address: int = 0x48, *, on_saturation: str = "raise",
                 attempts: int = 4, backoff_s: float = 0.002,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        super().__init__(bus, address, attempts=attempts, backoff_s=backoff_s, sleep=sleep)
        if on_saturation not in ("raise", "flag"):
            raise ValueError(f"on_saturation must be 'raise' or 'flag', got {on_saturation!r}")
        self.on_saturation = on_saturation
        self.saturated = False
        self._config = REGISTERS.CONFIG.reset & 0x7FFF  # cached, OS cleared

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
        self.write_register("HI_THRESH", 0x8000)
        self.write_register("LO_THRESH", 0x0000)
        self._config = REGISTERS.CONFIG.encode(self._config, COMP_QUE=1)
        self.write_register("CONFIG", self._config)

    @property
    def fsr_V(self) -> float:
        return fsr_for_code(REGISTERS.CONFIG.field("PGA").raw(self._config))

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
        cfg = self._config
        if mux is not None:
            cfg = REGISTERS.CONFIG.encode(cfg, MUX=mux)
        cfg = REGISTERS.CONFIG.encode(cfg, MODE="single", OS=0)
        self._config = cfg
        t_conv = 1.0 / self.data_rate_sps
        if timeout_s is None:
            timeout_s = 3.0 * t_conv + 0.01
        self.write_register("CONFIG", cfg | 0x8000)
        self.sleep(t_conv)
        waited = t_conv
        while not self.read_register("CONFIG") & 0x8000:  # OS reads 0 while converting
            if waited >= timeout_s:
                raise self.fault("timeout", f"conversion not done after {timeout_s:.4f} s")
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
