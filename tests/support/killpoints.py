"""Kill -9 at every step of a device operation, restart, and check that nothing was lost or half-written.

An *operation* (a MEASURE, a model flash, a run of CONFIG_SETs, the daemon's start-up) is a list of protocol requests
that a daemon built on the simulated rig answers. A *step* is anything the operation does that
outlives the process:

* ``file``: every ``os.open(O_CREAT)``, ``os.write``, ``os.fsync``, ``os.replace``,
  ``os.rename``, ``os.mkdir``, ``os.unlink`` and ``os.rmdir`` made from
  :mod:`edge.storage.durable`, :mod:`edge.model.store`, the bundle modules of :mod:`edge.model` or
  :mod:`edge.service.config` (found by the caller's stack, so ``shutil.rmtree`` and
  ``Path.unlink`` inside ``durable.remove_tree`` count, step by step);
* ``sqlite``: every writing statement the history issues (``BEGIN``, ``INSERT``, ``COMMIT``; at
  start-up ``PRAGMA journal_mode``, ``CREATE TABLE``, ``PRAGMA user_version``); SQLite's own page
  writes (and its WAL recovery) happen inside one C call and cannot be split from Python;
* ``heater``: every write to the simulated hardware that drives the heater (PWM sysfs files,
  the enable line);
* ``sample``: every sensor read of the touch (the heater is on during most of them; a kill there
  is the case the enable line's pull-down exists for);
* ``host``: the reply going to the host (killed before it, the host was never told);
* ``end``: after the last reply (everything confirmed).

:func:`dry_run` runs the operation once in a forked child and lists its steps. :func:`kill_at`
forks again, and the child kills itself with ``SIGKILL`` right before step N (``end``: right
after the last reply), so no ``finally``, ``atexit`` or signal handler runs -- exactly what
``kill -9`` or the OOM killer does. Right after step N is right before step N+1 as far as
anything outside the process can tell, so "before every step, and after the last" covers both.
The parent then *restarts*: it opens the history, the model store and the runtime overrides
fresh, as the daemon does at start-up, and checks the operation's invariants
(:class:`Operation.check`). Instrumentation is monkeypatched into the
child only; production code has no hooks.

Forking from the test process keeps a point at a few tens of ms (everything is imported, the
work directory is on tmpfs when there is one); a fresh interpreter per point would cost ~0.4 s.
Given a :class:`tests.support.daemon_proc.ForkServer`, the children are forked from that small
interpreter instead: the operation is rebuilt there from its description (:meth:`Operation.spec`),
warmed up once, and each child is its fork. A fork copies the forking process's page tables and
its children fault in copies of what they touch, so forking from a test worker that has grown to
hundreds of megabytes costs ~25 ms more a point than forking from the server. Children of the test
process itself (no server) inherit whatever the test monkeypatched, which the harness's own
"is it vacuous" tests need.
SIGKILL does not drop the page cache, so tmpfs and a disk behave the same for these kills
(power cuts are :mod:`tests.edge.model.test_store`'s business).
"""

from __future__ import annotations

import gc
import hashlib
import json
import os
import re
import select
import shutil
import signal
import sqlite3
import sys
import tempfile
import time
import traceback
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Collection, Iterator

from edge.protocol.commands import Command
from edge.protocol.errors import CommandError
from edge.protocol.messages import Request

__all__ = ["Steps", "Operation", "PointResult", "warm_up", "dry_run", "kill_at", "run_all", "work_root",
           "child_daemon", "full_restart", "measure_operation", "flash_operation", "config_operation",
           "startup_operation", "CONFIG_KEYS", "CONFIG_VALUES"]

#: Modules whose file-system calls are steps (the durable layer and everything that writes state through it).
WATCHED_MODULES = frozenset({"edge.storage.durable", "edge.storage.history", "edge.model.store", "edge.model.bundle",
                             "edge.model.container", "edge.model.loader", "edge.model.transport",
                             "edge.service.config"})
#: The os calls that change the file system (``open`` only with O_CREAT: opening to read, or to fsync a
#: directory, changes nothing).
MUTATING_OS_CALLS = ("open", "write", "fsync", "replace", "rename", "mkdir", "unlink", "rmdir")
#: Longest a child may take (a fork that inherited a held lock would hang; fail instead).
CHILD_TIMEOUT_s = 30.0
_EXIT_CRASHED = 70


class Steps:
    """Child side: numbers the steps and kills the process at the chosen one.

    Parameters
    ----------
    kill_at : int or None
        1-based step before which the process dies; None: run to the end (dry run).
    trace_fd : int
        Pipe to the parent: the dry run sends every step, a kill run the one it dies at
        (the parent checks it is the dry run's, i.e. the operation is deterministic).
    """

    def __init__(self, kill_at: int | None, trace_fd: int) -> None:
        self.kill_at = kill_at
        self.fd = trace_fd
        self.n = 0
        self.done = False

    def step(self, kind: str, what: str) -> None:
        """Count one step; die before it if it is the chosen one."""
        if self.done:
            return  # the daemon's shutdown after the last reply is not part of the operation
        self.n += 1
        if self.kill_at is None or self.n == self.kill_at:
            _write_all(self.fd, f"{kind}\t{_normal(what)}\n".encode())
        if self.n == self.kill_at:
            os.kill(os.getpid(), signal.SIGKILL)

    def end(self) -> None:
        """The point after the last reply, then stop counting."""
        self.step("end", "after the last reply")
        self.done = True


