"""Tests of the hardware-in-the-loop simulator: every test here runs on simulated hardware."""

import pytest


@pytest.hookimpl(tryfirst=True)  # before -m deselects
def pytest_collection_modifyitems(config, items):
    # One place marks the simulator's tests, so `-m hil` / `-m "not hil"` select them.
    for item in items:
        if "tests/firmware_sim/" in item.nodeid.replace("\\", "/"):
            item.add_marker(pytest.mark.hil)
