"""A simulated kernel sysfs PWM tree in a temporary directory.

The tree looks like ``/sys/class/pwm``::

    <root>/pwmchip0/{export, unexport, npwm}
    <root>/pwmchip0/pwm0/{period, duty_cycle, enable, polarity}   (times in ns)

How kernel rules are enforced (the design choice)
-------------------------------------------------
A plain directory cannot fail a ``write(2)`` with EINVAL the way sysfs does,
so the tree is backed by an in-memory kernel state and the files are a mirror
of it. Writes reach that state by two routes:

1. **Synchronously, through** :attr:`SimPwmTree.io` (an object with
   ``read(path)`` / ``write(path, text)``, the I/O seam of
   :class:`edge.hw.sysfs_pwm.SysfsPwm`). Each write is checked against the
   kernel's rules at once and either applied or refused with the same
   ``OSError`` errno the kernel returns (EINVAL, EBUSY, ENODEV, EACCES), the
   file left unchanged. The edge driver's write-then-read-back therefore
   behaves exactly as on a Pi. This is the route the simulated board uses.
2. **Raw file writes** (plain ``open().write()``, shell scripts, code that
   bypasses the seam) are picked up by :meth:`SimPwmTree.sync`, which runs on
   every virtual-clock advance and before every ``io`` call (on Linux it reads
   the files only when inotify saw a change in the tree since its last read:
   :class:`_DirWatch`). An invalid
   value is reverted and recorded in :attr:`SimPwmTree.violations` (it never
   reaches the simulated hardware). Limitation: several raw writes between
   two syncs are judged as one combined change, so their *order* (e.g.
   shrinking the period before the duty cycle) cannot be checked, and a
   read-back made before the next clock advance sees the unchecked value.

Kernel rules modelled (drivers/pwm/sysfs.c + pwm_apply_state): every applied
state needs ``period > 0`` and ``duty_cycle <= period`` (so the duty cycle,
and ``enable``, cannot be set before a period); ``enable`` accepts 0/1,
``polarity`` ``normal``/``inversed``; ``export`` of an exported channel is
EBUSY, of a channel >= npwm ENODEV; ``unexport`` of a channel that is not
exported is ENODEV; ``npwm`` is read-only. Unexporting does not stop the
output, as with most PWM controllers; device code must disable first.

The effective output over time, for the thermal world, is
:meth:`SimPwmTree.history` and :meth:`SimPwmTree.duty_at`.
"""

from __future__ import annotations

import bisect
import ctypes
import errno as _errno
import os
import struct
import shutil
import tempfile
import threading
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from edge.hw.sysfs_pwm import active_fraction

__all__ = ["PwmSample", "PwmViolation", "SimPwmTree", "SimSysfsIO"]

_U64_MAX = 2**64 - 1
_ATTRS = ("period", "duty_cycle", "enable", "polarity")


class PwmSample(NamedTuple):
    """State of one PWM channel from time ``t_s`` (s) on."""

    t_s: float
    period_ns: int
    duty_ns: int
    enabled: bool
    polarity: str

    @property
    def fraction(self) -> float:
        """Fraction of time the output is active (0 when disabled)."""
        return active_fraction(self.period_ns, self.duty_ns, self.enabled, self.polarity)


@dataclass(frozen=True)
class PwmViolation:
    """A raw write that broke a kernel rule and was reverted."""

    t_s: float
    path: str
    value: str
    reason: str


@dataclass
class _Channel:
    period: int = 0
    duty: int = 0
    enabled: bool = False
    polarity: str = "normal"
    exported: bool = False


def _err(code: int, path: Path | str, why: str) -> OSError:
    e = OSError(code, f"{os.strerror(code)} ({why})", str(path))
    return e


def _parse_u64(text: str, path: Path) -> int:
    s = text.strip()
    try:
        v = int(s, 0)
    except ValueError:
        raise _err(_errno.EINVAL, path, f"not an unsigned integer: {text!r}") from None
    if v < 0:
        raise _err(_errno.EINVAL, path, f"negative value {v}")
    if v > _U64_MAX:
        raise _err(_errno.ERANGE, path, f"value {v} does not fit in 64 bits")
    return v


def _check_state(ch: _Channel, path: Path) -> None:
    if ch.period == 0:
        raise _err(_errno.EINVAL, path, "period must be set (> 0) first")
    if ch.duty > ch.period:
        raise _err(_errno.EINVAL, path, f"duty_cycle {ch.duty} ns > period {ch.period} ns")


