import pytest

from edge.hw.registers import BitField, Register, RegisterMap, to_signed, to_unsigned


def test_signed_helpers():
    assert to_signed(0xFF60, 16) == -160
    assert to_signed(0x0190, 16) == 400
    assert to_unsigned(-160, 16) == 0xFF60
    with pytest.raises(ValueError):
        to_unsigned(70000, 16)


def test_bitfield_shift_width_and_get_set():
    bf = BitField(0x0E00)
    assert (bf.shift, bf.width) == (9, 3)
    assert bf.get(0x8583) == 2
    assert bf.set(0x8583, 5) == 0x8B83


def test_bitfield_rejects_noncontiguous_and_out_of_range():
    with pytest.raises(ValueError, match="contiguous"):
        BitField(0b1010)
    with pytest.raises(ValueError, match="out of range"):
        BitField(0x07).set(0, 8)
    with pytest.raises(ValueError, match="enum"):
        BitField(0x03, enum={"a": 4})


def test_signed_scaled_field():
    temp = BitField(0xFFFF, signed=True, scale=0.0625)
    assert temp.get(0x0190) == 25.0
    assert temp.get(0xFF60) == -10.0
    assert temp.set(0, -10.0) == 0xFF60
    assert temp.set(0, 25.0) == 0x0190


def test_enum_field_labels_and_unknown_code():
    bf = BitField(0x70, enum={"K": 0, "J": 1})
    assert bf.get(0x10) == "J"
    assert bf.get(0x70) == 7           # reserved code comes back as the integer
    with pytest.raises(ValueError, match="not one of"):
        bf.set(0, "X")


def test_register_encode_decode_bytes():
    reg = Register("CONFIG", 0x01, 2, {
        "OS": BitField(0x8000), "PGA": BitField(0x0E00, enum={2.048: 2, 0.256: 5}),
        "MODE": BitField(0x0100, enum={"continuous": 0, "single": 1}),
    }, reset=0x8583)
    assert reg.decode(0x8583) == {"OS": 1, "PGA": 2.048, "MODE": "single"}
    v = reg.encode(PGA=0.256, MODE="continuous")
    assert v == 0x8A83
    assert reg.to_bytes(v) == b"\x8a\x83"
    assert reg.from_bytes([0x8A, 0x83]) == v
    with pytest.raises(ValueError, match="no field"):
        reg.encode(FOO=1)
    with pytest.raises(ValueError, match="expected 2 bytes"):
        reg.from_bytes([1])


def test_register_validation():
    with pytest.raises(ValueError, match="exceeds"):
        Register("R", 0, 1, {"X": BitField(0x100)})
    with pytest.raises(ValueError, match="reset"):
        Register("R", 0, 1, reset=0x100)


def test_register_map_lookup():
    m = RegisterMap("chip", [Register("A", 0x00, 1), Register("B", 0x05, 2)])
    assert m["B"].address == 0x05 and m.B is m["B"] and m.at(0x05) is m.B
    assert m.has_address(0x00) and not m.has_address(0x01)
    assert m.reset_values() == {0x00: 0, 0x05: 0}
    with pytest.raises(KeyError):
        m["C"]
    with pytest.raises(ValueError, match="duplicate"):
        RegisterMap("chip", [Register("A", 0, 1), Register("A", 1, 1)])


def test_unscaled_field_rejects_non_integers():
    with pytest.raises(ValueError, match="expected an integer"):
        BitField(0x07).set(0, 1.5)
    import numpy as np
    assert BitField(0x07).set(0, np.int64(3)) == 3
    assert BitField(0x01).set(0, True) == 1