_os_write = os.write  # the real one: the child's os.write is instrumented, and its own pipes are no steps


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[_os_write(fd, view):]


_NOISE = re.compile(r"[0-9a-f]{8,}|\d+")


def _normal(text: str) -> str:
    # Staging names carry pids and random tokens: the same step has the same label in every run.
    return _NOISE.sub("#", text)


def _watched_caller() -> str | None:
    f = sys._getframe(2)
    while f is not None:
        name = f.f_globals.get("__name__")
        if name in WATCHED_MODULES:
            return name
        f = f.f_back
    return None


def _describe(name: str, args: tuple) -> str:
    if name in ("write", "fsync"):
        return f"{name} fd"
    shown = [os.path.basename(str(a)) for a in args[:2] if isinstance(a, (str, os.PathLike))]
    return f"{name} {' -> '.join(shown)}".strip()


def instrument_files(steps: Steps) -> None:
    """Make every mutating os call from the watched modules a step (child only: never restored)."""
    for name in MUTATING_OS_CALLS:
        real = getattr(os, name)

        def wrapper(*args: Any, _real: Callable = real, _name: str = name, **kw: Any) -> Any:
            if _name == "open" and not (args[1] if len(args) > 1 else kw.get("flags", 0)) & os.O_CREAT:
                return _real(*args, **kw)
            if _watched_caller() is not None:
                steps.step("file", _describe(_name, args))
            return _real(*args, **kw)

        setattr(os, name, wrapper)


#: Statements that write the database file (reads and per-connection settings are no steps).
_SQL_WRITES = frozenset({"BEGIN", "COMMIT", "INSERT", "UPDATE", "DELETE", "CREATE", "DROP", "ALTER"})
_SQL_WRITING_PRAGMAS = ("PRAGMA JOURNAL_MODE", "PRAGMA USER_VERSION=")


class _CountingConnection:
    """Stands in for the history's sqlite3 connection: every writing statement is a step."""

    def __init__(self, conn: sqlite3.Connection, steps: Steps) -> None:
        self._conn = conn
        self._steps = steps

    def execute(self, sql: str, *args: Any) -> Any:
        words = " ".join(sql.split()).upper()
        if words.split(" ", 1)[0] in _SQL_WRITES or words.startswith(_SQL_WRITING_PRAGMAS):
            self._steps.step("sqlite", " ".join(words.split(" ", 2)[:2]) if words.startswith(("CREATE", "PRAGMA"))
                             else words.split(" ", 1)[0])
        return self._conn.execute(sql, *args)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._conn, name)


def instrument_sqlite_connect(steps: Steps) -> None:
    """Count the writing statements of every connection opened from now on (a history opened at start-up)."""
    real = sqlite3.connect

    def connect(*args: Any, **kw: Any) -> Any:
        return _CountingConnection(real(*args, **kw), steps)

    sqlite3.connect = connect


def instrument_history(daemon: Any, steps: Steps) -> None:
    """Count the history's writing statements (the daemon's own connection, wrapped)."""
    daemon.history._db = _CountingConnection(daemon.history._db, steps)


class _CountingSensors:
    def __init__(self, inner: Any, heater: Any, steps: Steps) -> None:
        self.inner, self.heater, self.steps, self.n = inner, heater, steps, 0

    def read(self) -> Any:
        self.n += 1
        self.steps.step("sample", f"read {self.n} heater {'on' if self.heater.is_on else 'off'}")
        return self.inner.read()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


def instrument_heater(daemon: Any, steps: Steps) -> None:
    """Count every write to the heater's hardware and every sensor read of the touch."""
    heater = daemon.heater
    pwm_write, set_value = heater._pwm._write, heater._req.set_value

    def write(path: Any, value: Any) -> None:
        steps.step("heater", f"pwm {Path(path).name}={value}")
        pwm_write(path, value)

    def set_line(offset: int, value: Any) -> None:
        steps.step("heater", f"enable line {getattr(value, 'name', value)}")
        set_value(offset, value)

    heater._pwm._write = write
    heater._req.set_value = set_line
    daemon.sensors = _CountingSensors(daemon.sensors, heater, steps)


# ---------------------------------------------------------------------------------------------- operations

