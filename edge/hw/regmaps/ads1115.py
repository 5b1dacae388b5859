"""ADS1115 16-bit ADC (TI SBAS444): register map and datasheet constants as data.

Shared by the driver (edge.hw.drivers.ads1115) and the emulator
(firmware_sim.chips.ads1115.ADS1115Emulator): one statement of the chip, so the two cannot drift.
"""

from __future__ import annotations

from edge.hw.registers import BitField, Register, RegisterMap


ADDRESSES = (0x48, 0x49, 0x4A, 0x4B)

MUX = {"AIN0_AIN1": 0, "AIN0_AIN3": 1, "AIN1_AIN3": 2, "AIN2_AIN3": 3,
       "AIN0_GND": 4, "AIN1_GND": 5, "AIN2_GND": 6, "AIN3_GND": 7}
#: PGA code -> full-scale range (V); codes 5, 6, 7 are all ±0.256 V (datasheet Table 8).
PGA_FSR_V = {0: 6.144, 1: 4.096, 2: 2.048, 3: 1.024, 4: 0.512, 5: 0.256, 6: 0.256, 7: 0.256}
DATA_RATES_SPS = {8: 0, 16: 1, 32: 2, 64: 3, 128: 4, 250: 5, 475: 6, 860: 7}
CODE_MAX, CODE_MIN = 0x7FFF, -0x8000

REGISTERS = RegisterMap("ads1115", [
    Register("CONVERSION", 0x00, 2, {"CODE": BitField(0xFFFF, signed=True)}, read_only=True, volatile=True),
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
