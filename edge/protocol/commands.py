"""The command set as data: codes, argument and reply schemas, and their validation."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any, Mapping

from edge.schema import MISSING, Field, SchemaError, check_value
from edge.protocol.errors import ErrorCode, ProtocolError
from edge.protocol.frame import REPLY_FLAG, MAX_REQUEST_ID

#: Largest model bundle MODEL_BEGIN accepts, bytes.
MAX_MODEL_SIZE = 64 * 1024 * 1024
#: Upload session ids are non-zero u32 (MODEL_CHUNK carries one in its binary header).
MAX_SESSION_ID = 0xFFFF_FFFF
#: Largest object-set CSV OBJECTS_BEGIN accepts on the wire, bytes (the device's own bound may be lower).
MAX_OBJECTS_SIZE = 1024 * 1024


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
    ABORT = 0x0A
    MODEL_BEGIN = 0x10
    MODEL_CHUNK = 0x11
    MODEL_COMMIT = 0x12
    MODEL_ABORT = 0x13
    OBJECTS_BEGIN = 0x20
    OBJECTS_CHUNK = 0x21
    OBJECTS_COMMIT = 0x22
    OBJECTS_ABORT = 0x23
    OBJECTS_LIST = 0x24
    OBJECTS_REMOVE = 0x25
    OBJECTS_SELECT = 0x26
    CALIBRATION_SET = 0x30
    CALIBRATION_GET = 0x31


class MsgType(enum.IntEnum):
    """Non-command message types."""

    ERROR = 0xFF
    #: A device-pushed event during a MEASURE that asked for them (``stream``): addressed with that
    #: request's id, never a reply (the MEASURE reply still ends the exchange). See :data:`EVENTS`.
    EVENT = 0xFE


# --------------------------------------------------------------------------
# Command schemas (data)
# --------------------------------------------------------------------------

def arg(name: str, kind: str, *, required: bool = False, default: Any = None, **kw: Any) -> Field:
    """A named protocol field; optional ones without a default are left out when absent."""
    return Field(kind, MISSING if required else default, name=name, **kw)


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
#: Longest arming and settling a MEASURE may ask for (s): the worker's budget covers them.
MAX_ARM_s = 120.0
MAX_SETTLE_s = 30.0
#: Longest calibration text CALIBRATION_SET carries (a frame holds 4 kB; a calibration on three
#: references with two touches each is about 1.3 kB of compact JSON).
MAX_CALIBRATION_CHARS = 3500
#: Values of SERIES ``which``: the raw samples or the resampled grid (estimator input).
SERIES_KINDS = ("raw", "grid")
#: Most samples one SERIES reply may carry (the payload bound usually allows fewer).
SERIES_MAX_LIMIT = 2048
#: Longest stored series SERIES can address (edge.storage.history stores at most 10^6 values).
_SERIES_MAX_OFFSET = 1_000_000

COMMANDS: dict[Command, CommandSpec] = {spec.command: spec for spec in (
    CommandSpec(
        Command.PING,
        args=(arg("echo", "str", hi=_STR_MAX, doc="string echoed back"),),
        reply=(arg("echo", "str", nullable=True),),
        doc="Liveness check."),
    CommandSpec(
        Command.INFO,
        reply=(arg("protocol_version", "int", required=True),
               arg("firmware_version", "str", required=True),
               arg("model_version", "str", required=True, nullable=True),
               arg("model_sha256", "str", required=True, nullable=True),
               arg("board", "str", required=True),
               arg("device_id", "str", nullable=True, hi=_STR_MAX,
                   doc="the device's identity, generated at its first start (null: unreadable)")),
        doc="Firmware and model versions, model sha256, board name, device identity."),
    CommandSpec(
        Command.STATUS,
        reply=(arg("state", "str", required=True, doc="idle, measuring, fault, ..."),),
        doc="Current device state; extra fields are free-form (while measuring: phase, "
            "measurement_elapsed_s). Answered during a measurement."),
    CommandSpec(
        Command.MEASURE,
        args=(arg("power_W", "float", lo=0.0, hi=50.0, lo_open=True, doc="heater power, W"),
              arg("voltage_V", "float", lo=0.0, hi=48.0, lo_open=True, doc="heater voltage, V"),
              arg("contact_time_s", "float", lo=0.0, hi=60.0, lo_open=True, doc="touch duration, s"),
              arg("sample_rate_Hz", "float", lo=1.0, hi=200.0,
                  doc="sampling rate, Hz (default the device's; capped at what its converters can deliver)"),
              arg("until_decided", "bool", doc="stop heating once the running answer's posterior reaches "
                  "measurement.decide_posterior (record flagged 'decided')"),
              arg("arm_s", "float", lo=0.0, hi=MAX_ARM_s,
                  doc="armed: sample in air up to this long for the touch, heat settle_s after the detected "
                      "contact (0 = off; default measurement.arm_s); no contact in time ends 'no_contact'"),
              arg("settle_s", "float", lo=0.0, hi=MAX_SETTLE_s,
                  doc="armed: contact to heater-on, s (default measurement.settle_s)"),
              arg("stream", "bool", doc="push EVENT frames (phases, sample batches, the running answer; "
                  ":data:`EVENTS`) with this request's id while the touch runs; best effort: a slow "
                  "host loses events (counted), never the touch or the reply")),
        exclusive=(("power_W", "voltage_V"),),
        reply=(arg("measurement_id", "int", required=True, lo=0),),
        idempotent=False,
        doc="Run one touch measurement; replies with the stored record when it ends. Meanwhile the "
            "device answers STATUS and PING and refuses other requests with BUSY."),
    CommandSpec(
        Command.RESULT,
        args=(arg("measurement_id", "int", lo=0, hi=MAX_REQUEST_ID, doc="absent = latest"),),
        reply=(arg("measurement_id", "int", required=True, lo=0),),
        doc="One stored result record, by id or the latest."),
    CommandSpec(
        Command.HISTORY,
        args=(arg("offset", "int", lo=0, hi=MAX_REQUEST_ID, default=0, doc="0 = newest"),
              arg("limit", "int", lo=1, hi=100, default=20)),
        reply=(arg("offset", "int", required=True, lo=0),
               arg("total", "int", required=True, lo=0),
               arg("items", "list", required=True)),
        doc="Page of stored results, newest first, as many as fit one reply; each result is its answer's "
            "summary (values, u, names, ids, flags: no candidates, decision or sensor-chain detail), RESULT "
            "gives a whole record."),
    CommandSpec(
        Command.CONFIG_GET,
        args=(arg("keys", "list_str", lo=1, hi=_CONFIG_MAX_KEYS, doc="absent = all"),),
        reply=(arg("config", "dict", required=True),),
        doc="Read configuration values."),
    CommandSpec(
        Command.CONFIG_SET,
        args=(arg("values", "config", required=True, lo=1, hi=_CONFIG_MAX_KEYS),),
        reply=(arg("config", "dict", required=True, doc="full config after the change"),),
        doc="Set configuration values (the daemon validates each key)."),
    CommandSpec(
        Command.SERIES,
        args=(arg("measurement_id", "int", required=True, lo=0, hi=MAX_REQUEST_ID),
              arg("which", "str", default="raw", choices=SERIES_KINDS,
                    doc="raw: samples (t_s, T_C, q_W_m2); grid: resampled estimator input (t_s, dT_K, q_W_m2)"),
              arg("offset", "int", lo=0, hi=_SERIES_MAX_OFFSET, default=0, doc="first sample index"),
              arg("limit", "int", lo=1, hi=SERIES_MAX_LIMIT, doc="most samples wanted; absent = as many as fit")),
        reply=(arg("measurement_id", "int", required=True, lo=0),
               arg("which", "str", required=True, choices=SERIES_KINDS),
               arg("offset", "int", required=True, lo=0),
               arg("total", "int", required=True, lo=0, doc="samples in the whole series (0: not stored)"),
               arg("t_s", "list_num", required=True, hi=SERIES_MAX_LIMIT, doc="s from heater on"),
               arg("T_C", "list_num", hi=SERIES_MAX_LIMIT, doc="raw thermocouple, °C"),
               arg("dT_K", "list_num", hi=SERIES_MAX_LIMIT, doc="grid excess temperature, K"),
               arg("q_W_m2", "list_num", required=True, hi=SERIES_MAX_LIMIT, doc="heat flux, W/m^2")),
        reply_when=(("which", "raw", ("T_C",)), ("which", "grid", ("dT_K",))),
        same_length=("t_s", "T_C", "dT_K", "q_W_m2"),
        doc="One page of a stored measurement's series, samples [offset, offset + len(t_s)) of total; "
            "as many as fit in one reply (the host continues at offset + len(t_s)). Non-finite samples are null."),
    CommandSpec(
        Command.ABORT,
        reply=(arg("aborted", "bool", required=True, doc="a measurement was running and was cut"),
               arg("measurement_id", "int", required=True, nullable=True, lo=0,
                   doc="id of the stored aborted record; null if none was running or it is not stored yet")),
        doc="Cut a running measurement: heater off at once, the record stored with status aborted "
            "(reason host_abort); replies once it is stored. Answered during a measurement; a no-op "
            "when idle."),
    CommandSpec(
        Command.MODEL_BEGIN,
        args=(arg("size", "int", required=True, lo=1, hi=MAX_MODEL_SIZE, doc="bundle size, bytes"),
              arg("sha256", "sha256", required=True, doc="hex digest of the whole bundle"),
              arg("version", "str", hi=_STR_MAX),
              arg("downgrade", "str", hi=1024,
                  doc="a signed downgrade authorisation (JSON) that lets a signed bundle not newer than the "
                      "active one be installed over exactly that model")),
        reply=(arg("size", "int", required=True),
               arg("session", "int", lo=1, hi=MAX_SESSION_ID,
                   doc="upload session id; MODEL_CHUNK/COMMIT/ABORT must carry it")),
        doc="Start a model upload session (discards any unfinished one, whose session goes stale)."),
    CommandSpec(
        Command.MODEL_CHUNK,
        args=(arg("offset", "int", required=True, lo=0, hi=MAX_MODEL_SIZE),
              arg("data", "bytes", required=True, lo=1),
              arg("session", "int", lo=1, hi=MAX_SESSION_ID, doc="from MODEL_BEGIN")),
        reply=(arg("received", "int", required=True, lo=0, doc="contiguous bytes held"),),
        binary=True,
        doc="Binary payload: u32 LE offset, then the chunk bytes; with a session, the offset's top bit "
            "is set and a u32 LE session id follows it before the chunk bytes."),
    CommandSpec(
        Command.MODEL_COMMIT,
        args=(arg("session", "int", lo=1, hi=MAX_SESSION_ID, doc="from MODEL_BEGIN"),),
        reply=(arg("model_sha256", "str", required=True),),
        idempotent=False,
        doc="Verify size and sha256, install atomically."),
    CommandSpec(
        Command.MODEL_ABORT,
        args=(arg("session", "int", lo=1, hi=MAX_SESSION_ID, doc="from MODEL_BEGIN"),),
        doc="Discard an unfinished upload of this session (no-op if none)."),
    # -- the user's object sets (edge/service/objects.py, stored by edge/storage/objects_store.py) --
    CommandSpec(
        Command.OBJECTS_BEGIN,
        args=(arg("name", "str", required=True, lo=1, hi=64,
                  doc="set name: letters, digits, '.', '_', '-' ('library' is the built-in set)"),
              arg("size", "int", required=True, lo=1, hi=MAX_OBJECTS_SIZE, doc="CSV size, bytes"),
              arg("sha256", "sha256", required=True, doc="hex digest of the whole CSV"),
              arg("activate", "bool", default=True, doc="make it the active set once stored"),
              arg("signature", "str", lo=1, hi=4096,
                  doc="signature.json over the exact CSV bytes (Ed25519, edge.security.keys); "
                      "required unless the device allows unsigned updates")),
        reply=(arg("size", "int", required=True),
               arg("session", "int", required=True, lo=1, hi=MAX_SESSION_ID,
                   doc="OBJECTS_CHUNK/COMMIT/ABORT must carry it")),
        idempotent=False,
        doc="Start an object-set upload (an object-set CSV as `thermotouch estimate --objects` reads it); "
            "discards an unfinished one."),
    CommandSpec(
        Command.OBJECTS_CHUNK,
        args=(arg("offset", "int", required=True, lo=0, hi=MAX_OBJECTS_SIZE),
              arg("data", "bytes", required=True, lo=1),
              arg("session", "int", required=True, lo=1, hi=MAX_SESSION_ID, doc="from OBJECTS_BEGIN")),
        reply=(arg("received", "int", required=True, lo=0, doc="contiguous bytes held"),),
        binary=True,
        doc="Binary payload as MODEL_CHUNK's with a session: u32 LE offset with its top bit set, u32 LE "
            "session id, the chunk bytes."),
    CommandSpec(
        Command.OBJECTS_COMMIT,
        args=(arg("session", "int", required=True, lo=1, hi=MAX_SESSION_ID, doc="from OBJECTS_BEGIN"),),
        reply=(arg("name", "str", required=True),
               arg("sha256", "str", required=True, doc="of the stored CSV"),
               arg("objects", "int", required=True, lo=1, doc="number of objects in the set"),
               arg("active", "str", required=True, doc="name of the active set after the commit")),
        idempotent=False,
        doc="Verify size, sha256 and the CSV, store it atomically (replacing a set of that name) and, "
            "if asked, make it active. A refused upload (MODEL_REJECTED, naming line and column) changes "
            "nothing."),
    CommandSpec(
        Command.OBJECTS_ABORT,
        args=(arg("session", "int", lo=1, hi=MAX_SESSION_ID, doc="from OBJECTS_BEGIN"),),
        doc="Discard an unfinished object-set upload of this session (no-op if none)."),
    CommandSpec(
        Command.OBJECTS_LIST,
        reply=(arg("active", "str", required=True, doc="name of the active set ('library': the built-in)"),
               arg("sets", "list", required=True,
                   doc="stored sets: {name, sha256, size, objects, active, signed_by} (or {name, error})"),
               arg("error", "str", nullable=True, doc="why the chosen set could not be used, if so")),
        doc="The stored object sets and which one names the objects of each measurement."),
    CommandSpec(
        Command.OBJECTS_REMOVE,
        args=(arg("name", "str", required=True, lo=1, hi=64),),
        reply=(arg("removed", "str", required=True),
               arg("active", "str", required=True, doc="the active set afterwards ('library' if it was this one)")),
        idempotent=False,
        doc="Delete a stored object set (NOT_FOUND if there is none of that name)."),
    CommandSpec(
        Command.OBJECTS_SELECT,
        args=(arg("name", "str", required=True, lo=1, hi=64, doc="a stored set, or 'library'"),),
        reply=(arg("active", "str", required=True),),
        doc="Make a stored set (or the built-in library) the active one."),
    CommandSpec(
        Command.CALIBRATION_SET,
        args=(arg("calibration", "str", required=True, lo=2, hi=MAX_CALIBRATION_CHARS,
                  doc="the calibration file's text (thermotouch calibrate --out), compact JSON"),
              arg("signature", "str", lo=1, hi=1024,
                  doc="signature.json over the exact calibration bytes (UTF-8); required unless the device "
                      "allows unsigned updates")),
        reply=(arg("sha256", "str", required=True), arg("probe", "str", required=True),
               arg("created_utc", "str", required=True)),
        idempotent=False,
        doc="Install the probe's calibration (verified, signed per the update policy, stored atomically); "
            "every later measurement uses it and records its sha256."),
    CommandSpec(
        Command.CALIBRATION_GET,
        reply=(arg("calibration", "str", required=True, nullable=True, doc="the installed file's text, or null"),
               arg("sha256", "str", required=True, nullable=True),
               arg("calibrated", "bool", required=True),
               arg("signed_by", "str", nullable=True)),
        doc="The installed calibration (null: none; measurements are flagged 'uncalibrated')."),
)}


# --------------------------------------------------------------------------
# Events (data): what a streaming MEASURE pushes before its reply
# --------------------------------------------------------------------------

class EventKind(enum.StrEnum):
    """The ``kind`` of an EVENT frame's JSON payload."""

    PHASE = "phase"
    SAMPLES = "samples"
    ANSWER = "answer"