@dataclass
class Operation:
    """One operation: how to prepare its state, what the child sends, what must hold after a restart.

    Attributes
    ----------
    name : str
    template : Path
        The state before the operation (copied afresh for every point).
    requests : list of (Command, dict)
        Sent in order; each reply is sent to the host (the parent) as it comes.
    instrument : list of str
        What else counts besides files: ``"sqlite"``, ``"heater"``.
    check : callable (point_dir, confirmed replies) -> list of str
        The cheap restart check: what is wrong (empty: survived). None on the fork server's side.
    store_root : Path or None
        None: each child's daemon opens its model store, as at start-up. A directory: operations
        that leave the model alone share one store, verified once (in the process the children
        are forked from) under this directory, which saves a third of a child's start.
    """

    name: str
    template: Path
    requests: list[tuple[Command, dict]]
    check: Callable[[Path, list[dict]], list[str]] | None
    store_root: Path | None = None
    instrument: tuple[str, ...] = ()
    #: The daemon's start-up is the operation: instrument first, then build the daemon.
    startup: bool = False
    _store: Any = field(default=None, init=False, repr=False, compare=False)
    #: Where :meth:`spec` wrote the child side (set by :func:`dry_run` on a fork server).
    spec_path: Path | None = field(default=None, init=False, repr=False, compare=False)

    def make_daemon(self, point_dir: Path) -> Any:
        """The daemon of the child, as ``thermotouch-edge`` starts it on ``point_dir``."""
        if self.store_root is None:
            return child_daemon(point_dir)
        if self._store is None:
            self._store = _open_store(Path(tempfile.mkdtemp(prefix="shared-store-", dir=self.store_root)))
            self._store.current()
        return child_daemon(point_dir, model_store=self._store)

    def spec(self) -> Path:
        """Write what a child needs (everything but ``check``) as JSON beside the template; return its path.

        Request arguments that are bytes (model chunks) are written as ``{"bytes_hex": ...}``.
        """
        path = self.template.with_name(self.template.name + ".spec.json")
        doc = {"name": self.name, "template": str(self.template),
               "requests": [[c.name, {k: {"bytes_hex": v.hex()} if isinstance(v, bytes) else v for k, v in a.items()}]
                            for c, a in self.requests],
               "store_root": None if self.store_root is None else str(self.store_root),
               "instrument": list(self.instrument), "startup": self.startup}
        path.write_text(json.dumps(doc))
        return path

    @classmethod
    def from_spec(cls, path: Path) -> "Operation":
        """The child side of the operation :meth:`spec` wrote (no ``check``: that runs in the test process)."""
        doc = json.loads(Path(path).read_text())
        requests = [(Command[c], {k: bytes.fromhex(v["bytes_hex"]) if isinstance(v, dict) and "bytes_hex" in v else v
                                  for k, v in a.items()}) for c, a in doc["requests"]]
        return cls(doc["name"], Path(doc["template"]), requests, None,
                   None if doc["store_root"] is None else Path(doc["store_root"]), tuple(doc["instrument"]),
                   doc["startup"])


@dataclass
class PointResult:
    """What one kill point gave: the step it died before, the replies the host had, what broke."""

    n: int
    step: str
    confirmed: int
    problems: list[str] = field(default_factory=list)
    seconds: float = 0.0


def _child(op: Operation, point_dir: Path, n: int | None, trace_fd: int, host_fd: int) -> None:
    steps = Steps(n, trace_fd)
    if op.startup:
        instrument_files(steps)
        instrument_sqlite_connect(steps)
        daemon = op.make_daemon(point_dir)
    else:
        daemon = op.make_daemon(point_dir)
        instrument_files(steps)
    if "sqlite" in op.instrument:
        instrument_history(daemon, steps)
    if "heater" in op.instrument:
        instrument_heater(daemon, steps)
    session = None
    for i, (command, args) in enumerate(op.requests):
        if session is not None and command in (Command.MODEL_CHUNK, Command.MODEL_COMMIT):
            args = {**args, "session": session}
        try:
            body = daemon.handle(Request(command, i + 1, dict(args)))
        except CommandError as e:
            body = {"error": str(e.code), "message": e.message}
        if command == Command.MODEL_BEGIN and body and "session" in body:
            session = body["session"]
        steps.step("host", f"reply {command.name}")
        _write_all(host_fd, (json.dumps({"command": command.name, "body": body}, default=str) + "\n").encode())
    steps.end()
    daemon.close()


def _child_process(op: Operation, point_dir: Path, n: int | None, trace_w: int, host_w: int, err_w: int) -> None:
    """The forked child's whole life: the operation, then ``os._exit`` (or the SIGKILL at step ``n``)."""
    status = _EXIT_CRASHED
    try:
        _child(op, point_dir, n, trace_w, host_w)
        status = 0
    except BaseException:
        # sys.stderr may be the test runner's capture object: write to the pipe itself.
        _write_all(err_w, traceback.format_exc().encode())
    finally:
        os._exit(status)


#: The fork server's operations, by the path of their spec (filled in the server by :func:`_prepare_in_server`).
_SERVER_OPS: dict[str, Operation] = {}


def _prepare_in_server(spec: str) -> None:
    """Fork-server side of :func:`dry_run`: rebuild the operation and warm it up there, once."""
    op = Operation.from_spec(Path(spec))
    warm_up(op, op.template.parent)  # every builder makes its template in the operation's root
    _SERVER_OPS[spec] = op


def _point_in_server(arg: dict, fds: list[int]) -> None:  # pragma: no cover - runs in the server's child
    trace_w, host_w, err_w = fds
    _child_process(_SERVER_OPS[arg["spec"]], Path(arg["point"]), arg["n"], trace_w, host_w, err_w)


