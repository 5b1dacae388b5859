"""Steps already taken: a process-wide memo of :meth:`firmware_sim.rz.solver.Solver.step`.

A step is a pure function of its inputs: the solver's matrices and step (grid arrays, ``dt``,
scheme, ambient forcing), the source pattern, the amplitude and the field it starts from.  The
simulated devices of a test process replay the same touches again and again -- the same shipped
scene measured by one test after another, a fixture's world rebuilt per test, a daemon restarted
at a kill point and marching its session from the start -- and in the suite's faithful-world tests
about 40 % of the steps start from a field, with a power, that the process has stepped before
(counted over ``tests/firmware_sim/rz``, ``test_faithful_scenes.py`` and ``test_round_trip.py``).
Those steps are taken from here: the stored result of the very same arithmetic on the very same
numbers, so the same bits, for the price of a digest of the field (~0.1 ms against a step's 1-2 ms
of solves).

The key is a SHA-256 digest of everything the step reads (:meth:`Solver._step_key`), exact bytes
and shapes included; a hit returns a copy of the stored field.  Least recently used entries are
dropped first once the stored fields exceed :data:`MEMO_BYTES`.
"""

from __future__ import annotations

import threading

import numpy as np

from edge.physics.memo import BoundedMemo

__all__ = ["MEMO_BYTES", "clear_step_memo", "recall", "keep", "memo_stats"]

#: Bytes of stored fields kept (about 2000 steps of the small-heater probe's contact grid).
MEMO_BYTES = 160 * 2**20

_MEMO = BoundedMemo(max_entries=2**31, max_bytes=MEMO_BYTES)
_LOCK = threading.Lock()   # the counters: worlds step in the test's thread and in simulated daemons' threads
_hits = 0
_misses = 0


def clear_step_memo() -> None:
    """Forget every stored step (a benchmark that times a cold start calls it, with the factors)."""
    global _hits, _misses
    _MEMO.clear()
    with _LOCK:
        _hits = _misses = 0


def memo_stats() -> dict[str, int]:
    """Entries, stored bytes, hits and misses since the last clear."""
    with _LOCK:
        return {"entries": len(_MEMO), "bytes": _MEMO.nbytes, "hits": _hits, "misses": _misses}


def recall(key: bytes) -> tuple[np.ndarray, float, float] | None:
    """The step stored under ``key`` as ``(a copy of the new field, heat in J, heat lost J)``, or None."""
    global _hits, _misses
    hit = _MEMO.get(key)
    with _LOCK:
        if hit is None:
            _misses += 1
            return None
        _hits += 1
    T, e_in, lost = hit
    return T.copy(), e_in, lost


def keep(key: bytes, T: np.ndarray, e_in: float, lost: float) -> None:
    """Store a step's result under ``key`` (a private, read-only copy of the field)."""
    if _MEMO.get(key) is None:
        _MEMO.put(key, (T.copy(), e_in, lost))
