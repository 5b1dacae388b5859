"""Run the daemon on the sim rig in this process's main thread, as thermotouch-edge does.

Usage: python daemon_proc.py TMPDIR

Prints the host-side port on the first line, ``HEATING`` when the fifth heating
read starts (that read waits in wall time until the heater is cut, so a
signal sent on ``HEATING`` always arrives mid-heating), and at exit one JSON
line with the heater invariant (from the simulated hardware) and the stored
records; the exit status is the one ``thermotouch-edge`` would return.

Like ``thermotouch-edge`` it handles every catchable signal, drives the
heater off at exit, and speaks systemd's notify protocol when
``NOTIFY_SOCKET`` is set. The simulated GPIO line states and PWM tree live
in ``TMPDIR/gpio`` and ``TMPDIR/pwm``
(:func:`firmware_sim.gpiod.state.read_line`), readable after this process
is killed.

``python daemon_proc.py --fork-server FD`` is the same program behind a fork
server (:class:`ForkServer`): one interpreter pays for the imports (~0.5 s,
NumPy's most of it), then forks a child per daemon asked for on the control
socket ``FD``. From its fork on a child is that script's process: it runs
``main()`` to a normal interpreter exit (``atexit``, thread joins, exit status
and all), or dies by the signal the test sends it, just the same; what it
skips is only the re-import. Other test helpers use the same server for their own children:
:meth:`ForkServer.prepare` runs a function in the server itself (what its children should
inherit), :meth:`ForkServer.start_call` runs one in a child.
"""

import gc
import json
import os
import select
import signal
import socket
import sys
import threading
import time
from pathlib import Path

# This checkout's edge and firmware_sim, not whichever one the venv has installed, and the test helpers.
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import serial  # noqa: E402

from tests.support.daemons import FakeEstimator, HookedSensors, sim_config  # noqa: E402
from edge.service.daemon import Daemon  # noqa: E402
from edge.service.main import install_signal_handlers  # noqa: E402
from firmware_sim.rigs.daemon_rig import heater_invariant, make_rig  # noqa: E402
from firmware_sim.ptylink import NullModem  # noqa: E402


def main() -> int:
    tmp = Path(sys.argv[1])
    rig = make_rig(gpio_state_dir=tmp / "gpio", pwm_root=tmp / "pwm")
    cfg = sim_config(tmp)
    stop = threading.Event()
    built = {}
    handlers = install_signal_handlers(stop, heater_off=lambda: built["daemon"].heater.off(),
                                       wake=lambda: built["daemon"].wake() if "daemon" in built else None)
    nm = NullModem()
    port = serial.Serial(nm.device_port, timeout=0.05)
    built["daemon"] = daemon = Daemon(cfg, rig.board, estimator=FakeEstimator(), stop_event=stop)
    daemon.notifier.ready()

    heating_reads = []

    def hook(n, heater_on):
        if heater_on:
            heating_reads.append(n)
        if len(heating_reads) == 5 and heater_on:
            print("HEATING", flush=True)
            t_end = time.monotonic() + 20.0
            while rig.parts.chip.level(rig.parts.heater_enable_offset) == 1 and time.monotonic() < t_end:
                time.sleep(0.005)

    daemon.sensors = HookedSensors(daemon.sensors, daemon.heater, hook)
    print(nm.host_port, flush=True)
    try:
        daemon.serve(port, stop)
    finally:
        daemon.close()
    inv = heater_invariant(rig.parts, cfg.heater.max_on_time_s)
    from edge.storage.history import History

    with History(cfg.paths.history_db) as h:
        _, items = h.page(0, 10)
    print(json.dumps({"invariant": inv, "records": items, "history_closed": daemon.history.closed}), flush=True)
    port.close()
    nm.close()
    return handlers.exit_status()


# ---------------------------------------------------------------------------------------------- fork server

#: Longest a fork-server reply (the child's pid, its exit status) is waited for.
FORK_SERVER_TIMEOUT_s = 30.0
#: Exit status of a ``call`` child whose function returned or raised instead of ending the process.
_EXIT_CALL_RETURNED = 70


def _function(name: str):
    """The function ``"package.module:name"`` names (imported here, in the server or its child)."""
    import importlib

    module, _, attr = name.partition(":")
    return getattr(importlib.import_module(module), attr)


