"""The step memo (firmware_sim/rz/stepmemo.py): a recalled step is the solved step, bit for bit.

A step is recalled only when everything it reads is the same (solver, forcing, source, amplitude,
field); a world replaying a touch the process has marched gets the very same record and builds
no factor.
"""

from collections import OrderedDict

import numpy as np
import pytest

from firmware_sim.clock import VirtualClock
from firmware_sim.rz import blocktri as B
from firmware_sim.rz import solver as S
from firmware_sim.rz import stepmemo as M
from firmware_sim.rz.probe_world import FaithfulWorld
from firmware_sim.scene.files import read_scene
from firmware_sim.world import ScheduleDrive
from tests.support.faithful import cold_solver_caches


def _solver(scheme="trbdf2", dt_s=0.01):
    from edge.physics.solids import Solid
    from firmware_sim.rz.grid import probe_grid

    return S.Solver(probe_grid(Solid(1.1, 2500.0, 800.0)), dt_s, scheme, rannacher_steps=0)


@pytest.fixture
def cold(monkeypatch):
    """Empty memo, factor and row caches for the test; the process's own are put back after it."""
    cold_solver_caches(monkeypatch)


@pytest.mark.parametrize("scheme", ["trbdf2", "be"])
def test_a_recalled_step_is_the_solved_step_bit_for_bit_and_private(cold, scheme):
    s = _solver(scheme)
    T0 = s.run(s.initial_field(25.0, 22.0), 3, s.heater_source_W(), 2.0, keep_field=True).T_final_K
    src = s.heater_source_W()
    T1, e_in, lost = s.step(T0, src, 5.0)
    assert M.memo_stats()["hits"] == 0
    # A fresh solver of the same grid and step: the same inputs, so the stored step.
    s2 = _solver(scheme)
    T2, e_in2, lost2 = s2.step(T0.copy(), src.copy(), 5.0)
    assert M.memo_stats()["hits"] == 1
    assert np.array_equal(T1, T2) and (e_in, lost) == (e_in2, lost2)
    # ... and what the solve gives, to the last bit.
    solved = s2.run(T0, 1, src, 5.0, keep_field=True)
    assert np.array_equal(T2, solved.T_final_K) and lost2 == solved.E_lost_J[-1]
    # The caller owns what it gets: editing it does not edit the memo.
    T2 += 1.0
    T3, _, _ = s2.step(T0, src, 5.0)
    assert np.array_equal(T3, T1) and M.memo_stats()["hits"] == 2


def test_any_other_input_is_solved_not_recalled(cold):
    s = _solver()
    T0 = s.initial_field(25.0, 22.0)
    src = s.heater_source_W()
    T1, _, _ = s.step(T0, src, 1.0)
    T0b = T0.copy()
    cell = int(np.flatnonzero(s.grid.active)[200])
    T0b.flat[cell] = np.nextafter(T0b.flat[cell], np.inf)
    others = [s.step(T0, src, np.nextafter(1.0, 2.0))[0],             # another amplitude, by one ulp
              s.step(T0b, src, 1.0)[0],                               # another field, by one ulp in one cell
              s.step(T0, 2.0 * src, 0.5)[0],                          # the same power, another pattern
              _solver(dt_s=0.02).step(T0, src, 1.0)[0],               # another step
              _solver("be").step(T0, src, 1.0)[0]]                    # another scheme
    saved = s.g_t
    s.g_t = saved + 1e-3 * s.grid.active                              # another forcing
    try:
        others.append(s.step(T0, src, 1.0)[0])
    finally:
        s.g_t = saved
    assert M.memo_stats()["hits"] == 0 and M.memo_stats()["entries"] == 7
    for T in others[3:]:
        assert not np.array_equal(T, T1)
    # A cell outside the body is masked before the step: the same step, recalled.
    T0c = T0.copy()
    T0c.flat[int(np.flatnonzero(~s.grid.active)[0])] = 99.0
    assert np.array_equal(s.step(T0c, src, 1.0)[0], T1) and M.memo_stats()["hits"] == 1


def test_the_memo_stays_within_its_bytes(cold, monkeypatch):
    s = _solver()
    monkeypatch.setattr(M, "MEMO_BYTES", 3 * s.grid.active.size * 8)
    monkeypatch.setattr(M._MEMO, "max_bytes", M.MEMO_BYTES)
    T = s.initial_field(25.0, 22.0)
    for _ in range(6):
        T, _, _ = s.step(T, s.heater_source_W(), 1.0)
    st = M.memo_stats()
    assert st["entries"] == 3 and st["bytes"] <= M.MEMO_BYTES


def _touch(name: str) -> dict:
    """A scene's touch with 1 s of heating, read at 5-ms ticks as the chips would (everything in the past).

    40-ms steps: the recall is bit for bit at any step, and half the steps halve the first march.
    """
    sc = read_scene(name)
    clock = VirtualClock()
    clock.advance(100.0)
    on = sc.touch.heater_on_s
    w = FaithfulWorld.for_scene(sc, clock, ScheduleDrive([on, on + 1.0], [1.0, 0.0]), dt_s=0.04)
    t = np.arange(0.0, sc.touch.end_s + 0.3, 0.005)
    return w.series(t)


# The small-heater scene marches a second grid through the same memo: 0.5 s of CPU, left to the full suite;
# the faithful glass touch keeps the recall of a whole replayed touch in the fast tier.
@pytest.mark.parametrize("name", ["glass_15V_faithful", pytest.param("pmma_15V_small", marks=pytest.mark.slow)])
def test_a_replayed_touch_is_recalled_bit_for_bit_without_a_factor(cold, name, monkeypatch):
    first = _touch(name)
    solved = M.memo_stats()["misses"]
    built = []
    init = B.BlockTridiagonal.__init__

    def counting(self, *a, **k):
        built.append(1)
        init(self, *a, **k)

    monkeypatch.setattr(B.BlockTridiagonal, "__init__", counting)
    monkeypatch.setattr(S, "_FACTOR_CACHE", OrderedDict())
    monkeypatch.setattr(B, "_ROW_CACHE", OrderedDict())
    again = _touch(name)
    # Every step recalled: nothing factored, nothing solved, and the same record to the last bit.
    assert built == [] and M.memo_stats()["misses"] == solved
    for key in first:
        assert np.array_equal(first[key], again[key], equal_nan=True), key
