"""Register maps declared as data.

A chip's register map is written once, as data, and used both by the edge
driver (to encode what it writes and decode what it reads) and by the chip
emulation in ``firmware_sim`` (to hold and interpret the same bits). The style
follows Pimoroni's *i2cdevice* and Adafruit's register descriptors, without
the bus coupling: these objects only turn integers into field values and back.

Example
-------
>>> CONFIG = Register("CONFIG", 0x01, 2, fields={
...     "OS": BitField(0x8000),
...     "PGA": BitField(0x0E00, enum={"6.144": 0, "4.096": 1}),
... })
>>> CONFIG.decode(0x8200)
{'OS': 1, 'PGA': '4.096'}
>>> hex(CONFIG.encode(OS=1, PGA="6.144"))
'0x8000'
"""

from __future__ import annotations

from dataclasses import dataclass
from dataclasses import field as _dc_field
from typing import Any, Iterable, Mapping

__all__ = ["BitField", "Register", "RegisterMap", "to_signed", "to_unsigned"]


def to_signed(value: int, bits: int) -> int:
    """Interpret the low ``bits`` of ``value`` as a two's-complement integer."""
    value &= (1 << bits) - 1
    return value - (1 << bits) if value >> (bits - 1) else value


def to_unsigned(value: int, bits: int) -> int:
    """Two's-complement encode ``value`` into ``bits`` bits (range-checked)."""
    lo, hi = -(1 << (bits - 1)), (1 << bits) - 1
    if not lo <= value <= hi:
        raise ValueError(f"value {value} does not fit in {bits} bits")
    return value & ((1 << bits) - 1)


@dataclass(frozen=True)
class BitField:
    """A contiguous group of bits inside a register.

    Parameters
    ----------
    mask : int
        Bit mask of the field within the register value (must be contiguous).
    signed : bool
        Field holds a two's-complement number.
    enum : mapping of label -> code, optional
        Named values; ``decode`` returns the label, ``encode`` takes the label.
    scale : float, optional
        Physical units per LSB; ``decode`` returns ``raw * scale`` and
        ``encode`` takes the physical value (rounded to the nearest LSB).
    """

    mask: int
    signed: bool = False
    enum: Mapping[Any, int] | None = None
    scale: float | None = None

    def __post_init__(self) -> None:
        if self.mask <= 0:
            raise ValueError(f"mask must be a positive bit mask, got {self.mask!r}")
        shifted = self.mask >> self.shift
        if shifted & (shifted + 1):
            raise ValueError(f"mask 0x{self.mask:X} is not contiguous")
        if self.enum is not None and self.scale is not None:
            raise ValueError("a BitField takes enum or scale, not both")
        if self.enum is not None:
            for label, code in self.enum.items():
                if not 0 <= code <= shifted:
                    raise ValueError(f"enum code {code} for {label!r} does not fit mask 0x{self.mask:X}")

    @property
    def shift(self) -> int:
        return (self.mask & -self.mask).bit_length() - 1

    @property
    def width(self) -> int:
        return (self.mask >> self.shift).bit_length()

    def raw(self, reg_value: int) -> int:
        """The field's integer code (sign-extended if ``signed``)."""
        code = (reg_value & self.mask) >> self.shift
        return to_signed(code, self.width) if self.signed else code

    def get(self, reg_value: int):
        """Decoded value: enum label, scaled float, or integer."""
        code = self.raw(reg_value)
        if self.enum is not None:
            for label, c in self.enum.items():
                if c == code:
                    return label
            return code  # a code with no label (reserved) comes back as the integer
        if self.scale is not None:
            return code * self.scale
        return code

    def code_for(self, value, name: str = "field") -> int:
        """Integer code for a physical/label ``value`` (validated)."""
        if self.enum is not None:
            if value in self.enum:
                return self.enum[value]
            raise ValueError(f"{name}: {value!r} is not one of {list(self.enum)}")
        if self.scale is not None:
            value = round(float(value) / self.scale)
        elif hasattr(value, "__index__"):      # int, bool, numpy integers
            value = int(value.__index__())
        else:
            raise ValueError(f"{name}: expected an integer, got {value!r}")
        if self.signed:
            lo, hi = -(1 << (self.width - 1)), (1 << (self.width - 1)) - 1
        else:
            lo, hi = 0, (1 << self.width) - 1
        if not lo <= value <= hi:
            raise ValueError(f"{name}: {value} out of range [{lo}, {hi}]")
        return value & ((1 << self.width) - 1)

    def set(self, reg_value: int, value, name: str = "field") -> int:
        """Return ``reg_value`` with this field replaced by ``value``."""
        code = self.code_for(value, name)
        return (reg_value & ~self.mask) | (code << self.shift)