def _serve_forks(ctl_fd: int) -> dict:
    """Fork server loop: returns only in a forked child, with its job (``{"argv": [...]}`` or ``{"code": ...}``).

    Each request on the SOCK_SEQPACKET control socket is one JSON job plus the child's stdin, stdout
    and stderr as passed file descriptors. The server answers the child's pid at once and, when the
    child ends, its exit status (``{"pid", "returncode", "cpu_s"}``, as :attr:`subprocess.Popen.returncode`:
    negative for a signal; with the CPU seconds the child used). Several children may run at a time (each watched through a pidfd); this
    process stays single-threaded, so a fork never inherits a held lock.

    Two more jobs: ``{"prepare": "module:function", "arg": ...}`` calls the function in the server
    itself and answers ``{"ok": true}`` or ``{"error": traceback}`` (no child; children already
    running are not affected); ``{"call": "module:function", "arg": ...}`` forks a child that calls
    ``function(arg, fds)`` with the passed descriptors as they came, and must end the process itself
    (``os._exit`` or a signal).
    """
    ctl = socket.socket(fileno=ctl_fd)
    running: dict[int, int] = {}  # pidfd -> pid of a child not yet reaped
    while True:
        ready, _, _ = select.select([ctl, *running], [], [])
        for pidfd in [fd for fd in ready if fd is not ctl]:
            pid = running.pop(pidfd)
            os.close(pidfd)
            _, status, usage = os.wait4(pid, 0)
            ctl.send(json.dumps({"pid": pid, "returncode": os.waitstatus_to_exitcode(status),
                                 "cpu_s": usage.ru_utime + usage.ru_stime}).encode())
        if ctl not in ready:
            continue
        msg, fds, _, _ = socket.recv_fds(ctl, 1 << 16, 3)
        if not msg:  # the test process has gone
            os._exit(0)
        job = json.loads(msg)
        if "prepare" in job:
            try:
                _function(job["prepare"])(job["arg"])
                # What the preparation left as cyclic garbage (a warmed-up daemon's) is freed now, before the
                # next fork freezes it for good; the walk covers only what was made since that freeze.
                gc.collect()
                reply = {"ok": True}
            except BaseException:  # noqa: BLE001 - the test process reports it
                import traceback

                reply = {"error": traceback.format_exc()[-3000:]}
            ctl.send(json.dumps(reply).encode())
            continue
        sys.stdout.flush()
        sys.stderr.flush()
        # Everything the server holds now goes to the cyclic collector's permanent generation (as Python's
        # gc.freeze documentation advises before a fork): the child's collections, and above all the one
        # at its interpreter's exit, then walk only what the child made, instead of touching -- and so
        # copying, page by page -- the whole inherited heap (a daemon child's exit: ~90 -> ~55 ms of CPU).
        # Only the collector's bookkeeping changes: the child's own objects are collected as before, and
        # an inherited object the child drops is still freed by its reference count.
        gc.freeze()
        pid = os.fork()
        if pid == 0:
            ctl.close()
            for pidfd in running:  # the siblings' watches are the server's business
                os.close(pidfd)
            if "call" in job:
                try:
                    _function(job["call"])(job["arg"], list(fds))
                finally:
                    os._exit(_EXIT_CALL_RETURNED)
            for target, fd in enumerate(fds):
                os.dup2(fd, target)
                os.close(fd)
            if job.get("env") is not None:
                os.environ.clear()
                os.environ.update(job["env"])
            return job
        for fd in fds:
            os.close(fd)
        running[os.pidfd_open(pid)] = pid
        ctl.send(json.dumps({"pid": pid}).encode())