def _run_child(op: Operation, point_dir: Path, n: int | None, server: Any = None
               ) -> tuple[int, list[str], list[dict], str]:
    """Fork, run the operation (dying before step ``n``), return (exit code, trace, replies, stderr tail).

    The exit code is :attr:`subprocess.Popen.returncode`'s: ``-SIGKILL`` for the kill. ``server``: a
    :class:`~tests.support.daemon_proc.ForkServer` the operation was prepared on (:func:`dry_run`);
    None: fork this process.
    """
    if server is not None and op.spec_path is None:
        raise ValueError(f"{op.name}: not prepared on this fork server (run dry_run with it first)")
    trace_r, trace_w = os.pipe()
    host_r, host_w = os.pipe()
    err_r, err_w = os.pipe()
    child = None
    if server is None:
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child never returns into the test runner
            # No cyclic collections in the child: one would walk (and so copy-on-write) the whole
            # test process's heap, a large one in a worker that collected the suite. The child
            # lives for one operation.
            gc.disable()
            for fd in (trace_r, host_r, err_r):
                os.close(fd)
            _child_process(op, point_dir, n, trace_w, host_w, err_w)
    else:
        try:
            child = server.start_call("tests.support.killpoints:_point_in_server",
                                      {"spec": str(op.spec_path), "point": str(point_dir), "n": n},
                                      [trace_w, host_w, err_w])
        except BaseException:
            for fd in (trace_r, host_r, err_r, trace_w, host_w, err_w):
                os.close(fd)
            raise
        pid = child.pid
    for fd in (trace_w, host_w, err_w):
        os.close(fd)
    bufs: dict[int, bytearray] = {trace_r: bytearray(), host_r: bytearray(), err_r: bytearray()}
    open_fds = set(bufs)
    deadline = time.monotonic() + CHILD_TIMEOUT_s
    try:
        while open_fds:
            left = deadline - time.monotonic()
            if left <= 0:
                os.kill(pid, signal.SIGKILL)  # our own child, hung: fail the point instead of the suite
                raise TimeoutError(f"{op.name}: child for point {n} did not finish in {CHILD_TIMEOUT_s} s")
            ready, _, _ = select.select(list(open_fds), [], [], left)
            for fd in ready:
                chunk = os.read(fd, 65536)
                if chunk:
                    bufs[fd] += chunk
                else:
                    open_fds.discard(fd)
    finally:
        for fd in bufs:
            os.close(fd)
        if child is None:
            code = os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])
        else:
            code = child.wait()
    trace = bufs[trace_r].decode().splitlines()
    replies = [json.loads(line) for line in bufs[host_r].decode().splitlines()]
    return code, trace, replies, bufs[err_r].decode()[-3000:]


def _fresh_point(op: Operation, root: Path, tag: str) -> Path:
    # The same base name at every point: step labels name it (``mkdir state``), and the dry run's must match.
    point = root / f"{op.name}-{tag}" / "state"
    if point.parent.exists():
        shutil.rmtree(point.parent)
    shutil.copytree(op.template, point)
    return point


def warm_up(op: Operation, root: Path) -> None:
    """Run the operation once in this process, uninstrumented, on a scratch copy of its state.

    Whatever the daemon and the operation import lazily (the daemon's modules, NumPy's random
    generators, the object set of the running answer) is then inherited by every child instead
    of being compiled again in each (~60 ms a point, more than the point itself).
    """
    point = _fresh_point(op, root, "warm")
    daemon = op.make_daemon(point)
    try:
        session = None
        for i, (command, args) in enumerate(op.requests):
            if session is not None and command in (Command.MODEL_CHUNK, Command.MODEL_COMMIT):
                args = {**args, "session": session}
            body = daemon.handle(Request(command, i + 1, dict(args)))
            if command == Command.MODEL_BEGIN:
                session = body["session"]
    finally:
        daemon.close()
    shutil.rmtree(point.parent)


def dry_run(op: Operation, root: Path, server: Any = None) -> tuple[list[str], list[dict]]:
    """Run the operation to the end in a child (after :func:`warm_up`); return its steps and replies.

    ``server``: a :class:`~tests.support.daemon_proc.ForkServer` to fork this operation's children
    from (the operation is rebuilt and warmed up there); None: this process.
    """
    if server is None:
        warm_up(op, root)
    else:
        op.spec_path = op.spec()
        server.prepare("tests.support.killpoints:_prepare_in_server", str(op.spec_path))
    point = _fresh_point(op, root, "dry")
    code, trace, replies, err = _run_child(op, point, None, server)
    if code != 0:
        raise AssertionError(f"{op.name}: the dry run failed (exit code {code}):\n{err}")
    problems = op.check(point, replies)
    if problems:
        raise AssertionError(f"{op.name}: the operation run to its end breaks its own invariants: {problems}")
    shutil.rmtree(point.parent)
    return trace, replies


def kill_at(op: Operation, root: Path, n: int, expected_step: str, *, keep: bool = False,
            server: Any = None) -> PointResult:
    """Kill the operation right before step ``n``, restart, check; the point's directory
    (``root/<op>-k<n>/state``) is removed unless ``keep``. ``server``: as for :func:`dry_run`, which
    must have run on it first."""
    t0 = time.perf_counter()
    point = _fresh_point(op, root, f"k{n}")
    code, trace, replies, err = _run_child(op, point, n, server)
    res = PointResult(n, expected_step, len(replies))
    if code != -signal.SIGKILL:
        res.problems.append(f"child was not killed at step {n} (exit code {code}): {err}")
    elif trace != [expected_step]:
        res.problems.append(f"child died at {trace}, the dry run had {expected_step!r} (not deterministic)")
    else:
        res.problems += op.check(point, replies)
    if not keep:
        shutil.rmtree(point.parent)
    res.seconds = time.perf_counter() - t0
    return res


