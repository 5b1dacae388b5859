"""Shared set-up of the (r, z) verification tests."""

import pytest

from firmware_sim.rz.probe_world import FaithfulWorld

#: Time step of the FaithfulWorld tests that do not choose one. The simulator marches at 10 ms; the
#: tests here compare against analytic and 1-D limits whose tolerances hold at 20 ms as well
#: (TR-BDF2 is second order in time, test_world.py observes it), and 20 ms halves their cost.
TEST_DT_s = 0.02


@pytest.fixture(autouse=True)
def faithful_world_test_step(monkeypatch):
    monkeypatch.setitem(FaithfulWorld.__init__.__kwdefaults__, "dt_s", TEST_DT_s)
    monkeypatch.setitem(FaithfulWorld.for_scene.__func__.__kwdefaults__, "dt_s", TEST_DT_s)
