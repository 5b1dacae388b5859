"""MCP9600 (Microchip DS20005426): register map and datasheet constants as data.

Shared by the driver (edge.hw.drivers.mcp9600) and the emulator
(firmware_sim.chips.mcp9600.MCP9600Emulator): one statement of the chip, so the two cannot drift.
"""

from __future__ import annotations

from edge.hw.registers import BitField, Register, RegisterMap


DEVICE_ID = 0x40
ADDRESSES = tuple(range(0x60, 0x68))

_TEMP = BitField(0xFFFF, signed=True, scale=0.0625)  # 0.0625 °C/LSB two's complement (Reg 5-2..5-4)
_ALERT_CFG = {
    "CLEAR_INTERRUPT": BitField(0x80), "MONITOR_COLD": BitField(0x10), "RISING": BitField(0x08),
    "ACTIVE_HIGH": BitField(0x04), "INTERRUPT_MODE": BitField(0x02), "ENABLE": BitField(0x01),
}

ADC_RESOLUTIONS_BITS = {18: 0, 16: 1, 14: 2, 12: 3}
#: Hot-junction conversion time per ADC resolution, typical (datasheet Register 5-8 / Table 1).
CONVERSION_TIME_s = {18: 0.320, 16: 0.080, 14: 0.020, 12: 0.005}
#: Cold-junction conversion time per resolution (datasheet Table 5-2).
COLD_JUNCTION_TIME_s = {0.0625: 0.250, 0.25: 0.063}
#: Raw ADC register LSB: 2 µV at 18 bit (we keep the register in 18-bit units;
#: lower resolutions leave the low bits at zero).
RAW_ADC_LSB_V = 2e-6


def adc_step_V(resolution_bits: int) -> float:
    """Thermocouple-EMF step of the ADC at 18/16/14/12 bit: 2, 8, 32, 128 uV (datasheet)."""
    if resolution_bits not in (18, 16, 14, 12):
        raise ValueError(f"resolution_bits must be 18, 16, 14 or 12, got {resolution_bits!r}")
    return RAW_ADC_LSB_V * (1 << (18 - resolution_bits))

REGISTERS = RegisterMap("mcp9600", [
    Register("TH", 0x00, 2, {"TEMP_C": _TEMP}, read_only=True, volatile=True),
    Register("TDELTA", 0x01, 2, {"TEMP_C": _TEMP}, read_only=True, volatile=True),
    Register("TC", 0x02, 2, {"TEMP_C": _TEMP}, read_only=True, volatile=True),
    Register("RAW_ADC", 0x03, 3, {"CODE": BitField(0xFFFFFF, signed=True)}, read_only=True, volatile=True),
    Register("STATUS", 0x04, 1, {
        "BURST_COMPLETE": BitField(0x80), "TH_UPDATE": BitField(0x40),
        "INPUT_RANGE": BitField(0x10), "ALERT4": BitField(0x08), "ALERT3": BitField(0x04),
        "ALERT2": BitField(0x02), "ALERT1": BitField(0x01),
    }, volatile=True),
    Register("THERMOCOUPLE_CONFIG", 0x05, 1, {
        "TYPE": BitField(0x70, enum={"K": 0, "J": 1, "T": 2, "N": 3, "S": 4, "E": 5, "B": 6, "R": 7}),
        "FILTER": BitField(0x07),
    }),
    Register("DEVICE_CONFIG", 0x06, 1, {
        "COLD_JUNCTION_RESOLUTION": BitField(0x80, enum={0.0625: 0, 0.25: 1}),
        "ADC_RESOLUTION": BitField(0x60, enum=ADC_RESOLUTIONS_BITS),
        "BURST_SAMPLES": BitField(0x1C, enum={1: 0, 2: 1, 4: 2, 8: 3, 16: 4, 32: 5, 64: 6, 128: 7}),
        "MODE": BitField(0x03, enum={"normal": 0, "shutdown": 1, "burst": 2}),
    }),
    *[Register(f"ALERT{i}_CONFIG", 0x07 + i, 1, _ALERT_CFG) for i in range(1, 5)],
    *[Register(f"ALERT{i}_HYSTERESIS", 0x0B + i, 1, {"HYST_C": BitField(0xFF)}) for i in range(1, 5)],
    *[Register(f"ALERT{i}_LIMIT", 0x0F + i, 2,
               {"LIMIT_C": BitField(0xFFFC, signed=True, scale=0.25)}) for i in range(1, 5)],
    Register("DEVICE_ID", 0x20, 2, {"ID": BitField(0xFF00), "REVISION": BitField(0x00FF)},
             reset=(DEVICE_ID << 8) | 0x11, read_only=True),
])
