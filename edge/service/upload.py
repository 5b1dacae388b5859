"""A model upload over the serial line: MODEL_BEGIN, MODEL_CHUNKs, then MODEL_COMMIT or MODEL_ABORT.

:class:`ModelUpload` is the session's state machine::

    no upload --begin--> receiving --chunk...--> receiving --commit--> no upload (installed or refused)
                                   \\--abort / begin again--> no upload / new upload

Each MODEL_BEGIN opens a new *session* with a random non-zero u32 id
(:attr:`ModelUpload.session`, sent back in the MODEL_BEGIN reply); MODEL_CHUNK,
MODEL_COMMIT and MODEL_ABORT name it. A request for another session -- a
second host, or a host whose upload was superseded by a newer MODEL_BEGIN --
is refused with BAD_STATE and leaves the owner's upload untouched, so two
hosts cannot interleave their bytes into one bundle.

The blob is held in memory until commit (bundles are small; the size is
bounded before the first byte arrives), then handed to
:meth:`edge.model.store.ModelStore.install`, which verifies it and installs it
atomically. Each step answers with the reply body of its command or raises
:class:`~edge.protocol.messages.CommandError` for the ERROR reply, so the
daemon's handlers only forward their arguments.
"""

from __future__ import annotations

import logging
import secrets
from typing import Any

from edge.model.store import InstallError, ModelStore
from edge.protocol.errors import CommandError, ErrorCode

__all__ = ["MAX_UPLOAD_BYTES", "ModelUpload"]

log = logging.getLogger("thermotouch.edge")

#: Largest model upload held in memory (bytes); keeps the daemon within its RAM budget.
MAX_UPLOAD_BYTES = 8 * 1024 * 1024


def append_chunk(held: bytearray, size: int, offset: int, data: bytes) -> int:
    """Add one upload chunk to ``held`` (in place); the bytes held after it.

    The one rule for every chunked upload (models, object sets): chunks come
    in order; a chunk already held is accepted again when its bytes are the
    same (a host that lost our reply resends it); nothing may run past the
    announced ``size``.

    Raises
    ------
    CommandError
        BAD_ARGUMENT (field ``offset``) for a chunk past ``size`` or at an
        offset other than the next byte (and not a resend).
    """
    n = len(held)
    if offset + len(data) > size:
        raise CommandError(ErrorCode.BAD_ARGUMENT, f"chunk [{offset}, {offset + len(data)}) runs past the "
                           f"announced size {size}", "offset")
    if offset == n:
        held += data
    elif not (offset + len(data) <= n and held[offset:offset + len(data)] == data):
        raise CommandError(ErrorCode.BAD_ARGUMENT, f"chunk at offset {offset}, expected {n}", "offset")
    return len(held)


class _Pending:
    """What MODEL_BEGIN announced and the bytes received so far."""

    def __init__(self, size: int, sha256: str, version: str | None, session: int,
                 downgrade: str | None = None) -> None:
        self.session = session
        self.downgrade = downgrade
        self.size = size
        self.sha256 = sha256
        self.version = version
        self.data = bytearray()


