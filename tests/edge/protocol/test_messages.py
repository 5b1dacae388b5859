"""Framing, decoding and message validation of edge/protocol.py."""

import json
import random
import struct
import zlib

import pytest

from edge.protocol.commands import (
    COMMANDS,
    Command,
    MsgType,
    reply_type,
    validate_args,
    validate_reply,
)
from edge.protocol.messages import (
    CHUNK_HEADER_SIZE,
    ErrorReply,
    Reply,
    decode_reply,
    decode_request,
    encode_error,
    encode_reply,
    encode_request,
)
from edge.protocol.frame import (
    PROTOCOL_VERSION,
    Frame,
    FrameDecoder,
    encode_frame,
    max_encoded_size,
)
from edge.protocol.errors import ErrorCode, ProtocolError
from edge.protocol.cobs import cobs_decode, cobs_encode

SHA = "ab" * 32


# ---------------------------------------------------------------- COBS

@pytest.mark.parametrize("n", [0, 1, 2, 253, 254, 255, 256, 507, 508, 509, 1000, 4108])
@pytest.mark.parametrize("zero_p", [0.0, 0.05, 1.0])
def test_cobs_round_trip_and_bound(n, zero_p):
    r = random.Random(n * 7 + int(zero_p * 100))
    data = bytes(0 if r.random() < zero_p else r.randrange(1, 256) for _ in range(n))
    enc = cobs_encode(data)
    assert 0 not in enc
    assert cobs_decode(enc) == data
    assert len(enc) <= n + n // 254 + 1


@pytest.mark.parametrize("bad", [b"\x05ab", b"\x02a\x00", b"\x00"])
def test_cobs_decode_rejects_malformed(bad):
    with pytest.raises(ValueError):
        cobs_decode(bad)


# ---------------------------------------------------------------- frames

def test_frame_byte_layout():
    wire = encode_frame(0x04, 0x01020304, b"hi")
    assert wire[0] == 0 and wire[-1] == 0 and 0 not in wire[1:-1]
    body = cobs_decode(wire[1:-1])
    assert body[:8] == bytes([PROTOCOL_VERSION, 0x04, 0x04, 0x03, 0x02, 0x01, 0x02, 0x00])
    assert body[8:10] == b"hi"
    assert struct.unpack("<I", body[10:])[0] == zlib.crc32(body[:10])


def test_frame_round_trip_with_zeros_and_all_bytes():
    payload = bytes(range(256)) * 4
    d = FrameDecoder()
    frames = d.feed(encode_frame(0x11, 0xFFFFFFFF, payload))
    assert frames == [Frame(0x11, 0xFFFFFFFF, payload)]
    assert d.stats.frames == 1 and d.stats.bytes_dropped == 0


def test_partial_frames_byte_by_byte():
    wire = encode_frame(1, 5, b'{"echo":"x"}') + encode_frame(2, 6)
    d = FrameDecoder()
    out = []
    for b in wire:
        out += d.feed(bytes([b]))
    assert [(f.msg_type, f.request_id) for f in out] == [(1, 5), (2, 6)]
    assert d.pending == 0


def test_crc_error_dropped_and_next_frame_ok():
    good = encode_frame(3, 1, b"payload")
    body = bytearray(cobs_decode(good[1:-1]))
    body[9] ^= 0x01
    bad = b"\x00" + cobs_encode(bytes(body)) + b"\x00"
    d = FrameDecoder()
    frames = d.feed(bad + encode_frame(3, 2, b"ok"))
    assert [f.request_id for f in frames] == [2]
    assert d.stats.crc_errors == 1
    assert d.stats.bytes_dropped == len(bad) - 2


def test_garbage_before_and_between_frames():
    d = FrameDecoder()
    garbage = b"\xff\x13\x11\r\nAT+RESET"
    frames = d.feed(garbage + encode_frame(1, 1) + b"\x01\x02\x00\x07" + encode_frame(1, 2))
    assert [f.request_id for f in frames] == [1, 2]
    # "\x01\x02" and "\x07" are each terminated by a delimiter: two bad frames.
    assert d.stats.bad_frames == 3
    assert d.stats.bytes_dropped == len(garbage) + 3


def test_length_field_mismatch_is_bad_frame():
    body = struct.pack("<BBIH", 1, 1, 9, 5) + b"abc"
    body += struct.pack("<I", zlib.crc32(body))
    d = FrameDecoder()
    assert d.feed(b"\x00" + cobs_encode(body) + b"\x00") == []
    assert d.stats.bad_frames == 1


