"""The daemon's degraded start: faults by component, stand-ins for what cannot be opened, records kept in memory.

A state directory that is read-only or full, a corrupt history database, a model store that
cannot be used: the daemon still starts, keeps the heater off and reports ``faults``; the
faults are re-checked (at most every :data:`FAULT_RECHECK_s` on requests, at once before each
MEASURE), and a record the history cannot take is kept in memory (up to
:data:`MAX_UNSAVED_RECORDS`) and stored on a later re-check (see :mod:`edge.service.daemon`).
"""

from __future__ import annotations

import logging
import math
import os
import sqlite3
import time
from pathlib import Path
from typing import Any, Mapping

from edge.estimation.estimate import pipeline_golden_check
from edge.estimation.selfcheck import semantic_check
from edge.model.store import InstallError, ModelStore, ModelStoreError
from edge.service.config import Config
from edge.storage import durable
from edge.storage.history import History, HistoryError

__all__ = [
    "FAULT_RECHECK_s", "MAX_UNSAVED_RECORDS", "MIN_FREE_BYTES", "FaultKeeping",
]

log = logging.getLogger("thermotouch.edge")

#: Least time between two re-checks of active faults on ordinary requests, s.
FAULT_RECHECK_s = 1.0
#: Most records kept in memory while the history cannot store them (the oldest go first).
MAX_UNSAVED_RECORDS = 16
#: Free bytes the history's file system must have before a measurement (a record with its series
#: is a few hundred kB at most; SQLite needs room for its journal too).
MIN_FREE_BYTES = 4 * 1024 * 1024


def _factory_bundle(cfg: Config) -> Path | None:
    if cfg.paths.factory_model:
        return Path(cfg.paths.factory_model)
    try:
        # Function-local on purpose: thermotouch_models is optional package data, not a code
        # dependency (edge must import without it, see tests/test_edge_purity.py).
        from thermotouch_models import DEFAULT_BUNDLE  # noqa: PLC0415
    except ImportError:
        return None
    return DEFAULT_BUNDLE if (DEFAULT_BUNDLE / "manifest.json").exists() else None


class _UnavailableHistory:
    """Stands in for a history database that cannot be opened; every use raises HistoryError."""

    def __init__(self, path: str, error: str) -> None:
        self.path, self.error = path, error

    def __getattr__(self, name: str) -> Any:
        def unavailable(*args: Any, **kw: Any) -> Any:
            raise HistoryError(f"history database {self.path} unavailable: {self.error}")
        return unavailable

    def close(self) -> None:
        pass

    @property
    def closed(self) -> bool:
        return True


class _UnavailableStore:
    """Stands in for a model store that cannot be opened: no model, every install refused."""

    def __init__(self, root: str, error: str, limits: Any) -> None:
        self.root, self.error, self.limits, self.source = root, error, limits, None

    def current(self) -> Any:
        raise ModelStoreError(f"model store {self.root} unavailable: {self.error}")

    def status(self) -> dict:
        return {"source": None, "sha256": None, "model_version": None,
                "error": f"model store {self.root} unavailable: {self.error}"}

    def install(self, *args: Any, **kw: Any) -> Any:
        raise InstallError(f"model store {self.root} unavailable: {self.error}")


def _non_finite_to_none(x: Any, path: str, bad: list[str]) -> Any:
    """``x`` with every non-finite float (NaN, inf) replaced by None, their paths appended to ``bad``."""
    if isinstance(x, float) and not math.isfinite(x):
        bad.append(path)
        return None
    if isinstance(x, Mapping):
        return {k: _non_finite_to_none(v, f"{path}.{k}", bad) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_non_finite_to_none(v, f"{path}[{j}]", bad) for j, v in enumerate(x)]
    return x


