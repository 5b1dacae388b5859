"""A virtual null-modem cable made of two pseudo-terminals.

Each end is the slave side of its own pty, so both are real tty paths
(``/dev/pts/N``) that pyserial opens like a USB-serial adapter.  A thread
copies bytes between the two master sides.  Both ttys are put in raw mode so
every byte value (0x00, XON/XOFF, CR/LF, ...) passes unaltered.

Usage::

    with NullModem() as nm:
        device = serial.Serial(nm.device_port, timeout=0.1)
        host = serial.Serial(nm.host_port, timeout=0.1)

Linux-only (uses ``os.openpty`` and ``termios``).
"""

from __future__ import annotations

import errno
import os
import select
import termios
import threading
import tty

__all__ = ["NullModem"]

# Bytes buffered per direction before the bridge stops reading the source;
# beyond that the writer sees the pty fill up, as with a real flow-controlled line.
_PENDING_LIMIT = 64 * 1024
_READ_SIZE = 4096


def _make_raw(fd: int) -> None:
    """Put a tty into raw 8-bit mode: no echo, no CR/LF mapping, no XON/XOFF."""
    tty.setraw(fd, termios.TCSANOW)
    attrs = termios.tcgetattr(fd)
    # setraw leaves IXANY/IXOFF alone on some versions; clear all flow-control
    # and input-mapping bits explicitly so 0x11/0x13/0x0d reach the reader.
    attrs[0] &= ~(termios.IXON | termios.IXOFF | termios.IXANY | termios.ICRNL | termios.INLCR
                  | termios.IGNCR | termios.ISTRIP | termios.BRKINT | termios.PARMRK | termios.INPCK)
    attrs[1] &= ~termios.OPOST
    attrs[3] &= ~(termios.ECHO | termios.ECHONL | termios.ICANON | termios.ISIG | termios.IEXTEN)
    attrs[2] = (attrs[2] & ~(termios.CSIZE | termios.PARENB)) | termios.CS8 | termios.CREAD | termios.CLOCAL
    attrs[6][termios.VMIN] = 1
    attrs[6][termios.VTIME] = 0
    termios.tcsetattr(fd, termios.TCSANOW, attrs)


class NullModem:
    """Two ptys bridged back to back; ``device_port`` and ``host_port`` are tty paths.

    The object owns four pty fds, a wake-up pipe and one bridge thread; all
    are released by :meth:`close` (or leaving the ``with`` block).  The slave
    fds stay open for the modem's lifetime so that the masters never see a
    hang-up when a pyserial user closes and reopens a port.
    """

    def __init__(self) -> None:
        self._fds: list[int] = []
        self._thread: threading.Thread | None = None
        self._closed = False
        self.bytes_to_host = 0    # counters, for tests and diagnostics
        self.bytes_to_device = 0
        try:
            self._dev_master, self._dev_slave = self._openpty()
            self._host_master, self._host_slave = self._openpty()
            self.device_port: str = os.ttyname(self._dev_slave)
            self.host_port: str = os.ttyname(self._host_slave)
            self._wake_r, self._wake_w = os.pipe()
            self._fds += [self._wake_r, self._wake_w]
            for fd in (self._dev_master, self._host_master, self._wake_r):
                os.set_blocking(fd, False)
        except BaseException:
            self._close_fds()
            raise
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._bridge, name="NullModem-bridge", daemon=True)
        self._thread.start()

    def _openpty(self) -> tuple[int, int]:
        master, slave = os.openpty()
        self._fds += [master, slave]
        _make_raw(slave)
        return master, slave

    # -- lifecycle ---------------------------------------------------------

    def __enter__(self) -> "NullModem":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # last-resort cleanup; close() is the API
        try:
            self.close()
        except Exception:
            pass

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Stop the bridge thread and close every fd; safe to call twice."""
        if self._closed:
            return
        self._closed = True
        if self._thread is not None:
            self._stop.set()
            try:
                os.write(self._wake_w, b"x")
            except OSError:
                pass
            self._thread.join(timeout=5.0)
            if self._thread.is_alive():  # pragma: no cover - would be a bridge bug
                raise RuntimeError("NullModem bridge thread did not stop")
        self._close_fds()

    def _close_fds(self) -> None:
        while self._fds:
            fd = self._fds.pop()
            try:
                os.close(fd)
            except OSError:
                pass

    # -- bridge --------------------------------------------------------------

    def _bridge(self) -> None:
        dev, host = self._dev_master, self._host_master
        # pending[src] holds bytes read from src not yet written to its peer.
        pending = {dev: bytearray(), host: bytearray()}
        peer = {dev: host, host: dev}
        while not self._stop.is_set():
            readers = [self._wake_r] + [fd for fd in (dev, host) if len(pending[fd]) < _PENDING_LIMIT]
            writers = [peer[fd] for fd in (dev, host) if pending[fd]]
            try:
                rlist, _, _ = select.select(readers, writers, [], 1.0)
            except InterruptedError:  # pragma: no cover
                continue
            if self._wake_r in rlist:
                break
            for src in (dev, host):
                if src in rlist:
                    try:
                        data = os.read(src, _READ_SIZE)
                    except BlockingIOError:
                        data = b""
                    except OSError as exc:
                        # EIO means no slave is open; cannot happen while we
                        # hold the slaves, but never spin on it.
                        if exc.errno != errno.EIO:
                            raise
                        data = b""
                    pending[src] += data
                dst = peer[src]
                if pending[src]:
                    try:
                        n = os.write(dst, pending[src])
                    except BlockingIOError:
                        n = 0
                    if n:
                        if src == dev:
                            self.bytes_to_host += n
                        else:
                            self.bytes_to_device += n
                        del pending[src][:n]