def test_oversize_frame_discarded_with_bounded_buffer():
    d = FrameDecoder(max_payload=16)
    big = encode_frame(1, 1, bytes(range(1, 200)), max_payload=4096)
    frames = d.feed(big[:-1])
    assert frames == [] and d.pending <= max_encoded_size(16) + 1
    frames = d.feed(big[-1:] + encode_frame(1, 2, b"small"))
    assert [f.request_id for f in frames] == [2]
    assert d.stats.oversize == 1


def test_endless_input_without_delimiter_stays_bounded():
    d = FrameDecoder(max_payload=64)
    chunk = bytes(range(1, 256))
    for _ in range(400):  # ~100 kB of noise, no delimiter
        assert d.feed(chunk) == []
        assert d.pending <= max_encoded_size(64)
    assert [f.request_id for f in d.feed(encode_frame(1, 3))] == [3]
    assert d.stats.bytes_dropped == 400 * 255


def test_oversize_admitted_by_cobs_slack_is_rejected():
    # Zeros make COBS overhead minimal, so a 301-B payload still fits the
    # streaming bound for max_payload=300 and must be caught by the length check.
    wire = encode_frame(1, 1, bytes(301), max_payload=4096)
    d = FrameDecoder(max_payload=300)
    assert len(wire) - 2 <= max_encoded_size(300)
    assert d.feed(wire) == []
    assert d.stats.oversize == 1


def test_discard_partial_counts_and_resyncs():
    d = FrameDecoder()
    wire = encode_frame(1, 1, b"abc")
    d.feed(wire[:6])
    assert d.pending == 5
    assert d.discard_partial() == 5
    assert d.stats.timeouts == 1
    assert [f.request_id for f in d.feed(wire[6:] + encode_frame(1, 2))] == [2]


def test_encode_frame_rejects_bad_header_and_size():
    with pytest.raises(ProtocolError) as ei:
        encode_frame(1, 1, b"x" * 11, max_payload=10)
    assert ei.value.field == "payload"
    with pytest.raises(ProtocolError) as ei:
        encode_frame(1, 2**32)
    assert ei.value.field == "request_id"
    with pytest.raises(ProtocolError):
        encode_frame(256, 1)
    with pytest.raises(ValueError, match="max_payload"):
        FrameDecoder(max_payload=70000)


# ---------------------------------------------------------------- requests

VALID = {
    Command.PING: [{}, {"echo": "hello"}],
    Command.INFO: [{}],
    Command.STATUS: [{}],
    Command.MEASURE: [{}, {"power_W": 0.5}, {"voltage_V": 5, "contact_time_s": 2.0}],
    Command.RESULT: [{}, {"measurement_id": 12}],
    Command.HISTORY: [{}, {"offset": 40, "limit": 100}],
    Command.CONFIG_GET: [{}, {"keys": ["heater.power_W"]}],
    Command.CONFIG_SET: [{"values": {"heater.power_W": 0.4, "name": "probe", "on": True, "cal": [1, 2.5]}}],
    Command.SERIES: [{"measurement_id": 3}, {"measurement_id": 0, "which": "grid", "offset": 120, "limit": 2048}],
    Command.MODEL_BEGIN: [{"size": 1000, "sha256": SHA}, {"size": 1, "sha256": SHA.upper(), "version": "v2"}],
    Command.MODEL_CHUNK: [{"offset": 0, "data": b"\x00\x01\xff"}, {"offset": 4096, "data": bytes(4092)},
                          {"offset": 7, "data": b"\x00", "session": 0xFFFFFFFF},
                          {"offset": 0, "data": bytes(4088), "session": 1}],
    Command.MODEL_COMMIT: [{}, {"session": 12345}],
    Command.MODEL_ABORT: [{}, {"session": 1}],
    Command.ABORT: [{}],
    Command.OBJECTS_BEGIN: [{"name": "kitchen", "size": 120, "sha256": SHA},
                            {"name": "a", "size": 1, "sha256": SHA.upper(), "activate": False}],
    Command.OBJECTS_CHUNK: [{"offset": 0, "data": b"name,class\n", "session": 7},
                            {"offset": 4088, "data": bytes(4088), "session": 0xFFFFFFFF}],
    Command.OBJECTS_COMMIT: [{"session": 3}],
    Command.OBJECTS_ABORT: [{}, {"session": 3}],
    Command.OBJECTS_LIST: [{}],
    Command.OBJECTS_REMOVE: [{"name": "kitchen"}],
    Command.OBJECTS_SELECT: [{"name": "library"}, {"name": "kitchen"}],
    Command.CALIBRATION_SET: [{"calibration": "{}"}, {"calibration": "{}", "signature": "{\"k\": 1}"}],
    Command.CALIBRATION_GET: [{}],
}

