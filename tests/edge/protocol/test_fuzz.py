"""Property tests: the frame decoder never crashes, stays bounded and resynchronises.

Hypothesis is imported where a test runs, not at the module's top: collection imports every test
module in both xdist workers, and Hypothesis there costs each of them ~0.1 CPU-s to import plus
~0.12 s (1 s without a .hypothesis cache) for its plugin's scan of the project's sources for
constants, before either runs a test. The worker that runs these tests pays that once (they share
one worker: ``shares_import``, tests/support/schedule.py). Each test runs its property -- same
strategies, same settings -- through a ``@given`` function it calls.
"""

import pytest

from edge.protocol.commands import Command
from edge.protocol.frame import Frame, FrameDecoder, encode_frame, max_encoded_size
from edge.protocol.errors import ProtocolError
from edge.protocol.messages import decode_reply, decode_request
from tests.support.fuzz_text import text as fuzz_text

pytestmark = pytest.mark.shares_import("hypothesis")

MAX_PAYLOAD = 256


def _fuzz():
    """The fuzzing settings: 150 derandomized examples, no deadline."""
    from hypothesis import HealthCheck, settings

    return settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


def _frames_st():
    """A frame's (type, request id, payload), the payload within the decoder's bound."""
    from hypothesis import strategies as st

    return st.builds(lambda t, rid, payload: (t, rid, payload),
                     st.integers(0, 255), st.integers(0, 2**32 - 1), st.binary(max_size=MAX_PAYLOAD))


def _split(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts})
    pieces, prev = [], 0
    for p in points + [len(data)]:
        pieces.append(data[prev:p])
        prev = p
    return pieces


def _feed_all(decoder: FrameDecoder, data: bytes, cuts: list[int]) -> list[Frame]:
    out = []
    for piece in _split(data, cuts):
        out += decoder.feed(piece)
        assert decoder.pending <= max_encoded_size(decoder.max_payload) + 1
    return out


def test_random_bytes_never_crash_and_stay_bounded():
    from hypothesis import given, strategies as st

    @_fuzz()
    @given(noise=st.binary(max_size=2000), cuts=st.lists(st.integers(0, 5000), max_size=8))
    def prop(noise, cuts):
        d = FrameDecoder(MAX_PAYLOAD)
        frames = _feed_all(d, noise, cuts)
        # Whatever came out passed the CRC; parsing it must fail only with ProtocolError.
        for f in frames:
            for parse in (decode_request, decode_reply):
                try:
                    parse(f)
                except ProtocolError:
                    pass
        assert d.stats.frames == len(frames)

    prop()


def test_resync_after_noise():
    from hypothesis import given, strategies as st

    @_fuzz()
    @given(noise=st.binary(max_size=1500), frame=_frames_st(), cuts=st.lists(st.integers(0, 5000), max_size=8))
    def prop(noise, frame, cuts):
        t, rid, payload = frame
        d = FrameDecoder(MAX_PAYLOAD)
        out = _feed_all(d, noise + encode_frame(t, rid, payload, max_payload=MAX_PAYLOAD), cuts)
        assert out and out[-1] == Frame(t, rid, payload)

    prop()


def test_mutated_frame_then_valid_frame():
    from hypothesis import given, strategies as st

    @_fuzz()
    @given(frame=_frames_st(), follow=_frames_st(), data=st.data())
    def prop(frame, follow, data):
        wire = bytearray(encode_frame(*frame, max_payload=MAX_PAYLOAD))
        n_mut = data.draw(st.integers(1, 6), label="n_mut")
        for _ in range(n_mut):
            op = data.draw(st.sampled_from(["flip", "set", "insert", "delete", "truncate"]), label="op")
            if not wire:
                break
            i = data.draw(st.integers(0, len(wire) - 1), label="index")
            if op == "flip":
                wire[i] ^= 1 << data.draw(st.integers(0, 7), label="bit")
            elif op == "set":
                wire[i] = data.draw(st.integers(0, 255), label="byte")
            elif op == "insert":
                wire.insert(i, data.draw(st.integers(0, 255), label="byte"))
            elif op == "delete":
                del wire[i]
            else:
                del wire[i:]
        good = encode_frame(*follow, max_payload=MAX_PAYLOAD)
        d = FrameDecoder(MAX_PAYLOAD)
        cuts = data.draw(st.lists(st.integers(0, 5000), max_size=6), label="cuts")
        out = _feed_all(d, bytes(wire) + good, cuts)
        assert out and out[-1] == Frame(*follow)
        # A mutated frame passes only if it is byte-identical to some valid frame;
        # CRC-32 makes anything else astronomically unlikely.
        assert len(out) <= 2

    prop()


def test_oversize_frames_dropped_then_resync():
    from hypothesis import given, strategies as st

    @_fuzz()
    @given(overlong=st.integers(MAX_PAYLOAD + 1, 4 * MAX_PAYLOAD), frame=_frames_st())
    def prop(overlong, frame):
        d = FrameDecoder(MAX_PAYLOAD)
        big = encode_frame(1, 1, bytes([7]) * overlong, max_payload=4096)
        out = d.feed(big + encode_frame(*frame, max_payload=MAX_PAYLOAD))
        assert out == [Frame(*frame)]
        assert d.stats.oversize == 1

    prop()


def test_decode_request_on_arbitrary_payload_raises_only_protocol_error():
    from hypothesis import given, strategies as st

    @_fuzz()
    @given(payload=st.binary(max_size=300), rid=st.integers(0, 2**32 - 1),
           msg_type=st.sampled_from([int(c) for c in Command] + [0x00, 0x7F, 0x80, 0x99, 0xFF]))
    def prop(payload, rid, msg_type):
        try:
            req = decode_request(Frame(msg_type, rid, payload))
        except ProtocolError as exc:
            assert exc.request_id == rid
        else:
            assert req.request_id == rid and req.command == msg_type

    prop()


def test_decode_request_on_json_like_text():
    from hypothesis import given, strategies as st

    @_fuzz()
    @given(text=fuzz_text(max_size=60), rid=st.integers(1, 1000),
           command=st.sampled_from([c for c in Command if c != Command.MODEL_CHUNK]))
    def prop(text, rid, command):
        for payload in (text, '{"' + text + '":1}', '{"limit":' + text + "}"):
            try:
                decode_request(Frame(command, rid, payload.encode("utf-8")))
            except ProtocolError as exc:
                assert exc.request_id == rid

    prop()


def test_fuzz_bound_is_meaningful():
    # The oversize strategy above must really exceed the bound.
    assert max_encoded_size(MAX_PAYLOAD) < 4 * MAX_PAYLOAD
    with pytest.raises(ProtocolError):
        encode_frame(1, 1, bytes(MAX_PAYLOAD + 1), max_payload=MAX_PAYLOAD)