def run_all(op: Operation, root: Path, *, keep: Callable[[list[str]], Collection[int]] | None = None,
            server: Any = None) -> tuple[list[str], list[PointResult]]:
    """Dry run, then a kill before every step; returns (steps, results).

    ``keep(steps)``: the points whose directories stay for a later look (a full restart), so that
    they need not be killed a second time. ``server``: as for :func:`dry_run`.
    """
    trace, _ = dry_run(op, root, server)
    kept = set(keep(trace)) if keep is not None else set()
    return trace, [kill_at(op, root, i + 1, step, keep=i + 1 in kept, server=server) for i, step in enumerate(trace)]


@contextmanager
def work_root(fallback: Path | None = None) -> Iterator[Path]:
    """A scratch directory on tmpfs when there is one (fsync is free there), removed afterwards."""
    base = "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else None
    root = Path(tempfile.mkdtemp(prefix="thermotouch-killpts-", dir=base or fallback))
    try:
        yield root
    finally:
        shutil.rmtree(root, ignore_errors=True)


# ---------------------------------------------------------------------------------------------- daemons

def child_daemon(point_dir: Path, model_store: Any = None, **sections: Any) -> Any:
    """The daemon as ``thermotouch-edge`` starts it, on a sim rig whose GPIO and PWM state live in files.

    ``model_store``: an already verified store to hand it (operations that do not touch the model
    save the golden check, a third of a child's start); None: the daemon opens its own.
    """
    from firmware_sim.rigs.daemon_rig import make_rig
    from edge.service.daemon import Daemon
    from tests.support.daemons import FakeEstimator, sim_config

    rig = make_rig(gpio_state_dir=point_dir / "gpio", pwm_root=point_dir / "pwm")
    return Daemon(sim_config(point_dir, **sections), rig.board, estimator=FakeEstimator(), model_store=model_store)


def heater_line(point_dir: Path, which: str = "gpio") -> dict | None:
    """The enable line as the kernel shows it after the child died (a dead holder's request released)."""
    from firmware_sim.gpiod.state import read_line

    return read_line(point_dir / which, "gpiochip0", 17)


def full_restart(point_dir: Path, *, measure: bool = True, **sections: Any) -> dict:
    """Start a daemon on the killed child's state, as after a reboot; return what it reports.

    The simulated PWM tree cannot be adopted from a dead process, so the restarted rig gets its
    own (``pwm-restart``); the GPIO line files are the child's.
    """
    from firmware_sim.rigs.daemon_rig import make_rig
    from edge.service.daemon import Daemon
    from tests.support.daemons import FakeEstimator, sim_config

    rig = make_rig(gpio_state_dir=point_dir / "gpio", pwm_root=point_dir / "pwm-restart")
    cfg = sim_config(point_dir, **sections)
    with Daemon(cfg, rig.board, estimator=FakeEstimator()) as d:
        st = d.handle(Request(Command.STATUS, 1, {}))
        info = d.handle(Request(Command.INFO, 2, {}))
        out = {"status": st, "info": info, "heater_level": rig.parts.chip.level(rig.parts.heater_enable_offset),
               "pwm_duty": rig.parts.pwm_tree.history(rig.parts.pwm_chip, rig.parts.pwm_channel)[-1].fraction,
               "config": d.config.runtime()}
        if measure:
            out["measure"] = d.measure()  # the touch the (possibly just changed) configuration asks for
        out["heater_on_after"] = d.heater.is_on
    out["line_after_close"] = heater_line(point_dir)
    return out


# ---------------------------------------------------------------------------------------------- the three operations

_SERIES = ("raw_t_s", "raw_T_C", "raw_q_W_m2")


def _history_rows(db: Path) -> tuple[list[str], dict[int, tuple]]:
    """Open the history as the daemon does, then (problems, {id: full row}) read with plain SQL."""
    from edge.storage.history import History, HistoryError

    problems: list[str] = []
    try:
        h = History(db)  # WAL recovery happens here, as at the daemon's start
    except HistoryError as e:
        return [f"history does not open after the kill: {e}"], {}
    try:
        check = h._db.execute("PRAGMA integrity_check").fetchall()
        if check != [("ok",)]:
            problems.append(f"integrity_check: {check[:3]}")
        cur = h._db.execute("SELECT * FROM measurements ORDER BY id")
        cols = [c[0] for c in cur.description]
        rows = {int(r[0]): dict(zip(cols, r)) for r in cur.fetchall()}
    finally:
        h.close()
    for mid, r in rows.items():
        n = r["n_samples"]
        for name in _SERIES:
            if r[name] is None or len(r[name]) != 8 * n:
                problems.append(f"measurement {mid}: {name} holds {None if r[name] is None else len(r[name]) // 8} "
                                f"values, n_samples says {n} (half-written)")
        try:
            json.loads(r["config"]), json.loads(r["flags"])
            if r["result"] is not None:
                json.loads(r["result"])
        except (TypeError, ValueError) as e:
            problems.append(f"measurement {mid}: a JSON column does not parse ({e})")
    return problems, rows


