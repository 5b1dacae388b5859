"""estimate_from_contact keeps whole answers by their exact inputs: a repeat is the same answer, anything else is not.

The device estimates the record its running decision last refitted, and an exported touch re-estimated in the
same process repeats the device's estimate (edge.estimation.chain_estimate._ESTIMATES).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from edge.estimation import chain_estimate as ce
from tests.support.calibrations import sample_calibration


@pytest.fixture
def record():
    """A 20-Hz touch: 1 s before heater-on, 2 s of heating into glass (noisy, synthetic)."""
    t = np.round(np.arange(-1.0, 2.0001, 0.05), 10)
    rng = np.random.default_rng(1)
    on = t > 0
    q = np.where(on, 1500.0, 0.0) + rng.normal(0, 5, t.size)
    T = 25.0 + np.where(on, 2.0 * np.sqrt(np.clip(t, 0, None) / np.pi), 0.0) + rng.normal(0, 0.005, t.size)
    return t, T, q


@pytest.fixture
def computed(monkeypatch):
    """Counts the estimates actually computed (the memo emptied first)."""
    monkeypatch.setattr(ce, "_ESTIMATES", ce.BoundedMemo(32))
    calls = []
    real = ce._estimate_from_contact

    def counting(*args, **kw):
        calls.append(args)
        return real(*args, **kw)
    monkeypatch.setattr(ce, "_estimate_from_contact", counting)
    return calls


@pytest.mark.parametrize("calibrated", [False, True])
def test_the_same_inputs_give_the_same_answer_computed_once_and_a_copy(record, computed, calibrated):
    t, T, q = record
    cal = sample_calibration() if calibrated else None
    first = ce.estimate_from_contact(t, T, q, cal)
    again = ce.estimate_from_contact(list(t), T.copy(), q.copy(), sample_calibration() if calibrated else None)
    assert len(computed) == 1
    assert repr(again) == repr(first) and again["effusivity_W_s05_m2K"] is not None
    assert repr(again) == repr(ce._estimate_from_contact(t, T, q, cal))   # what a recomputation gives
    # A copy: the caller may change it, the next answer is not changed.
    again["flags"].append("poor_fit")
    again["u_e_parts"]["fit"] = -1.0
    assert repr(ce.estimate_from_contact(t, T, q, cal)) == repr(first)


def test_another_record_calibration_library_or_tunable_is_computed_again(record, computed, monkeypatch):
    t, T, q = record
    cal = sample_calibration()
    base = ce.estimate_from_contact(t, T, q, cal)
    T2 = T.copy()
    T2[-1] += 1e-9
    ce.estimate_from_contact(t, T2, q, cal)
    ce.estimate_from_contact(t, T, q, replace(cal, u_rel_floor=cal.u_rel_floor + 0.01))
    ce.estimate_from_contact(t, T, q, None)
    lib = ce._library()
    ce.estimate_from_contact(t, T, q, cal, library=lib)       # the CSV's library, passed: another key, same prior
    ce.estimate_from_contact(t, T, q, cal, heater_radius_m=float("inf"))
    assert len(computed) == 6
    monkeypatch.setattr(ce, "POOR_FIT", 0.0)                   # as the seam's tests do: every fit poor
    poor = ce.estimate_from_contact(t, T, q, cal)
    assert len(computed) == 7 and "poor_fit" in poor["flags"] and "poor_fit" not in base["flags"]


def test_inputs_without_a_content_key_are_not_kept(record, computed):
    t, T, q = record

    class Chain(ce.DatasheetChain):   # a subclass: not the datasheet chain itself
        pass
    for _ in range(2):
        ce.estimate_from_contact(t, T, q, Chain())
    assert len(computed) == 2 and len(ce._ESTIMATES) == 0


def test_a_growing_record_reuses_its_earlier_windows_and_answers_as_computed_afresh(monkeypatch):
    """A running decision's refits: each window ending before the record does is fitted and profiled once."""
    t = np.round(np.arange(-1.0, 3.0001, 0.05), 10)
    rng = np.random.default_rng(2)
    on = t > 0
    q = np.where(on, 1500.0, 0.0) + rng.normal(0, 5, t.size)
    T = 25.0 + np.where(on, 2.0 * np.sqrt(np.clip(t, 0, None) / np.pi), 0.0) + rng.normal(0, 0.005, t.size)
    built = []

    class Counting(ce.DiskFitter):
        def __init__(self, *args, **kw):
            built.append(args[0].size)
            super().__init__(*args, **kw)
    monkeypatch.setattr(ce, "DiskFitter", Counting)
    ends = (2.0, 2.5, 3.0)                                   # heater-on + 1 s is a window of every prefix

    def answers(fresh: bool) -> list[str]:
        out = []
        for end in ends:
            if fresh:
                monkeypatch.setattr(ce, "_WINDOWS", ce.BoundedMemo(64))
            monkeypatch.setattr(ce, "_ESTIMATES", ce.BoundedMemo(32))
            keep = t <= end + 1e-9
            out.append(repr(ce.estimate_from_contact(t[keep], T[keep], q[keep], sample_calibration())))
        return out
    monkeypatch.setattr(ce, "_WINDOWS", ce.BoundedMemo(64))
    growing = answers(False)
    n_growing = len(built)
    built.clear()
    assert answers(True) == growing
    assert "effusivity_W_s05_m2K': None" not in growing[0]
    # Afresh every prefix fits its earlier windows again (here 8 windows of 4 lengths); growing, each length once.
    assert n_growing == len(set(built)) < len(built)
