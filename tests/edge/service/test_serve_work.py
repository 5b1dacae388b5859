"""Work per request between the serve loop's watchdog beats (ISSUE #35 §7), counted in work units.

The serve loop pets systemd's watchdog only when it turns; a request that parses a 256-kB object set
or decodes a history page holds it meanwhile. The simulator's clock does not move while the device
computes, so these tests count the work itself between consecutive ``beat("serve")`` calls: object-set
rows parsed and history records decoded. Each request kind is bounded by one parse of one upload
(at most :data:`MAX_SET_BYTES`) or one page (at most HISTORY's ``limit``), whatever is stored:
OBJECTS_LIST parses nothing it verified before, even after a restart; a commit parses its upload once.
(On this machine one 256-kB parse is ~0.25 s of CPU, a tenth of the 2.5-s pet interval at
``WatchdogSec=10``: ``python bench/serve_work_bench.py``.)
"""

from __future__ import annotations

import contextlib
import hashlib
import threading

import pytest
import serial

import edge.service.objects as service_objects
from edge.protocol.commands import Command
from edge.protocol.errors import ErrorCode
from edge.protocol.messages import encode_request
from edge.service.notify import Notifier
from edge.storage.history import History
from edge.storage.objects_store import MAX_SET_BYTES
from firmware_sim.daemon_thread import DaemonThread
from firmware_sim.ptylink import NullModem
from firmware_sim.rigs.daemon_rig import make_rig
from host.client import DeviceClient, DeviceError
from host.objects import list_object_sets, upload_object_set
from tests.support.daemons import FakeEstimator, sim_config

pytestmark = pytest.mark.hil

HEADER = "name,class,k_W_mK,rho_kg_m3,c_J_kgK\n"


def big_set(tag: str, duplicate: bool = False) -> bytes:
    """An object set as close to MAX_SET_BYTES as rows allow (~9 700 rows), optionally ending in a duplicate."""
    rows, size, i = [HEADER], len(HEADER), 0
    tail = f"{tag}0,glass,1.0,2500,800\n" if duplicate else ""
    while True:
        row = f"{tag}{i},glass,1.0,2500,800\n"
        if size + len(row) + len(tail) > MAX_SET_BYTES:
            break
        rows.append(row)
        size += len(row)
        i += 1
    return ("".join(rows) + tail).encode()


class Meter:
    """Work units done on the device and the serve loop's beats, read together."""

    def __init__(self) -> None:
        self.rows = 0        # object-set rows parsed
        self.records = 0     # history records decoded
        self.turns: list[tuple[int, int]] = []
        self._lock = threading.Lock()

    def reading(self) -> tuple[int, int]:
        with self._lock:
            return self.rows, self.records

    def longest_turn(self) -> tuple[int, int]:
        """Most rows and most records between two consecutive serve beats."""
        t = self.turns
        rows = max((b[0] - a[0] for a, b in zip(t, t[1:])), default=0)
        recs = max((b[1] - a[1] for a, b in zip(t, t[1:])), default=0)
        return rows, recs

    def reset(self) -> None:
        self.turns = [self.reading()]


class MeteredNotifier(Notifier):
    def __init__(self, meter: Meter) -> None:
        super().__init__(env={})
        self.meter = meter

    def beat(self, loop: str) -> None:
        if loop == "serve":
            self.meter.turns.append(self.meter.reading())
        super().beat(loop)


@pytest.fixture
def meter(monkeypatch):
    m = Meter()
    parse = service_objects.parse_object_set

    def counted(text, label):
        m.rows += max(0, sum(1 for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#"))
                      - 1)
        return parse(text, label)

    summary = History._summary

    def decoded(self, row):
        m.records += 1
        return summary(self, row)

    monkeypatch.setattr(service_objects, "parse_object_set", counted)
    monkeypatch.setattr(History, "_summary", decoded)
    return m


@contextlib.contextmanager
def metered_daemon(tmp_path, meter):
    cfg = sim_config(tmp_path)
    rig = make_rig()
    with NullModem() as nm, serial.Serial(nm.device_port, timeout=0.05) as port:
        with DaemonThread(cfg, rig.board, port, estimator=FakeEstimator(rig.parts),
                          notifier=MeteredNotifier(meter)) as dt:
            with DeviceClient(nm.host_port, timeout_s=20.0) as client:
                meter.reset()
                yield client
        assert dt.error is None


def test_object_set_requests_parse_at_most_one_upload_per_turn(tmp_path, meter):
    sets = {"a": big_set("a"), "b": HEADER.encode() + b"b0,glass,1.0,2500,800\n"}
    n_rows = sets["a"].count(b"\n") - 1
    with metered_daemon(tmp_path, meter) as c:
        for tag, blob in sets.items():               # OBJECTS install of a 256-kB set (and a small one)
            upload_object_set(c, tag, blob, activate=tag == "a")
        assert meter.longest_turn()[0] == n_rows and meter.rows == n_rows + 1   # each parsed once
        meter.reset()
        for _ in range(3):                           # OBJECTS_LIST: nothing parsed again
            assert [s["objects"] for s in list_object_sets(c)["sets"]] == [n_rows, 1]
        assert meter.rows == n_rows + 1
        meter.reset()
        dup = big_set("a", duplicate=True)           # the duplicate check: one linear parse, refused
        with pytest.raises(DeviceError, match="duplicate name 'a0'") as ei:
            upload_object_set(c, "d", dup)
        assert ei.value.code == ErrorCode.MODEL_REJECTED
        assert meter.longest_turn()[0] == dup.count(b"\n") - 1
    rows = meter.rows
    with metered_daemon(tmp_path, meter) as c:      # restarted: the sets' bytes were verified when installed
        listed = list_object_sets(c)
        assert [s["objects"] for s in listed["sets"]] == [n_rows, 1] and listed["active"] == "a"
        assert meter.rows - rows <= n_rows            # the active set is loaded (once); the listing parses none


def test_history_pages_decode_at_most_one_page_per_turn(tmp_path, meter):
    n = 60
    with History(tmp_path / "history.db") as h:
        for i in range(n):
            h.add({"status": "ok", "flags": [], "result": {"effusivity_W_s05_m2K": 1000.0 + i, "object": f"o{i}",
                                                         "flags": [], "measurement_id": i + 1}})
    with metered_daemon(tmp_path, meter) as c:
        seen, offset, requests = [], 0, 0
        while True:                                 # the host's export: every record once, page by page
            page = c.request(Command.HISTORY, {"offset": offset, "limit": 100})
            requests += 1
            if not page["items"]:
                break
            seen += [it["measurement_id"] for it in page["items"]]
            offset += len(page["items"])
        assert len(seen) == n and len(set(seen)) == n
        assert meter.longest_turn()[1] <= 100       # HISTORY's limit bounds a turn, whatever is stored
        assert requests < n / 3                      # several records to a reply (ISSUE #35 §8)
        # A burst: five requests in one write are five turns, not one (the loop beats per request).
        rids = [c._new_id() for _ in range(5)]
        c._write(b"".join(encode_request(Command.HISTORY, rid, {"offset": 0, "limit": 100}) for rid in rids))
        assert c._await(rids[-1], Command.HISTORY, 20.0)["total"] == n
        assert meter.longest_turn()[1] <= 100
