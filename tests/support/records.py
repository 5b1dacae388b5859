"""Simulated reference touches shared by the tests that ask for the very same one.

:func:`recorded_touch` is :func:`firmware_sim.rigs.contact_record.record_touch` (a faithful-world
simulation, about half a second of CPU each) computed once per test session: the calibrate tests of
tests/host/cli and tests/edge/calibration record the same seeded touches of the same as-built probe.
The key is the call's full text (the touch, the probe as built, the geometry, the board, the seed:
dataclass reprs with every field), so a hit is what the call would return; the result is kept in
memory and, for the other xdist worker, as an ``.npz`` in the session's temporary directory (never
in the repository, never across runs). Every caller gets its own copies of the arrays.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

_memory: dict[str, dict] = {}
#: The session's shared directory (set by tests/conftest.py; None: memory only).
cache_dir: Path | None = None


def session_cache_dir(basetemp: Path) -> Path:
    """The directory both xdist workers see: the controller's base temp (a worker's is inside it)."""
    root = basetemp.parent if os.environ.get("PYTEST_XDIST_WORKER") else basetemp
    d = root / "shared-records"
    d.mkdir(parents=True, exist_ok=True)
    return d


def recorded_touch(touch, **kwargs) -> dict:
    """``record_touch(touch, **kwargs)``, simulated once per session (see the module docstring)."""
    from firmware_sim.rigs.contact_record import record_touch  # noqa: PLC0415

    key = hashlib.sha256(repr((touch, sorted(kwargs.items()))).encode()).hexdigest()
    got = _memory.get(key)
    path = None if cache_dir is None else cache_dir / f"{key}.npz"
    if got is None and path is not None and path.exists():
        try:
            with np.load(path) as z:
                got = {k: (z[k].item() if z[k].ndim == 0 else z[k]) for k in z.files}
        except (OSError, ValueError, EOFError):
            got = None   # the other worker's write is not there yet (or torn): simulate it here
    if got is None:
        got = record_touch(touch, **kwargs)
        if path is not None:
            tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
            np.savez(tmp, **got)
            os.replace(tmp, path)   # whole or absent for the other worker
    _memory[key] = got
    return {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in got.items()}
