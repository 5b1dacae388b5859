"""NullModem byte transparency and request/reply through edge/link.py + host/client.py."""

import hashlib
import os
import threading
import time

import pytest
import serial

from edge.protocol.endpoint import SerialEndpoint
from edge.protocol.commands import Command
from edge.protocol.errors import CommandError, ErrorCode
from edge.protocol.frame import FrameDecoder, encode_frame
from edge.protocol.cobs import cobs_encode
from edge.protocol.messages import decode_reply, encode_request
from firmware_sim.clock import VirtualClock
from firmware_sim.ptylink import NullModem
from host.client import (
    BadReply,
    DeviceClient,
    DeviceError,
    DeviceNotAnswering,
    PortUnavailable,
)
from tests.support.waiting import wait_until


def _open_fds() -> set[str]:
    return set(os.listdir("/proc/self/fd"))


def _leaked_fds(before: set[str]) -> set[str]:
    """Descriptors opened since ``before`` and still open. (Not equality with ``before``: an earlier
    test's object that the garbage collector or a finishing thread closes meanwhile is not a leak here.)"""
    return _open_fds() - before


def _read_exactly(ser, n, limit_s=5.0):
    buf = bytearray()
    end = time.monotonic() + limit_s
    while len(buf) < n and time.monotonic() < end:
        buf += ser.read(n - len(buf))
    return bytes(buf)


# ---------------------------------------------------------------- the cable

def test_all_byte_values_pass_both_ways():
    with NullModem() as nm:
        assert nm.device_port.startswith("/dev/pts/") and nm.host_port.startswith("/dev/pts/")
        dev = serial.Serial(nm.device_port, 115200, timeout=0.5)
        host = serial.Serial(nm.host_port, 115200, timeout=0.5)
        try:
            data = bytes(range(256)) + b"\r\n\n\r\x11\x13\x00\x03\x04\x1a\x7f" + bytes(range(255, -1, -1))
            host.write(data)
            assert _read_exactly(dev, len(data)) == data
            dev.write(data)
            assert _read_exactly(host, len(data)) == data
            # nothing extra (e.g. an echo) arrives on either side
            host.timeout = dev.timeout = 0.05
            assert dev.read(10) == b"" and host.read(10) == b""
        finally:
            dev.close()
            host.close()
        assert nm.bytes_to_device == nm.bytes_to_host == len(data)


def test_bulk_transfer_with_backpressure():
    payload = bytes((i * 7919) % 256 for i in range(200_000))
    with NullModem() as nm:
        dev = serial.Serial(nm.device_port, timeout=0.5)
        host = serial.Serial(nm.host_port, timeout=0.5)
        try:
            writer = threading.Thread(target=host.write, args=(payload,))
            writer.start()
            got = _read_exactly(dev, len(payload), limit_s=20)
            writer.join(10)
            assert got == payload
        finally:
            dev.close()
            host.close()


def test_close_releases_fds_threads_and_ports():
    # Threads by identity, not a count: an earlier test's thread that ends meanwhile (later on a
    # loaded machine) is not this test's business.
    threads_before = set(threading.enumerate())
    fds_before = _open_fds()
    nm = NullModem()
    ports = (nm.device_port, nm.host_port)
    dev = serial.Serial(nm.device_port, timeout=0.1)
    client = DeviceClient(nm.host_port, timeout_s=0.1)
    started = set(threading.enumerate()) - threads_before
    assert len(started) == 1  # the cable's bridge
    client.close()
    dev.close()
    nm.close()
    nm.close()  # idempotent
    assert nm.closed
    assert not any(t.is_alive() for t in started)
    assert not _leaked_fds(fds_before)
    assert not any(os.path.exists(p) for p in ports)


def test_port_reopen_keeps_link_working():
    with NullModem() as nm:
        dev = serial.Serial(nm.device_port, timeout=0.5)
        for _ in range(2):
            host = serial.Serial(nm.host_port, timeout=0.5)
            host.write(b"\x00abc\x00")
            assert _read_exactly(dev, 5) == b"\x00abc\x00"
            host.close()
        dev.close()


# ---------------------------------------------------------------- request/reply