def _row_digest(row: dict) -> str:
    return hashlib.sha256(repr(sorted(row.items())).encode()).hexdigest()


def _heater_problems(point: Path) -> list[str]:
    line = heater_line(point)
    if line is None:
        return ["the enable line was never mirrored"]
    return [] if line["level"] == 0 else [f"heater enable line high after the kill: {line}"]


def measure_operation(root: Path, n_prior: int = 2) -> Operation:
    """One MEASURE with the configured touch, on a history that already holds ``n_prior`` records."""
    from firmware_sim.rigs.daemon_rig import make_rig
    from edge.service.daemon import Daemon
    from tests.support.daemons import FakeEstimator, sim_config

    template = Path(tempfile.mkdtemp(prefix="measure-template-", dir=root))
    scratch = Path(tempfile.mkdtemp(prefix="measure-template-hw-", dir=root))
    rig = make_rig(gpio_state_dir=scratch / "gpio", pwm_root=scratch / "pwm")
    with Daemon(sim_config(template), rig.board, estimator=FakeEstimator()) as d:
        for _ in range(n_prior):
            d.measure(contact_time_s=0.5)
    shutil.rmtree(scratch)
    problems, prior = _history_rows(template / "history.db")
    assert not problems and len(prior) == n_prior, problems
    prior_digest = {mid: _row_digest(r) for mid, r in prior.items()}

    def check(point: Path, replies: list[dict]) -> list[str]:
        problems, rows = _history_rows(point / "history.db")
        for mid, digest in prior_digest.items():
            if mid not in rows:
                problems.append(f"measurement {mid}, stored before the operation, is gone")
            elif _row_digest(rows[mid]) != digest:
                problems.append(f"measurement {mid}, stored before the operation, changed")
        new = sorted(set(rows) - set(prior_digest))
        if len(new) > 1:
            problems.append(f"one MEASURE left {len(new)} new records: {new}")
        for rep in replies:
            body = rep["body"]
            if rep["command"] != "MEASURE" or "measurement_id" not in body:
                problems.append(f"unexpected reply {rep}")
                continue
            row = rows.get(body["measurement_id"])
            if row is None:
                problems.append(f"measurement {body['measurement_id']} was confirmed to the host and is lost")
            elif (row["status"], row["n_samples"]) != (body["status"], body["n_samples"]):
                problems.append(f"measurement {body['measurement_id']} differs from what the host was told")
        return problems + _heater_problems(point)

    return Operation("measure", template, [(Command.MEASURE, {})], check, root, ("sqlite", "heater"))


def _variant_blobs(tags: tuple[str, ...]) -> dict[str, bytes]:
    """Transport blobs of the shipped bundle under new identities (its manifest's description differs)."""
    from edge.model.bundle import BUNDLE_FILES, MANIFEST_FILE, pack_entries
    from thermotouch_models import DEFAULT_BUNDLE

    out = {}
    for tag in tags:
        files = {name: (DEFAULT_BUNDLE / name).read_bytes() for name in BUNDLE_FILES}
        manifest = json.loads(files[MANIFEST_FILE])
        manifest["description"] = f"kill-point test model {tag}"
        manifest["model_version"] = f"killpts-{tag}"
        files[MANIFEST_FILE] = (json.dumps(manifest, indent=2, sort_keys=True) + "\n").encode()
        out[tag] = pack_entries([(name.encode(), files[name]) for name in BUNDLE_FILES])
    return out


def _open_store(point: Path) -> Any:
    from edge.estimation.estimate import pipeline_golden_check
    from edge.model.bundle import limits_for_ram
    from edge.model.store import ModelStore
    from edge.service.config import Config
    from thermotouch_models import DEFAULT_BUNDLE

    from edge.security.policy import UpdatePolicy

    # A development policy, as the simulated daemon's: these kill points are about durability, not signatures.
    return ModelStore(point / "models", DEFAULT_BUNDLE, golden_check=pipeline_golden_check,
                      limits=limits_for_ram(Config().limits.ram_bytes), policy=UpdatePolicy(allow_unsigned=True))


