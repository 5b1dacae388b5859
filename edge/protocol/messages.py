"""Requests, replies and errors as messages: JSON payloads in frames, validated against the command set.

Payloads are compact UTF-8 JSON objects (an empty payload means ``{}``),
except ``MODEL_CHUNK`` requests, whose payload is binary: ``u32 offset`` then
the raw chunk bytes (with an upload session, the offset word has its top bit
set and ``u32 session`` follows it).  ``ERROR`` payloads are JSON
``{"code": "<ErrorCode name>", "message": str, "field": str | null}``.

The command set, with argument and reply schemas, is data: see
:data:`COMMANDS`.  Measured series travel as JSON number arrays in pages:
``SERIES {"measurement_id", "which": "raw"|"grid", "offset", "limit"?}``
answers ``{"measurement_id", "which", "offset", "total", "t_s", "T_C"
(raw) | "dT_K" (grid), "q_W_m2"}`` with as many samples as fit in one
reply (null for a non-finite sample); the host asks again from
``offset + len(t_s)`` until it holds ``total``.  A MEASURE with ``stream``
is answered as usual, preceded by EVENT frames (msg_type 0xFE, the MEASURE's
request id, a JSON payload ``{"kind", "seq", "t_s", ...}`` per
:data:`edge.protocol.commands.EVENTS`).  Requests are validated strictly (unknown fields are
rejected); replies must carry their required fields and may carry more.

This module is pure Python (no NumPy) so the host can import it cheaply.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field
from typing import Any, Mapping

from edge.protocol.commands import (COMMANDS, Command, EventKind, MsgType, reply_type, validate_args,
                                    validate_event, validate_reply)
from edge.protocol.errors import ErrorCode, ProtocolError
from edge.protocol.frame import DEFAULT_MAX_PAYLOAD, Frame, PROTOCOL_VERSION, REPLY_FLAG, encode_frame

_CHUNK_HEADER = struct.Struct("<I")
#: Bytes of a MODEL_CHUNK payload taken by the offset field.
CHUNK_HEADER_SIZE = _CHUNK_HEADER.size
#: Set in a MODEL_CHUNK offset word when a u32 session id follows it (offsets stay below 2**26).
CHUNK_SESSION_FLAG = 0x8000_0000
#: Bytes of a MODEL_CHUNK payload taken by the offset and session fields.
SESSION_CHUNK_HEADER_SIZE = 2 * CHUNK_HEADER_SIZE


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
class Event:
    """An EVENT pushed by the device during the request ``request_id`` (a streaming MEASURE)."""

    request_id: int
    kind: EventKind
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
    try:
        # JSON's \\u escapes can spell a lone UTF-16 surrogate, which is no text: refused here, not
        # met later as an internal error when a reply echoes it (ISSUE #35 §11).
        json.dumps(obj, ensure_ascii=False).encode("utf-8")
    except UnicodeEncodeError:
        raise ProtocolError("payload holds a lone UTF-16 surrogate (\\ud800-\\udfff), which is not text",
                            "payload", ErrorCode.BAD_FRAME, request_id) from None
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
        if "session" in norm:
            header = _CHUNK_HEADER.pack(norm["offset"] | CHUNK_SESSION_FLAG) + _CHUNK_HEADER.pack(norm["session"])
        else:
            header = _CHUNK_HEADER.pack(norm["offset"])
        payload = header + norm["data"]
        if len(payload) > max_payload:
            raise ProtocolError(f"chunk of {len(norm['data'])} B exceeds max_payload {max_payload} B "
                                f"minus {len(header)} B header", "data")
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
        if offset & CHUNK_SESSION_FLAG:
            if len(frame.payload) < SESSION_CHUNK_HEADER_SIZE:
                raise ProtocolError(f"{command.name} payload shorter than its {SESSION_CHUNK_HEADER_SIZE}-byte "
                                    "offset and session", "session", ErrorCode.BAD_FRAME, rid)
            (session,) = _CHUNK_HEADER.unpack_from(frame.payload, CHUNK_HEADER_SIZE)
            raw_args = {"offset": offset & ~CHUNK_SESSION_FLAG, "session": session,
                        "data": frame.payload[SESSION_CHUNK_HEADER_SIZE:]}
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


def encode_event(request_id: int, body: Mapping[str, Any], *, max_payload: int = DEFAULT_MAX_PAYLOAD) -> bytes:
    """Return the wire bytes of an EVENT frame (``body`` holds ``kind`` and its fields).

    Raises
    ------
    ProtocolError
        If ``body`` breaks :data:`~edge.protocol.commands.EVENTS` or does not fit ``max_payload``
        (code INTERNAL: a device bug).
    """
    try:
        body = validate_event(body)
    except ProtocolError as exc:
        raise ProtocolError(f"bad event: {exc.message}", exc.field, ErrorCode.INTERNAL) from None
    payload = _json_dumps(body)
    if len(payload) > max_payload:
        raise ProtocolError(f"{body['kind']} event of {len(payload)} B exceeds max_payload {max_payload} B",
                            "event", ErrorCode.INTERNAL)
    return encode_frame(MsgType.EVENT, request_id, payload, max_payload=max_payload)


def is_event(frame: Frame) -> bool:
    """Whether ``frame`` is an EVENT (to be routed to :func:`decode_event`, not :func:`decode_reply`)."""
    return frame.msg_type == MsgType.EVENT


def decode_event(frame: Frame) -> Event:
    """Parse and validate an EVENT frame.

    Raises
    ------
    ProtocolError
        Code BAD_FRAME for a frame that is no event or no JSON object, BAD_ARGUMENT (``field``
        set) for a payload that breaks the event's schema.
    """
    rid = frame.request_id
    if frame.version != PROTOCOL_VERSION:
        raise ProtocolError(f"unsupported protocol version {frame.version}", "version", ErrorCode.BAD_FRAME, rid)
    if frame.msg_type != MsgType.EVENT:
        raise ProtocolError(f"msg_type 0x{frame.msg_type:02x} is not an event", "msg_type", ErrorCode.BAD_FRAME, rid)
    try:
        body = validate_event(_json_loads(frame.payload, rid))
    except ProtocolError as exc:
        exc.request_id = rid
        raise
    return Event(rid, EventKind(body["kind"]), body)
