"""The command set as data: codes, argument and reply schemas, and their validation."""

from __future__ import annotations

import enum
import math
import re
from dataclasses import dataclass
from typing import Any, Mapping

from edge.protocol.errors import ErrorCode, ProtocolError
from edge.protocol.frame import REPLY_FLAG, MAX_REQUEST_ID

#: Largest model bundle MODEL_BEGIN accepts, bytes.
MAX_MODEL_SIZE = 64 * 1024 * 1024


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
        args=(Field("measurement_id", "int", lo=0, hi=MAX_REQUEST_ID, doc="absent = latest"),),
        reply=(Field("measurement_id", "int", required=True, lo=0),),
        doc="One stored result record, by id or the latest."),
    CommandSpec(
        Command.HISTORY,
        args=(Field("offset", "int", lo=0, hi=MAX_REQUEST_ID, default=0, doc="0 = newest"),
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
        args=(Field("measurement_id", "int", required=True, lo=0, hi=MAX_REQUEST_ID),
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
