"""ADS122C04 24-bit ADC (TI SBAS751): register map and datasheet constants as data.

Shared by the driver (edge.hw.drivers.ads122c04) and the emulator
(firmware_sim.chips.ads122c04.ADS122C04Emulator): one statement of the chip, so the two cannot drift.
"""

from __future__ import annotations

from edge.hw.registers import BitField, Register, RegisterMap, to_signed


ADDRESSES = tuple(range(0x40, 0x50))

# Commands (datasheet Table 16).
CMD_RESET = 0x06
CMD_START = 0x08
CMD_POWERDOWN = 0x02
CMD_RDATA = 0x10
CMD_RREG = 0x20
CMD_WREG = 0x40


def rreg(reg: int) -> int:
    return CMD_RREG | ((reg & 0x3) << 2)


def wreg(reg: int) -> int:
    return CMD_WREG | ((reg & 0x3) << 2)


MUX = {"AIN0_AIN1": 0, "AIN0_AIN2": 1, "AIN0_AIN3": 2, "AIN1_AIN0": 3, "AIN1_AIN2": 4,
       "AIN1_AIN3": 5, "AIN2_AIN3": 6, "AIN3_AIN2": 7, "AIN0_AVSS": 8, "AIN1_AVSS": 9,
       "AIN2_AVSS": 10, "AIN3_AVSS": 11, "REFP_REFN_DIV4": 12, "AVDD_AVSS_DIV4": 13,
       "SHORTED": 14}
GAINS = {1: 0, 2: 1, 4: 2, 8: 3, 16: 4, 32: 5, 64: 6, 128: 7}
#: Nominal data rates (SPS) per DR code in normal mode; turbo doubles them (Table 20).
DATA_RATES_NORMAL_SPS = (20, 45, 90, 175, 330, 600, 1000)

REGISTERS = RegisterMap("ads122c04", [
    Register("CONFIG0", 0, 1, {
        "MUX": BitField(0xF0, enum=MUX),
        "GAIN": BitField(0x0E, enum=GAINS),
        "PGA_BYPASS": BitField(0x01),
    }),
    Register("CONFIG1", 1, 1, {
        "DR": BitField(0xE0),
        "MODE": BitField(0x10, enum={"normal": 0, "turbo": 1}),
        "CM": BitField(0x08, enum={"single": 0, "continuous": 1}),
        "VREF": BitField(0x06, enum={"internal": 0, "external": 1, "avdd": 2}),
        "TS": BitField(0x01),
    }),
    Register("CONFIG2", 2, 1, {
        "DRDY": BitField(0x80),
        "DCNT": BitField(0x40),
        "CRC": BitField(0x30, enum={"off": 0, "inverted": 1, "crc16": 2}),
        "BCS": BitField(0x08),
        "IDAC_uA": BitField(0x07, enum={0: 0, 10: 1, 50: 2, 100: 3, 250: 4, 500: 5, 1000: 6, 1500: 7}),
    }, volatile=True),   # DRDY is set by the chip
    Register("CONFIG3", 3, 1, {
        "I1MUX": BitField(0xE0, enum={"off": 0, "AIN0": 1, "AIN1": 2, "AIN2": 3, "AIN3": 4, "REFP": 5, "REFN": 6}),
        "I2MUX": BitField(0x1C, enum={"off": 0, "AIN0": 1, "AIN1": 2, "AIN2": 3, "AIN3": 4, "REFP": 5, "REFN": 6}),
    }),
])

# Conversion times in t_CLK cycles (datasheet Table 12). Normal mode counts at
# f_CLK = 1.024 MHz; turbo-mode times equal the same counts at 2.048 MHz.
F_CLK_Hz = 1.024e6
CYCLES_CONTINUOUS = (51192, 22780, 11532, 5916, 3116, 1724, 1036)
CYCLES_SINGLE_NORMAL = (51213, 22805, 11557, 5941, 3141, 1749, 1061)
# The last two turbo single-shot entries follow the table's +29-cycle pattern.
CYCLES_SINGLE_TURBO = (51217, 22809, 11561, 5945, 3145, 1753, 1065)

INTERNAL_VREF_V = 2.048
TEMP_LSB_C = 0.03125     # 14-bit temperature result, left-justified in 24 bits (8.3.10)
CODE_MAX, CODE_MIN = 0x7FFFFF, -0x800000


def data_rate_sps(dr_code: int, turbo: bool) -> int:
    if not 0 <= dr_code <= 6:
        raise ValueError(f"dr_code must be 0..6, got {dr_code!r}")
    return DATA_RATES_NORMAL_SPS[dr_code] * (2 if turbo else 1)


def conversion_time_s(dr_code: int, turbo: bool, single_shot: bool) -> float:
    """Actual conversion time (Table 12): single-shot from START latch to DRDY,
    continuous between DRDY edges."""
    if not 0 <= dr_code <= 6:
        raise ValueError(f"dr_code must be 0..6, got {dr_code!r}")
    if single_shot:
        cycles = (CYCLES_SINGLE_TURBO if turbo else CYCLES_SINGLE_NORMAL)[dr_code]
    else:
        cycles = CYCLES_CONTINUOUS[dr_code]
    return cycles / (F_CLK_Hz * (2.0 if turbo else 1.0))


def code_to_volts(code: int, gain: int, vref_V: float = INTERNAL_VREF_V) -> float:
    """Differential input voltage for a 24-bit code: LSB = 2 Vref / gain / 2^24."""
    return code * vref_V / (gain * float(1 << 23))


def temperature_code_to_C(code24: int) -> float:
    """Internal temperature from the 24-bit result (14 MSBs, 0.03125 °C/LSB)."""
    return to_signed((code24 & 0xFFFFFF) >> 10, 14) * TEMP_LSB_C


def crc16_ccitt(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16-CCITT (x^16 + x^12 + x^5 + 1), preset 0xFFFF, as in datasheet 8.5.2."""
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def rdata_frame(code24: int, counter: int | None, crc_mode: str) -> bytes:
    """Bytes the chip sends after RDATA: [counter] data[3] [check].

    ``crc_mode`` "inverted" appends the bitwise inverse of the preceding bytes,
    "crc16" appends their CRC-16. Shared by the driver and the chip model.
    """
    payload = (bytes([counter & 0xFF]) if counter is not None else b"") + \
        (code24 & 0xFFFFFF).to_bytes(3, "big")
    if crc_mode == "inverted":
        return payload + bytes(b ^ 0xFF for b in payload)
    if crc_mode == "crc16":
        return payload + crc16_ccitt(payload).to_bytes(2, "big")
    return payload
