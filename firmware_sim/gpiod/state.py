"""The simulated GPIO lines' state in a directory, where it outlives the process that drives them.

A real kernel keeps a line's state when the process that requested it dies,
and releases that process's line requests (closing their file descriptors).
The simulated kernel (:class:`firmware_sim.gpiod.kernel.GpioSim`) lives inside the
device code's process, so it dies with it; with ``GpioSim(clock,
state_dir=DIR)`` every line change is mirrored to ``DIR/<chip>/<offset>.json``
(written atomically) together with the pid of the process holding the line.

:func:`read_line` is the kernel's view from another process (a test that
has just killed the daemon): if the holder is dead, its request is released
as the kernel would -- with :func:`released_level` -- so an output line
requested with a pull-down bias reads low, one with no bias keeps its level.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

__all__ = ["LineStateDir", "released_level", "read_line", "pid_alive"]


def released_level(direction: str, bias: str, level: int) -> int:
    """Physical level of a line once its request is released (the kernel frees the line).

    The freed line stops being driven and returns to an input: a pull-up or
    pull-down bias decides its level. With no bias (``AS_IS``/``DISABLED``)
    nothing pulls it, and like most GPIO controllers (and the Raspberry Pi
    kernel that keeps freed outputs by default) it keeps its last level.

    Parameters
    ----------
    direction, bias : str
        Names of the line's ``Direction`` and ``Bias`` while it was requested.
    level : int
        Its physical level then (0 or 1).
    """
    if bias == "PULL_DOWN":
        return 0
    if bias == "PULL_UP":
        return 1
    return level


def pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie (a killed child not yet waited for)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True
    # Field 3, after the parenthesised command name (which may itself hold spaces or parentheses).
    return stat[stat.rfind(")") + 2:][:1] not in ("Z", "X")


class LineStateDir:
    """Writer side: mirrors line states under ``root`` (one JSON file per line)."""

    def __init__(self, root: str | os.PathLike) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    def path(self, chip_name: str, offset: int) -> Path:
        """``<root>/<chip_name>/<offset>.json``."""
        return self.root / chip_name / f"{offset}.json"

    def write(self, chip_name: str, offset: int, state: dict[str, Any]) -> None:
        """Replace the line's state file atomically (a reader never sees half a file)."""
        p = self.path(chip_name, offset)
        p.parent.mkdir(exist_ok=True)
        tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(state, sort_keys=True))
        os.replace(tmp, p)


def read_line(root: str | os.PathLike, chip: str, offset: int) -> dict[str, Any] | None:
    """The line as the kernel shows it now, or None if it was never mirrored.

    Returns the mirrored state (``level``, ``direction``, ``bias``,
    ``consumer``, ``pid``, ``t_s``) with ``requested`` and, if the holding
    process has died, the release applied (``released_by_death`` True).
    ``chip`` is the chip's name or path (``"gpiochip0"``, ``"/dev/gpiochip0"``).
    """
    p = LineStateDir.__new__(LineStateDir)
    p.root = Path(root)
    try:
        st = json.loads(p.path(os.path.basename(chip), offset).read_text())
    except FileNotFoundError:
        return None
    st["released_by_death"] = False
    pid = st.get("pid")
    if pid is not None and not pid_alive(int(pid)):
        st["level"] = released_level(st["direction"], st["bias"], st["level"])
        if st["direction"] == "OUTPUT" and st["bias"] in ("PULL_UP", "PULL_DOWN"):
            st["direction"] = "INPUT"
        st.update(pid=None, consumer=None, released_by_death=True)
    st["requested"] = st.get("pid") is not None
    return st