class SimSysfsIO:
    """Kernel-faithful ``read``/``write`` on a :class:`SimPwmTree` (see module doc)."""

    def __init__(self, tree: "SimPwmTree") -> None:
        self._tree = tree

    def read(self, path: str | os.PathLike) -> str:
        """Return the attribute's text like a sysfs read."""
        return self._tree._io_read(Path(path))

    def write(self, path: str | os.PathLike, text: str) -> None:
        """Write an attribute like a sysfs write; OSError if the kernel would refuse."""
        self._tree._io_write(Path(path), str(text))



class _Watched:
    """One tree's side of :class:`_DirWatch`: whether its files may have changed since its last read."""

    __slots__ = ("dirty", "wds", "pid", "closed")

    def __init__(self) -> None:
        self.dirty = True           # nothing read yet
        self.wds: set[int] = set()
        self.pid = os.getpid()
        self.closed = False


class _DirWatch:
    """Linux inotify on the trees' directories, one instance per process shared by its trees.

    A sync read seven files (three syscalls each) on every clock advance, 50 us of the ~400 us a
    simulated sample cost; the raw writes it looks for are rare. The kernel queues an event in the
    write itself, so "no event since the last read" means no file changed: a sync then reads none.
    Any event (ours included), a queue overflow or a watch the kernel dropped marks the tree for a
    full read, which re-adds its watches first (a write after that is an event, one before is read).
    """

    _IN_MODIFY, _IN_ATTRIB, _IN_CLOSE_WRITE = 0x2, 0x4, 0x8
    _IN_MOVED_FROM, _IN_MOVED_TO, _IN_CREATE, _IN_DELETE = 0x40, 0x80, 0x100, 0x200
    _IN_DELETE_SELF, _IN_MOVE_SELF = 0x400, 0x800
    _IN_Q_OVERFLOW, _IN_IGNORED = 0x4000, 0x8000
    _MASK = (_IN_MODIFY | _IN_ATTRIB | _IN_CLOSE_WRITE | _IN_MOVED_FROM | _IN_MOVED_TO | _IN_CREATE
             | _IN_DELETE | _IN_DELETE_SELF | _IN_MOVE_SELF)
    _IN_NONBLOCK, _IN_CLOEXEC = 0o4000, 0o2000000
    _EVENT = struct.Struct("iIII")

    def __init__(self) -> None:
        libc = ctypes.CDLL(None, use_errno=True)
        self._add = libc.inotify_add_watch
        self._add.argtypes = (ctypes.c_int, ctypes.c_char_p, ctypes.c_uint32)
        self._rm = libc.inotify_rm_watch
        self._rm.argtypes = (ctypes.c_int, ctypes.c_int)
        fd = libc.inotify_init1(self._IN_NONBLOCK | self._IN_CLOEXEC)
        if fd < 0:
            raise OSError(ctypes.get_errno(), "inotify_init1 failed")
        self.fd = fd
        self.pid = os.getpid()
        # Re-entrant: a tree's finalizer (forget) may run from the garbage collector inside poll.
        self._lock = threading.RLock()
        self._owners: dict[int, set[_Watched]] = {}

    def add(self, w: _Watched, path: Path) -> bool:
        """Watch directory ``path`` for ``w``; False if it cannot be (missing)."""
        with self._lock:
            wd = self._add(self.fd, os.fsencode(path), self._MASK)
            if wd < 0:
                return False
            w.wds.add(wd)
            self._owners.setdefault(wd, set()).add(w)
            return True

    def poll(self) -> None:
        """Mark the trees whose directories saw an event since the last poll."""
        with self._lock:
            while True:
                try:
                    buf = os.read(self.fd, 65536)
                except BlockingIOError:
                    return
                off = 0
                while off + 16 <= len(buf):
                    wd, mask, _cookie, n = self._EVENT.unpack_from(buf, off)
                    off += 16 + n
                    if mask & self._IN_Q_OVERFLOW:
                        for ws in self._owners.values():
                            for w in ws:
                                w.dirty = True
                        continue
                    for w in list(self._owners.get(wd, ())):
                        w.dirty = True
                        if mask & self._IN_IGNORED:
                            w.wds.discard(wd)
                    if mask & self._IN_IGNORED:
                        self._owners.pop(wd, None)

    def forget(self, w: _Watched) -> None:
        """Drop ``w``'s watches (those no other tree shares)."""
        with self._lock:
            w.closed = True
            for wd in w.wds:
                ws = self._owners.get(wd)
                if ws is not None:
                    ws.discard(w)
                    if not ws:
                        del self._owners[wd]
                        self._rm(self.fd, wd)
            w.wds.clear()