#: Words of a phase event, in the order a touch passes them (``cooldown`` only after a recent heating,
#: ``armed`` instead of ``baseline`` for an armed touch, ``contact`` when an armed touch found its
#: contact and settled, just before ``heating``); ``done`` comes last, with the stored record's id.
EVENT_PHASES = ("cooldown", "baseline", "armed", "contact", "heating", "estimating", "done")
#: Most samples one ``samples`` event carries (about 1 kB of JSON).
MAX_EVENT_SAMPLES = 64


@dataclass(frozen=True)
class EventSpec:
    """Schema of one event kind: its fields (besides ``kind`` and ``seq``) and ``same_length`` lists."""

    kind: EventKind
    fields: tuple[Field, ...] = ()
    same_length: tuple[str, ...] = ()
    doc: str = ""


_EVENT_COMMON = (arg("seq", "int", required=True, lo=0, doc="event number within this MEASURE, from 0"),
                 arg("t_s", "float", required=True, doc="board-clock s since the measurement began"))

EVENTS: dict[EventKind, EventSpec] = {spec.kind: spec for spec in (
    EventSpec(
        EventKind.PHASE,
        fields=_EVENT_COMMON + (
            arg("phase", "str", required=True, choices=EVENT_PHASES),
            arg("measurement_id", "int", nullable=True, lo=0, doc="done: the stored record (null: not stored)"),
            arg("status", "str", nullable=True, doc="done: the record's status (ok, aborted, failed)"),
            arg("events_sent", "int", lo=0, doc="done: events queued for this host before this one"),
            arg("events_dropped", "int", lo=0, doc="done: events of this MEASURE the link dropped so far")),
        doc="The touch entered a phase; ``heating``'s t_s is heater-on, the record's time origin."),
    EventSpec(
        EventKind.SAMPLES,
        fields=_EVENT_COMMON + (
            arg("sample_t_s", "list_num", required=True, lo=1, hi=MAX_EVENT_SAMPLES,
                doc="board-clock s since the measurement began, per sample"),
            arg("T_C", "list_num", required=True, hi=MAX_EVENT_SAMPLES, doc="thermocouple, °C"),
            arg("q_W_m2", "list_num", required=True, hi=MAX_EVENT_SAMPLES, doc="heat flux, W/m^2")),
        same_length=("sample_t_s", "T_C", "q_W_m2"),
        doc="A batch of the record's raw samples in the order read (null: a non-finite reading; the "
            "cool-down's readings are not the record's and are not sent)."),
    EventSpec(
        EventKind.ANSWER,
        fields=_EVENT_COMMON + (
            arg("answer", "dict", required=True,
                doc="the running answer (edge.estimation.running.RunningAnswer.to_dict: object, posterior, "
                    "effusivity_W_s05_m2K, u_ln_e, elapsed_s, samples, decided, class, source)"),),
        doc="The running answer changed (at most one per event period; the last one before each phase)."),
)}


