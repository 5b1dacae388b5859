"""Kill points' steps: what counts as one, and the child's instrumentation that counts them.

:class:`Steps` numbers the steps of an operation in the forked child and kills it with ``SIGKILL``
right before the chosen one; ``instrument_*`` monkeypatch the child (file-system calls made from
:data:`WATCHED_MODULES`, SQLite writing statements, heater writes, sensor reads). The overview is
:mod:`tests.support.killpoints`.
"""

from __future__ import annotations

import os
import re
import signal
import sqlite3
import sys
from pathlib import Path
from typing import Any, Callable

__all__ = ["WATCHED_MODULES", "MUTATING_OS_CALLS", "Steps", "instrument_files", "instrument_sqlite_connect",
           "instrument_history", "instrument_heater", "write_all"]

#: Modules whose file-system calls are steps (the durable layer and everything that writes state through it).
WATCHED_MODULES = frozenset({"edge.storage.durable", "edge.storage.history", "edge.model.store", "edge.model.bundle",
                             "edge.model.container", "edge.model.loader", "edge.model.transport",
                             "edge.service.config", "edge.storage.calibration_store",
                             "edge.storage.objects_store"})
#: The os calls that change the file system (``open`` only with O_CREAT: opening to read, or to fsync a
#: directory, changes nothing).
MUTATING_OS_CALLS = ("open", "write", "fsync", "replace", "rename", "mkdir", "unlink", "rmdir")


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
            write_all(self.fd, f"{kind}\t{_normal(what)}\n".encode())
        if self.n == self.kill_at:
            os.kill(os.getpid(), signal.SIGKILL)

    def end(self) -> None:
        """The point after the last reply, then stop counting."""
        self.step("end", "after the last reply")
        self.done = True


_os_write = os.write  # the real one: the child's os.write is instrumented, and its own pipes are no steps


def write_all(fd: int, data: bytes) -> None:
    """Write all of ``data`` to ``fd`` with the real ``os.write`` (the child's own pipes are no steps)."""
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