_WATCH: _DirWatch | None = None
_WATCH_PID: int | None = None     # the process _WATCH was tried in (None: never)
_WATCH_LOCK = threading.Lock()


def _dir_watch() -> _DirWatch | None:
    """This process's :class:`_DirWatch` (None where inotify is unavailable: every sync reads)."""
    global _WATCH, _WATCH_PID, _WATCH_LOCK
    pid = os.getpid()
    if _WATCH_PID == pid:
        return _WATCH
    if _WATCH_PID is not None:
        # A forked child: the inherited instance is the parent's (reading it would take the parent's
        # events), and the inherited lock may have been held by a thread that does not exist here.
        _WATCH_LOCK = threading.Lock()
        if _WATCH is not None:
            try:
                os.close(_WATCH.fd)
            except OSError:
                pass
            _WATCH = None
    with _WATCH_LOCK:
        if _WATCH_PID != pid:
            try:
                _WATCH = _DirWatch()
            except (OSError, AttributeError):   # not Linux, or out of inotify instances
                _WATCH = None
            _WATCH_PID = pid
    return _WATCH


def _drop_watch() -> None:
    """Stop using this process's inotify instance: every sync reads its files again."""
    global _WATCH
    _WATCH = None


def _forget_watch(w: _Watched) -> None:
    watch = _dir_watch() if w.wds else None
    if watch is not None and w.pid == os.getpid():
        watch.forget(w)
    w.closed = True


def _remove_tree(root: str, owner_pid: int) -> None:
    """Remove a simulated sysfs tree, in the process that created it only."""
    if os.getpid() == owner_pid:
        shutil.rmtree(root, ignore_errors=True)