class ToyDevice:
    """A minimal handler exercising every reply path."""

    def __init__(self):
        self.config = {"heater.power_W": 0.5}
        self.model = None
        self.upload = None
        self.seen = []
        self.fail_chunk_at = None
        #: A PING "slow" is answered once this is set (the test sets it once its client has given up).
        self.slow_release = threading.Event()

    def __call__(self, req):
        self.seen.append(req.command)
        c, a = req.command, req.args
        if c == Command.PING:
            if a.get("echo") == "slow":
                self.slow_release.wait(5.0)
            if a.get("echo") == "crash":
                raise RuntimeError("boom")
            if a.get("echo") == "badreply":
                return {"echo": 42}
            return {"echo": a.get("echo")}
        if c == Command.INFO:
            return {"protocol_version": 1, "firmware_version": "0.1.0", "model_version": None,
                    "model_sha256": None, "board": "toy"}
        if c == Command.STATUS:
            return {"state": "idle", "uptime_s": 1.0}
        if c == Command.MEASURE:
            if a.get("power_W", 0) > 10:
                raise CommandError(ErrorCode.BUSY, "heater cooling down")
            return {"measurement_id": 1, "power_W": a.get("power_W"), "k_W_mK": 1.1}
        if c == Command.RESULT:
            if a.get("measurement_id", 1) != 1:
                raise CommandError(ErrorCode.NOT_FOUND, "no such measurement", "measurement_id")
            return {"measurement_id": 1}
        if c == Command.HISTORY:
            return {"offset": a["offset"], "total": 1, "items": [{"measurement_id": 1}][a["offset"]:]}
        if c == Command.CONFIG_GET:
            return {"config": dict(self.config)}
        if c == Command.CONFIG_SET:
            self.config.update(a["values"])
            return {"config": dict(self.config)}
        if c == Command.MODEL_BEGIN:
            self.upload = {"size": a["size"], "sha256": a["sha256"], "data": bytearray()}
            return {"size": a["size"]}
        if c == Command.MODEL_CHUNK:
            if self.upload is None:
                raise CommandError(ErrorCode.BAD_STATE, "no upload in progress")
            if a["offset"] == self.fail_chunk_at:
                raise CommandError(ErrorCode.INTERNAL, "flash write failed")
            if a["offset"] != len(self.upload["data"]):
                raise CommandError(ErrorCode.BAD_ARGUMENT, "offset out of order", "offset")
            self.upload["data"] += a["data"]
            return {"received": len(self.upload["data"])}
        if c == Command.MODEL_COMMIT:
            up, self.upload = self.upload, None
            digest = hashlib.sha256(up["data"]).hexdigest()
            if len(up["data"]) != up["size"] or digest != up["sha256"]:
                raise CommandError(ErrorCode.MODEL_REJECTED, "sha256 mismatch")
            self.model = bytes(up["data"])
            return {"model_sha256": digest}
        if c == Command.MODEL_ABORT:
            self.upload = None
            return {}
        raise AssertionError(c)


@pytest.fixture
def link_clock():
    """The served endpoint's clock: it stands still unless a test advances it.

    A request frame split by the cable's bridge thread (held up on a loaded machine) would
    otherwise be discarded as a partial frame after ``partial_timeout_s`` of wall time; here a
    partial frame is timed out only where a test says the silence has lasted.
    """
    return VirtualClock()


@pytest.fixture
def link(link_clock):
    """NullModem with a ToyDevice served on the device end; yields (nm, endpoint, device)."""
    fds_before = _open_fds()
    nm = NullModem()
    dev_ser = serial.Serial(nm.device_port, 115200)
    endpoint = SerialEndpoint(dev_ser, partial_timeout_s=0.05, poll_s=0.01, clock=link_clock.monotonic)
    device = ToyDevice()
    stop = threading.Event()
    thread = threading.Thread(target=endpoint.serve, args=(device, stop), daemon=True)
    thread.start()
    try:
        yield nm, endpoint, device
    finally:
        stop.set()
        thread.join(5)
        assert not thread.is_alive()
        dev_ser.close()
        nm.close()
        assert not _leaked_fds(fds_before)


def test_client_convenience_methods(link):
    nm, endpoint, device = link
    with DeviceClient(nm.host_port, timeout_s=2.0) as dev:
        assert dev.ping("hi") == {"echo": "hi"}
        assert dev.info()["board"] == "toy"
        assert dev.status()["state"] == "idle"
        rec = dev.measure(power_W=0.5, contact_time_s=2.0)
        assert rec == {"measurement_id": 1, "power_W": 0.5, "k_W_mK": 1.1}
        assert dev.result()["measurement_id"] == 1
        assert dev.history(0, 10) == {"offset": 0, "total": 1, "items": [{"measurement_id": 1}]}
        assert dev.config_set(**{"heater.power_W": 0.7}) == {"heater.power_W": 0.7}
        assert dev.config_get() == {"heater.power_W": 0.7}
        assert dev.request("PING", {"echo": "by name"}) == {"echo": "by name"}
        assert dev._next_id == 10  # ids 1..9 used, one per request
    assert endpoint.requests_handled == 9