@dataclass(frozen=True)
class Register:
    """One register of a chip.

    Parameters
    ----------
    name : str
        Register name as in the datasheet.
    address : int
        Pointer / register address.
    width_bytes : int
        Size on the wire.
    fields : mapping name -> BitField
        The register's fields (may be empty: whole-register access only).
    reset : int
        Power-on value (used by the chip emulations and for documentation).
    byteorder : {"big", "little"}
        Wire byte order; the chips here all send the most significant byte first.
    read_only : bool
        Writes are ignored by the emulation / refused by :meth:`encode` users.
    volatile : bool
        The chip changes the value by itself (conversion results, status
        flags), so ``reset`` is only its power-on state.
    """

    name: str
    address: int
    width_bytes: int
    fields: Mapping[str, BitField] = _dc_field(default_factory=dict)
    reset: int = 0
    byteorder: str = "big"
    read_only: bool = False
    volatile: bool = False

    def __post_init__(self) -> None:
        if self.width_bytes < 1:
            raise ValueError(f"{self.name}: width_bytes must be >= 1")
        if self.byteorder not in ("big", "little"):
            raise ValueError(f"{self.name}: byteorder must be 'big' or 'little'")
        full = (1 << (8 * self.width_bytes)) - 1
        for fname, bf in self.fields.items():
            if bf.mask & ~full:
                raise ValueError(f"{self.name}.{fname}: mask exceeds {self.width_bytes} bytes")
        if not 0 <= self.reset <= full:
            raise ValueError(f"{self.name}: reset value does not fit")

    @property
    def bits(self) -> int:
        return 8 * self.width_bytes

    def field(self, name: str) -> BitField:
        try:
            return self.fields[name]
        except KeyError:
            raise ValueError(f"{self.name} has no field {name!r} (fields: {list(self.fields)})") from None

    def decode(self, value: int) -> dict:
        """All fields of ``value`` as a dict name -> decoded value."""
        return {n: bf.get(value) for n, bf in self.fields.items()}

    def get(self, value: int, name: str):
        return self.field(name).get(value)

    def encode(self, base: int | None = None, **values) -> int:
        """Register value with the given fields set, other bits from ``base``
        (default: the reset value)."""
        reg = self.reset if base is None else base
        for n, v in values.items():
            reg = self.field(n).set(reg, v, f"{self.name}.{n}")
        return reg

    def to_bytes(self, value: int) -> bytes:
        if not 0 <= value < (1 << self.bits):
            raise ValueError(f"{self.name}: value 0x{value:X} does not fit {self.width_bytes} bytes")
        return int(value).to_bytes(self.width_bytes, self.byteorder)

    def from_bytes(self, data: Iterable[int]) -> int:
        data = bytes(data)
        if len(data) != self.width_bytes:
            raise ValueError(f"{self.name}: expected {self.width_bytes} bytes, got {len(data)}")
        return int.from_bytes(data, self.byteorder)


class RegisterMap:
    """A chip's registers, looked up by name or address."""

    def __init__(self, chip: str, registers: Iterable[Register]) -> None:
        self.chip = chip
        self._by_name: dict[str, Register] = {}
        self._by_addr: dict[int, Register] = {}
        for r in registers:
            if r.name in self._by_name:
                raise ValueError(f"{chip}: duplicate register name {r.name!r}")
            if r.address in self._by_addr:
                raise ValueError(f"{chip}: duplicate register address 0x{r.address:02X}")
            self._by_name[r.name] = r
            self._by_addr[r.address] = r

    def __getitem__(self, name: str) -> Register:
        try:
            return self._by_name[name]
        except KeyError:
            raise KeyError(f"{self.chip} has no register {name!r}") from None

    def __getattr__(self, name: str) -> Register:
        by_name = self.__dict__.get("_by_name", {})
        if name in by_name:
            return by_name[name]
        raise AttributeError(name)

    def __iter__(self):
        return iter(self._by_name.values())

    def __len__(self) -> int:
        return len(self._by_name)

    def at(self, address: int) -> Register:
        try:
            return self._by_addr[address]
        except KeyError:
            raise KeyError(f"{self.chip} has no register at 0x{address:02X}") from None

    def has_address(self, address: int) -> bool:
        return address in self._by_addr

    def reset_values(self) -> dict[int, int]:
        """address -> power-on value, for emulations."""
        return {r.address: r.reset for r in self}