class ModelUpload:
    """One model-upload session into ``store`` (at most one upload at a time).

    Parameters
    ----------
    store : ModelStore
        Where a committed upload is installed; its ``limits.max_blob_bytes``
        also bounds the announced size.
    max_upload_bytes : int
        Largest upload held in memory.
    """

    def __init__(self, store: ModelStore, max_upload_bytes: int = MAX_UPLOAD_BYTES) -> None:
        self.store = store
        self.max_upload_bytes = int(max_upload_bytes)
        self._pending: _Pending | None = None
        self._last_session = 0

    @property
    def session(self) -> int | None:
        """Id of the upload session in progress (None without one)."""
        return None if self._pending is None else self._pending.session

    def _new_session(self) -> int:
        while True:  # random, so a host's id from before a restart is (almost surely) stale
            sid = secrets.randbits(32)
            if sid and sid != self._last_session:
                self._last_session = sid
                return sid

    def _owned(self, session: int | None, command: str, *, required: bool) -> _Pending:
        """The upload in progress if ``session`` owns it (None is not checked unless ``required``)."""
        up = self._pending
        if up is None:
            raise CommandError(ErrorCode.BAD_STATE, "no upload in progress (send MODEL_BEGIN first)")
        if session is None and required:
            raise CommandError(ErrorCode.BAD_STATE, f"{command} must carry the session id from MODEL_BEGIN",
                               "session")
        if session is not None and session != up.session:
            log.warning("%s for session %d refused: upload session %d is in progress", command, session, up.session)
            raise CommandError(ErrorCode.BAD_STATE, f"session {session} is not the upload in progress "
                               "(stale or another host's); it is left untouched", "session")
        return up

    @property
    def in_progress(self) -> bool:
        """Whether an upload was begun and neither committed nor aborted."""
        return self._pending is not None

    def progress(self) -> dict[str, int] | None:
        """``{"received": bytes held, "size": announced size}`` of the upload in progress, or None."""
        up = self._pending
        return None if up is None else {"received": len(up.data), "size": up.size}

    def begin(self, size: int, sha256: str, version: str | None = None,
              downgrade: str | None = None) -> dict[str, Any]:
        """Start an upload of ``size`` bytes with digest ``sha256`` (drops one in progress).

        ``downgrade`` is a signed authorisation that lets a signed bundle that is not newer than
        the active one be installed (see :mod:`edge.security.policy`); the signature is checked
        all the same.

        Returns
        -------
        dict
            ``{"size": size}``.

        Raises
        ------
        CommandError
            MODEL_REJECTED if ``size`` exceeds the store's or the memory limit.
        """
        limit = min(self.store.limits.max_blob_bytes, self.max_upload_bytes)
        if size > limit:
            raise CommandError(ErrorCode.MODEL_REJECTED, f"size {size} B exceeds the upload limit of {limit} B",
                               "size")
        if self._pending is not None:
            log.info("model upload session %d superseded by a new MODEL_BEGIN", self._pending.session)
        self._pending = _Pending(size, sha256, version, self._new_session(), downgrade)
        log.info("model upload session %d started: %d B, sha256 %s%s", self._pending.session, size, sha256[:12],
                 " (downgrade authorisation attached)" if downgrade else "")
        return {"size": size}

    def chunk(self, offset: int, data: bytes, session: int | None = None, *,
              require_session: bool = False) -> dict[str, Any]:
        """Add ``data`` at ``offset``; a resent chunk already held is accepted again.

        ``session`` must name the upload in progress (None: not checked,
        unless ``require_session``).

        Returns
        -------
        dict
            ``{"received": bytes held}``.

        Raises
        ------
        CommandError
            BAD_STATE without an upload or for another session; BAD_ARGUMENT
            for a chunk past the announced size or at an offset other than the
            next byte (and not a resend).
        """
        up = self._owned(session, "MODEL_CHUNK", required=require_session)
        return {"received": append_chunk(up.data, up.size, offset, data)}

    def commit(self, session: int | None = None, *, require_session: bool = False) -> dict[str, Any]:
        """Install the complete upload; the session ends whether the store accepts it or not.

        ``session`` as for :meth:`chunk`.

        Returns
        -------
        dict
            ``model_sha256`` (the uploaded blob's), ``bundle_sha256`` and
            ``model_version`` of the installed bundle.

        Raises
        ------
        CommandError
            BAD_STATE without an upload, for another session or before all
            bytes arrived (the upload stays open); MODEL_REJECTED if the store
            refuses the blob.
        """
        up = self._owned(session, "MODEL_COMMIT", required=require_session)
        if len(up.data) != up.size:
            raise CommandError(ErrorCode.BAD_STATE, f"upload incomplete: {len(up.data)} of {up.size} B")
        self._pending = None
        try:
            bundle = self.store.install(bytes(up.data), up.sha256, up.size, downgrade=up.downgrade)
        except InstallError as e:
            detail = str(e)  # InstallError's message already carries the cause
            log.warning("model upload refused: %s", detail)
            raise CommandError(ErrorCode.MODEL_REJECTED, detail[:1000]) from None
        auth = getattr(self.store, "last_authentication", None)
        log.info("model %s (%s) installed%s", bundle.model_version, bundle.sha256[:12],
                 f", {auth.describe()}" if auth is not None else "")
        return {"model_sha256": up.sha256, "bundle_sha256": bundle.sha256, "model_version": bundle.model_version}

    def abort(self, session: int | None = None, *, require_session: bool = False) -> dict[str, Any]:
        """Drop the upload in progress, if any and if ``session`` owns it (as for :meth:`chunk`).

        Raises
        ------
        CommandError
            BAD_STATE if another session's upload is in progress (it goes on).
        """
        if self._pending is not None:
            self._owned(session, "MODEL_ABORT", required=require_session)
            log.info("model upload session %d aborted", self._pending.session)
        self._pending = None
        return {}
