"""COBS's vectorised paths (binary frames of many blocks) give the byte-for-byte output of its block loop."""

from __future__ import annotations

import random

import pytest

from edge.protocol import cobs


def _loop_only(monkeypatch):
    """The block loop alone: no frame reaches either vectorised path."""
    monkeypatch.setattr(cobs, "_VECTOR_MIN_ZEROS", 1 << 30)
    monkeypatch.setattr(cobs, "_DECODE_LOOP_BLOCKS", -1)


def _outcome(fn, data):
    try:
        return "ok", fn(data)
    except ValueError as e:
        return "error", str(e)


def _inputs():
    rng = random.Random(11)
    for n in (0, 1, 2, 253, 254, 255, 600, 3000):
        for zero_p in (0.0, 0.05, 0.5, 1.0):
            yield bytes(0 if rng.random() < zero_p else rng.randint(1, 255) for _ in range(n))
    for run in (253, 254, 255, 508, 509):  # runs around the 254-byte block, mid-frame and at its end
        for after in (b"", b"\x00", b"\x00\x00\x07"):
            yield b"\x00\x05" * 9 + bytes([9]) * run + after


@pytest.mark.parametrize("vector_min_zeros, loop_blocks", [(0, 0), (1, 3)])
def test_vectorised_paths_match_the_block_loop(monkeypatch, vector_min_zeros, loop_blocks):
    cases = list(_inputs())
    with monkeypatch.context() as m:
        _loop_only(m)
        expected = [cobs.cobs_encode(d) for d in cases]
        garbage = [e[:-1] for e in expected] + [e + b"\x07" for e in expected] + [bytes([255]) * len(d) for d in cases]
        expected_garbage = [_outcome(cobs.cobs_decode, g) for g in garbage]
    monkeypatch.setattr(cobs, "_VECTOR_MIN_ZEROS", vector_min_zeros)
    monkeypatch.setattr(cobs, "_DECODE_LOOP_BLOCKS", loop_blocks)
    for data, enc in zip(cases, expected):
        assert cobs.cobs_encode(data) == enc
        assert cobs.cobs_decode(enc) == data
    # Malformed frames fail the same way, with the same message (a block past the end, a zero byte).
    assert [_outcome(cobs.cobs_decode, g) for g in garbage] == expected_garbage
    assert any(o[0] == "error" for o in expected_garbage) and any(o[0] == "ok" for o in expected_garbage)
