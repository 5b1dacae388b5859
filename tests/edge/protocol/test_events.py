"""EVENT frames: the event table, their encoding, and the endpoint's bounds on them."""

from __future__ import annotations

import json
import threading

import pytest

from edge.protocol.commands import EVENT_PHASES, EVENTS, MAX_EVENT_SAMPLES, Command, EventKind, MsgType
from edge.protocol.endpoint import SerialEndpoint
from edge.protocol.errors import ErrorCode, ProtocolError
from edge.protocol.frame import Frame, FrameDecoder
from edge.protocol.messages import Request, decode_event, decode_reply, encode_event, is_event
from tests.support.fuzz_text import text as fuzz_text

VALID = {
    EventKind.PHASE: {"kind": "phase", "seq": 0, "t_s": 0.0, "phase": "heating"},
    EventKind.SAMPLES: {"kind": "samples", "seq": 3, "t_s": 0.2, "sample_t_s": [0.1, 0.2], "T_C": [25.0, None],
                        "q_W_m2": [1.5, 2.5]},
    EventKind.ANSWER: {"kind": "answer", "seq": 4, "t_s": 0.3, "answer": {"object": "pmma", "posterior": 0.9}},
}


def _frames(data: bytes):
    return FrameDecoder().feed(data)


def test_every_event_kind_has_a_spec_and_round_trips():
    assert set(EVENTS) == set(EventKind) == set(VALID)
    for kind, body in VALID.items():
        (frame,) = _frames(encode_event(42, body))
        assert frame.msg_type == MsgType.EVENT == 0xFE and is_event(frame)
        ev = decode_event(frame)
        assert ev.request_id == 42 and ev.kind == kind and ev.body["seq"] == body["seq"]
    # Done carries the record's id and the counts; a newer device's extra keys are kept.
    done = {"kind": "phase", "seq": 9, "t_s": 2.5, "phase": "done", "measurement_id": 7, "status": "ok",
            "events_sent": 9, "events_dropped": 0, "extra": 1}
    assert decode_event(_frames(encode_event(1, done))[0]).body == done


@pytest.mark.parametrize("change, field", [
    ({"kind": "nope"}, "kind"),
    ({"phase": "boiling"}, "phase"),
    ({"seq": -1}, "seq"),
    ({"t_s": None}, "t_s"),
])
def test_a_bad_phase_event_is_refused_naming_the_field(change, field):
    body = {**VALID[EventKind.PHASE], **change}
    with pytest.raises(ProtocolError) as e:
        encode_event(1, body)
    assert e.value.field == field and e.value.code == ErrorCode.INTERNAL  # the device's own bug


def test_sample_batches_are_bounded_and_aligned():
    body = dict(VALID[EventKind.SAMPLES])
    with pytest.raises(ProtocolError, match="differ in length"):
        encode_event(1, {**body, "T_C": [25.0]})
    n = MAX_EVENT_SAMPLES + 1
    with pytest.raises(ProtocolError):
        encode_event(1, {**body, "sample_t_s": [0.0] * n, "T_C": [0.0] * n, "q_W_m2": [0.0] * n})


def test_an_event_is_no_reply_and_a_reply_no_event():
    (frame,) = _frames(encode_event(5, VALID[EventKind.PHASE]))
    with pytest.raises(ProtocolError):
        decode_reply(frame)
    from edge.protocol.messages import encode_reply

    (reply,) = _frames(encode_reply(Command.PING, 5, {"echo": None}))
    assert not is_event(reply)
    with pytest.raises(ProtocolError) as e:
        decode_event(reply)
    assert e.value.code == ErrorCode.BAD_FRAME


def test_measure_takes_stream_and_the_phase_words_are_the_documented_ones():
    from edge.protocol.commands import validate_args

    assert validate_args(Command.MEASURE, {"stream": True}) == {"stream": True}
    with pytest.raises(ProtocolError):
        validate_args(Command.MEASURE, {"stream": "yes"})
    assert EVENT_PHASES[-1] == "done" and {"armed", "contact", "heating"} <= set(EVENT_PHASES)


class StuckPort:
    """A port whose writes block until released, then time out (a host that stopped reading)."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.written: list[bytes] = []
        self.timeout = self.write_timeout = None

    def read(self, n=1):
        return b""

    def write(self, data):
        self.release.wait(5.0)
        raise type("SerialTimeoutException", (Exception,), {})("write timeout")


def test_events_fill_only_their_share_of_the_queue_and_replies_still_fit():
    port = StuckPort()
    ep = SerialEndpoint(port, max_pending_bytes=8192, max_event_bytes=2048, write_timeout_s=0.05)
    body = {**VALID[EventKind.SAMPLES], "sample_t_s": [0.1] * 40, "T_C": [25.0] * 40, "q_W_m2": [1.0] * 40}
    sent = [ep.send_event(1, body) for _ in range(50)]
    assert sent[0] and not all(sent)
    assert ep.events_dropped == sent.count(False) and ep.events_sent == sent.count(True)
    assert ep.replies_dropped == 0
    # The reply to the same request still finds room: events never crowd it out.
    ep.send_reply(Request(Command.PING, 2), {"echo": "x"})
    assert ep.replies_dropped == 0
    port.release.set()
    ep.close(timeout_s=1.0)


def test_an_event_not_taken_in_time_drops_the_events_behind_it_but_not_the_reply():
    port = StuckPort()
    port.release.set()  # every write times out at once
    ep = SerialEndpoint(port, write_timeout_s=0.05)
    for _ in range(5):
        ep.send_event(1, VALID[EventKind.PHASE])
    ep.send_reply(Request(Command.PING, 2), {"echo": "x"})
    assert ep.flush(2.0)
    assert ep.events_sent == 5 and ep.events_dropped == 5
    assert ep.replies_dropped == 1  # the reply was tried (and timed out itself), not dropped with the events
    ep.close(timeout_s=0.5)


@pytest.mark.shares_import("hypothesis")
def test_decode_event_on_arbitrary_payload_raises_only_protocol_error():
    # Hypothesis imported where this runs, not at collection in every xdist worker (see tests/edge/protocol/test_fuzz.py).
    from hypothesis import given, settings
    from hypothesis import strategies as st

    @settings(max_examples=80, deadline=None, derandomize=True)
    @given(payload=st.one_of(st.binary(max_size=200), st.builds(
               lambda kind, seq, extra: json.dumps({"kind": kind, "seq": seq, **extra}).encode(),
               st.sampled_from(["phase", "samples", "answer", "x", ""]), st.integers(-2, 3),
               st.dictionaries(st.sampled_from(["t_s", "phase", "sample_t_s", "T_C", "q_W_m2", "answer"]),
                               st.one_of(st.none(), st.floats(allow_nan=False), fuzz_text(max_size=5),
                                         st.lists(st.floats(allow_nan=False, allow_infinity=False), max_size=3)),
                               max_size=6))),
           rid=st.integers(0, 2**32 - 1))
    def prop(payload, rid):
        try:
            ev = decode_event(Frame(MsgType.EVENT, rid, payload))
        except ProtocolError as exc:
            assert exc.request_id == rid
        else:
            assert ev.request_id == rid and ev.kind in set(EventKind)

    prop()