def flash_operation(root: Path, chunk_bytes: int = 48 * 1024) -> Operation:
    """A model flash through the daemon's upload path (MODEL_BEGIN, MODEL_CHUNKs, MODEL_COMMIT).

    The store already holds two installs (``current`` = B, ``previous`` = A), so the flash of C
    rewrites both pointers and collects A.
    """
    from edge.storage.history import History

    template = Path(tempfile.mkdtemp(prefix="flash-template-", dir=root))
    History(template / "history.db").close()
    blobs = _variant_blobs(("A", "B", "C"))
    store = _open_store(template)
    sha = {tag: store.install(blobs[tag], hashlib.sha256(blobs[tag]).hexdigest(), len(blobs[tag])).sha256
           for tag in ("A", "B")}
    blob = blobs["C"]
    blob_sha = hashlib.sha256(blob).hexdigest()
    requests: list[tuple[Command, dict]] = [(Command.MODEL_BEGIN, {"size": len(blob), "sha256": blob_sha,
                                                                    "version": "killpts-C"})]
    for off in range(0, len(blob), chunk_bytes):
        requests.append((Command.MODEL_CHUNK, {"offset": off, "data": blob[off:off + chunk_bytes]}))
    requests.append((Command.MODEL_COMMIT, {}))
    states = None  # (current, previous) pairs a restart may find; C's identity is known after the dry run

    def check(point: Path, replies: list[dict]) -> list[str]:
        nonlocal states
        problems: list[str] = []
        committed = [r["body"] for r in replies if r["command"] == "MODEL_COMMIT"]
        if committed and "bundle_sha256" not in committed[0]:
            return [f"MODEL_COMMIT refused: {committed[0]}"]
        if committed and states is None:
            c = committed[0]["bundle_sha256"]
            states = {(sha["B"], sha["A"]): "old", (sha["B"], sha["B"]): "old", (c, sha["B"]): "new"}
        st = _open_store(point)  # start-up cleaning happens here, as in the daemon
        try:
            active = st.current()
        except Exception as e:  # noqa: BLE001 - any failure to serve a model is what we look for
            return [f"no model after the kill: {e}"] + _heater_problems(point)
        pointers = (st._read_pointer(st.CURRENT), st._read_pointer(st.PREVIOUS))
        if st.source != "current" or active.sha256 != pointers[0]:
            problems.append(f"served {st.source} ({active.sha256[:12]}), boot errors {st.boot_errors}")
        if states is not None and pointers not in states:
            problems.append(f"pointers {[p[:12] if p else p for p in pointers]} are neither the old nor the new state")
        if committed and states is not None and states.get(pointers) != "new":
            problems.append("the flash was confirmed to the host but the old model is active")
        if pointers[1] != pointers[0]:  # current() has just verified the bundle ``current`` names
            try:
                st._load_verified(st._bundle_path(pointers[1]), pointers[1])  # hashes, schema, golden vectors
            except Exception as e:  # noqa: BLE001
                problems.append(f"previous names a bundle that does not verify (no rollback): {e}")
        leftovers = sorted(os.listdir(st.tmp_dir)) + [e for e in os.listdir(st.root) if e.startswith(".")]
        unreferenced = sorted(set(os.listdir(st.bundles_dir)) - set(pointers))
        if leftovers:
            problems.append(f"stray temporaries survive start-up: {leftovers}")
        if unreferenced:
            problems.append(f"unreferenced bundles survive start-up: {[u[:12] for u in unreferenced]}")
        return problems + _heater_problems(point)

    return Operation("flash", template, requests, check)


#: A new value for every runtime key (each valid on the sim board, each unlike the default).
CONFIG_VALUES: dict[str, Any] = {
    "heater.power_W": 3.0, "measurement.baseline_s": 0.8, "measurement.contact_time_s": 1.5,
    "measurement.sample_rate_Hz": 5.0, "measurement.cooldown_s": 2.0,
    "measurement.no_contact_e_W_s05_m2K": 20.0, "measurement.decide_posterior": 0.9,
    "measurement.decide_min_s": 0.5, "measurement.noise_T_K": 0.2, "measurement.noise_q_W_m2": 60.0,
    "measurement.unstable_baseline_K": 0.3, "estimation.method": "paper", "logging.level": "WARNING",
}


#: The CONFIG_SETs of the operation: both string keys and four float keys of three sections (every key
#: takes the same path through the daemon; all 13 would only repeat it, at 7 points each).
CONFIG_KEYS = ("heater.power_W", "measurement.contact_time_s", "measurement.sample_rate_Hz",
               "measurement.decide_posterior", "estimation.method", "logging.level")


def config_operation(root: Path, keys: tuple[str, ...] | None = None) -> Operation:
    """One CONFIG_SET per runtime key, in order; the overrides file already holds one value."""
    from edge.service.config import RuntimeOverrides
    from edge.storage.history import History
    from tests.support.daemons import sim_config

    keys = CONFIG_KEYS if keys is None else keys
    template = Path(tempfile.mkdtemp(prefix="config-template-", dir=root))
    History(template / "history.db").close()
    (template / "runtime.json").write_text(json.dumps({"heater.power_W": 2.0}))
    base = sim_config(template)
    old = RuntimeOverrides(template / "runtime.json").load(base)
    requests = [(Command.CONFIG_SET, {"values": {k: CONFIG_VALUES[k]}}) for k in keys]

    def check(point: Path, replies: list[dict]) -> list[str]:
        problems: list[str] = []
        path = point / "runtime.json"
        ro = RuntimeOverrides(path)
        ro.clean_temporaries()  # what the daemon does first at start-up
        stray = [p for p in os.listdir(point) if p.startswith(".runtime.json")]
        if stray:
            problems.append(f"stray temporaries survive start-up: {stray}")
        try:
            data = json.loads(path.read_text("utf-8"))
            assert isinstance(data, dict)
        except (OSError, ValueError, AssertionError) as e:
            return problems + [f"runtime overrides unreadable after the kill: {e}"]
        cfg = ro.load(sim_config(point))
        if ro.errors:
            problems.append(f"overrides refused at start-up: {ro.errors}")
        state = ["new" if cfg.get(k) == CONFIG_VALUES[k] else "old" if cfg.get(k) == old.get(k) else "other"
                 for k in keys]
        if "other" in state:
            problems.append(f"a key is neither old nor new: {dict(zip(keys, state))}")
        n_new = state.count("new")
        if state != ["new"] * n_new + ["old"] * (len(keys) - n_new):
            problems.append(f"the settings are not a prefix of the CONFIG_SETs: {state}")
        confirmed = sum(1 for r in replies if r["command"] == "CONFIG_SET" and "error" not in r["body"])
        if confirmed != len(replies):
            problems.append(f"a CONFIG_SET was refused: {replies}")
        if n_new < confirmed:
            problems.append(f"{confirmed} CONFIG_SETs confirmed to the host, {n_new} survive")
        return problems + _heater_problems(point)

    return Operation("config", template, requests, check, root)