def test_device_errors_become_exceptions_and_loop_survives(link):
    nm, endpoint, device = link
    with DeviceClient(nm.host_port, timeout_s=2.0) as dev:
        with pytest.raises(DeviceError) as ei:
            dev.measure(power_W=20)
        assert ei.value.code == ErrorCode.BUSY and ei.value.command == Command.MEASURE
        with pytest.raises(DeviceError) as ei:
            dev.result(5)
        assert ei.value.code == ErrorCode.NOT_FOUND and ei.value.field == "measurement_id"
        with pytest.raises(DeviceError) as ei:
            dev.ping("crash")
        assert ei.value.code == ErrorCode.INTERNAL and "RuntimeError: boom" in ei.value.message
        with pytest.raises(DeviceError) as ei:
            dev.ping("badreply")
        assert ei.value.code == ErrorCode.INTERNAL and ei.value.field == "echo"
        assert dev.ping("still alive") == {"echo": "still alive"}
    assert endpoint.errors_sent == 4


def test_invalid_args_rejected_locally_and_by_device(link):
    nm, endpoint, device = link
    with DeviceClient(nm.host_port, timeout_s=2.0) as dev:
        with pytest.raises(ValueError) as ei:
            dev.history(limit=1000)
        assert ei.value.field == "limit"
        # Bypass client validation: the device must reject it with BAD_ARGUMENT.
        dev.ser.write(encode_frame(Command.HISTORY, 99, b'{"limit":1000}'))
        dev.ser.write(encode_frame(0x42, 100, b""))
        dev.ser.write(encode_frame(Command.PING, 101, b"{oops"))
        replies = []
        dec = FrameDecoder()
        end = time.monotonic() + 5
        while len(replies) < 3 and time.monotonic() < end:
            replies += [decode_reply(f) for f in dec.feed(dev.ser.read(1))]
        assert [(r.request_id, r.code, r.field) for r in replies] == [
            (99, ErrorCode.BAD_ARGUMENT, "limit"),
            (100, ErrorCode.UNKNOWN_COMMAND, "msg_type"),
            (101, ErrorCode.BAD_FRAME, "payload")]
    assert Command.HISTORY not in device.seen


