"""Serial protocol shared by the probe (edge) and the host.

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

Payloads are compact UTF-8 JSON objects (an empty payload means ``{}``),
except ``MODEL_CHUNK`` requests, whose payload is binary: ``u32 offset`` then
the raw chunk bytes.  ``ERROR`` payloads are JSON
``{"code": "<ErrorCode name>", "message": str, "field": str | null}``.

The command set, with argument and reply schemas, is data: see
:data:`COMMANDS`.  Measured series travel as JSON number arrays in pages:
``SERIES {"measurement_id", "which": "raw"|"grid", "offset", "limit"?}``
answers ``{"measurement_id", "which", "offset", "total", "t_s", "T_C"
(raw) | "dT_K" (grid), "q_W_m2"}`` with as many samples as fit in one
reply (null for a non-finite sample); the host asks again from
``offset + len(t_s)`` until it holds ``total``.  Requests are validated strictly (unknown fields are
rejected); replies must carry their required fields and may carry more.

This module is pure Python (no NumPy) so the host can import it cheaply.
"""

from __future__ import annotations

import enum
import json
import math
import re
import struct
import zlib
from dataclasses import dataclass, field
from typing import Any, Mapping

__all__ = [
    "PROTOCOL_VERSION", "DEFAULT_MAX_PAYLOAD", "MAX_PAYLOAD_LIMIT", "MAX_MODEL_SIZE",
    "SERIES_KINDS", "SERIES_MAX_LIMIT",
    "HEADER_SIZE", "CRC_SIZE", "REPLY_FLAG", "CHUNK_HEADER_SIZE",
    "MsgType", "Command", "ErrorCode", "CommandError", "ProtocolError",
    "Field", "CommandSpec", "COMMANDS",
    "Frame", "DecoderStats", "FrameDecoder",
    "cobs_encode", "cobs_decode", "encode_frame", "max_encoded_size",
    "Request", "Reply", "ErrorReply",
    "encode_request", "decode_request", "encode_reply", "encode_error", "decode_reply",
    "validate_args", "validate_reply", "reply_type",
]

PROTOCOL_VERSION = 1
#: Default bound on a frame's payload, bytes.
DEFAULT_MAX_PAYLOAD = 4096
#: The payload length field is a u16.
MAX_PAYLOAD_LIMIT = 0xFFFF
#: Largest model bundle MODEL_BEGIN accepts, bytes.
MAX_MODEL_SIZE = 64 * 1024 * 1024

_HEADER = struct.Struct("<BBIH")
HEADER_SIZE = _HEADER.size  # 8
_CRC = struct.Struct("<I")
CRC_SIZE = _CRC.size  # 4
_CHUNK_HEADER = struct.Struct("<I")
#: Bytes of a MODEL_CHUNK payload taken by the offset field.
CHUNK_HEADER_SIZE = _CHUNK_HEADER.size
#: Bit set in msg_type for replies.
REPLY_FLAG = 0x80
_MAX_REQUEST_ID = 0xFFFFFFFF


# --------------------------------------------------------------------------
# Enumerations and errors
# --------------------------------------------------------------------------

class Command(enum.IntEnum):
    """Request message types (replies use ``command | REPLY_FLAG``)."""

    PING = 0x01
    INFO = 0x02
    STATUS = 0x03
    MEASURE = 0x04
    RESULT = 0x05
    HISTORY = 0x06
    CONFIG_GET = 0x07
    CONFIG_SET = 0x08
    SERIES = 0x09
    MODEL_BEGIN = 0x10
    MODEL_CHUNK = 0x11
    MODEL_COMMIT = 0x12
    MODEL_ABORT = 0x13


class MsgType(enum.IntEnum):
    """Non-command message types."""

    ERROR = 0xFF


class ErrorCode(enum.IntEnum):
    """Error codes carried by ERROR replies (sent on the wire by name)."""

    BAD_FRAME = 1         # CRC-valid frame that cannot be parsed (version, JSON, layout)
    UNKNOWN_COMMAND = 2   # msg_type is not a known request
    BAD_ARGUMENT = 3      # argument missing, of the wrong type or out of range
    BUSY = 4              # device busy (e.g. a measurement or upload is running)
    MODEL_REJECTED = 5    # model upload failed size/sha256/format checks
    SENSOR_FAULT = 6      # hardware fault during a measurement
    INTERNAL = 7          # unexpected device-side exception
    NOT_FOUND = 8         # e.g. RESULT for an unknown measurement id
    BAD_STATE = 9         # command not valid now (e.g. MODEL_CHUNK without MODEL_BEGIN)