def _die_after(fn: Callable[[], None]) -> None:
    """Run ``fn`` in a child that is then SIGKILLed (leaves what a killed daemon leaves: a WAL not checkpointed)."""
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child never returns
        try:
            fn()
            os.kill(os.getpid(), signal.SIGKILL)
        finally:
            os._exit(_EXIT_CRASHED)
    _, status = os.waitpid(pid, 0)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, status


def startup_operation(root: Path, *, after_crash: bool) -> Operation:
    """The daemon's start-up, then one STATUS: on an empty state directory (first boot), or on what a
    killed daemon left (``after_crash``: a record only in the WAL, a staged upload, pointer and
    overrides temporaries, a bundle no pointer names).
    """
    from edge.storage.history import History

    template = Path(tempfile.mkdtemp(prefix=f"startup-{'crash' if after_crash else 'first'}-template-", dir=root))
    blobs = _variant_blobs(("A", "B")) if after_crash else {}
    sha: dict[str, str] = {}
    prior: dict[int, str] = {}
    if after_crash:
        store = _open_store(template)
        sha = {tag: store.install(blobs[tag], hashlib.sha256(blobs[tag]).hexdigest(), len(blobs[tag])).sha256
               for tag in ("A", "B")}
        (template / "runtime.json").write_text(json.dumps({"heater.power_W": 2.0}))
        rec = {"status": "ok", "flags": [], "config": {}, "raw_t_s": [0.0, 0.1], "raw_T_C": [25.0, 25.5],
               "raw_q_W_m2": [0.0, 900.0]}

        def add_and_die() -> None:
            h = History(template / "history.db")
            h.add(rec)
            h.add(rec)

        _die_after(add_and_die)
        models = template / "models"
        shutil.copytree(models / "bundles" / sha["A"], models / "bundles" / ("c" * 64))  # moved in, never named
        (models / "tmp" / "upload-0123456789ab").mkdir()
        (models / "tmp" / "upload-0123456789ab" / "arrays.npz").write_bytes(b"partial")
        (models / ".current.tmp4242").write_bytes(b"half a poi")
        (template / ".runtime.json.tmp777").write_bytes(b"{\"heater.pow")
        problems, rows = _history_rows(Path(shutil.copytree(template, root / "startup-probe")) / "history.db")
        shutil.rmtree(root / "startup-probe")
        assert not problems and len(rows) == 2, problems
        prior = {mid: _row_digest(r) for mid, r in rows.items()}
        assert (template / "history.db-wal").stat().st_size > 0  # the records live in the WAL only

    def check(point: Path, replies: list[dict]) -> list[str]:
        problems, rows = _history_rows(point / "history.db") if (point / "history.db").exists() else ([], {})
        if set(rows) != set(prior) or any(_row_digest(rows[m]) != d for m, d in prior.items()):
            problems.append(f"history records changed across the start-up: {sorted(rows)} vs {sorted(prior)}")
        st = _open_store(point)
        try:
            active = st.current()
            if after_crash and (st.source, active.sha256) != ("current", sha["B"]):
                problems.append(f"serves {st.source} {active.sha256[:12]}, not the installed model")
            if not after_crash and st.source != "factory":
                problems.append(f"first boot serves {st.source}")
        except Exception as e:  # noqa: BLE001
            problems.append(f"no model after the kill: {e}")
        leftovers = sorted(os.listdir(st.tmp_dir)) + [e for e in os.listdir(st.root) if e.startswith(".")]
        pointers = {p for p in (st._read_pointer(st.CURRENT), st._read_pointer(st.PREVIOUS)) if p}
        unreferenced = sorted(set(os.listdir(st.bundles_dir)) - pointers)
        if leftovers or unreferenced:
            problems.append(f"left after a second start-up: temporaries {leftovers}, unreferenced {unreferenced}")
        from edge.service.config import RuntimeOverrides
        from tests.support.daemons import sim_config

        ro = RuntimeOverrides(point / "runtime.json")
        ro.clean_temporaries()
        cfg = ro.load(sim_config(point))
        if ro.errors or cfg.heater.power_W != (2.0 if after_crash else sim_config(point).heater.power_W):
            problems.append(f"runtime overrides: {ro.errors}, power {cfg.heater.power_W}")
        if replies and replies[0]["body"].get("faults"):
            problems.append(f"the daemon started with faults: {replies[0]['body']['faults']}")
        return problems + _heater_problems(point)

    return Operation(f"startup-{'crash' if after_crash else 'first'}", template, [(Command.STATUS, {})], check,
                     startup=True)