INVALID = [
    (Command.PING, {"echo": 5}, "echo"),
    (Command.PING, {"echo": "x" * 257}, "echo"),
    (Command.INFO, {"verbose": True}, "verbose"),
    (Command.STATUS, {"x": 1}, "x"),
    (Command.MEASURE, {"power_W": 0}, "power_W"),
    (Command.MEASURE, {"power_W": -1.0}, "power_W"),
    (Command.MEASURE, {"power_W": 51}, "power_W"),
    (Command.MEASURE, {"power_W": "1"}, "power_W"),
    (Command.MEASURE, {"power_W": True}, "power_W"),
    (Command.MEASURE, {"power_W": float("nan")}, "power_W"),
    (Command.MEASURE, {"voltage_V": 49}, "voltage_V"),
    (Command.MEASURE, {"power_W": 1, "voltage_V": 1}, "voltage_V"),
    (Command.MEASURE, {"contact_time_s": 0}, "contact_time_s"),
    (Command.MEASURE, {"contact_time_s": 61}, "contact_time_s"),
    (Command.RESULT, {"measurement_id": -1}, "measurement_id"),
    (Command.RESULT, {"measurement_id": 1.5}, "measurement_id"),
    (Command.HISTORY, {"offset": -1}, "offset"),
    (Command.HISTORY, {"limit": 0}, "limit"),
    (Command.HISTORY, {"limit": 101}, "limit"),
    (Command.HISTORY, {"limit": "10"}, "limit"),
    (Command.CONFIG_GET, {"keys": "a"}, "keys"),
    (Command.CONFIG_GET, {"keys": []}, "keys"),
    (Command.CONFIG_GET, {"keys": ["ok", 3]}, "keys[1]"),
    (Command.CONFIG_SET, {}, "values"),
    (Command.CONFIG_SET, {"values": {}}, "values"),
    (Command.CONFIG_SET, {"values": [1]}, "values"),
    (Command.CONFIG_SET, {"values": {"a": {"nested": 1}}}, "values.a"),
    (Command.CONFIG_SET, {"values": {"a": [[1]]}}, "values.a"),
    (Command.CONFIG_SET, {"values": {"a": "x" * 300}}, "values.a"),
    (Command.SERIES, {}, "measurement_id"),
    (Command.SERIES, {"measurement_id": -1}, "measurement_id"),
    (Command.SERIES, {"measurement_id": 1, "which": "smooth"}, "which"),
    (Command.SERIES, {"measurement_id": 1, "which": 1}, "which"),
    (Command.SERIES, {"measurement_id": 1, "offset": -5}, "offset"),
    (Command.SERIES, {"measurement_id": 1, "limit": 0}, "limit"),
    (Command.SERIES, {"measurement_id": 1, "limit": 2049}, "limit"),
    (Command.SERIES, {"measurement_id": 1, "rows": 2}, "rows"),
    (Command.MODEL_BEGIN, {"sha256": SHA}, "size"),
    (Command.MODEL_BEGIN, {"size": 0, "sha256": SHA}, "size"),
    (Command.MODEL_BEGIN, {"size": 2**27, "sha256": SHA}, "size"),
    (Command.MODEL_BEGIN, {"size": 10}, "sha256"),
    (Command.MODEL_BEGIN, {"size": 10, "sha256": "xyz"}, "sha256"),
    (Command.MODEL_BEGIN, {"size": 10, "sha256": SHA + "0"}, "sha256"),
    (Command.MODEL_CHUNK, {"offset": 0, "data": b""}, "data"),
    (Command.MODEL_CHUNK, {"offset": 0, "data": "text"}, "data"),
    (Command.MODEL_CHUNK, {"offset": -1, "data": b"x"}, "offset"),
    (Command.MODEL_CHUNK, {"data": b"x"}, "offset"),
    (Command.MODEL_COMMIT, {"sha256": SHA}, "sha256"),
    (Command.MODEL_ABORT, {"now": 1}, "now"),
    (Command.MODEL_ABORT, {"session": 0}, "session"),
    (Command.MODEL_COMMIT, {"session": "abc"}, "session"),
    (Command.MODEL_CHUNK, {"offset": 0, "data": b"x", "session": 2**32}, "session"),
    (Command.ABORT, {"measurement_id": 1}, "measurement_id"),
    (Command.OBJECTS_BEGIN, {"size": 10, "sha256": SHA}, "name"),
    (Command.OBJECTS_BEGIN, {"name": "", "size": 10, "sha256": SHA}, "name"),
    (Command.OBJECTS_BEGIN, {"name": "k", "size": 0, "sha256": SHA}, "size"),
    (Command.OBJECTS_BEGIN, {"name": "k", "size": 2**21, "sha256": SHA}, "size"),
    (Command.OBJECTS_BEGIN, {"name": "k", "size": 10, "sha256": "xyz"}, "sha256"),
    (Command.OBJECTS_BEGIN, {"name": "k", "size": 10, "sha256": SHA, "activate": 1}, "activate"),
    (Command.OBJECTS_CHUNK, {"offset": 0, "data": b"x"}, "session"),
    (Command.OBJECTS_CHUNK, {"offset": 0, "data": b"", "session": 1}, "data"),
    (Command.OBJECTS_COMMIT, {}, "session"),
    (Command.OBJECTS_ABORT, {"session": 0}, "session"),
    (Command.OBJECTS_LIST, {"all": True}, "all"),
    (Command.OBJECTS_REMOVE, {}, "name"),
    (Command.OBJECTS_SELECT, {"name": 3}, "name"),
    (Command.CALIBRATION_SET, {}, "calibration"),
    (Command.CALIBRATION_SET, {"calibration": "x" * 3501}, "calibration"),
    (Command.CALIBRATION_GET, {"which": 1}, "which"),
]


