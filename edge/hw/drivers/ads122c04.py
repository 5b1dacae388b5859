"""ADS122C04 24-bit delta-sigma ADC with I2C (TI SBAS751): driver (register map in edge.hw.regmaps.ads122c04),
command set, conversion timing and driver.

The precision option of the probe: it reads the thermocouple EMF (µV level,
PGA gain up to 128) and the heat-flux sensor voltage, and its internal
temperature sensor can serve as the cold junction. Hot-junction temperature is
``T_hot = T(E_meas + E(T_cj))`` with the NIST type K functions (edge.physics.typek).

The chip is command driven (datasheet 8.5.3): a command byte is the SMBus
"register" argument, so RREG maps to ``read_byte_data(addr, 0x20 | r << 2)``,
WREG to ``write_byte_data(addr, 0x40 | r << 2, value)``, RDATA to
``read_i2c_block_data(addr, 0x10, n)`` and RESET/START/POWERDOWN to
``write_byte(addr, cmd)``.

A frozen converter (ISSUE #35 §5): every conversion, single shot or
continuous, is waited for on the chip's DRDY bit; none within three
conversion times plus 5 ms raises ``SensorFault(reason="timeout")`` naming
the chip.
"""

from __future__ import annotations

import errno
import functools
import time
from typing import Callable

from edge.physics import typek
from edge.hw.faults import SensorFault
from edge.hw.drivers.i2c_base import I2CDevice
from edge.hw.registers import to_signed
from edge.hw.regmaps.ads122c04 import (
    ADDRESSES,
    CMD_RESET,
    CMD_START,
    CMD_POWERDOWN,
    CMD_RDATA,
    rreg,
    wreg,
    DATA_RATES_NORMAL_SPS,
    REGISTERS,
    CODE_MIN,
    CODE_MAX,
    INTERNAL_VREF_V,
    conversion_time_s,
    code_to_volts,
    temperature_code_to_C,
    rdata_frame,
)


# The register arithmetic of a conversion depends only on register values and arguments, and a touch
# asks the same few each sample: memoised (the map stays the one statement of the bits).
@functools.lru_cache(maxsize=256)
def _timing(config1: int) -> tuple[float, float, bool]:
    """(single-shot, continuous) conversion time and whether continuous, for a CONFIG1 value."""
    c1 = REGISTERS.CONFIG1
    dr = min(c1.get(config1, "DR"), 6)    # codes 6 and 7 are both 1000 SPS
    turbo = c1.get(config1, "MODE") == "turbo"
    return (conversion_time_s(dr, turbo, single_shot=True), conversion_time_s(dr, turbo, single_shot=False),
            c1.get(config1, "CM") == "continuous")


@functools.lru_cache(maxsize=256)
def _input(config0: int, mux: str | None, gain: int | None) -> int:
    """CONFIG0 with ``mux`` and ``gain`` (unchanged if None; no PGA bypass above gain 4)."""
    r0 = config0
    if mux is not None:
        r0 = REGISTERS.CONFIG0.encode(r0, MUX=mux)
    if gain is not None:
        r0 = REGISTERS.CONFIG0.encode(r0, GAIN=gain)
        if gain > 4:  # PGA cannot be bypassed above gain 4
            r0 = REGISTERS.CONFIG0.encode(r0, PGA_BYPASS=0)
    return r0


@functools.lru_cache(maxsize=256)
def _with_ts(config1: int, on: bool) -> int:
    return REGISTERS.CONFIG1.encode(config1, TS=int(on))


@functools.lru_cache(maxsize=256)
def _drdy(config2: int) -> bool:
    return bool(REGISTERS.CONFIG2.get(config2, "DRDY"))


@functools.lru_cache(maxsize=256)
def _frame(config2: int) -> tuple[bool, str, int]:
    """RDATA's frame for a CONFIG2 value: (data counter on, integrity mode, bytes to read)."""
    dcnt = bool(REGISTERS.CONFIG2.get(config2, "DCNT"))
    crc_mode = REGISTERS.CONFIG2.get(config2, "CRC")
    n = 3 + (1 if dcnt else 0)
    n += {"inverted": n, "crc16": 2}.get(crc_mode, 0)
    return dcnt, crc_mode, n


@functools.lru_cache(maxsize=256)
def _gain(config0: int) -> int:
    return REGISTERS.CONFIG0.get(config0, "GAIN")


@functools.lru_cache(maxsize=256)
def _internal_vref(config1: int) -> bool:
    return REGISTERS.CONFIG1.get(config1, "VREF") == "internal"


class _IntegrityError(OSError):
    """RDATA bytes failed the inverted-data / CRC check."""


