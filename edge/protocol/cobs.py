"""Consistent-overhead byte stuffing: frames are delimited by 0x00, so their bodies must not contain it."""

from __future__ import annotations

# --------------------------------------------------------------------------
# COBS
# --------------------------------------------------------------------------

#: Zero bytes from which :func:`cobs_encode` takes the vectorised path (below, the loop's few blocks cost less
#: than NumPy's fixed cost).
_VECTOR_MIN_ZEROS = 256
#: Blocks :func:`cobs_decode` walks one by one before it decodes the rest of a long frame at once.
_DECODE_LOOP_BLOCKS = 256


def _encode_vectorised(data: bytes) -> bytes:
    """:func:`cobs_encode`'s loop, block for block, at NumPy's speed (a 48-kB model chunk: ~44 000 blocks).

    Behind a virtual leading zero, every zero starts a run of non-zero bytes up to the next zero (or the
    end). The loop cuts a run of length L into blocks of 254 bytes (code 0xFF) and a last block of the
    rest (code rest + 1, 1 when empty; the final run has no such block when L is a positive multiple of
    254); each block is its code byte then its bytes, and the zero before the run is not written. So:
    each zero becomes its run's first code, min(L, 254) + 1, and each further block's code goes in
    before its first byte.
    """
    import numpy as np  # noqa: PLC0415 - only frames with many zeros (binary payloads) come here

    n = len(data)
    buf = np.empty(n + 1, dtype=np.uint8)
    buf[0] = 0
    buf[1:] = np.frombuffer(data, dtype=np.uint8)
    zeros = np.flatnonzero(buf == 0)
    lengths = np.diff(zeros, append=n + 1) - 1  # the run after each zero
    buf[zeros] = np.minimum(lengths, 254) + 1
    long_runs = np.flatnonzero(lengths >= 254)
    if long_runs.size == 0:
        return buf.tobytes()
    where: list[int] = []
    codes: list[int] = []
    last = len(zeros) - 1
    for k in long_runs.tolist():  # few: each is at least 254 bytes of the frame
        z, length = int(zeros[k]), int(lengths[k])
        n_more = length // 254 - (1 if k == last and length % 254 == 0 else 0)
        for j in range(1, n_more + 1):
            where.append(z + 1 + 254 * j)
            codes.append(min(length - 254 * j, 254) + 1)
    return np.insert(buf, where, np.asarray(codes, dtype=np.uint8)).tobytes()


def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: return ``data`` with no 0x00 bytes."""
    data = bytes(data)
    if data.count(0) >= _VECTOR_MIN_ZEROS:
        return _encode_vectorised(data)
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


def _decode_tail(data: bytes, start: int) -> bytes | None:
    """:func:`cobs_decode`'s output from the block at ``start`` to the end, when ``data`` has no zero byte
    there; None when it runs past the end (the loop raises that error, at the block that does).

    Each block starts where the previous one ends (its start plus its code): the chain of block starts
    is found for all blocks at once by pointer doubling (after t rounds, every start within 2**t blocks
    of ``start`` is marked). The output is ``data`` without the code bytes, each but the first replaced
    by a zero unless the block before it is a full one (code 0xFF) -- what the loop appends block by block.
    """
    import numpy as np  # noqa: PLC0415 - only long frames of many blocks (binary payloads) come here

    e = np.frombuffer(data, dtype=np.uint8)[start:]
    m = len(e)
    # Node m: the frame's exact end; node m + 1: past it. Both lead to themselves.
    jump = np.minimum(np.arange(m, dtype=np.int64) + e, m + 1)
    jump = np.append(jump, [m, m + 1])
    on = np.zeros(m + 2, dtype=bool)
    on[0] = True
    for _ in range(m.bit_length() + 1):
        on[jump[np.flatnonzero(on)]] = True
        jump = jump[jump]
    if on[m + 1]:
        return None
    starts = np.flatnonzero(on[:m])
    later, before = starts[1:], e[starts[:-1]]
    out = e.copy()
    out[later[before != 0xFF]] = 0
    keep = np.ones(m, dtype=bool)
    keep[0] = False
    keep[later[before == 0xFF]] = False
    return out[keep].tobytes()


def cobs_decode(data: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raises ``ValueError`` on malformed input."""
    out = bytearray()
    i = 0
    n = len(data)
    blocks = 0
    while i < n:
        if blocks == _DECODE_LOOP_BLOCKS and isinstance(data, (bytes, bytearray)) and data.find(b"\x00", i) < 0:
            # A long frame of many blocks (a model chunk, a series page): the rest at once, the same bytes.
            tail = _decode_tail(bytes(data), i)
            if tail is not None:
                return bytes(out + tail)
        blocks += 1
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