class CommandError(Exception):
    """A command failed; the device answers with an ERROR reply.

    Device-side handlers raise this (e.g. ``CommandError(ErrorCode.BUSY,
    "measurement in progress")``) and the link turns it into an ERROR reply.

    Parameters
    ----------
    code : ErrorCode
        Machine-readable error class.
    message : str
        Human-readable explanation.
    field : str, optional
        Name of the offending argument, if any.
    """

    def __init__(self, code: ErrorCode, message: str, field: str | None = None) -> None:
        self.code = ErrorCode(code)
        self.message = str(message)
        self.field = field
        super().__init__(f"{self.code.name}: {self.message}" + (f" (field {field!r})" if field else ""))


class ProtocolError(CommandError, ValueError):
    """A message violates the protocol; ``field`` names the offending field.

    ``request_id`` is set when the error concerns a frame whose id is known,
    so an ERROR reply can be addressed to it.
    """

    def __init__(self, message: str, field: str | None = None,
                 code: ErrorCode = ErrorCode.BAD_ARGUMENT, request_id: int | None = None) -> None:
        super().__init__(code, message, field)
        self.request_id = request_id


# --------------------------------------------------------------------------
# Command schemas (data)
# --------------------------------------------------------------------------

_SHA256_RE = re.compile(r"^[0-9a-fA-F]{64}$")


@dataclass(frozen=True)
class Field:
    """One named value in a request or reply.

    ``kind`` is one of ``int``, ``float``, ``bool``, ``str``, ``sha256``,
    ``bytes``, ``list``, ``list_str``, ``list_num`` (finite numbers or null,
    null standing for a non-finite sample), ``dict``, ``config`` (a dict of
    scalars or flat lists of scalars), ``any``.  Ranges ``lo``/``hi`` apply
    to numbers (value) and to str/bytes/list/dict (length); ``lo_open``
    makes the lower bound exclusive.  ``nullable`` accepts JSON null.
    ``choices`` restricts a value to the listed ones.
    """

    name: str
    kind: str
    required: bool = False
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    default: Any = None
    nullable: bool = False
    choices: tuple[Any, ...] | None = None
    doc: str = ""


@dataclass(frozen=True)
class CommandSpec:
    """Schema of one command: request arguments and reply fields.

    ``exclusive`` lists groups of arguments of which at most one may be given.
    ``idempotent`` commands are safe for the host to resend after a timeout.
    ``binary`` requests carry a raw payload instead of JSON (MODEL_CHUNK).
    ``reply_when`` makes reply fields conditional: ``(field, value, names)``
    requires ``names`` when the reply's ``field`` equals ``value``.
    ``same_length`` lists reply fields (lists) that must be equally long
    when present.
    """

    command: Command
    args: tuple[Field, ...] = ()
    reply: tuple[Field, ...] = ()
    exclusive: tuple[tuple[str, ...], ...] = ()
    reply_when: tuple[tuple[str, Any, tuple[str, ...]], ...] = ()
    same_length: tuple[str, ...] = ()
    idempotent: bool = True
    binary: bool = False
    doc: str = ""


_CONFIG_MAX_KEYS = 64
_STR_MAX = 256
#: Values of SERIES ``which``: the raw samples or the resampled grid (estimator input).
SERIES_KINDS = ("raw", "grid")
#: Most samples one SERIES reply may carry (the payload bound usually allows fewer).
SERIES_MAX_LIMIT = 2048
#: Longest stored series SERIES can address (edge.storage.history stores at most 10^6 values).
_SERIES_MAX_OFFSET = 1_000_000

