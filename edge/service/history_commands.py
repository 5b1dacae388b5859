"""The daemon's RESULT, HISTORY and SERIES replies: stored measurements, paged to fit one reply.

Reply sizing is :mod:`edge.service.requests`'.
"""

from __future__ import annotations

import logging

from edge.protocol.errors import CommandError, ErrorCode
from edge.service.requests import fit_record, history_page, series_page

__all__ = [
    "HistoryCommands",
]

log = logging.getLogger("thermotouch.edge")

class HistoryCommands:
    """RESULT (by id or latest), HISTORY (paged, newest first), SERIES (a record's series, paged).

    Mixed into :class:`edge.service.daemon.Daemon`, whose constructor sets the attributes used
    here; the methods are the daemon's own (``self`` is the daemon).
    """

    def _cmd_result(self, args: dict) -> dict:
        mid = args.get("measurement_id")
        if mid is None:
            mid = self.history.latest_id()
            if mid is None:
                raise CommandError(ErrorCode.NOT_FOUND, "no measurement stored yet", "measurement_id")
        rec = self.history.get(mid)
        if rec is None:
            raise CommandError(ErrorCode.NOT_FOUND, f"no measurement {mid}", "measurement_id")
        return fit_record(rec, self.max_payload)

    def _cmd_history(self, args: dict) -> dict:
        offset, limit = args.get("offset", 0), args.get("limit", 20)
        total, items = self.history.page(offset, limit)
        return history_page(offset, total, items, self.max_payload)

    def _series_record(self, mid: int) -> dict | None:
        # A host pages through one series after another: keep the last record's arrays
        # (stored records never change, and ids are never reused).
        cached = self._series_cache
        if cached is not None and cached[0] == mid:
            return cached[1]
        rec = self.history.get(mid, series=True)
        if rec is not None:
            self._series_cache = (mid, rec)
        return rec

    def _cmd_series(self, args: dict) -> dict:
        mid, which = args["measurement_id"], args.get("which", "raw")
        offset, limit = args.get("offset", 0), args.get("limit")
        rec = self._series_record(mid)
        if rec is None:
            raise CommandError(ErrorCode.NOT_FOUND, f"no measurement {mid}", "measurement_id")
        return series_page(rec, mid, which, offset, limit, self.max_payload)
