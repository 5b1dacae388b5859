"""Object sets on the daemon over the virtual serial cable: upload, list, select, remove, refusals, restarts."""

import contextlib
import hashlib

import pytest
import serial

from edge.protocol.commands import Command
from edge.protocol.errors import ErrorCode
from firmware_sim.daemon_thread import DaemonThread
from firmware_sim.ptylink import NullModem
from firmware_sim.rigs.daemon_rig import make_rig
from host.client import DeviceClient, DeviceError
from host.objects import list_object_sets, remove_object_set, select_object_set, upload_object_set
from tests.support.daemons import FakeEstimator, assert_heater_safe, sim_config

pytestmark = pytest.mark.hil

#: The rig's object has e = 1400 W s^0.5/(m^2 K) (make_rig's default).
KITCHEN = (b"name,class,e_W_s05_m2K,spread_rel\n"
           b"cup,ceramic,1400,0.05\n"
           b"sponge,foam,60,0.1\n"
           b"pan,metal,15000,0.05\n")
OFFICE = b"name,class,k_W_mK,rho_kg_m3,c_J_kgK\ndesk,wood,0.15,600,1700\nchair,polymer,0.2,1200,1400\n"


@contextlib.contextmanager
def running(tmp_path, rig=None):
    rig = rig or make_rig()
    # Pinned at 10 Hz: MEASURE until_decided below stops at the decision's 4th sample, 0.4 s; at the
    # rig's 12.5 Hz that is 0.32 s, where the stopped record's own estimate can fall outside the set.
    cfg = sim_config(tmp_path, measurement={"sample_rate_Hz": 10.0})
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
        with DaemonThread(cfg, rig.board, port, estimator=FakeEstimator(rig.parts)) as dt:
            with DeviceClient(nm.host_port, timeout_s=5.0) as client:
                yield client, dt.daemon
    assert_heater_safe(rig.parts, cfg.heater.max_on_time_s)


def test_upload_names_each_measurement_and_survives_a_restart(tmp_path):
    with running(tmp_path) as (c, d):
        assert list_object_sets(c) == {"active": "library", "sets": [], "error": None}
        rec = c.measure(contact_time_s=0.5)["result"]
        assert rec["object_set"] == "library" and rec["object"] is not None and len(rec["candidates"]) == 3
        res = upload_object_set(c, "kitchen", KITCHEN, chunk_size=25)  # many chunks
        assert res == {"name": "kitchen", "sha256": hashlib.sha256(KITCHEN).hexdigest(), "objects": 3,
                       "active": "kitchen"}
        r = c.measure(contact_time_s=0.5)["result"]
        assert r["object_set"] == "kitchen" and r["object"] == "cup" and r["class"] == "glass/ceramic/stone"
        assert r["object_posterior"] > 0.5 and r["class_posterior"] >= r["object_posterior"]
        assert [x["name"] for x in r["candidates"]][0] == "cup" and len(r["candidates"]) == 3
        assert c.result()["result"]["object"] == "cup"  # stored with the record
        # The running answer (MEASURE until_decided) chooses among the same set.
        decided = c.measure(contact_time_s=1.0, until_decided=True)["result"]
        assert decided["decision"]["object"] == "cup" and decided["object"] == "cup"
        upload_object_set(c, "office", OFFICE, activate=False)
        listing = list_object_sets(c)
        assert listing["active"] == "kitchen"
        assert [(s["name"], s["objects"], s["active"]) for s in listing["sets"]] == [
            ("kitchen", 3, True), ("office", 2, False)]
    with running(tmp_path) as (c, d):
        assert list_object_sets(c)["active"] == "kitchen"
        assert c.measure(contact_time_s=0.5)["result"]["object"] == "cup"


