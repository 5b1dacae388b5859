"""Frames of the serial protocol: the wire format, encoding and a streaming decoder.

Wire format
-----------
Every message travels as one frame::

    0x00  COBS( header | payload | crc32 )  0x00

The leading delimiter is redundant when frames follow each other back to back
(the decoder skips empty frames), but it terminates any garbage left in the
receiver's buffer, so a frame sent after line noise is never merged with it.

The COBS-decoded body is (all integers little-endian)::

    offset  size  field
    0       1     version       PROTOCOL_VERSION (1)
    1       1     msg_type      command code, command | 0x80 for its reply, 0xFF = ERROR
    2       4     request_id    u32, chosen by the host, echoed in the reply (0 = unattributed)
    6       2     payload_len   u16, <= the decoder's max_payload (default 4096)
    8       n     payload       n = payload_len bytes
    8+n     4     crc32         CRC-32/IEEE (zlib.crc32) over bytes [0, 8+n)
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

from edge.protocol.cobs import cobs_decode, cobs_encode
from edge.protocol.errors import ErrorCode, ProtocolError

PROTOCOL_VERSION = 1
#: Default bound on a frame's payload, bytes.
DEFAULT_MAX_PAYLOAD = 4096
#: The payload length field is a u16.
MAX_PAYLOAD_LIMIT = 0xFFFF

_HEADER = struct.Struct("<BBIH")
HEADER_SIZE = _HEADER.size  # 8
_CRC = struct.Struct("<I")
CRC_SIZE = _CRC.size  # 4
#: Bit set in msg_type for replies.
REPLY_FLAG = 0x80
MAX_REQUEST_ID = 0xFFFFFFFF


# --------------------------------------------------------------------------
# Frames
# --------------------------------------------------------------------------

@dataclass(frozen=True)
class Frame:
    """One CRC-checked frame: header fields and raw payload."""

    msg_type: int
    request_id: int
    payload: bytes = b""
    version: int = PROTOCOL_VERSION


def max_encoded_size(max_payload: int) -> int:
    """Largest COBS-encoded frame body (no delimiters) for ``max_payload``, bytes."""
    raw = HEADER_SIZE + max_payload + CRC_SIZE
    return raw + raw // 254 + 1


def _check_max_payload(max_payload: int) -> int:
    if isinstance(max_payload, bool) or not isinstance(max_payload, int):
        raise ValueError(f"max_payload must be an int, got {max_payload!r}")
    if not 1 <= max_payload <= MAX_PAYLOAD_LIMIT:
        raise ValueError(f"max_payload must be in [1, {MAX_PAYLOAD_LIMIT}], got {max_payload}")
    return max_payload


def encode_frame(msg_type: int, request_id: int, payload: bytes = b"", *,
                 max_payload: int = DEFAULT_MAX_PAYLOAD, version: int = PROTOCOL_VERSION) -> bytes:
    """Build the wire bytes of one frame, delimiters included.

    Raises
    ------
    ProtocolError
        If a header field is out of range or ``payload`` exceeds ``max_payload``.
    """
    _check_max_payload(max_payload)
    if not isinstance(msg_type, int) or not 0 <= msg_type <= 0xFF:
        raise ProtocolError(f"msg_type must be a u8, got {msg_type!r}", "msg_type", ErrorCode.INTERNAL)
    if not isinstance(request_id, int) or not 0 <= request_id <= MAX_REQUEST_ID:
        raise ProtocolError(f"request_id must be a u32, got {request_id!r}", "request_id", ErrorCode.INTERNAL)
    if not isinstance(version, int) or not 0 <= version <= 0xFF:
        raise ProtocolError(f"version must be a u8, got {version!r}", "version", ErrorCode.INTERNAL)
    payload = bytes(payload)
    if len(payload) > max_payload:
        raise ProtocolError(f"payload of {len(payload)} B exceeds max_payload {max_payload} B",
                            "payload", ErrorCode.INTERNAL)
    body = _HEADER.pack(version, msg_type, request_id, len(payload)) + payload
    body += _CRC.pack(zlib.crc32(body))
    return b"\x00" + cobs_encode(body) + b"\x00"


@dataclass
class DecoderStats:
    """Counters of what a :class:`FrameDecoder` accepted and dropped."""

    frames: int = 0          # valid frames returned
    bytes_dropped: int = 0   # wire bytes discarded (delimiters not counted)
    crc_errors: int = 0      # frames with a bad CRC
    bad_frames: int = 0      # COBS errors, short frames, length mismatch
    oversize: int = 0        # frames longer than the bound (discarded while streaming)
    timeouts: int = 0        # partial frames discarded by discard_partial()


class FrameDecoder:
    """Incremental frame decoder with bounded buffering.

    Feed it whatever the port returns; it yields every valid frame and
    silently drops (but counts, in :attr:`stats`) garbage, frames with bad
    CRC or layout, and over-long input.  Memory use is bounded by
    :func:`max_encoded_size` of ``max_payload``: once a frame grows past it,
    the decoder discards bytes until the next 0x00 delimiter.

    Parameters
    ----------
    max_payload : int
        Largest payload accepted, bytes (default 4096, at most 65535).
    """

    def __init__(self, max_payload: int = DEFAULT_MAX_PAYLOAD) -> None:
        self.max_payload = _check_max_payload(max_payload)
        self._max_encoded = max_encoded_size(max_payload)
        self._buf = bytearray()
        self._skipping = False
        self.stats = DecoderStats()

    @property
    def pending(self) -> int:
        """Bytes of an unfinished frame currently buffered (or being skipped)."""
        return len(self._buf) + (1 if self._skipping else 0)

    def discard_partial(self) -> int:
        """Drop an unfinished frame (e.g. after a read timeout); return bytes dropped."""
        dropped = len(self._buf)
        if dropped or self._skipping:
            self.stats.timeouts += 1
        self.stats.bytes_dropped += dropped
        self._buf.clear()
        # Bytes after the timeout start a fresh frame even if we were skipping.
        self._skipping = False
        return dropped

    def reset(self) -> None:
        """Forget buffered input and zero the counters."""
        self._buf.clear()
        self._skipping = False
        self.stats = DecoderStats()

    def feed(self, data: bytes) -> list[Frame]:
        """Consume ``data``; return the frames it completed, in order."""
        frames: list[Frame] = []
        data = bytes(data)
        pos = 0
        n = len(data)
        while pos < n:
            zero = data.find(b"\x00", pos)
            end = n if zero < 0 else zero
            chunk = data[pos:end]
            if self._skipping:
                self.stats.bytes_dropped += len(chunk)
            else:
                if len(self._buf) + len(chunk) > self._max_encoded:
                    self.stats.oversize += 1
                    self.stats.bytes_dropped += len(self._buf) + len(chunk)
                    self._buf.clear()
                    self._skipping = True
                else:
                    self._buf += chunk
            if zero < 0:
                break
            # Delimiter reached: finish the current frame.
            if self._skipping:
                self._skipping = False
            elif self._buf:
                frame = self._finish(bytes(self._buf))
                self._buf.clear()
                if frame is not None:
                    frames.append(frame)
            pos = zero + 1
        return frames

    def _finish(self, encoded: bytes) -> Frame | None:
        try:
            body = cobs_decode(encoded)
        except ValueError:
            self._drop(encoded, "bad")
            return None
        if len(body) < HEADER_SIZE + CRC_SIZE:
            self._drop(encoded, "bad")
            return None
        version, msg_type, request_id, length = _HEADER.unpack_from(body)
        if length != len(body) - HEADER_SIZE - CRC_SIZE:
            self._drop(encoded, "bad")
            return None
        (crc,) = _CRC.unpack_from(body, len(body) - CRC_SIZE)
        if crc != zlib.crc32(body[:-CRC_SIZE]):
            self._drop(encoded, "crc")
            return None
        if length > self.max_payload:
            # Only reachable when the COBS slack admits a few extra bytes.
            self._drop(encoded, "oversize")
            return None
        self.stats.frames += 1
        return Frame(msg_type, request_id, body[HEADER_SIZE:-CRC_SIZE], version)

    def _drop(self, encoded: bytes, why: str) -> None:
        self.stats.bytes_dropped += len(encoded)
        if why == "crc":
            self.stats.crc_errors += 1
        elif why == "oversize":
            self.stats.oversize += 1
        else:
            self.stats.bad_frames += 1
