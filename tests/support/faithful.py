"""The faithful (r, z) world's time step in tests."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import pytest

#: Time step of the faithful world in every test that does not choose one.  The simulator marches at
#: 10 ms; TR-BDF2 is second order in time (tests/firmware_sim/rz/test_world.py observes it) and the
#: tolerances the tests assert hold at 20 ms as well (40 ms breaks the provisional-step test), which
#: costs about a third less CPU in the suite's faithful-world tests.  The benches keep the
#: simulator's own step.  ``tests/conftest.py`` applies it to every test.
TEST_DT_s = 0.02
#: The step of the faithful world under a simulated device in tests that assert what the device does with
#: the record it gets (round trip, the daemon unchanged on a faithful scene), not the world's accuracy:
#: twice :data:`TEST_DT_s`, half the steps.  One value for those modules, so that the same scene's
#: touch, simulated by two of them in one process, is marched once (firmware_sim/rz/stepmemo.py).
DEVICE_DT_s = 0.04


@contextlib.contextmanager
def world_step(dt_s: float) -> Iterator[None]:
    """Every faithful world built inside marches at ``dt_s`` unless its builder chooses (the default).

    ``tests/conftest.py`` sets :data:`TEST_DT_s` for the session this way; a module whose assertions
    do not depend on the world's accuracy in time (a property of the record, whatever the record)
    may take a coarser step for its block (:data:`DEVICE_DT_s`).  Worlds built in
    other threads meanwhile (a simulated probe's daemon) take it too.
    """
    from firmware_sim.rz.probe_world import FaithfulWorld  # noqa: PLC0415

    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(FaithfulWorld.__init__.__kwdefaults__, "dt_s", dt_s)
        mp.setitem(FaithfulWorld.for_scene.__func__.__kwdefaults__, "dt_s", dt_s)
        yield


def cold_solver_caches(monkeypatch: pytest.MonkeyPatch) -> None:
    """Empty step memo, factor and row caches for one test; ``monkeypatch`` puts the process's own back after it.

    A test of the caches themselves (what is shared, what is evicted, what a clear forgets) runs on these,
    not on the process's: :func:`firmware_sim.rz.solver.clear_factor_cache` called on those would make the
    worker's later faithful-world tests factor and step again what its earlier ones already had.
    """
    from collections import OrderedDict  # noqa: PLC0415

    from edge.physics.memo import BoundedMemo  # noqa: PLC0415
    from firmware_sim.rz import blocktri, solver, stepmemo  # noqa: PLC0415

    monkeypatch.setattr(stepmemo, "_MEMO", BoundedMemo(2**31, stepmemo.MEMO_BYTES))
    for name in ("_hits", "_misses"):
        monkeypatch.setattr(stepmemo, name, 0)
    monkeypatch.setattr(solver, "_FACTOR_CACHE", OrderedDict())
    monkeypatch.setattr(blocktri, "_ROW_CACHE", OrderedDict())
    monkeypatch.setattr(blocktri, "_row_bytes", 0)