def test_garbage_and_partial_frames_do_not_stop_device(link, link_clock):
    nm, endpoint, device = link
    with DeviceClient(nm.host_port, timeout_s=2.0) as dev:
        dev.ser.write(bytes(range(1, 256)) * 40)  # 10 kB of noise, no delimiter: oversize
        dev.ser.write(b"\x00\x13\x11\r\n\x00")
        assert dev.ping("after noise") == {"echo": "after noise"}
        # Half a frame, then silence longer than partial_timeout_s, then a
        # frame *without* its leading delimiter: only the timeout separates them.
        half = encode_request(Command.PING, 500, {"echo": "lost"})
        half = half[: len(half) // 2]
        assert half[:1] == b"\x00" and b"\x00" not in half[1:]  # a delimiter, then half a frame's bytes
        dev.ser.write(half)
        wait_until(lambda: endpoint.decoder.pending == len(half) - 1, "the half frame to arrive")
        link_clock.advance(2 * endpoint.partial_timeout_s)  # the silence
        wait_until(lambda: endpoint.stats.timeouts == 1, "the endpoint to time the half frame out")
        rid = dev._new_id()
        dev.ser.write(encode_request(Command.PING, rid, {"echo": "x"})[1:])
        assert dev._await(rid, Command.PING, 2.0) == {"echo": "x"}
    stats = endpoint.stats
    assert stats.oversize >= 1 and stats.timeouts == 1 and stats.bytes_dropped >= 10_200


def test_model_upload_in_chunks(link):
    nm, endpoint, device = link
    blob = bytes((i * 31 + 7) % 256 for i in range(10_000))
    progress = []
    with DeviceClient(nm.host_port, timeout_s=2.0) as dev:
        res = dev.upload_model(blob, hashlib.sha256(blob).hexdigest(), chunk_size=3000,
                               progress=lambda sent, total: progress.append((sent, total)))
        assert res["model_sha256"] == hashlib.sha256(blob).hexdigest()
        assert device.model == blob
        assert progress == [(3000, 10000), (6000, 10000), (9000, 10000), (10000, 10000)]
        # default chunk size is the largest that fits a frame
        dev.upload_model(blob)
        assert device.seen.count(Command.MODEL_CHUNK) == 4 + 3
        with pytest.raises(ValueError, match="sha256"):
            dev.upload_model(blob, "0" * 64)
        with pytest.raises(ValueError, match="chunk_size"):
            dev.upload_model(blob, chunk_size=5000)


def test_failed_upload_sends_abort(link):
    nm, endpoint, device = link
    with DeviceClient(nm.host_port, timeout_s=2.0) as dev:
        dev.request(Command.MODEL_BEGIN, {"size": 10, "sha256": "0" * 64})
        with pytest.raises(DeviceError) as ei:
            dev.request(Command.MODEL_COMMIT)
        assert ei.value.code == ErrorCode.MODEL_REJECTED
        device.fail_chunk_at = 2
        device_calls = len(device.seen)
        with pytest.raises(DeviceError, match="flash write failed"):
            dev.upload_model(b"abcd", chunk_size=1)
        assert device.seen[device_calls:] == [Command.MODEL_BEGIN] + [Command.MODEL_CHUNK] * 3 + [
            Command.MODEL_ABORT]
        assert device.upload is None and device.model is None


def test_stale_reply_is_skipped(link):
    nm, endpoint, device = link
    # The device holds "slow" until it is released below, so the client's timeout expires whatever its length.
    with DeviceClient(nm.host_port, timeout_s=0.02, retries=0) as dev:
        with pytest.raises(DeviceNotAnswering) as ei:
            dev.ping("slow")
        assert ei.value.attempts == 1
        device.slow_release.set()  # the device answers "slow" only now, after the client gave up
        # The device is still busy with "slow"; its late reply must be skipped.
        assert dev.request(Command.PING, {"echo": "next"}, timeout_s=3.0) == {"echo": "next"}
        assert dev.stale_replies == 1


def test_no_device_raises_not_answering():
    # Nothing answers, so every attempt waits out its timeout: short ones (and a read poll to match),
    # the client's own parameters; the attempts counted are the same at any length.
    timeout_s, abort_timeout_s = 0.02, 0.06
    with NullModem() as nm:
        with DeviceClient(nm.host_port, timeout_s=timeout_s, retries=2, abort_timeout_s=abort_timeout_s,
                          poll_s=0.005) as dev:
            with pytest.raises(DeviceNotAnswering) as ei:
                dev.info()
            assert ei.value.attempts == 3 and ei.value.command == Command.INFO
            # non-idempotent commands are not resent; the ABORT that follows a lost MEASURE
            # is tried within its own deadline and then the original error stands
            t0 = time.monotonic()
            with pytest.raises(DeviceNotAnswering) as ei:
                dev.measure(timeout_s=timeout_s)
            assert ei.value.attempts == 1 and ei.value.command == Command.MEASURE
            assert dev.last_abort is None
            assert time.monotonic() - t0 < timeout_s + abort_timeout_s + 2.0  # a deadline, not a speed figure


def test_port_unavailable():
    with pytest.raises(PortUnavailable) as ei:
        DeviceClient("/dev/does-not-exist-thermotouch")
    assert ei.value.port == "/dev/does-not-exist-thermotouch"
    with NullModem() as nm:
        with DeviceClient(nm.host_port, timeout_s=0.1):
            with pytest.raises(PortUnavailable, match="lock"):
                DeviceClient(nm.host_port, timeout_s=0.1)


def test_bad_reply_from_device_is_reported():
    with NullModem() as nm:
        dev_ser = serial.Serial(nm.device_port, timeout=0.5)
        try:
            with DeviceClient(nm.host_port, timeout_s=1.0) as client:
                # The "device" answers STATUS without the required 'state'.
                def fake():
                    dec = FrameDecoder()
                    frames = []
                    while not frames:
                        frames = dec.feed(dev_ser.read(1))
                    dev_ser.write(encode_frame(Command.STATUS | 0x80, frames[0].request_id, b"{}"))
                t = threading.Thread(target=fake)
                t.start()
                with pytest.raises(BadReply, match="state"):
                    client.status()
                t.join(5)
        finally:
            dev_ser.close()


def test_endpoint_rejects_bad_settings():
    with pytest.raises(ValueError, match="partial_timeout_s"):
        SerialEndpoint(object(), partial_timeout_s=0)
    with pytest.raises(ValueError, match="timeout_s"):
        DeviceClient(object(), timeout_s=0)
    assert cobs_encode(b"") == b"\x01"
