"""The user's object sets on the device: OBJECTS_* requests and the active set (the estimate path names objects in it).

:class:`ObjectSets` joins the store (:mod:`edge.storage.objects_store`,
which knows files, not objects) and the recognition
(:mod:`edge.recognition`, which knows objects, not files), as
:mod:`edge.service.estimator` joins the model store and the estimator.

Upload (a CSV is small, but a frame is 4 kB)::

    OBJECTS_BEGIN {name, size, sha256, activate} -> {session}
    OBJECTS_CHUNK (binary: offset, session, bytes) ... -> {received}
    OBJECTS_COMMIT {session} -> {name, sha256, objects, active}   (or OBJECTS_ABORT)

The bytes are held in memory (bounded by the store's ``max_bytes`` before
the first arrives) and verified completely on commit
(:func:`edge.storage.objects_store.verify_upload`); a refused upload answers
MODEL_REJECTED with the parser's line and column, and the active set stays.
Each OBJECTS_BEGIN opens a new random session that later requests must
name, so two hosts cannot interleave their bytes.

Without a chosen set (or when the store cannot be used) the built-in library
names the objects.
"""

from __future__ import annotations

import logging
import secrets
from pathlib import Path
from typing import Any

from edge.recognition import LIBRARY_SET, ObjectSet
from edge.protocol.errors import CommandError, ErrorCode
from edge.storage.objects_store import MAX_SET_BYTES, ObjectSetStore, ObjectStoreError, UploadRefused, check_name
from edge.service.upload import append_chunk

__all__ = ["ObjectSets", "parse_object_set"]

log = logging.getLogger("thermotouch.edge")


def parse_object_set(text: str, label: str) -> ObjectSet:
    """The store's parser: :meth:`ObjectSet.from_csv_text` (one definition of the format, shared with the host)."""
    return ObjectSet.from_csv_text(text, label=label)


class _Pending:
    """What OBJECTS_BEGIN announced and the bytes received so far."""

    def __init__(self, name: str, size: int, sha256: str, activate: bool, session: int,
                 signature: bytes | None = None) -> None:
        self.name, self.size, self.sha256, self.activate, self.session = name, size, sha256, activate, session
        self.signature = signature
        self.data = bytearray()


