"""Faults the kill-point harness's own tests put into the code under test, to show its checks are not vacuous.

Each function patches a class or module of edge with ``put`` (``setattr`` by default: in a kill
point's child, which dies with the patch, named in :attr:`tests.support.killpoint_runner.Operation.faults`;
a test passes ``monkeypatch.setattr`` to give its own process, where the restart checks run, the
same fault for the test's length). The tests are in :mod:`tests.edge.service.test_kill_points`.
"""

from __future__ import annotations

import os
from typing import Any, Callable

__all__ = ["no_pending_finish", "newest_signature_wins", "overrides_written_in_place", "reply_before_commit"]

Put = Callable[[Any, str, Any], None]


def no_pending_finish(put: Put = setattr) -> None:
    """The object-set store's start-up leaves a cut install as it found it (the old store: stored, never activated)."""
    from edge.storage.objects_store import ObjectSetStore

    put(ObjectSetStore, "_finish_pending", lambda self: None)


def newest_signature_wins(put: Put = setattr) -> None:
    """The calibration store reads whichever signature file is newest, whatever bytes it signed, and never
    cleans (the old store's one ``calibration.sig``)."""
    from edge.security.keys import parse_signature
    from edge.storage.calibration_store import CalibrationStore

    def newest_signer(self):
        sigs = sorted(self.root.glob("calibration.*.sig"), key=lambda p: p.stat().st_mtime_ns)
        return parse_signature(sigs[-1].read_bytes())[0] if sigs else None

    put(CalibrationStore, "_clean", lambda self: None)
    put(CalibrationStore, "signed_by", newest_signer)


def overrides_written_in_place(put: Put = setattr) -> None:
    """Durable writes truncate and write the file itself, in two parts (no temporary, no rename)."""
    from edge.storage import durable

    def in_place(path, data):
        with open(path, "wb") as f:
            f.write(data[: len(data) // 2])
            f.flush()
            os.fsync(f.fileno())  # a step: the kill lands here with half the file written
            f.write(data[len(data) // 2:])

    put(durable, "atomic_write_file", in_place)


def reply_before_commit(put: Put = setattr) -> None:
    """The history answers from an uncommitted transaction: the reply goes out, the COMMIT never happens."""
    from edge.storage.history import History

    real_add = History.add

    def add_without_commit(self, record):
        db = self._db

        class NoCommit:
            def execute(self, sql, *args):
                return None if sql.strip().upper() == "COMMIT" else db.execute(sql, *args)

            def __getattr__(self, name):
                return getattr(db, name)

        self._db = NoCommit()
        try:
            return real_add(self, record)
        finally:
            self._db = db

    put(History, "add", add_without_commit)
