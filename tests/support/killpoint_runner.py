"""Kill points' runner: an operation, its forked children (or a fork server's), the restart check.

:func:`dry_run` runs an :class:`Operation` once in a forked child and lists its steps;
:func:`kill_at` forks again and kills the child right before step N, then checks the
operation's invariants on what it left; :func:`run_all` does both for every step.
:func:`child_daemon` and :func:`full_restart` start the daemon on a point's state as
``thermotouch-edge`` would. The overview is :mod:`tests.support.killpoints`.
"""

from __future__ import annotations

import gc
import importlib
import json
import os
import select
import shutil
import signal
import stat
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
from tests.support.killpoint_steps import (Steps, instrument_files, instrument_heater, instrument_history,
                                           instrument_sqlite_connect, write_all)

__all__ = ["CHILD_TIMEOUT_s", "EXIT_CRASHED", "Operation", "PointResult", "warm_up", "dry_run", "kill_at", "run_all",
           "work_root", "child_daemon", "heater_line", "full_restart", "open_model_store"]

#: Longest a child may take (a fork that inherited a held lock would hang; fail instead).
CHILD_TIMEOUT_s = 30.0
EXIT_CRASHED = 70


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
    faults : tuple of str
        ``"module:function"`` names, each called with no argument first thing in every child (and
        only there): a fault the harness's own tests put into the code under test (see
        :mod:`tests.support.killpoint_faults`), so that their children too can be forked from a
        fork server rather than inherit a monkeypatch of the test process.
    """

    name: str
    template: Path
    requests: list[tuple[Command, dict]]
    check: Callable[[Path, list[dict]], list[str]] | None
    store_root: Path | None = None
    instrument: tuple[str, ...] = ()
    #: The daemon's start-up is the operation: instrument first, then build the daemon.
    startup: bool = False
    faults: tuple[str, ...] = ()
    _store: Any = field(default=None, init=False, repr=False, compare=False)
    #: Where :meth:`spec` wrote the child side (set by :func:`dry_run` on a fork server).
    spec_path: Path | None = field(default=None, init=False, repr=False, compare=False)

    def make_daemon(self, point_dir: Path) -> Any:
        """The daemon of the child, as ``thermotouch-edge`` starts it on ``point_dir``."""
        if self.store_root is None:
            return child_daemon(point_dir)
        return child_daemon(point_dir, model_store=self.shared_store())

    def shared_store(self) -> Any:
        """The verified store of :attr:`store_root` (one per directory and process, whichever operation
        opened it first: these operations leave the model alone, and a daemon never closes a store it was
        handed)."""
        if self._store is None:
            key = str(self.store_root)
            if key not in _SHARED_STORES:
                store = open_model_store(Path(tempfile.mkdtemp(prefix="shared-store-", dir=self.store_root)))
                store.current()
                _SHARED_STORES[key] = store
            self._store = _SHARED_STORES[key]
        return self._store

    def spec(self) -> Path:
        """Write what a child needs (everything but ``check``) as JSON beside the template; return its path.

        Request arguments that are bytes (model chunks) are written as ``{"bytes_hex": ...}``.
        """
        path = self.template.with_name(self.template.name + ".spec.json")
        doc = {"name": self.name, "template": str(self.template),
               "requests": [[c.name, {k: {"bytes_hex": v.hex()} if isinstance(v, bytes) else v for k, v in a.items()}]
                            for c, a in self.requests],
               "store_root": None if self.store_root is None else str(self.store_root),
               "instrument": list(self.instrument), "startup": self.startup,
               "faults": list(self.faults)}
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
                   doc["startup"], tuple(doc["faults"]))


@dataclass
class PointResult:
    """What one kill point gave: the step it died before, the replies the host had, what broke."""

    n: int
    step: str
    confirmed: int
    problems: list[str] = field(default_factory=list)
    seconds: float = 0.0


#: Verified stores of :meth:`Operation.shared_store`, by their ``store_root``.
_SHARED_STORES: dict[str, Any] = {}

#: Uploads: the session their BEGIN's reply names goes into their CHUNKs and COMMIT.
_BEGINS = (Command.MODEL_BEGIN, Command.OBJECTS_BEGIN)
_IN_SESSION = (Command.MODEL_CHUNK, Command.MODEL_COMMIT, Command.OBJECTS_CHUNK, Command.OBJECTS_COMMIT)


def _child(op: Operation, point_dir: Path, n: int | None, trace_fd: int, host_fd: int) -> None:
    for name in op.faults:
        module, _, function = name.partition(":")
        getattr(importlib.import_module(module), function)()
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
        if session is not None and command in _IN_SESSION:
            args = {**args, "session": session}
        try:
            body = daemon.handle(Request(command, i + 1, dict(args)))
        except CommandError as e:
            body = {"error": str(e.code), "message": e.message}
        if command in _BEGINS and body and "session" in body:
            session = body["session"]
        steps.step("host", f"reply {command.name}")
        write_all(host_fd, (json.dumps({"command": command.name, "body": body}, default=str) + "\n").encode())
    steps.end()
    daemon.close()


def _child_process(op: Operation, point_dir: Path, n: int | None, trace_w: int, host_w: int, err_w: int) -> None:
    """The forked child's whole life: the operation, then ``os._exit`` (or the SIGKILL at step ``n``)."""
    status = EXIT_CRASHED
    try:
        _child(op, point_dir, n, trace_w, host_w)
        status = 0
    except BaseException:
        # sys.stderr may be the test runner's capture object: write to the pipe itself.
        write_all(err_w, traceback.format_exc().encode())
    finally:
        os._exit(status)


