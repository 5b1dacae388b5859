"""Consistent-overhead byte stuffing: frames are delimited by 0x00, so their bodies must not contain it."""

from __future__ import annotations

# --------------------------------------------------------------------------
# COBS
# --------------------------------------------------------------------------

def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: return ``data`` with no 0x00 bytes."""
    data = bytes(data)
    out = bytearray()
    start = 0
    n = len(data)
    while True:
        # A block is a code byte (block length + 1) and up to 254 non-zero
        # bytes; codes below 0xFF imply a zero after the block.
        zero = data.find(b"\x00", start, start + 254)
        if zero < 0:
            end = min(start + 254, n)
            out.append(end - start + 1)
            out += data[start:end]
            if end == n:
                break
            start = end
        else:
            out.append(zero - start + 1)
            out += data[start:zero]
            start = zero + 1
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raises ``ValueError`` on malformed input."""
    out = bytearray()
    i = 0
    n = len(data)
    while i < n:
        code = data[i]
        if code == 0:
            raise ValueError("COBS data contains a zero byte")
        end = i + code
        if end > n:
            raise ValueError("COBS block runs past the end of the frame")
        block = data[i + 1:end]
        if 0 in block:
            raise ValueError("COBS data contains a zero byte")
        out += block
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)