def test_refused_uploads_keep_the_active_set(tmp_path):
    with running(tmp_path) as (c, d):
        upload_object_set(c, "kitchen", KITCHEN)
        before = list_object_sets(c)
        bad_files = {
            "missing column": b"name,class,k_W_mK\ncup,ceramic,1.0\n",
            "not a number": b"name,class,e_W_s05_m2K\ncup,ceramic,lots\n",
            "negative k": b"name,class,k_W_mK,rho_kg_m3,c_J_kgK\ncup,ceramic,-1,2000,800\n",
            "duplicate": b"name,class,e_W_s05_m2K\ncup,ceramic,1400\ncup,ceramic,1500\n",
            "not utf-8": b"name,class,e_W_s05_m2K\nt\xe4sse,ceramic,1400\n",
        }
        for why, blob in bad_files.items():
            with pytest.raises(DeviceError) as ei:
                upload_object_set(c, "kitchen", blob)
            assert ei.value.code == ErrorCode.MODEL_REJECTED, why
            assert "kitchen" in str(ei.value), why
            assert list_object_sets(c) == before, why
        with pytest.raises(DeviceError) as ei:
            upload_object_set(c, "kitchen", bad_files["negative k"])
        assert "line 2" in str(ei.value) and "k_W_mK" in str(ei.value)
        # A wrong digest and an oversized announcement are refused before anything is stored.
        sid = c.request(Command.OBJECTS_BEGIN, {"name": "kitchen", "size": len(OFFICE), "sha256": "0" * 64})["session"]
        c.request(Command.OBJECTS_CHUNK, {"offset": 0, "data": OFFICE, "session": sid})
        with pytest.raises(DeviceError) as ei:
            c.request(Command.OBJECTS_COMMIT, {"session": sid})
        assert ei.value.code == ErrorCode.MODEL_REJECTED and "sha256" in str(ei.value)
        with pytest.raises(DeviceError) as ei:
            c.request(Command.OBJECTS_BEGIN, {"name": "big", "size": 1024 * 1024, "sha256": "1" * 64})
        assert ei.value.code == ErrorCode.MODEL_REJECTED and ei.value.field == "size"
        for name in ("library", "../etc", ".hidden"):
            with pytest.raises(DeviceError) as ei:
                upload_object_set(c, name, OFFICE)
            assert ei.value.code == ErrorCode.BAD_ARGUMENT and ei.value.field == "name"
        # Another session's chunks and commit are refused; the owner's upload goes on.
        sid = c.request(Command.OBJECTS_BEGIN, {"name": "office", "size": len(OFFICE),
                                                "sha256": hashlib.sha256(OFFICE).hexdigest()})["session"]
        with pytest.raises(DeviceError) as ei:
            c.request(Command.OBJECTS_CHUNK, {"offset": 0, "data": OFFICE, "session": sid ^ 1})
        assert ei.value.code == ErrorCode.BAD_STATE
        with pytest.raises(DeviceError) as ei:
            c.request(Command.OBJECTS_COMMIT, {"session": sid})  # incomplete
        assert ei.value.code == ErrorCode.BAD_STATE
        c.request(Command.OBJECTS_ABORT, {"session": sid})
        assert list_object_sets(c) == before
        assert c.measure(contact_time_s=0.5)["result"]["object"] == "cup"


def test_select_and_remove(tmp_path):
    with running(tmp_path) as (c, d):
        upload_object_set(c, "kitchen", KITCHEN)
        upload_object_set(c, "office", OFFICE)
        assert list_object_sets(c)["active"] == "office"
        assert select_object_set(c, "kitchen") == {"active": "kitchen"}
        assert remove_object_set(c, "office") == {"removed": "office", "active": "kitchen"}
        assert remove_object_set(c, "kitchen") == {"removed": "kitchen", "active": "library"}
        for fn in (remove_object_set, select_object_set):
            with pytest.raises(DeviceError) as ei:
                fn(c, "kitchen")
            assert ei.value.code == ErrorCode.NOT_FOUND
        assert list_object_sets(c) == {"active": "library", "sets": [], "error": None}
        assert c.measure(contact_time_s=0.5)["result"]["object_set"] == "library"
    with running(tmp_path) as (c, d):
        assert list_object_sets(c)["active"] == "library"


def test_a_damaged_active_set_falls_back_to_the_library_and_says_so(tmp_path):
    with running(tmp_path) as (c, d):
        upload_object_set(c, "kitchen", KITCHEN)
    (tmp_path / "objects" / "sets" / "kitchen.csv").write_bytes(b"garbage\n")
    with running(tmp_path) as (c, d):
        listing = list_object_sets(c)
        assert listing["active"] == "library" and "kitchen" in listing["error"]
        assert any(f.startswith("objects:") for f in c.status()["faults"])
        assert c.measure(contact_time_s=0.5)["result"]["object_set"] == "library"  # still measures
        upload_object_set(c, "kitchen", KITCHEN)  # a good upload heals it
        assert list_object_sets(c)["error"] is None
        assert not any(f.startswith("objects:") for f in c.status()["faults"])


def test_an_unusable_store_directory_is_a_fault_that_heals(tmp_path):
    blocker = tmp_path / "objects"
    blocker.write_text("a file where the store's directory should be")
    with running(tmp_path) as (c, d):
        assert any(f.startswith("objects:") for f in c.status()["faults"])
        assert c.status()["can_measure"]  # the library names objects meanwhile
        with pytest.raises(DeviceError) as ei:
            upload_object_set(c, "kitchen", KITCHEN)
        assert ei.value.code == ErrorCode.BAD_STATE
        assert c.measure(contact_time_s=0.5)["result"]["object_set"] == "library"
        blocker.unlink()
        d._check_faults(force=True)
        assert upload_object_set(c, "kitchen", KITCHEN)["active"] == "kitchen"
        assert not any(f.startswith("objects:") for f in c.status()["faults"])