COMMANDS: dict[Command, CommandSpec] = {spec.command: spec for spec in (
    CommandSpec(
        Command.PING,
        args=(Field("echo", "str", hi=_STR_MAX, doc="string echoed back"),),
        reply=(Field("echo", "str", nullable=True),),
        doc="Liveness check."),
    CommandSpec(
        Command.INFO,
        reply=(Field("protocol_version", "int", required=True),
               Field("firmware_version", "str", required=True),
               Field("model_version", "str", required=True, nullable=True),
               Field("model_sha256", "str", required=True, nullable=True),
               Field("board", "str", required=True)),
        doc="Firmware and model versions, model sha256, board name."),
    CommandSpec(
        Command.STATUS,
        reply=(Field("state", "str", required=True, doc="idle, measuring, fault, ..."),),
        doc="Current device state; extra fields are free-form (while measuring: phase, "
            "measurement_elapsed_s). Answered during a measurement."),
    CommandSpec(
        Command.MEASURE,
        args=(Field("power_W", "float", lo=0.0, hi=50.0, lo_open=True, doc="heater power, W"),
              Field("voltage_V", "float", lo=0.0, hi=48.0, lo_open=True, doc="heater voltage, V"),
              Field("contact_time_s", "float", lo=0.0, hi=60.0, lo_open=True, doc="touch duration, s")),
        exclusive=(("power_W", "voltage_V"),),
        reply=(Field("measurement_id", "int", required=True, lo=0),),
        idempotent=False,
        doc="Run one touch measurement; replies with the stored record when it ends. Meanwhile the "
            "device answers STATUS and PING and refuses other requests with BUSY."),
    CommandSpec(
        Command.RESULT,
        args=(Field("measurement_id", "int", lo=0, hi=_MAX_REQUEST_ID, doc="absent = latest"),),
        reply=(Field("measurement_id", "int", required=True, lo=0),),
        doc="One stored result record, by id or the latest."),
    CommandSpec(
        Command.HISTORY,
        args=(Field("offset", "int", lo=0, hi=_MAX_REQUEST_ID, default=0, doc="0 = newest"),
              Field("limit", "int", lo=1, hi=100, default=20)),
        reply=(Field("offset", "int", required=True, lo=0),
               Field("total", "int", required=True, lo=0),
               Field("items", "list", required=True)),
        doc="Page of stored results, newest first."),
    CommandSpec(
        Command.CONFIG_GET,
        args=(Field("keys", "list_str", lo=1, hi=_CONFIG_MAX_KEYS, doc="absent = all"),),
        reply=(Field("config", "dict", required=True),),
        doc="Read configuration values."),
    CommandSpec(
        Command.CONFIG_SET,
        args=(Field("values", "config", required=True, lo=1, hi=_CONFIG_MAX_KEYS),),
        reply=(Field("config", "dict", required=True, doc="full config after the change"),),
        doc="Set configuration values (the daemon validates each key)."),
    CommandSpec(
        Command.SERIES,
        args=(Field("measurement_id", "int", required=True, lo=0, hi=_MAX_REQUEST_ID),
              Field("which", "str", default="raw", choices=SERIES_KINDS,
                    doc="raw: samples (t_s, T_C, q_W_m2); grid: resampled estimator input (t_s, dT_K, q_W_m2)"),
              Field("offset", "int", lo=0, hi=_SERIES_MAX_OFFSET, default=0, doc="first sample index"),
              Field("limit", "int", lo=1, hi=SERIES_MAX_LIMIT, doc="most samples wanted; absent = as many as fit")),
        reply=(Field("measurement_id", "int", required=True, lo=0),
               Field("which", "str", required=True, choices=SERIES_KINDS),
               Field("offset", "int", required=True, lo=0),
               Field("total", "int", required=True, lo=0, doc="samples in the whole series (0: not stored)"),
               Field("t_s", "list_num", required=True, hi=SERIES_MAX_LIMIT, doc="s from heater on"),
               Field("T_C", "list_num", hi=SERIES_MAX_LIMIT, doc="raw thermocouple, °C"),
               Field("dT_K", "list_num", hi=SERIES_MAX_LIMIT, doc="grid excess temperature, K"),
               Field("q_W_m2", "list_num", required=True, hi=SERIES_MAX_LIMIT, doc="heat flux, W/m^2")),
        reply_when=(("which", "raw", ("T_C",)), ("which", "grid", ("dT_K",))),
        same_length=("t_s", "T_C", "dT_K", "q_W_m2"),
        doc="One page of a stored measurement's series, samples [offset, offset + len(t_s)) of total; "
            "as many as fit in one reply (the host continues at offset + len(t_s)). Non-finite samples are null."),
    CommandSpec(
        Command.MODEL_BEGIN,
        args=(Field("size", "int", required=True, lo=1, hi=MAX_MODEL_SIZE, doc="bundle size, bytes"),
              Field("sha256", "sha256", required=True, doc="hex digest of the whole bundle"),
              Field("version", "str", hi=_STR_MAX)),
        reply=(Field("size", "int", required=True),),
        doc="Start a model upload (discards any unfinished one)."),
    CommandSpec(
        Command.MODEL_CHUNK,
        args=(Field("offset", "int", required=True, lo=0, hi=MAX_MODEL_SIZE),
              Field("data", "bytes", required=True, lo=1)),
        reply=(Field("received", "int", required=True, lo=0, doc="contiguous bytes held"),),
        binary=True,
        doc="Binary payload: u32 LE offset, then the chunk bytes."),
    CommandSpec(
        Command.MODEL_COMMIT,
        reply=(Field("model_sha256", "str", required=True),),
        idempotent=False,
        doc="Verify size and sha256, install atomically."),
    CommandSpec(
        Command.MODEL_ABORT,
        doc="Discard an unfinished upload (no-op if none)."),
)}