class FaultKeeping:
    """What is wrong now and what heals by itself: opening the history and the model store, faults, unsaved records.

    Mixed into :class:`edge.service.daemon.Daemon`, whose constructor sets the attributes used
    here; the methods are the daemon's own (``self`` is the daemon).
    """

    # -- set-up helpers --------------------------------------------------------------
    def _open_history(self) -> Any:
        path = self.config.paths.history_db
        try:
            h = History(path)
        except (HistoryError, OSError, sqlite3.Error) as e:
            self._set_fault("history", f"cannot open {path}: {e}")
            return _UnavailableHistory(path, str(e))
        self._clear_fault("history")
        return h

    def _open_store(self) -> Any:
        root = self.config.paths.model_store
        try:
            policy = self._update_policy()
            store = ModelStore(root, _factory_bundle(self.config), golden_check=pipeline_golden_check,
                               limits=self.model_limits, semantic_check=semantic_check, policy=policy)
        except (ModelStoreError, OSError) as e:
            self._set_fault("model_store", f"cannot open {root}: {e}")
            return _UnavailableStore(root, str(e), self.model_limits)
        self._clear_fault("model_store")
        return store

    # -- faults ------------------------------------------------------------------------
    def _set_fault(self, component: str, message: str) -> None:
        if self.component_faults.get(component) != message:
            log.error("fault %s: %s", component, message)
        self.component_faults[component] = message

    def _clear_fault(self, component: str) -> None:
        if self.component_faults.pop(component, None) is not None:
            log.warning("fault %s cleared", component)

    def fault_list(self) -> list[str]:
        """What is wrong now: component faults, then the last heater faults (``faults`` in STATUS/INFO)."""
        out = [f"{k}: {v}" for k, v in sorted(self.component_faults.items())]
        return out + [f"heater: {f}" for f in self.faults[-5:]]

    def _check_faults(self, *, force: bool = False) -> None:
        """Re-check every fault that can heal by itself (at most every FAULT_RECHECK_s unless ``force``)."""
        now = time.monotonic()
        if not force and now - self._last_check < FAULT_RECHECK_s:
            return
        self._last_check = now
        if isinstance(self.history, _UnavailableHistory) and self._own_history:
            self.history = self._open_history()
            if not isinstance(self.history, _UnavailableHistory):
                try:
                    self.last_id = self.history.latest_id()
                except HistoryError as e:
                    self._set_fault("history", str(e))
        if isinstance(self.store, _UnavailableStore) and self._own_store:
            self.store = self._open_store()
            self._model_est.store = self.upload.store = self.store
        if getattr(self, "device_id", "") is None:  # a card that was read-only at start may be writable now
            self.device_id = self._load_device_id()
            if self.device_id is not None:
                self._clear_fault("identity")
        self._check_storage()
        self._store_unsaved()
        self._check_objects()
        err = self.calibration.error()
        if err:
            self._set_fault("calibration", err)
        else:
            self._clear_fault("calibration")
        if self.estimator is self._model_est:
            try:
                self.store.current()
                self._clear_fault("model")
            except ModelStoreError as e:
                self._set_fault("model", f"{e} (a measurement would end estimation_failed)")

    def _check_objects(self) -> None:
        """The ``objects`` fault: a chosen set that cannot be used (reported, not blocking: the library names)."""
        self.objects.reopen()
        err = self.objects.error
        if err:
            self._set_fault("objects", err)
        else:
            self._clear_fault("objects")

    def _check_storage(self) -> None:
        path = getattr(self.history, "path", ":memory:")
        if path == ":memory:":
            return
        directory = os.path.dirname(os.path.abspath(path))
        try:
            free = durable.free_bytes(directory)
        except OSError:
            return  # cannot tell; the history's own errors will say
        if free < MIN_FREE_BYTES:
            self._set_fault("storage", f"{directory} is full: {free} B free, {MIN_FREE_BYTES} B needed")
        elif not os.access(directory, os.W_OK):
            self._set_fault("storage", f"{directory} is not writable")
        else:
            self._clear_fault("storage")

    def _store_unsaved(self) -> None:
        while self.unsaved:
            try:
                mid = self.history.add(self.unsaved[0])
            except HistoryError as e:
                self._set_fault("unsaved", f"{len(self.unsaved)} record(s) kept in memory: {e}")
                return
            rec = self.unsaved.pop(0)
            self.last_id = mid
            log.warning("measurement %d (%s) stored late", mid, rec.get("status"))
        self._clear_fault("unsaved")

    def _measure_blockers(self) -> list[str]:
        model = ("model", "model_store") if self.estimator is self._model_est else ()
        return [f"{k}: {v}" for k, v in sorted(self.component_faults.items())
                if k in ("history", "storage", "unsaved") + model]

    def _add_record(self, rec: dict) -> int | None:
        """Store ``rec``; on failure keep it in memory (None) -- a touch that heated is never lost."""
        try:
            return self.history.add(rec)
        except HistoryError as e:
            err: Exception = e
        except (ValueError, TypeError) as e:
            # Something in it the database refuses (e.g. a NaN in the estimator's result): keep the
            # measurement and as much of its result as can be stored, say what was dropped.
            bad: list[str] = []
            result = _non_finite_to_none(rec.get("result"), "result", bad)
            flags = [str(f) for f in rec.get("flags") or []]
            err = None
            if bad:
                log.error("record not storable as is (%s); storing it with %s as null", e, ", ".join(bad))
                try:
                    return self.history.add(dict(rec, result=result, flags=flags, error=(
                        f"{rec.get('error') or ''}; not finite, stored as null: {', '.join(bad)}").lstrip("; ")))
                except (HistoryError, ValueError, TypeError) as e2:
                    err = e2
            log.error("record not storable as is (%s); storing it without its result", err or e)
            rec = dict(rec, result=None, flags=flags,
                       error=f"{rec.get('error') or ''}; result not storable: {err or e}".lstrip("; "))
            try:
                return self.history.add(rec)
            except (HistoryError, ValueError, TypeError) as e2:
                err = e2
        if len(self.unsaved) >= MAX_UNSAVED_RECORDS:
            lost = self.unsaved.pop(0)
            log.critical("unsaved record of %s dropped: %d are kept at most", lost.get("started_utc"),
                         MAX_UNSAVED_RECORDS)
        self.unsaved.append(rec)
        self._set_fault("unsaved", f"{len(self.unsaved)} record(s) kept in memory: {err}")
        return None