class ADS122C04(I2CDevice):
    """Driver for one ADS122C04.

    Parameters
    ----------
    bus : smbus2-compatible bus
    address : int
        0x40..0x4F.
    vref_V : float
        Reference voltage used for code conversion when VREF is not internal.
    on_saturation : {"raise", "flag"}
        Full-scale codes 0x7FFFFF / 0x800000 raise SensorFault("saturated")
        or set :attr:`saturated`.
    attempts, backoff_s, sleep, clock
        Retry policy; ``sleep`` also waits for conversions.
    """

    CHIP = "ads122c04"
    ADDRESSES = ADDRESSES

    def __init__(self, bus, address: int = 0x40, *, vref_V: float = INTERNAL_VREF_V,
                 on_saturation: str = "raise", attempts: int = 4, backoff_s: float = 0.002,
                 sleep: Callable[[float], None] = time.sleep,
                 clock: Callable[[], float] | None = None) -> None:
        super().__init__(bus, address, attempts=attempts, backoff_s=backoff_s, sleep=sleep, clock=clock)
        if on_saturation not in ("raise", "flag"):
            raise ValueError(f"on_saturation must be 'raise' or 'flag', got {on_saturation!r}")
        if not vref_V > 0:
            raise ValueError(f"vref_V must be > 0, got {vref_V!r}")
        self.vref_V = float(vref_V)
        self.on_saturation = on_saturation
        self.saturated = False
        self._regs = [0, 0, 0, 0]   # cached configuration (power-on: all zero)

    # -- commands ------------------------------------------------------------
    def _command(self, cmd: int, what: str) -> None:
        self._retry(what, lambda: self.bus.write_byte(self.address, cmd))

    def reset(self) -> None:
        """RESET command: all registers back to 0x00."""
        self._command(CMD_RESET, "RESET")
        self._regs = [0, 0, 0, 0]

    def start(self) -> None:
        """START/SYNC: begin a single-shot conversion or (re)start continuous ones."""
        self._command(CMD_START, "START/SYNC")

    def powerdown(self) -> None:
        self._command(CMD_POWERDOWN, "POWERDOWN")

    def read_register(self, reg: int) -> int:
        if reg not in (0, 1, 2, 3):
            raise ValueError(f"reg must be 0..3, got {reg!r}")
        return self._retry(f"RREG {reg}", lambda: self.bus.read_byte_data(self.address, rreg(reg)))

    def write_register(self, reg: int, value: int) -> None:
        if reg not in (0, 1, 2, 3):
            raise ValueError(f"reg must be 0..3, got {reg!r}")
        if not 0 <= value <= 0xFF:
            raise ValueError(f"value must be 0..255, got {value!r}")
        self._retry(f"WREG {reg}", lambda: self.bus.write_byte_data(self.address, wreg(reg), value))
        self._regs[reg] = value

    def _write_if_changed(self, reg: int, value: int) -> None:
        if self._regs[reg] != value:
            self.write_register(reg, value)

    # -- configuration ---------------------------------------------------------
    def configure(self, *, mux: str = "AIN0_AIN1", gain: int = 1, pga_bypass: bool = False,
                  data_rate_sps: int = 20, turbo: bool = False, continuous: bool = False,
                  vref: str = "internal", temperature_sensor: bool = False,
                  data_counter: bool = False, crc: str = "off", burnout_current: bool = False,
                  idac_uA: int = 0, i1mux: str = "off", i2mux: str = "off") -> None:
        """Write all four configuration registers.

        ``data_rate_sps`` is the nominal rate for the chosen mode (normal: 20,
        45, 90, 175, 330, 600, 1000; turbo: twice those).
        """
        rates = [r * (2 if turbo else 1) for r in DATA_RATES_NORMAL_SPS]
        if data_rate_sps not in rates:
            raise ValueError(f"data_rate_sps must be one of {rates} in "
                             f"{'turbo' if turbo else 'normal'} mode, got {data_rate_sps!r}")
        if pga_bypass and gain > 4:
            raise ValueError("pga_bypass is only allowed for gain 1, 2 or 4 (datasheet 8.3.2.2)")
        r0 = REGISTERS.CONFIG0.encode(0, MUX=mux, GAIN=gain, PGA_BYPASS=int(pga_bypass))
        r1 = REGISTERS.CONFIG1.encode(0, DR=rates.index(data_rate_sps),
                                      MODE="turbo" if turbo else "normal",
                                      CM="continuous" if continuous else "single",
                                      VREF=vref, TS=int(temperature_sensor))
        r2 = REGISTERS.CONFIG2.encode(0, DCNT=int(data_counter), CRC=crc, BCS=int(burnout_current),
                                      IDAC_uA=idac_uA)
        r3 = REGISTERS.CONFIG3.encode(0, I1MUX=i1mux, I2MUX=i2mux)
        for i, v in enumerate((r0, r1, r2, r3)):
            self.write_register(i, v)

    def read_config(self) -> dict:
        out = {}
        for i, reg in enumerate(REGISTERS):
            out.update(reg.decode(self.read_register(i)))
        return out

    @property
    def gain(self) -> int:
        return _gain(self._regs[0])

    @property
    def continuous(self) -> bool:
        return _timing(self._regs[1])[2]

    @property
    def conversion_time_s(self) -> float:
        single, cont, continuous = _timing(self._regs[1])
        return cont if continuous else single

    # -- data -------------------------------------------------------------------
    def data_ready(self) -> bool:
        """DRDY bit of CONFIG2 (set on a new result, cleared by reading it)."""
        return _drdy(self.read_register(2))

    def read_data_code(self) -> int:
        """RDATA: the latest 24-bit two's-complement result (checks CRC if enabled)."""
        dcnt, crc_mode, n = _frame(self._regs[2])

        def xfer() -> int:
            raw = bytes(self.bus.read_i2c_block_data(self.address, CMD_RDATA, n))
            off = 1 if dcnt else 0
            code = int.from_bytes(raw[off:off + 3], "big")
            if crc_mode in ("inverted", "crc16"):
                expect = rdata_frame(code, raw[0] if dcnt else None, crc_mode)
                if raw != expect:
                    # A corrupted transfer is an I/O error: retry it like one.
                    raise _IntegrityError(errno.EIO, f"RDATA {crc_mode} check failed: {raw.hex()}")
            return to_signed(code, 24)

        try:
            return self._retry("RDATA", xfer)
        except SensorFault as exc:
            if isinstance(exc.__cause__, _IntegrityError):
                raise self.fault("crc", str(exc.__cause__)) from exc.__cause__
            raise

    def convert(self, timeout_s: float | None = None) -> int:
        """One conversion: START, wait the conversion time, poll DRDY, RDATA.

        In continuous mode this waits for the next DRDY instead of sending START.
        """
        t_conv = self.conversion_time_s
        if timeout_s is None:
            timeout_s = 3.0 * t_conv + 0.005
        if not self.continuous:
            self.start()
        self.sleep(t_conv)
        waited = t_conv
        while not self.data_ready():
            if waited >= timeout_s:
                raise self.fault("timeout", f"converter stuck: DRDY not set after {timeout_s:.4f} s, "
                                            f"a conversion takes {t_conv:.4f} s")
            step = max(t_conv / 20.0, 1e-4)
            self.sleep(step)
            waited += step
        return self.read_data_code()

    def _check(self, code: int) -> int:
        self.saturated = code in (CODE_MAX, CODE_MIN)
        if self.saturated and self.on_saturation == "raise":
            raise self.fault("saturated", f"code 0x{code & 0xFFFFFF:06x} at gain {self.gain}")
        return code

    def _vref(self) -> float:
        return INTERNAL_VREF_V if _internal_vref(self._regs[1]) else self.vref_V

    def read_voltage_V(self, mux: str | None = None, gain: int | None = None) -> float:
        """Single conversion of ``mux`` at ``gain`` (unchanged if None), in volts."""
        self._write_if_changed(0, _input(self._regs[0], mux, gain))
        self._write_if_changed(1, _with_ts(self._regs[1], False))
        return code_to_volts(self._check(self.convert()), self.gain, self._vref())

    def read_temperature_C(self) -> float:
        """Internal temperature sensor (TS=1), 0.03125 °C resolution."""
        r1 = self._regs[1]
        self._write_if_changed(1, _with_ts(r1, True))
        try:
            return temperature_code_to_C(self.convert() & 0xFFFFFF)
        finally:
            self._write_if_changed(1, _with_ts(r1, False))

    def read_thermocouple_emf_V(self, mux: str = "AIN0_AIN1", gain: int = 128) -> float:
        """Thermocouple EMF (V); ±16 mV full scale at gain 128 with the internal reference."""
        return self.read_voltage_V(mux, gain)

    def read_flux_voltage_V(self, mux: str = "AIN2_AIN3", gain: int = 128) -> float:
        """Heat-flux sensor voltage (V)."""
        return self.read_voltage_V(mux, gain)

    def read_thermocouple_C(self, mux: str = "AIN0_AIN1", gain: int = 128,
                            cold_junction_C: float | None = None) -> float:
        """Cold-junction-compensated type K hot-junction temperature (°C).

        ``cold_junction_C`` defaults to this chip's internal temperature sensor
        (pass the MCP9600's cold junction instead if it sits nearer the
        terminals).
        """
        if cold_junction_C is None:
            cold_junction_C = self.read_temperature_C()
        e_V = self.read_thermocouple_emf_V(mux, gain)
        try:
            return typek.hot_junction_C(e_V * 1e3, cold_junction_C, refine=True)
        except ValueError as exc:
            raise self.fault("open_thermocouple", f"EMF {e_V * 1e6:.1f} µV not a type K value: {exc}") from exc