class _Pipe:
    """The read end of a child's stdout or stderr: text ``readline``/``read``, its own buffer (so that
    :meth:`ForkedChild.communicate` gets what ``readline`` read ahead)."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.buf = bytearray()
        self.eof = False

    def fileno(self) -> int:
        return self.fd

    def fill(self) -> bool:
        """One read into the buffer; False at end of file."""
        chunk = os.read(self.fd, 1 << 16)
        self.eof = not chunk
        self.buf += chunk
        return bool(chunk)

    def readline(self) -> str:
        while b"\n" not in self.buf and not self.eof:
            self.fill()
        end = self.buf.find(b"\n") + 1 or len(self.buf)
        line = bytes(self.buf[:end])
        del self.buf[:end]
        return line.decode()

    def read(self) -> str:
        while not self.eof:
            self.fill()
        out = bytes(self.buf)
        self.buf.clear()
        return out.decode()

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


class ForkedChild:
    """A child of the fork server, driven like :class:`subprocess.Popen` (text ``stdout``/``stderr`` pipes).

    It is the server's child, not ours: its exit status comes over the control socket.
    """

    def __init__(self, server: "ForkServer", pid: int, stdout, stderr) -> None:
        self._server = server
        self.pid = pid
        self.stdout = stdout
        self.stderr = stderr
        self.returncode: int | None = None

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:  # not reaped yet, so the pid is still this child's
            os.kill(self.pid, sig)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def poll(self) -> int | None:
        if self.returncode is None:
            self._server._collect(self, block=False)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if self.returncode is None:
            self._server._collect(self, block=True, timeout_s=FORK_SERVER_TIMEOUT_s if timeout is None else timeout)
        return self.returncode

    def communicate(self, timeout: float | None = None) -> tuple[str, str]:
        """Read stdout and stderr to their end (the child's exit closes them), then wait for it."""
        import subprocess

        deadline = time.monotonic() + (FORK_SERVER_TIMEOUT_s if timeout is None else timeout)
        pending = [p for p in (self.stdout, self.stderr) if not p.eof]
        while pending:
            ready, _, _ = select.select(pending, [], [], max(deadline - time.monotonic(), 0.0))
            if not ready:
                raise subprocess.TimeoutExpired(f"forked child {self.pid}", timeout)
            for p in ready:
                if not p.fill():
                    pending.remove(p)
        self.wait(max(deadline - time.monotonic(), 0.1))
        return self.stdout.read(), self.stderr.read()

    def close(self) -> None:
        for f in (self.stdout, self.stderr):
            if f is not None:
                f.close()


class ForkServer:
    """Runs :func:`main` (or a code snippet) in children forked from one warmed-up interpreter.

    ``spawn(tmp, env=None)`` stands in for ``Popen([python, daemon_proc.py, tmp], stdout=PIPE,
    stderr=PIPE, text=True, env=env)``; ``run_code(code)`` for ``python -c code``.
    """

    #: CPU seconds of the children collected so far, of every server of this process still open: they
    #: are the server's children, not ours, so ``RUSAGE_CHILDREN`` sees them only once the server has
    #: exited (then this drops by the closed server's share). :mod:`tests.support.cpu_times` adds it, so
    #: that a test is charged its own children, not the test that happens to close the server.
    children_cpu_s: float = 0.0

    def __init__(self) -> None:
        import subprocess

        self._ctl, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self._proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--fork-server",
                                       str(theirs.fileno())], pass_fds=(theirs.fileno(),),
                                      stdin=subprocess.DEVNULL)
        theirs.close()
        #: The one daemon or code child (spawn, run_code): a later one ends it, as before.
        self._child: ForkedChild | None = None
        #: Every child not yet collected (start_call's may run several at a time).
        self._live: dict[int, ForkedChild] = {}
        #: Exit statuses that came while waiting for something else, by pid.
        self._exits: dict[int, int] = {}
        #: This server's share of :attr:`children_cpu_s`.
        self._cpu_s = 0.0

    def _recv(self, timeout_s: float | None) -> dict:
        self._ctl.settimeout(timeout_s)
        msg = self._ctl.recv(1 << 16)
        if not msg:
            raise RuntimeError(f"the fork server died (status {self._proc.poll()})")
        return json.loads(msg)

    def _reply(self, timeout_s: float) -> dict:
        """The server's answer to the request just sent (exit statuses that come first are kept)."""
        deadline = time.monotonic() + timeout_s
        while True:
            msg = self._recv(max(deadline - time.monotonic(), 0.001))
            if "returncode" not in msg:
                return msg
            self._exited(msg)

    def _exited(self, msg: dict) -> None:
        self._exits[msg["pid"]] = msg["returncode"]
        self._cpu_s += msg["cpu_s"]
        ForkServer.children_cpu_s += msg["cpu_s"]

    def _collect(self, child: ForkedChild, *, block: bool, timeout_s: float | None = None) -> None:
        import subprocess

        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while child.pid not in self._exits:
            try:
                left = None if deadline is None else max(deadline - time.monotonic(), 0.001)
                msg = self._recv(left if block else 0.0)
            except (socket.timeout, BlockingIOError):
                if block:
                    raise subprocess.TimeoutExpired(f"forked child {child.pid}", timeout_s) from None
                return
            assert "returncode" in msg, msg
            self._exited(msg)
        child.returncode = self._exits.pop(child.pid)
        self._live.pop(child.pid, None)
        if self._child is child:
            self._child = None

    def spawn(self, tmp: Path | str, env: dict | None = None) -> ForkedChild:
        """A daemon process on ``tmp``, as ``python daemon_proc.py TMP`` (env: its environment)."""
        return self._start({"argv": [str(tmp)], "env": None if env is None else dict(env)})

    def run_code(self, code: str, timeout_s: float = FORK_SERVER_TIMEOUT_s) -> tuple[int, str, str]:
        """Run ``code`` as a fresh interpreter's ``__main__`` would; (exit status, stdout, stderr)."""
        child = self._start({"code": code, "env": None})
        try:
            out, err = child.communicate(timeout_s)
        finally:
            self.reap(child)
        return child.returncode, out, err

    def prepare(self, function: str, arg) -> None:
        """Call ``function(arg)`` (``"module:function"``) in the server, so that every later child inherits
        what it did (imports, warmed-up state); its exception is raised here as a RuntimeError."""
        self._ctl.send(json.dumps({"prepare": function, "arg": arg}).encode())
        reply = self._reply(FORK_SERVER_TIMEOUT_s)
        if "error" in reply:
            raise RuntimeError(f"{function} failed in the fork server:\n{reply['error']}")

    def start_call(self, function: str, arg, fds: list[int]) -> ForkedChild:
        """A child that calls ``function(arg, fds)`` and ends itself; ``fds`` are passed (the caller closes its
        copies). The child has no pipes of ours: ``stdout`` and ``stderr`` are None. Several may run at a
        time: the caller waits for (or reaps) each."""
        socket.send_fds(self._ctl, [json.dumps({"call": function, "arg": arg}).encode()], fds)
        child = ForkedChild(self, self._reply(FORK_SERVER_TIMEOUT_s)["pid"], None, None)
        self._live[child.pid] = child
        return child

    def _start(self, job: dict) -> ForkedChild:
        if self._child is not None:  # a test that failed before waiting: end it, a daemon child is one at a time
            self.reap(self._child)
        pipes = [os.pipe() for _ in range(2)]
        devnull = os.open(os.devnull, os.O_RDONLY)
        try:
            socket.send_fds(self._ctl, [json.dumps(job).encode()], [devnull, pipes[0][1], pipes[1][1]])
        finally:
            for fd in (devnull, pipes[0][1], pipes[1][1]):
                os.close(fd)
        pid = self._reply(FORK_SERVER_TIMEOUT_s)["pid"]
        self._child = ForkedChild(self, pid, _Pipe(pipes[0][0]), _Pipe(pipes[1][0]))
        self._live[pid] = self._child
        return self._child

    def reap(self, child: ForkedChild) -> None:
        """SIGKILL ``child`` if it still runs, wait for it, close its pipes."""
        try:
            if child.poll() is None:
                child.kill()
                child.wait()
        finally:
            child.close()

    def close(self) -> None:
        try:
            for child in list(self._live.values()):
                self.reap(child)
        finally:
            self._ctl.close()  # the server sees EOF and exits
            try:
                self._proc.wait(FORK_SERVER_TIMEOUT_s)
            finally:
                if self._proc.poll() is None:
                    self._proc.kill()
                    self._proc.wait()
                # Reaped: RUSAGE_CHILDREN now holds the server and all its children.
                ForkServer.children_cpu_s -= self._cpu_s
                self._cpu_s = 0.0

    def __enter__(self) -> "ForkServer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


if __name__ == "__main__":
    if sys.argv[1:2] == ["--fork-server"]:
        _job = _serve_forks(int(sys.argv[2]))
        # From here on this is the forked child: the job runs as this script's main program would.
        del sys.argv[1:]
        if "code" in _job:
            exec(compile(_job["code"], "<string>", "exec"), {"__name__": "__main__", "__builtins__": __builtins__})
            sys.exit(0)
        sys.argv += _job["argv"]
    sys.exit(main())