def test_every_command_has_valid_and_invalid_cases():
    assert set(VALID) == set(COMMANDS) == set(Command)
    assert {c for c, _, _ in INVALID} == set(Command)


@pytest.mark.parametrize("command,args", [(c, a) for c, lst in VALID.items() for a in lst])
def test_request_round_trip(command, args):
    wire = encode_request(command, 77, args)
    (frame,) = FrameDecoder().feed(wire)
    assert frame.msg_type == command
    req = decode_request(frame)
    assert req.command == command and req.request_id == 77
    assert req.args == validate_args(command, args)
    for key, value in args.items():
        if key == "sha256":
            assert req.args[key] == value.lower()
        else:
            assert req.args[key] == value


@pytest.mark.parametrize("command,args,field", INVALID)
def test_request_validation_names_field(command, args, field):
    with pytest.raises(ProtocolError) as ei:
        encode_request(command, 1, args)
    assert ei.value.field == field
    assert ei.value.code == ErrorCode.BAD_ARGUMENT
    assert isinstance(ei.value, ValueError)


def _json_able(args):
    # NaN has no JSON encoding (see test_decode_rejects_nan).
    return not any(isinstance(v, float) and v != v for v in args.values())


@pytest.mark.parametrize("command,args,field",
                         [i for i in INVALID if not COMMANDS[i[0]].binary and _json_able(i[1])])
def test_decode_request_rejects_invalid_json_args(command, args, field):
    frame = Frame(command, 9, json.dumps(args).encode())
    with pytest.raises(ProtocolError) as ei:
        decode_request(frame)
    assert ei.value.field == field and ei.value.request_id == 9


def test_defaults_filled_in():
    assert validate_args(Command.HISTORY, {}) == {"offset": 0, "limit": 20}
    # SERIES without a limit: as many samples as fit in one reply.
    assert validate_args(Command.SERIES, {"measurement_id": 4}) == {"measurement_id": 4, "which": "raw", "offset": 0}
    assert validate_args(Command.MEASURE, {"power_W": 1}) == {"power_W": 1.0}
    assert isinstance(validate_args(Command.MEASURE, {"power_W": 1})["power_W"], float)


def test_decode_unknown_command_bad_json_and_version():
    with pytest.raises(ProtocolError) as ei:
        decode_request(Frame(0x42, 3))
    assert ei.value.code == ErrorCode.UNKNOWN_COMMAND and ei.value.request_id == 3
    with pytest.raises(ProtocolError) as ei:
        decode_request(Frame(reply_type(Command.INFO), 3))
    assert ei.value.code == ErrorCode.UNKNOWN_COMMAND
    for payload in (b"{not json", b"\xff\xfe", b"[1,2]", b'"str"'):
        with pytest.raises(ProtocolError) as ei:
            decode_request(Frame(Command.PING, 4, payload))
        assert ei.value.code == ErrorCode.BAD_FRAME and ei.value.field == "payload"
    with pytest.raises(ProtocolError) as ei:
        decode_request(Frame(Command.PING, 5, b"", version=2))
    assert ei.value.code == ErrorCode.BAD_FRAME and ei.value.field == "version"