#: The fork server's operations, by the path of their spec (filled in the server by :func:`_prepare_in_server`).
_SERVER_OPS: dict[str, Operation] = {}


#: Names of the operations the fork server has warmed up (:func:`_prepare_in_server`).
_WARMED: set[str] = set()


def _prepare_in_server(spec: str) -> None:
    """Fork-server side of :func:`dry_run`: rebuild the operation and warm it up there, once per name.

    An operation of a name already warmed up in this server (the harness's own tests run the same
    operations again, with a fault in the children or fewer keys) takes the code paths that warm-up
    took: what it imported and cached is here already, so only its shared store is made sure of.
    """
    op = Operation.from_spec(Path(spec))
    if op.name in _WARMED:
        if op.store_root is not None:
            op.shared_store()
    else:
        warm_up(op, op.template.parent)  # every builder makes its template in the operation's root
        _WARMED.add(op.name)
    _SERVER_OPS[spec] = op


def _point_in_server(arg: dict, fds: list[int]) -> None:  # pragma: no cover - runs in the server's child
    trace_w, host_w, err_w = fds
    _child_process(_SERVER_OPS[arg["spec"]], Path(arg["point"]), arg["n"], trace_w, host_w, err_w)


class _Running:
    """One forked child (of this process or of a fork server) and the three pipes it writes: trace, host, stderr."""

    def __init__(self, op: Operation, point_dir: Path, n: int | None, server: Any = None) -> None:
        if server is not None and op.spec_path is None:
            raise ValueError(f"{op.name}: not prepared on this fork server (run dry_run with it first)")
        self.op, self.point, self.n = op, point_dir, n
        trace_r, trace_w = os.pipe()
        host_r, host_w = os.pipe()
        err_r, err_w = os.pipe()
        self.child = None
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
                self.child = server.start_call("tests.support.killpoint_runner:_point_in_server",
                                               {"spec": str(op.spec_path), "point": str(point_dir), "n": n},
                                               [trace_w, host_w, err_w])
            except BaseException:
                for fd in (trace_r, host_r, err_r, trace_w, host_w, err_w):
                    os.close(fd)
                raise
            pid = self.child.pid
        self.pid = pid
        for fd in (trace_w, host_w, err_w):
            os.close(fd)
        self.fds = (trace_r, host_r, err_r)
        self.bufs: dict[int, bytearray] = {fd: bytearray() for fd in self.fds}
        self.open_fds = set(self.fds)
        self.deadline = time.monotonic() + CHILD_TIMEOUT_s
        self.t0 = time.perf_counter()
        self.code: int | None = None

    def read(self, fd: int) -> None:
        chunk = os.read(fd, 65536)
        if chunk:
            self.bufs[fd] += chunk
        else:
            self.open_fds.discard(fd)

    def kill_if_late(self) -> None:
        if time.monotonic() > self.deadline:
            os.kill(self.pid, signal.SIGKILL)  # our own child, hung: fail the point instead of the suite
            raise TimeoutError(f"{self.op.name}: child for point {self.n} did not finish in {CHILD_TIMEOUT_s} s")

    def finish(self) -> tuple[int, list[str], list[dict], str]:
        """Close the pipes, wait for the child; (exit code, trace, replies, stderr tail)."""
        for fd in self.fds:
            os.close(fd)
        self.open_fds.clear()
        if self.child is None:
            self.code = os.waitstatus_to_exitcode(os.waitpid(self.pid, 0)[1])
        else:
            self.code = self.child.wait()
        trace_r, host_r, err_r = self.fds
        trace = self.bufs[trace_r].decode().splitlines()
        replies = [json.loads(line) for line in self.bufs[host_r].decode().splitlines()]
        return self.code, trace, replies, self.bufs[err_r].decode()[-3000:]

    def abandon(self) -> None:
        """After a failure elsewhere: kill the child if it still runs, reap it, close the pipes."""
        if self.code is not None:
            return
        try:
            os.kill(self.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.finish()


def _pump(running: list[_Running]) -> list[_Running]:
    """Read whatever the running children wrote (waiting for the first bytes or end of file); return the
    children whose pipes have all closed (the child is dead or about to be)."""
    by_fd = {fd: r for r in running for fd in r.open_fds}
    left = min(r.deadline for r in running) - time.monotonic()
    ready, _, _ = select.select(list(by_fd), [], [], max(left, 0.0)) if by_fd else ([], [], [])
    for fd in ready:
        by_fd[fd].read(fd)
    for r in running:
        if r.open_fds:
            r.kill_if_late()
    return [r for r in running if not r.open_fds]


def _pipe_step(arg: str, fds: list[int]) -> None:  # pragma: no cover - runs in the server's child
    """A fork-server child for the server's own test: ``"send"`` writes a byte to ``fds[0]``; ``"relay"``
    waits for a byte on ``fds[0]`` and passes it on to ``fds[1]``."""
    status = EXIT_CRASHED
    try:
        write_all(fds[-1], b"x" if arg == "send" else os.read(fds[0], 1))
        status = 0
    finally:
        os._exit(status)


def _run_child(op: Operation, point_dir: Path, n: int | None, server: Any = None
               ) -> tuple[int, list[str], list[dict], str]:
    """Fork, run the operation (dying before step ``n``), return (exit code, trace, replies, stderr tail).

    The exit code is :attr:`subprocess.Popen.returncode`'s: ``-SIGKILL`` for the kill. ``server``: a
    :class:`~tests.support.daemon_proc.ForkServer` the operation was prepared on (:func:`dry_run`);
    None: fork this process.
    """
    run = _Running(op, point_dir, n, server)
    try:
        while run.open_fds:
            _pump([run])
    except BaseException:
        run.abandon()
        raise
    return run.finish()


#: Each template's directories and files as read once: (directories top-down, files), see :func:`_snapshot`.
#: Keyed by the template's path (each a fresh ``mkdtemp``, complete before its operation runs); this process only.
_TEMPLATES: dict[Path, tuple[list, list] | None] = {}


def _snapshot(template: Path) -> tuple[list, list] | None:
    """The template's directories (relative path, mode, atime, mtime) top-down and its regular files (relative
    path, bytes, mode, atime, mtime); None if it holds anything else (a link), which :func:`shutil.copytree`
    then copies."""
    dirs, files = [], []
    for dirpath, dirnames, filenames in os.walk(template):
        st = os.stat(dirpath)
        dirs.append((os.path.relpath(dirpath, template), st.st_mode, st.st_atime_ns, st.st_mtime_ns))
        for name in dirnames + filenames:
            path = os.path.join(dirpath, name)
            st = os.lstat(path)
            if name in filenames:
                if not stat.S_ISREG(st.st_mode):
                    return None
                with open(path, "rb") as fh:
                    files.append((os.path.relpath(path, template), fh.read(), st.st_mode, st.st_atime_ns,
                                  st.st_mtime_ns))
            elif stat.S_ISLNK(st.st_mode):
                return None
    return dirs, files


def _copy_template(op: Operation, point: Path) -> None:
    """What ``shutil.copytree(op.template, point)`` makes (the bytes, modes and times of every file and
    directory), from the template read once: a point's copy was ~1 ms of copytree's per-file stat, sendfile,
    copystat and xattr calls, ~350 times a run."""
    if op.template not in _TEMPLATES:
        _TEMPLATES[op.template] = _snapshot(op.template)
    snap = _TEMPLATES[op.template]
    if snap is None:
        shutil.copytree(op.template, point)
        return
    dirs, files = snap
    point.parent.mkdir(parents=True, exist_ok=True)
    for rel, *_ in dirs:
        os.mkdir(os.path.join(point, rel) if rel != "." else point)
    for rel, data, mode, atime_ns, mtime_ns in files:
        path = os.path.join(point, rel)
        with open(path, "xb") as fh:
            fh.write(data)
        os.chmod(path, stat.S_IMODE(mode))
        os.utime(path, ns=(atime_ns, mtime_ns))
    for rel, mode, atime_ns, mtime_ns in reversed(dirs):  # innermost first, as copytree's copystat after the contents
        path = os.path.join(point, rel) if rel != "." else str(point)
        os.chmod(path, stat.S_IMODE(mode))
        os.utime(path, ns=(atime_ns, mtime_ns))


def _fresh_point(op: Operation, root: Path, tag: str) -> Path:
    # The same base name at every point: step labels name it (``mkdir state``), and the dry run's must match.
    point = root / f"{op.name}-{tag}" / "state"
    if point.parent.exists():
        shutil.rmtree(point.parent)
    _copy_template(op, point)
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
            if session is not None and command in _IN_SESSION:
                args = {**args, "session": session}
            body = daemon.handle(Request(command, i + 1, dict(args)))
            if command in _BEGINS:
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
        server.prepare("tests.support.killpoint_runner:_prepare_in_server", str(op.spec_path))
    point = _fresh_point(op, root, "dry")
    code, trace, replies, err = _run_child(op, point, None, server)
    if code != 0:
        raise AssertionError(f"{op.name}: the dry run failed (exit code {code}):\n{err}")
    problems = op.check(point, replies)
    if problems:
        raise AssertionError(f"{op.name}: the operation run to its end breaks its own invariants: {problems}")
    shutil.rmtree(point.parent)
    return trace, replies


def _judge(run: _Running, expected_step: str, keep: bool) -> PointResult:
    """The restart check of a kill point whose child's pipes have closed."""
    code, trace, replies, err = run.finish()
    res = PointResult(run.n, expected_step, len(replies))
    if code != -signal.SIGKILL:
        res.problems.append(f"child was not killed at step {run.n} (exit code {code}): {err}")
    elif trace != [expected_step]:
        res.problems.append(f"child died at {trace}, the dry run had {expected_step!r} (not deterministic)")
    else:
        res.problems += run.op.check(run.point, replies)
    if not keep:
        shutil.rmtree(run.point.parent)
    res.seconds = time.perf_counter() - run.t0
    return res


def kill_at(op: Operation, root: Path, n: int, expected_step: str, *, keep: bool = False,
            server: Any = None) -> PointResult:
    """Kill the operation right before step ``n``, restart, check; the point's directory
    (``root/<op>-k<n>/state``) is removed unless ``keep``. ``server``: as for :func:`dry_run`, which
    must have run on it first."""
    return _kill_points(op, root, [(n, expected_step)], lambda n: keep, server, jobs=1)[0]


#: Kill points whose children run at a time. Each child is CPU-bound (its daemon's start and the
#: operation up to the point, ~15-30 ms) and the test process checks a dead child's state meanwhile:
#: two keep both cores of the machine busy when nothing else runs; more only queue.
KILL_JOBS = 2


def _kill_points(op: Operation, root: Path, points: list[tuple[int, str]], keep: Callable[[int], bool],
                 server: Any, jobs: int) -> list[PointResult]:
    """Kill at each (n, expected step) of ``points``, up to ``jobs`` children at a time; results in that order."""
    todo = list(reversed(points))
    running: list[_Running] = []
    expected: dict[int, str] = dict(points)
    results: dict[int, PointResult] = {}
    try:
        while todo or running:
            while todo and len(running) < jobs:
                n, _ = todo.pop()
                running.append(_Running(op, _fresh_point(op, root, f"k{n}"), n, server))
            for run in _pump(running):
                running.remove(run)
                results[run.n] = _judge(run, expected[run.n], keep(run.n))
    except BaseException:
        for run in running:
            run.abandon()
        raise
    return [results[n] for n, _ in points]


def run_all(op: Operation, root: Path, *, keep: Callable[[list[str]], Collection[int]] | None = None,
            server: Any = None, jobs: int = KILL_JOBS) -> tuple[list[str], list[PointResult]]:
    """Dry run, then a kill before every step, ``jobs`` children at a time; returns (steps, results).

    ``keep(steps)``: the points whose directories stay for a later look (a full restart), so that
    they need not be killed a second time. ``server``: as for :func:`dry_run`.
    """
    trace, _ = dry_run(op, root, server)
    kept = set(keep(trace)) if keep is not None else set()
    return trace, _kill_points(op, root, list(enumerate(trace, 1)), kept.__contains__, server, jobs)


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




def open_model_store(point: Path) -> Any:
    """The model store under ``point`` as the simulated daemon opens it (shipped bundle, development policy)."""
    from edge.estimation.estimate import pipeline_golden_check
    from edge.model.bundle import limits_for_ram
    from edge.model.store import ModelStore
    from edge.service.config import Config
    from thermotouch_models import DEFAULT_BUNDLE

    from edge.security.policy import UpdatePolicy

    # A development policy, as the simulated daemon's: these kill points are about durability, not signatures.
    return ModelStore(point / "models", DEFAULT_BUNDLE, golden_check=pipeline_golden_check,
                      limits=limits_for_ram(Config().limits.ram_bytes), policy=UpdatePolicy(allow_unsigned=True))