class SimPwmTree:
    """A sysfs PWM class directory backed by a simulated PWM controller.

    Parameters
    ----------
    clock : VirtualClock
        Simulated time for history stamps; raw writes are synced on each advance.
    root : path, optional
        Directory to build the tree in (must not contain ``pwmchip*``
        already). Default: a new temporary directory removed by :meth:`close`.
    chips : dict of int to int, optional
        ``{chip_index: npwm}``; default one chip with two channels, like the
        Raspberry Pi's PWM0.
    initial_period_ns : int
        Period a channel reports before anyone sets it (0 on most drivers).
    """

    def __init__(
        self,
        clock: Any,
        root: str | os.PathLike | None = None,
        *,
        chips: dict[int, int] | None = None,
        initial_period_ns: int = 0,
    ) -> None:
        if not isinstance(initial_period_ns, int) or initial_period_ns < 0:
            raise ValueError(f"initial_period_ns must be an int >= 0, got {initial_period_ns!r}")
        chips = {0: 2} if chips is None else dict(chips)
        for idx, n in chips.items():
            if not isinstance(idx, int) or idx < 0 or not isinstance(n, int) or n <= 0:
                raise ValueError(f"chips must map chip index >= 0 to npwm > 0, got {idx!r}: {n!r}")
        self.clock = clock
        self._owns_root = root is None
        self.root = Path(tempfile.mkdtemp(prefix="sim-pwm-")) if root is None else Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self._root_resolved: Path | None = None
        self._parts_of: dict[str, tuple[str, ...] | None] = {}
        # A tree nobody closed (a simulator dropped mid-test, a session ended by an exception) is
        # still removed when the object is collected or the interpreter exits: ten thousand
        # leaked trees had piled up in /tmp before this.  Only by the process that made it: a forked
        # child (a test's daemon) inherits the parent's trees, and its collector must not delete them.
        self._cleanup = (weakref.finalize(self, _remove_tree, str(self.root), os.getpid())
                         if self._owns_root else None)
        self._lock = threading.RLock()
        self._watched = _Watched()
        self._unwatch = weakref.finalize(self, _forget_watch, self._watched)
        self._npwm = chips
        self._mirror: dict[Path, str] = {}
        # sync() runs on every clock step and bus transfer: its paths are built once, not per call.
        self._channel_files: dict[tuple[int, int], tuple[Path, tuple[tuple[str, Path], ...]]] = {}
        self._channels: dict[tuple[int, int], _Channel] = {}
        self._history: dict[tuple[int, int], list[PwmSample]] = {}
        #: Raw writes that broke a kernel rule and were reverted.
        self.violations: list[PwmViolation] = []
        self.io = SimSysfsIO(self)
        t0 = clock.now()
        for idx, n in chips.items():
            cdir = self.chip_dir(idx)
            if cdir.exists():
                raise ValueError(f"root {self.root} already contains {cdir.name}")
            cdir.mkdir()
            self._put(cdir / "export", "")
            self._put(cdir / "unexport", "")
            self._put(cdir / "npwm", f"{n}\n")
            for c in range(n):
                self._channels[(idx, c)] = _Channel(period=initial_period_ns)
                self._history[(idx, c)] = [PwmSample(t0, initial_period_ns, 0, False, "normal")]
        clock.on_advance(self._on_advance)

    # ---- paths

    def chip_dir(self, chip: int = 0) -> Path:
        """``<root>/pwmchipN``."""
        return self.root / f"pwmchip{chip}"

    def channel_dir(self, chip: int = 0, channel: int = 0) -> Path:
        """``<root>/pwmchipN/pwmM``."""
        return self.chip_dir(chip) / f"pwm{channel}"

    # ---- observation (simulator side)

    def _key(self, chip: int, channel: int) -> tuple[int, int]:
        if (chip, channel) not in self._channels:
            raise ValueError(f"no PWM channel {channel} on chip {chip} in {self.root}")
        return (chip, channel)

    def is_exported(self, chip: int = 0, channel: int = 0) -> bool:
        """Whether the channel is currently exported."""
        with self._lock:
            return self._channels[self._key(chip, channel)].exported

    def state(self, chip: int = 0, channel: int = 0) -> PwmSample:
        """Current state of the channel (as its latest history sample)."""
        return self.history(chip, channel)[-1]

    def live_history(self, chip: int = 0, channel: int = 0) -> list[PwmSample]:
        """The append-only list behind :meth:`history` (read it, never modify it; no copy per call)."""
        return self._history[self._key(chip, channel)]

    def history(self, chip: int = 0, channel: int = 0) -> list[PwmSample]:
        """Every accepted state change of the channel, oldest first."""
        with self._lock:
            return list(self._history[self._key(chip, channel)])

    def duty_at(self, t_s: float, chip: int = 0, channel: int = 0) -> float:
        """Fraction of time the output is active at simulated time ``t_s`` (0..1)."""
        hist = self.history(chip, channel)
        i = bisect.bisect_right([h.t_s for h in hist], t_s) - 1
        return hist[i].fraction if i >= 0 else 0.0

    # ---- lifecycle

    def close(self) -> None:
        """Remove the tree if this object created it (idempotent)."""
        self._unwatch()
        if self._cleanup is not None:
            self._cleanup()

    def __enter__(self) -> SimPwmTree:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ---- internals: files

    def _put(self, path: Path, text: str) -> None:
        # os-level, like _read: Path.write_text's text-wrapper set-up costs more than the write,
        # and the simulator rewrites a channel's four files after every accepted change.
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666)
        try:
            os.write(fd, text.encode())
        finally:
            os.close(fd)
        self._mirror[path] = text

    def _record(self, key: tuple[int, int], t: float) -> None:
        ch = self._channels[key]
        s = PwmSample(t, ch.period, ch.duty, ch.enabled, ch.polarity)
        hist = self._history[key]
        if hist[-1][1:] != s[1:]:
            hist.append(s)

    def _write_channel_files(self, key: tuple[int, int], *, changed_only: bool = False) -> None:
        """Write the channel's four attribute files from its kernel state.

        ``changed_only``: skip a file whose text is what it already holds -- right after a
        :meth:`sync` (which leaves every file equal to its mirror), where one accepted write changes
        one attribute and rewriting all four was most of the simulated PWM's cost per duty change.
        """
        ch = self._channels[key]
        text = {"period": f"{ch.period}\n", "duty_cycle": f"{ch.duty}\n", "enable": f"{int(ch.enabled)}\n",
                "polarity": f"{ch.polarity}\n"}
        for name, p in self._files(*key)[1]:
            if not (changed_only and self._mirror.get(p) == text[name]):
                self._put(p, text[name])

    def _relative_parts(self, path: Path) -> tuple[str, ...] | None:
        """``path``'s parts below the tree's root (symlinks resolved), None outside it; kept per path.

        Resolving walks every component with a system call, twice (the path and the root), on each
        of a touch's hundreds of duty writes and reads: it was most of the simulated PWM's cost in the
        suite.  The tree holds no symlinks of its own, and the answer for a path is kept only while
        the tree lives (a user's symlink to it is resolved once, as the kernel's sysfs links are fixed).
        """
        key = str(path)
        parts = self._parts_of.get(key, False)
        if parts is False:
            if self._root_resolved is None:
                self._root_resolved = self.root.resolve()
            try:
                parts = path.resolve().relative_to(self._root_resolved).parts
            except ValueError:
                parts = None
            if len(self._parts_of) < 4096:
                self._parts_of[key] = parts
        return parts

    def _resolve(self, path: Path) -> tuple[int, int | None, str]:
        """Map a path to (chip, channel or None, attribute name)."""
        parts = self._relative_parts(path)
        if parts is None:
            raise _err(_errno.ENOENT, path, f"not inside the simulated PWM tree {self.root}")
        try:
            if len(parts) == 2 and parts[0].startswith("pwmchip"):
                chip = int(parts[0][7:])
                if chip in self._npwm and parts[1] in ("export", "unexport", "npwm"):
                    return chip, None, parts[1]
            if len(parts) == 3 and parts[0].startswith("pwmchip") and parts[1].startswith("pwm"):
                chip, channel = int(parts[0][7:]), int(parts[1][3:])
                key = (chip, channel)
                if key in self._channels and self._channels[key].exported and parts[2] in _ATTRS:
                    return chip, channel, parts[2]
        except ValueError:
            pass
        raise _err(_errno.ENOENT, path, "no such sysfs attribute")

    # ---- internals: kernel semantics

    def _export(self, chip: int, text: str, path: Path) -> None:
        n = _parse_u64(text, path)
        if n >= self._npwm[chip]:
            raise _err(_errno.ENODEV, path, f"channel {n} >= npwm {self._npwm[chip]}")
        ch = self._channels[(chip, n)]
        if ch.exported:
            raise _err(_errno.EBUSY, path, f"channel {n} is already exported")
        ch.exported = True
        self.channel_dir(chip, n).mkdir(exist_ok=True)
        self._write_channel_files((chip, n))

    def _unexport(self, chip: int, text: str, path: Path) -> None:
        n = _parse_u64(text, path)
        if n >= self._npwm[chip] or not self._channels[(chip, n)].exported:
            raise _err(_errno.ENODEV, path, f"channel {n} is not exported")
        self._channels[(chip, n)].exported = False
        d = self.channel_dir(chip, n)
        for name in _ATTRS:
            self._mirror.pop(d / name, None)
        shutil.rmtree(d, ignore_errors=True)

    def _apply_attr(self, key: tuple[int, int], attr: str, text: str, path: Path) -> None:
        """Apply one attribute write to the kernel state, or raise like the kernel."""
        saved = self._channels[key]
        self._apply_attr_unchecked(key, attr, text, path)
        try:
            _check_state(self._channels[key], path)
        except OSError:
            self._channels[key] = saved
            raise

    def _io_write(self, path: Path, text: str) -> None:
        with self._lock:
            self.sync()
            chip, channel, attr = self._resolve(path)
            t = self.clock.now()
            if channel is None:
                if attr == "npwm":
                    raise _err(_errno.EACCES, path, "npwm is read-only")
                (self._export if attr == "export" else self._unexport)(chip, text, path)
                return
            key = (chip, channel)
            self._apply_attr(key, attr, text, path)
            # sync() above left every file equal to its mirror.
            self._write_channel_files(key, changed_only=True)
            self._record(key, t)

    def _io_read(self, path: Path) -> str:
        with self._lock:
            self.sync()
            chip, channel, attr = self._resolve(path)
            if channel is None and attr != "npwm":
                raise _err(_errno.EACCES, path, f"{attr} is write-only")
            return self._mirror[path if path in self._mirror else self._canonical(chip, channel, attr)]

    def _canonical(self, chip: int, channel: int | None, attr: str) -> Path:
        base = self.chip_dir(chip) if channel is None else self.channel_dir(chip, channel)
        return base / attr

    def _on_advance(self, t_old: float, t_new: float) -> None:
        # Raw writes were made while time stood at t_old.
        self.sync(t_old)

    def sync(self, t_s: float | None = None) -> None:
        """Pick up raw file writes: apply valid ones, revert and record invalid ones.

        ``t_s`` is the time stamp for accepted changes (default: now).
        """
        with self._lock:
            if self._unchanged():
                return
            t = self.clock.now() if t_s is None else float(t_s)
            for chip in self._npwm:
                _, (export, unexport, npwm) = self._files(chip, None)
                for name, p in (export, unexport):
                    text = _read(p)
                    if text == self._mirror.get(p) or text is None:
                        continue
                    self._put(p, "")
                    for tok in text.split():
                        try:
                            (self._export if name == "export" else self._unexport)(chip, tok, p)
                        except OSError as e:
                            self.violations.append(PwmViolation(t, str(p), tok, e.strerror or str(e)))
                p = npwm[1]
                if _read(p) != self._mirror.get(p):
                    self.violations.append(PwmViolation(t, str(p), _read(p) or "", "npwm is read-only"))
                    self._put(p, self._mirror[p])
            for key, ch in self._channels.items():
                if ch.exported:
                    self._sync_channel(key, t)

    def _unchanged(self) -> bool:
        """Whether no file of the tree can have changed since the last full read (:class:`_DirWatch`).

        False re-adds the watches before the caller reads: a write after that is an event.
        """
        watch, w = _dir_watch(), self._watched
        if watch is None or w.closed:
            return False
        if w.pid != os.getpid():            # a forked child's inherited tree: watch it from here
            w.pid, w.wds, w.dirty = os.getpid(), set(), True
        try:
            watch.poll()
        except OSError:                     # the instance is gone (its fd closed under us): read from now on
            _drop_watch()
            return False
        if not w.dirty:
            return True
        w.dirty = False
        dirs = [self.chip_dir(chip) for chip in self._npwm]
        dirs += [self._files(*key)[0] for key, ch in self._channels.items() if ch.exported]
        for d in dirs:
            if not watch.add(w, d):
                w.dirty = True              # missing (the read recreates a channel's): read again next time
        return False

    def _files(self, chip: int, channel: int | None) -> tuple[Path, tuple[tuple[str, Path], ...]]:
        """A directory and its watched files (cached: Path arithmetic dominated sync())."""
        key = (chip, -1 if channel is None else channel)
        got = self._channel_files.get(key)
        if got is None:
            if channel is None:
                d = self.chip_dir(chip)
                got = (d, tuple((n, d / n) for n in ("export", "unexport", "npwm")))
            else:
                d = self.channel_dir(chip, channel)
                got = (d, tuple((n, d / n) for n in _ATTRS))
            self._channel_files[key] = got
        return got

    def _sync_channel(self, key: tuple[int, int], t: float) -> None:
        d, files = self._files(*key)
        if not os.path.isdir(d):
            d.mkdir(parents=True)
        changed = {}
        for name, p in files:
            text = _read(p)
            if text != self._mirror.get(p):
                changed[name] = "" if text is None else text
        if not changed:
            return
        saved = self._channels[key]
        try:
            for name in ("period", "duty_cycle", "enable", "polarity"):
                if name in changed:
                    # Each value alone must parse; the combination must be valid.
                    self._apply_attr_unchecked(key, name, changed[name], d / name)
            _check_state(self._channels[key], d / next(iter(changed)))
        except OSError as e:
            self._channels[key] = saved
            for name, text in changed.items():
                self.violations.append(PwmViolation(t, str(d / name), text, e.strerror or str(e)))
        self._write_channel_files(key)
        self._record(key, t)

    def _apply_attr_unchecked(self, key: tuple[int, int], attr: str, text: str, path: Path) -> None:
        ch = self._channels[key]
        new = _Channel(ch.period, ch.duty, ch.enabled, ch.polarity, ch.exported)
        if attr == "period":
            new.period = _parse_u64(text, path)
        elif attr == "duty_cycle":
            new.duty = _parse_u64(text, path)
        elif attr == "enable":
            v = _parse_u64(text, path)
            if v not in (0, 1):
                raise _err(_errno.EINVAL, path, f"enable must be 0 or 1, got {v}")
            new.enabled = bool(v)
        else:
            s = text.strip()
            if s not in ("normal", "inversed"):
                raise _err(_errno.EINVAL, path, f"polarity must be 'normal' or 'inversed', got {text!r}")
            new.polarity = s
        self._channels[key] = new


def _read(p: Path) -> str | None:
    # os-level read: sysfs attribute files are tiny, and Path.read_text's
    # text-wrapper set-up was most of the simulator's cost per step.
    try:
        fd = os.open(p, os.O_RDONLY)
    except OSError:
        return None
    try:
        return os.read(fd, 4096).decode()
    except (OSError, UnicodeDecodeError):
        return None
    finally:
        os.close(fd)