def test_decode_rejects_a_lone_surrogate_as_a_bad_frame():
    """ISSUE #35 §11: PING echo with a lone surrogate answered INTERNAL when the reply was encoded."""
    for payload in (b'{"echo":"\\ud800"}', b'{"echo":["ok","\\udfff"]}', b'{"\\udc00":1}'):
        with pytest.raises(ProtocolError) as ei:
            decode_request(Frame(Command.PING, 6, payload))
        assert ei.value.code == ErrorCode.BAD_FRAME and "surrogate" in str(ei.value)
    # A surrogate pair is one character and fine.
    assert decode_request(Frame(Command.PING, 7, b'{"echo":"\\ud83d\\ude00"}')).args["echo"] == "\U0001F600"


def test_decode_rejects_nan():
    with pytest.raises(ProtocolError) as ei:
        decode_request(Frame(Command.MEASURE, 1, b'{"power_W":NaN}'))
    assert ei.value.field == "payload"


def test_model_chunk_binary_layout_and_short_payload():
    wire = encode_request(Command.MODEL_CHUNK, 1, {"offset": 0x0302010F, "data": b"\x00\x00"})
    (frame,) = FrameDecoder().feed(wire)
    assert frame.payload == b"\x0f\x01\x02\x03\x00\x00"
    with pytest.raises(ProtocolError) as ei:
        decode_request(Frame(Command.MODEL_CHUNK, 1, b"\x00\x01"))
    assert ei.value.field == "offset" and ei.value.code == ErrorCode.BAD_FRAME
    with pytest.raises(ProtocolError) as ei:
        encode_request(Command.MODEL_CHUNK, 1, {"offset": 0, "data": bytes(4096 - CHUNK_HEADER_SIZE + 1)})
    assert ei.value.field == "data"


def test_model_chunk_with_a_session_sets_the_flag_and_carries_the_id():
    wire = encode_request(Command.MODEL_CHUNK, 1, {"offset": 0x0302010F, "session": 0x0A0B0C0D, "data": b"\x07"})
    (frame,) = FrameDecoder().feed(wire)
    assert frame.payload == b"\x0f\x01\x02\x83\x0d\x0c\x0b\x0a\x07"
    assert decode_request(frame).args == {"offset": 0x0302010F, "session": 0x0A0B0C0D, "data": b"\x07"}
    # The flag promises a session: a payload too short for it is a bad frame.
    with pytest.raises(ProtocolError) as ei:
        decode_request(Frame(Command.MODEL_CHUNK, 1, b"\x00\x00\x00\x80\x01\x00"))
    assert ei.value.field == "session" and ei.value.code == ErrorCode.BAD_FRAME
    with pytest.raises(ProtocolError) as ei:
        encode_request(Command.MODEL_CHUNK, 1, {"offset": 0, "session": 1, "data": bytes(4096 - 8 + 1)})
    assert ei.value.field == "data"


def test_abort_reply_schema():
    ok = decode_reply(Frame(reply_type(Command.ABORT), 3, b'{"aborted":true,"measurement_id":4}'))
    assert ok.body == {"aborted": True, "measurement_id": 4}
    assert decode_reply(Frame(reply_type(Command.ABORT), 3, b'{"aborted":false,"measurement_id":null}')).body[
        "measurement_id"] is None
    with pytest.raises(ProtocolError) as ei:
        decode_reply(Frame(reply_type(Command.ABORT), 3, b'{"aborted":true}'))
    assert ei.value.field == "measurement_id"


# ---------------------------------------------------------------- replies

def test_reply_round_trip_and_extra_fields_kept():
    body = {"protocol_version": 1, "firmware_version": "0.1.0", "model_version": None,
            "model_sha256": None, "board": "rpi-zero-2w", "extra": [1, 2]}
    (frame,) = FrameDecoder().feed(encode_reply(Command.INFO, 12, body))
    assert frame.msg_type == Command.INFO | 0x80
    reply = decode_reply(frame)
    assert reply == Reply(Command.INFO, 12, body)


