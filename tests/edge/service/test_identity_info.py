"""INFO names the device; the name survives restarts; a damaged one is a fault that does not stop measuring."""

from pathlib import Path

import pytest

from edge.protocol.commands import Command
from edge.protocol.messages import validate_reply
from edge.service.daemon import Daemon
from edge.storage.identity import DEVICE_ID_RE
from firmware_sim import load_scene
from firmware_sim.run import config_for_scene
from tests.support.daemons import FakeEstimator

pytestmark = pytest.mark.hil


def _daemon(tmp_path):
    sim = load_scene("glass_15V")
    cfg = config_for_scene(sim.scene, tmp_path, {"measurement": {"trigger_button": False}})
    return sim, cfg, Daemon(cfg, sim.board(), estimator=FakeEstimator())


def test_info_carries_the_identity_made_at_first_start_and_kept(tmp_path):
    sim, cfg, d = _daemon(tmp_path)
    try:
        info = d._cmd_info({})
        validate_reply(Command.INFO, info)
        first = info["device_id"]
        assert DEVICE_ID_RE.match(first)
        sim.advance_to(0.6)
        mid = d.measure(contact_time_s=1.0)["measurement_id"]
        header = d.history.get(mid, series=True)["touch_header"]  # every record, and so its export, names the instrument
        assert header["device_id"] == first and header["firmware_version"] == info["firmware_version"]
    finally:
        d.close()
    sim, cfg, d = _daemon(tmp_path)  # restart on the same storage
    try:
        assert d._cmd_info({})["device_id"] == first
    finally:
        d.close()


def test_a_damaged_identity_is_a_fault_and_the_device_still_measures(tmp_path):
    sim, cfg, d = _daemon(tmp_path)
    d.close()
    path = Path(cfg.paths.model_store).parent / "device_id"
    path.write_text("garbage\n")
    sim, cfg, d = _daemon(tmp_path)
    try:
        info = d._cmd_info({})
        assert info["device_id"] is None and any(f.startswith("identity: ") for f in info["faults"])
        sim.advance_to(0.6)
        assert d.measure(contact_time_s=1.0)["status"] == "ok"
        assert path.read_text() == "garbage\n"  # never overwritten: a person should look
    finally:
        d.close()