def reply_type(command: Command) -> int:
    """msg_type of the reply to ``command``."""
    return int(command) | REPLY_FLAG


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
    if not isinstance(request_id, int) or not 0 <= request_id <= _MAX_REQUEST_ID:
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


# --------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------

def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return (_is_int(v) or isinstance(v, float)) and math.isfinite(v)


def _is_scalar(v: Any) -> bool:
    return v is None or isinstance(v, (bool, str)) or _is_number(v)


def _fmt(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else repr(x)


def _check_range(f: Field, value: float, what: str, name: str) -> None:
    subject = f"{name} {what}" if what else name
    if f.lo is not None:
        if (value <= f.lo) if f.lo_open else (value < f.lo):
            op = ">" if f.lo_open else ">="
            raise ProtocolError(f"{subject} must be {op} {_fmt(f.lo)}, got {value!r}", name)
    if f.hi is not None and value > f.hi:
        raise ProtocolError(f"{subject} must be <= {_fmt(f.hi)}, got {value!r}", name)


def _check_field(f: Field, value: Any, name: str) -> Any:
    """Validate one value against ``f``; return it normalised."""
    if value is None:
        if f.nullable:
            return None
        raise ProtocolError(f"{name} must not be null", name)
    value = _check_kind(f, value, name)
    if f.choices is not None and value not in f.choices:
        raise ProtocolError(f"{name} must be one of {', '.join(map(str, f.choices))}, got {value!r}", name)
    return value


def _check_kind(f: Field, value: Any, name: str) -> Any:
    k = f.kind
    if k == "int":
        if not _is_int(value):
            raise ProtocolError(f"{name} must be an integer, got {type(value).__name__}", name)
        _check_range(f, value, "", name)
        return value
    if k == "float":
        if not _is_number(value):
            raise ProtocolError(f"{name} must be a finite number, got {value!r}", name)
        _check_range(f, float(value), "", name)
        return float(value)
    if k == "bool":
        if not isinstance(value, bool):
            raise ProtocolError(f"{name} must be a boolean, got {type(value).__name__}", name)
        return value
    if k in ("str", "sha256"):
        if not isinstance(value, str):
            raise ProtocolError(f"{name} must be a string, got {type(value).__name__}", name)
        if k == "sha256":
            if not _SHA256_RE.match(value):
                raise ProtocolError(f"{name} must be 64 hex digits", name)
            return value.lower()
        _check_range(f, len(value), "length", name)
        return value
    if k == "bytes":
        if not isinstance(value, (bytes, bytearray, memoryview)):
            raise ProtocolError(f"{name} must be bytes, got {type(value).__name__}", name)
        value = bytes(value)
        _check_range(f, len(value), "length", name)
        return value
    if k in ("list", "list_str", "list_num"):
        if not isinstance(value, (list, tuple)):
            raise ProtocolError(f"{name} must be a list, got {type(value).__name__}", name)
        _check_range(f, len(value), "length", name)
        if k == "list_num":
            for i, item in enumerate(value):
                if item is not None and not _is_number(item):
                    raise ProtocolError(f"{name}[{i}] must be a finite number or null, got {item!r}", f"{name}[{i}]")
            return [None if x is None else float(x) for x in value]
        if k == "list_str":
            for i, item in enumerate(value):
                if not isinstance(item, str) or not 1 <= len(item) <= _STR_MAX:
                    raise ProtocolError(f"{name}[{i}] must be a non-empty string", f"{name}[{i}]")
        return list(value)
    if k in ("dict", "config"):
        if not isinstance(value, Mapping):
            raise ProtocolError(f"{name} must be an object, got {type(value).__name__}", name)
        _check_range(f, len(value), "size", name)
        if k == "config":
            for key, item in value.items():
                if not isinstance(key, str) or not 1 <= len(key) <= 64:
                    raise ProtocolError(f"{name} keys must be strings of 1..64 characters", name)
                sub = f"{name}.{key}"
                if isinstance(item, (list, tuple)):
                    if len(item) > 1024 or not all(_is_scalar(x) and x is not None for x in item):
                        raise ProtocolError(f"{sub} must be a list of at most 1024 scalars", sub)
                    item = list(item)
                elif not _is_scalar(item):
                    raise ProtocolError(f"{sub} must be a scalar or list of scalars, got {item!r}", sub)
                if isinstance(item, str) and len(item) > _STR_MAX:
                    raise ProtocolError(f"{sub} string must be at most {_STR_MAX} characters", sub)
        return dict(value)
    if k == "any":
        return value
    raise AssertionError(f"unknown field kind {k!r}")  # schema bug, not input


def validate_args(command: Command, args: Mapping[str, Any] | None) -> dict[str, Any]:
    """Validate request arguments of ``command``; return them normalised.

    Defaults are filled in, numbers converted to float where the schema says
    so, sha256 lower-cased.  Absent optional arguments without a default are
    left out.

    Raises
    ------
    ProtocolError
        ``field`` names the offending argument (code BAD_ARGUMENT).
    """
    spec = _spec(command)
    if args is None:
        args = {}
    if not isinstance(args, Mapping):
        raise ProtocolError(f"{spec.command.name} arguments must be an object", "args")
    known = {f.name: f for f in spec.args}
    for key in args:
        if key not in known:
            raise ProtocolError(f"{spec.command.name} has no argument {key!r}", str(key))
    out: dict[str, Any] = {}
    for f in spec.args:
        if f.name in args and not (args[f.name] is None and not f.required and not f.nullable):
            out[f.name] = _check_field(f, args[f.name], f.name)
        elif f.required:
            raise ProtocolError(f"{spec.command.name} requires argument {f.name!r}", f.name)
        elif f.default is not None:
            out[f.name] = f.default
    for group in spec.exclusive:
        given = [g for g in group if g in out]
        if len(given) > 1:
            raise ProtocolError(f"give at most one of {', '.join(group)}", given[1])
    return out


def validate_reply(command: Command, body: Mapping[str, Any]) -> dict[str, Any]:
    """Check a reply body against the schema of ``command``; extra keys are kept.

    Raises
    ------
    ProtocolError
        If a required field is missing or has the wrong type.
    """
    spec = _spec(command)
    if not isinstance(body, Mapping):
        raise ProtocolError(f"{spec.command.name} reply must be an object", "reply")
    out = dict(body)
    for f in spec.reply:
        if f.name in body:
            out[f.name] = _check_field(f, body[f.name], f.name)
        elif f.required:
            raise ProtocolError(f"{spec.command.name} reply lacks field {f.name!r}", f.name)
    for key, value, names in spec.reply_when:
        if out.get(key) == value:
            for n in names:
                if n not in out:
                    raise ProtocolError(f"{spec.command.name} reply with {key}={value!r} lacks field {n!r}", n)
    lengths = [(n, len(out[n])) for n in spec.same_length if isinstance(out.get(n), list)]
    for n, length in lengths[1:]:
        if length != lengths[0][1]:
            raise ProtocolError(f"{spec.command.name} reply: {n} has {length} values, "
                                f"{lengths[0][0]} has {lengths[0][1]}", n)
    return out


def _spec(command: Command | int) -> CommandSpec:
    try:
        return COMMANDS[Command(command)]
    except ValueError:
        raise ProtocolError(f"unknown command {command!r}", "msg_type", ErrorCode.UNKNOWN_COMMAND) from None


# --------------------------------------------------------------------------
# Messages
# --------------------------------------------------------------------------

@dataclass(frozen=True)
class Request:
    """A validated request: ``args`` follows the command's schema."""

    command: Command
    request_id: int
    args: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Reply:
    """A successful reply: ``body`` is the decoded JSON object."""

    command: Command
    request_id: int
    body: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ErrorReply:
    """An ERROR reply."""

    request_id: int
    code: ErrorCode
    message: str
    field: str | None = None


def _reject_constant(name: str) -> Any:
    raise ValueError(f"non-finite number {name} is not allowed")


def _json_dumps(obj: Any) -> bytes:
    try:
        return json.dumps(obj, separators=(",", ":"), ensure_ascii=False, allow_nan=False).encode("utf-8")
    except (TypeError, ValueError) as exc:
        raise ProtocolError(f"payload is not JSON-serialisable: {exc}", "payload", ErrorCode.INTERNAL) from exc


def _json_loads(payload: bytes, request_id: int | None) -> dict[str, Any]:
    if not payload:
        return {}
    try:
        obj = json.loads(payload.decode("utf-8"), parse_constant=_reject_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise ProtocolError(f"payload is not valid UTF-8 JSON: {exc}", "payload",
                            ErrorCode.BAD_FRAME, request_id) from None
    if not isinstance(obj, dict):
        raise ProtocolError("payload must be a JSON object", "payload", ErrorCode.BAD_FRAME, request_id)
    return obj


def encode_request(command: Command, request_id: int, args: Mapping[str, Any] | None = None, *,
                   max_payload: int = DEFAULT_MAX_PAYLOAD) -> bytes:
    """Validate ``args`` and return the wire bytes of a request frame.

    For MODEL_CHUNK, ``args`` is ``{"offset": int, "data": bytes}``.
    """
    command = Command(command)
    spec = COMMANDS[command]
    norm = validate_args(command, args)
    if spec.binary:
        payload = _CHUNK_HEADER.pack(norm["offset"]) + norm["data"]
        if len(payload) > max_payload:
            raise ProtocolError(f"chunk of {len(norm['data'])} B exceeds max_payload {max_payload} B "
                                f"minus {CHUNK_HEADER_SIZE} B offset", "data")
    else:
        payload = _json_dumps(norm) if norm else b""
        if len(payload) > max_payload:
            raise ProtocolError(f"arguments encode to {len(payload)} B, over max_payload {max_payload} B", "args")
    return encode_frame(command, request_id, payload, max_payload=max_payload)


def decode_request(frame: Frame) -> Request:
    """Parse and validate a request frame.

    Raises
    ------
    ProtocolError
        With ``request_id`` set to the frame's id and ``code`` BAD_FRAME,
        UNKNOWN_COMMAND or BAD_ARGUMENT.
    """
    rid = frame.request_id
    if frame.version != PROTOCOL_VERSION:
        raise ProtocolError(f"unsupported protocol version {frame.version} (expected {PROTOCOL_VERSION})",
                            "version", ErrorCode.BAD_FRAME, rid)
    try:
        command = Command(frame.msg_type)
    except ValueError:
        raise ProtocolError(f"unknown command type 0x{frame.msg_type:02x}", "msg_type",
                            ErrorCode.UNKNOWN_COMMAND, rid) from None
    spec = COMMANDS[command]
    if spec.binary:
        if len(frame.payload) < CHUNK_HEADER_SIZE:
            raise ProtocolError(f"{command.name} payload shorter than its {CHUNK_HEADER_SIZE}-byte offset",
                                "offset", ErrorCode.BAD_FRAME, rid)
        (offset,) = _CHUNK_HEADER.unpack_from(frame.payload)
        raw_args: dict[str, Any] = {"offset": offset, "data": frame.payload[CHUNK_HEADER_SIZE:]}
    else:
        raw_args = _json_loads(frame.payload, rid)
    try:
        args = validate_args(command, raw_args)
    except ProtocolError as exc:
        exc.request_id = rid
        raise
    return Request(command, rid, args)


def encode_reply(command: Command, request_id: int, body: Mapping[str, Any] | None = None, *,
                 max_payload: int = DEFAULT_MAX_PAYLOAD, validate: bool = True) -> bytes:
    """Return the wire bytes of a successful reply to ``command``.

    Raises
    ------
    ProtocolError
        If ``body`` fails :func:`validate_reply` (when ``validate``) or is too
        large / not JSON-serialisable (code INTERNAL).
    """
    command = Command(command)
    body = {} if body is None else body
    if validate:
        body = validate_reply(command, body)
    elif not isinstance(body, Mapping):
        raise ProtocolError("reply body must be an object", "reply", ErrorCode.INTERNAL)
    payload = _json_dumps(dict(body))
    if len(payload) > max_payload:
        raise ProtocolError(f"{command.name} reply of {len(payload)} B exceeds max_payload {max_payload} B",
                            "reply", ErrorCode.INTERNAL)
    return encode_frame(reply_type(command), request_id, payload, max_payload=max_payload)


def encode_error(request_id: int, code: ErrorCode, message: str, field: str | None = None, *,
                 max_payload: int = DEFAULT_MAX_PAYLOAD) -> bytes:
    """Return the wire bytes of an ERROR reply; an over-long message is truncated."""
    code = ErrorCode(code)
    message = str(message)
    body = {"code": code.name, "message": message, "field": field}
    payload = _json_dumps(body)
    while len(payload) > max_payload and message:
        message = message[: max(0, len(message) - (len(payload) - max_payload) - 3)] + "..."
        if len(message) <= 3:
            message = ""
        body["message"] = message
        payload = _json_dumps(body)
    return encode_frame(MsgType.ERROR, request_id, payload, max_payload=max_payload)


def decode_reply(frame: Frame, *, validate: bool = True) -> Reply | ErrorReply:
    """Parse a reply frame into :class:`Reply` or :class:`ErrorReply`.

    Raises
    ------
    ProtocolError
        If the frame is not a well-formed reply (code BAD_FRAME) or its body
        fails the reply schema (code BAD_ARGUMENT, ``field`` set).
    """
    rid = frame.request_id
    if frame.version != PROTOCOL_VERSION:
        raise ProtocolError(f"unsupported protocol version {frame.version}", "version", ErrorCode.BAD_FRAME, rid)
    body = _json_loads(frame.payload, rid)
    if frame.msg_type == MsgType.ERROR:
        name = body.get("code")
        try:
            code = ErrorCode[name] if isinstance(name, str) else ErrorCode(name)
        except (KeyError, ValueError):
            raise ProtocolError(f"unknown error code {name!r}", "code", ErrorCode.BAD_FRAME, rid) from None
        message = body.get("message", "")
        fld = body.get("field")
        if not isinstance(message, str):
            raise ProtocolError("error message must be a string", "message", ErrorCode.BAD_FRAME, rid)
        if fld is not None and not isinstance(fld, str):
            raise ProtocolError("error field must be a string or null", "field", ErrorCode.BAD_FRAME, rid)
        return ErrorReply(rid, code, message, fld)
    if not frame.msg_type & REPLY_FLAG:
        raise ProtocolError(f"msg_type 0x{frame.msg_type:02x} is not a reply", "msg_type", ErrorCode.BAD_FRAME, rid)
    try:
        command = Command(frame.msg_type & ~REPLY_FLAG)
    except ValueError:
        raise ProtocolError(f"reply to unknown command 0x{frame.msg_type:02x}", "msg_type",
                            ErrorCode.BAD_FRAME, rid) from None
    if validate:
        try:
            body = validate_reply(command, body)
        except ProtocolError as exc:
            exc.request_id = rid
            raise
    return Reply(command, rid, body)
