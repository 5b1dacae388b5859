"""The host's serial client against a scripted port: what the terminal calls may throw."""

import errno

import pytest

termios = pytest.importorskip("termios")

from edge.protocol.commands import Command  # noqa: E402
from edge.protocol.frame import FrameDecoder  # noqa: E402
from edge.protocol.messages import decode_request, encode_reply  # noqa: E402
from host.client import TTY_EINTR_ATTEMPTS, DeviceClient, PortUnavailable  # noqa: E402


class ScriptedPort:
    """A pyserial-like port that answers PING; ``flush`` and ``reset_input_buffer`` raise from a script.

    ``failures[name]`` is a list of exceptions the call raises, one per call, before it succeeds.
    """

    def __init__(self, **failures):
        self.failures = {k: list(v) for k, v in failures.items()}
        self.calls = {"flush": 0, "reset_input_buffer": 0}
        self.timeout = None
        self.port = "scripted"
        self._decoder = FrameDecoder()
        self._out = b""

    def _maybe_fail(self, name):
        self.calls[name] += 1
        if self.failures.get(name):
            raise self.failures[name].pop(0)

    def reset_input_buffer(self):
        self._maybe_fail("reset_input_buffer")

    def flush(self):
        self._maybe_fail("flush")

    def write(self, data):
        for frame in self._decoder.feed(data):
            req = decode_request(frame)
            self._out += encode_reply(Command.PING, req.request_id, {"echo": req.args.get("echo", "")})
        return len(data)

    @property
    def in_waiting(self):
        return len(self._out)

    def read(self, n=1):
        data, self._out = self._out[:n], self._out[n:]
        return data

    def close(self):
        pass


def _eintr():
    return termios.error(errno.EINTR, "Interrupted system call")


def test_a_signal_during_the_drain_or_the_input_reset_is_retried():
    # tcdrain/tcflush are not retried by Python on EINTR; before, this ended the command as an
    # internal error (seen when a signal reached `thermotouch measure` while it drained the line).
    port = ScriptedPort(flush=[_eintr(), _eintr()], reset_input_buffer=[_eintr()])
    client = DeviceClient(port, timeout_s=1.0)
    assert client.ping("hi") == {"echo": "hi"}
    assert port.calls == {"flush": 3, "reset_input_buffer": 2}


def test_other_terminal_failures_and_endless_interruptions_make_the_port_unavailable():
    with pytest.raises(PortUnavailable, match="terminal call failed.*Input/output error"):
        DeviceClient(ScriptedPort(reset_input_buffer=[termios.error(errno.EIO, "Input/output error")]))
    client = DeviceClient(ScriptedPort(flush=[_eintr()] * TTY_EINTR_ATTEMPTS), timeout_s=1.0)
    with pytest.raises(PortUnavailable, match=f"interrupted by signals {TTY_EINTR_ATTEMPTS} times"):
        client.ping()