def test_reply_schema_violations_name_field():
    with pytest.raises(ProtocolError) as ei:
        encode_reply(Command.STATUS, 1, {})
    assert ei.value.field == "state"
    with pytest.raises(ProtocolError) as ei:
        validate_reply(Command.HISTORY, {"offset": 0, "total": "3", "items": []})
    assert ei.value.field == "total"
    with pytest.raises(ProtocolError) as ei:
        decode_reply(Frame(reply_type(Command.MODEL_CHUNK), 4, b'{"received":-1}'))
    assert ei.value.field == "received" and ei.value.request_id == 4
    with pytest.raises(ProtocolError) as ei:
        encode_reply(Command.PING, 1, {"echo": object()}, validate=False)
    assert ei.value.code == ErrorCode.INTERNAL


def test_reply_too_large_is_internal_error():
    with pytest.raises(ProtocolError) as ei:
        encode_reply(Command.HISTORY, 1, {"offset": 0, "total": 1, "items": ["x" * 5000]})
    assert ei.value.code == ErrorCode.INTERNAL


@pytest.mark.parametrize("code", list(ErrorCode))
def test_error_round_trip(code):
    (frame,) = FrameDecoder().feed(encode_error(8, code, "went wrong", "power_W"))
    assert frame.msg_type == MsgType.ERROR == 0xFF
    assert decode_reply(frame) == ErrorReply(8, code, "went wrong", "power_W")


def test_long_error_message_truncated_to_fit():
    wire = encode_error(1, ErrorCode.INTERNAL, "x" * 10000, max_payload=200)
    (frame,) = FrameDecoder(200).feed(wire)
    err = decode_reply(frame)
    assert err.code == ErrorCode.INTERNAL and err.message.endswith("...") and len(frame.payload) <= 200


def test_decode_reply_rejects_requests_and_unknown_codes():
    with pytest.raises(ProtocolError):
        decode_reply(Frame(Command.PING, 1))
    with pytest.raises(ProtocolError) as ei:
        decode_reply(Frame(MsgType.ERROR, 1, b'{"code":"NOPE","message":"x"}'))
    assert ei.value.field == "code"


def test_series_command_byte_and_choices_error_message():
    assert Command.SERIES == 0x09 and reply_type(Command.SERIES) == 0x89
    with pytest.raises(ProtocolError, match="which must be one of raw, grid, got 'smooth'"):
        validate_args(Command.SERIES, {"measurement_id": 1, "which": "smooth"})


def _series_body(**kw):
    body = {"measurement_id": 2, "which": "raw", "offset": 0, "total": 3,
            "t_s": [-0.1, 0.0, 0.1], "T_C": [25.0, None, 25.5], "q_W_m2": [0, 10, 12.5]}
    body.update(kw)
    return body


def test_series_reply_round_trip_with_null_samples():
    (frame,) = FrameDecoder().feed(encode_reply(Command.SERIES, 5, _series_body()))
    reply = decode_reply(frame)
    assert reply.body["T_C"] == [25.0, None, 25.5]
    assert reply.body["q_W_m2"] == [0.0, 10.0, 12.5] and all(isinstance(x, float) for x in reply.body["q_W_m2"])
    grid = _series_body(which="grid", dT_K=[0.0, 0.1, 0.2])
    del grid["T_C"]
    assert validate_reply(Command.SERIES, grid)["dT_K"] == [0.0, 0.1, 0.2]


@pytest.mark.parametrize("change,field", [
    ({"T_C": None}, "T_C"),                           # raw needs T_C (dropped below)
    ({"which": "grid"}, "dT_K"),                      # grid needs dT_K
    ({"which": "both"}, "which"),
    ({"q_W_m2": [0, 1]}, "q_W_m2"),                   # lengths differ
    ({"t_s": [0.0, "x", 1.0]}, "t_s[1]"),
    ({"T_C": [1.0, True, 2.0]}, "T_C[1]"),
    ({"total": -1}, "total"),
    ({"t_s": [0.0] * 2049, "T_C": [0.0] * 2049, "q_W_m2": [0.0] * 2049}, "t_s"),
])
def test_series_reply_violations_name_the_field(change, field):
    body = _series_body(**change)
    if change.get("T_C", 0) is None:
        del body["T_C"]
    with pytest.raises(ProtocolError) as ei:
        validate_reply(Command.SERIES, body)
    assert ei.value.field == field


def test_series_reply_rejects_nan_on_the_wire():
    payload = json.dumps(_series_body()).replace("null", "NaN").encode()
    with pytest.raises(ProtocolError) as ei:
        decode_reply(Frame(reply_type(Command.SERIES), 1, payload))
    assert ei.value.field == "payload"