def reply_type(command: Command) -> int:
    """msg_type of the reply to ``command``."""
    return int(command) | REPLY_FLAG


# --------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------

def _check_field(f: Field, value: Any, name: str) -> Any:
    try:
        return check_value(f, value, name)
    except SchemaError as e:
        raise ProtocolError(f"{e.path} {e.message}", e.path) from None


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
    out = _checked_fields(spec.reply, body, f"{spec.command.name} reply")
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


def _checked_fields(fields: Any, body: Mapping[str, Any], what: str) -> dict[str, Any]:
    """``body`` with each of ``fields`` type-checked; a required one missing is refused, naming ``what``."""
    out = dict(body)
    for f in fields:
        if f.name in body:
            out[f.name] = _check_field(f, body[f.name], f.name)
        elif f.required:
            raise ProtocolError(f"{what} lacks field {f.name!r}", f.name)
    return out


def validate_event(body: Mapping[str, Any]) -> dict[str, Any]:
    """Check an EVENT payload against :data:`EVENTS`; extra keys are kept (a newer device may add some).

    Raises
    ------
    ProtocolError
        If ``kind`` is unknown or a field is missing or of the wrong type.
    """
    if not isinstance(body, Mapping):
        raise ProtocolError("event must be an object", "event")
    try:
        spec = EVENTS[EventKind(body.get("kind"))]
    except ValueError:
        raise ProtocolError(f"unknown event kind {body.get('kind')!r}", "kind") from None
    out = _checked_fields(spec.fields, body, f"{spec.kind} event")
    lengths = {len(out[n]) for n in spec.same_length}
    if len(lengths) > 1:
        raise ProtocolError(f"{spec.kind} event: {', '.join(spec.same_length)} differ in length",
                            spec.same_length[1])
    return out


def _spec(command: Command | int) -> CommandSpec:
    try:
        return COMMANDS[Command(command)]
    except ValueError:
        raise ProtocolError(f"unknown command {command!r}", "msg_type", ErrorCode.UNKNOWN_COMMAND) from None