class ObjectSets:
    """The device's object sets: the store, the upload in progress, and the active :class:`ObjectSet`.

    Parameters
    ----------
    root : path-like
        Store directory. If the store cannot be opened, :attr:`error` says
        why, uploads are refused and the library names the objects.
    max_bytes : int
        Largest set accepted.
    """

    def __init__(self, root: str | Path, *, max_bytes: int = MAX_SET_BYTES, policy: Any = None) -> None:
        self.root = Path(root)
        self.max_bytes = int(max_bytes)
        self.policy = policy
        self._pending: _Pending | None = None
        self._library: ObjectSet | None = None
        self._open_error: str | None = None
        self.store: ObjectSetStore | None = None
        self.reopen()

    def reopen(self) -> None:
        """Open the store if it is not open (at start, and on the daemon's fault re-checks: a card may return)."""
        if self.store is not None:
            return
        try:
            self.store = ObjectSetStore(self.root, parse_object_set, max_bytes=self.max_bytes, policy=self.policy)
            self._open_error = None
        except OSError as e:
            err = f"object-set store {self.root} unavailable: {e}"
            if err != self._open_error:
                log.error("%s", err)
            self._open_error = err

    # -- the active set --------------------------------------------------------------
    @property
    def error(self) -> str | None:
        """Why the chosen set (or the store) cannot be used now; None when all is well."""
        if self.store is None:
            return self._open_error
        self.store.active()  # loads the pointer once, setting the store's error
        return self.store.error

    def library(self) -> ObjectSet:
        """The built-in set: every library material (built once)."""
        if self._library is None:
            self._library = ObjectSet.from_library()
        return self._library

    def active(self) -> tuple[str, ObjectSet]:
        """``(name, set)`` naming measurements now: the chosen stored set, else ``("library", ...)``."""
        s = self.store.active() if self.store is not None else None
        if s is None:
            return LIBRARY_SET, self.library()
        return s.name, s.objects

    # -- upload ----------------------------------------------------------------------
    def _require_store(self) -> ObjectSetStore:
        if self.store is None:
            raise CommandError(ErrorCode.BAD_STATE, self._open_error or "object-set store unavailable")
        return self.store

    def _owned(self, session: int | None, command: str) -> _Pending:
        up = self._pending
        if up is None:
            raise CommandError(ErrorCode.BAD_STATE, "no object-set upload in progress (send OBJECTS_BEGIN first)")
        if session != up.session:
            raise CommandError(ErrorCode.BAD_STATE, f"{command}: session {session} is not the upload in progress "
                               "(stale or another host's); it is left untouched", "session")
        return up

    def begin(self, name: str, size: int, sha256: str, activate: bool = True,
              signature: bytes | None = None) -> dict:
        """OBJECTS_BEGIN: open an upload session (dropping an unfinished one)."""
        self._require_store()
        try:
            check_name(name)  # before any byte is sent, not after
        except ObjectStoreError as e:
            raise CommandError(ErrorCode.BAD_ARGUMENT, str(e), "name") from None
        if size > self.max_bytes:
            raise CommandError(ErrorCode.MODEL_REJECTED, f"object set of {size} B exceeds the device's limit of "
                               f"{self.max_bytes} B", "size")
        if self._pending is not None:
            log.info("object-set upload session %d superseded", self._pending.session)
        sid = 0
        while not sid:  # random and non-zero: an id from before a restart is (almost surely) stale
            sid = secrets.randbits(32)
        self._pending = _Pending(name, size, sha256, bool(activate), sid, signature)
        return {"size": size, "session": sid}

    def chunk(self, offset: int, data: bytes, session: int) -> dict:
        """OBJECTS_CHUNK: append ``data`` at ``offset`` (a resent chunk already held is accepted)."""
        up = self._owned(session, "OBJECTS_CHUNK")
        return {"received": append_chunk(up.data, up.size, offset, data)}

    def commit(self, session: int) -> dict:
        """OBJECTS_COMMIT: verify and store the upload; the session ends either way.

        Raises
        ------
        CommandError
            BAD_STATE before every byte arrived (the upload stays open);
            MODEL_REJECTED when verification fails, BAD_STATE when the store
            cannot take it -- in both cases the stored sets and the active
            one are unchanged.
        """
        up = self._owned(session, "OBJECTS_COMMIT")
        if len(up.data) != up.size:
            raise CommandError(ErrorCode.BAD_STATE, f"upload incomplete: {len(up.data)} of {up.size} B")
        self._pending = None
        store = self._require_store()
        try:
            s = store.install(up.name, bytes(up.data), up.sha256, up.size, activate=up.activate,
                              signature=up.signature)
        except UploadRefused as e:
            log.warning("object-set upload refused: %s", e)
            raise CommandError(ErrorCode.MODEL_REJECTED, str(e)[:1000]) from None
        except ObjectStoreError as e:
            log.warning("object-set upload not stored: %s", e)
            raise CommandError(ErrorCode.BAD_STATE, str(e)[:1000]) from None
        return {"name": s.name, "sha256": s.sha256, "objects": len(s.objects), "active": self.active()[0]}

    def abort(self, session: int | None = None) -> dict:
        """OBJECTS_ABORT: drop the upload in progress if ``session`` owns it (no-op without one)."""
        if self._pending is not None:
            if session is not None:
                self._owned(session, "OBJECTS_ABORT")
            self._pending = None
        return {}

    # -- listing and choosing ----------------------------------------------------------
    def listing(self) -> dict:
        """OBJECTS_LIST: the stored sets and the active one's name."""
        sets = self.store.listing() if self.store is not None else []
        return {"active": self.active()[0], "sets": sets, "error": self.error}

    def remove(self, name: str) -> dict:
        """OBJECTS_REMOVE: delete a stored set (the library becomes active if it was)."""
        store = self._require_store()
        if name not in store.names():
            raise CommandError(ErrorCode.NOT_FOUND, f"no object set {name!r}", "name")
        try:
            store.remove(name)
        except ObjectStoreError as e:
            raise CommandError(ErrorCode.BAD_STATE, str(e)) from None
        return {"removed": name, "active": self.active()[0]}

    def select(self, name: str) -> dict:
        """OBJECTS_SELECT: make a stored set, or ``"library"``, the active one."""
        store = self._require_store()
        if name != LIBRARY_SET and name not in store.names():
            raise CommandError(ErrorCode.NOT_FOUND, f"no object set {name!r}", "name")
        try:
            store.select(name)
        except ObjectStoreError as e:
            raise CommandError(ErrorCode.BAD_STATE, str(e)) from None
        return {"active": self.active()[0]}
