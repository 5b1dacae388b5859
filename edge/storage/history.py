"""Measurement history on the device: SQLite, committed before anything is reported.

Every measurement -- successful, aborted by a safety cut, or failed -- is
written with its raw series, result, flags, timestamps, the configuration
snapshot and the model identity, and the transaction is committed (WAL
journal, ``synchronous=FULL``: the commit is on stable storage when
:meth:`History.add` returns) before the daemon replies to the host. A lost
link therefore loses nothing; the host pages through :meth:`History.page`.

Schema (version 2)::

    CREATE TABLE measurements (
        id             INTEGER PRIMARY KEY AUTOINCREMENT,
        created_utc    TEXT NOT NULL,     -- ISO 8601, when the record was written
        started_utc    TEXT,              -- when the sequence started
        status         TEXT NOT NULL,     -- 'ok' | 'aborted' | 'failed'
        reason         TEXT,              -- why not ok, e.g. 'over_temperature'
        error          TEXT,              -- exception text, if any
        flags          TEXT NOT NULL,     -- JSON list of quality flags
        result         TEXT,              -- JSON estimator output, NULL if none
        model_sha256   TEXT,
        power_W        REAL,
        contact_time_s REAL,
        heater_on_s    REAL,              -- on-time of this measurement, s
        T0_C           REAL,
        q_offset_W_m2  REAL,
        sample_rate_Hz REAL,
        config         TEXT NOT NULL,     -- JSON config snapshot
        n_samples      INTEGER NOT NULL,
        raw_t_s        BLOB,              -- float64 little-endian, s from heater on
        raw_T_C        BLOB,              -- float64 LE, thermocouple
        raw_q_W_m2     BLOB,              -- float64 LE, heat flux
        grid_t_s       BLOB,              -- resampled uniform grid (estimator input)
        grid_dT_K      BLOB,
        grid_q_W_m2    BLOB,
        touch_header   TEXT,              -- JSON: the touch record's header (version 2)
        raw_T_dt_s     BLOB,              -- float64 LE, thermocouple read time vs raw_t_s (version 2)
        raw_q_dt_s     BLOB               -- float64 LE, flux read time vs raw_t_s (version 2)
    );
    PRAGMA user_version = 2;

A version-1 database is migrated when opened (the three columns added, in one
transaction): its rows keep everything they had, read back with
``touch_header`` None, and :func:`touch_header` rebuilds their header from what
the row holds (configuration snapshot, power, sample clock, flags).
"""

from __future__ import annotations

import json
import math
import os
import sqlite3
import threading
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from edge.status import Status

__all__ = ["HistoryError", "History", "SCHEMA_VERSION", "series_header", "touch_header", "utc_now"]

SCHEMA_VERSION = 2
_SERIES = ("raw_t_s", "raw_T_C", "raw_q_W_m2", "grid_t_s", "grid_dT_K", "grid_q_W_m2", "raw_T_dt_s", "raw_q_dt_s")
#: Columns version 2 added to version 1's table (name, SQL type).
_V2_COLUMNS = (("touch_header", "TEXT"), ("raw_T_dt_s", "BLOB"), ("raw_q_dt_s", "BLOB"))
_SCALARS = ("started_utc", "status", "reason", "error", "model_sha256", "power_W", "contact_time_s",
            "heater_on_s", "T0_C", "q_offset_W_m2", "sample_rate_Hz")
#: Plain strings, so the error message lists them as it always did.
_STATUSES = tuple(s.value for s in Status)
_MAX_SERIES = 1_000_000

_DDL = """
CREATE TABLE IF NOT EXISTS measurements (
    id             INTEGER PRIMARY KEY AUTOINCREMENT,
    created_utc    TEXT NOT NULL,
    started_utc    TEXT,
    status         TEXT NOT NULL,
    reason         TEXT,
    error          TEXT,
    flags          TEXT NOT NULL,
    result         TEXT,
    model_sha256   TEXT,
    power_W        REAL,
    contact_time_s REAL,
    heater_on_s    REAL,
    T0_C           REAL,
    q_offset_W_m2  REAL,
    sample_rate_Hz REAL,
    config         TEXT NOT NULL,
    n_samples      INTEGER NOT NULL,
    raw_t_s        BLOB,
    raw_T_C        BLOB,
    raw_q_W_m2     BLOB,
    grid_t_s       BLOB,
    grid_dT_K      BLOB,
    grid_q_W_m2    BLOB,
    touch_header   TEXT,
    raw_T_dt_s     BLOB,
    raw_q_dt_s     BLOB
)
"""


class HistoryError(RuntimeError):
    """The history database cannot be used."""


def utc_now() -> str:
    """Current UTC time as ISO 8601 with milliseconds."""
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def _json(obj: Any, what: str) -> str:
    try:
        return json.dumps(obj, allow_nan=False, separators=(",", ":"), sort_keys=True)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{what} is not JSON-serialisable: {e}") from None


def _blob(name: str, x: Any) -> bytes | None:
    if x is None:
        return None
    a = np.asarray(x, dtype="<f8")
    if a.ndim != 1 or a.size > _MAX_SERIES:
        raise ValueError(f"{name} must be a 1-D series of at most {_MAX_SERIES} values, got shape {a.shape}")
    return a.tobytes()


def _unblob(b: bytes | None) -> np.ndarray | None:
    return None if b is None else np.frombuffer(b, dtype="<f8").copy()


def _finite_or_none(x: Any) -> float | None:
    if x is None:
        return None
    f = float(x)
    return f if math.isfinite(f) else None


def _header_json(header: Any) -> str | None:
    if header is None:
        return None
    if not isinstance(header, Mapping):
        raise ValueError(f"touch_header must be a dict or None, got {type(header).__name__}")
    return _json(dict(header), "touch_header")


def touch_header(record: Mapping[str, Any]) -> dict[str, Any] | None:
    """The touch record's header of a stored measurement (``History.get(..., series=True)``).

    The stored header when the row has one. A row stored before schema version 2 has none: its
    header is rebuilt from what the row holds -- the probe, baseline and method of its
    configuration snapshot, its power, heater on-time and sample clock, ``saturated`` from its
    flags, an armed run from a record that starts well before its baseline -- and says so
    (``header_rebuilt: true``); what version 1 never stored (the converter's lag and
    resolution, when an armed run found the contact) is absent and takes the record's
    defaults. None for a row without a raw series (nothing was sampled).
    """
    stored = record.get("touch_header")
    if stored is not None:
        return dict(stored)
    if record.get("raw_t_s") is None or not record.get("n_samples"):
        return None
    cfg = record.get("config") or {}

    def conf(section: str, key: str, default: Any) -> Any:
        value = (cfg.get(section) or {}).get(key)
        return default if value is None else value

    header = {
        "probe": conf("board", "probe", "paper"),
        "power_W": record.get("power_W"),
        "heater_on_s": record.get("heater_on_s") or 0.0,
        "sample_rate_Hz": record.get("sample_rate_Hz"),
        "baseline_s": conf("measurement", "baseline_s", 0.0),
        "method": conf("estimation", "method", "default"),
        "saturated": "saturated" in (record.get("flags") or []),
        "header_rebuilt": True,
    }
    # An armed run sampled the air before its baseline: a record that starts well before its baseline
    # was armed (its arming time at least that long), and only its last baseline_s is the baseline.
    rate, lead_s = record.get("sample_rate_Hz"), -float(record["raw_t_s"][0])
    if header["heater_on_s"] > 0 and rate and lead_s > header["baseline_s"] + 1.5 / rate:
        header["arm_s"] = lead_s
    return header


def series_header(record: Mapping[str, Any]) -> dict[str, Any] | None:
    """What an exported series states before its columns: :func:`touch_header` and the settings of
    the row's ``[measurement]`` snapshot (``measurement.noise_T_K`` ...: the thresholds its quality
    flags were judged by), so that the touch can be estimated offline as the device estimated it.
    None when the row has no header to give."""
    header = touch_header(record)
    if header is None:
        return None
    settings = (record.get("config") or {}).get("measurement") or {}
    header.update((f"measurement.{k}", v) for k, v in sorted(settings.items())
                  if isinstance(v, (bool, int, float, str)))
    return header


class History:
    """SQLite-backed measurement history.

    Parameters
    ----------
    path : path-like
        Database file (created with its directory if missing); ``":memory:"``
        for tests.

    Thread-safe: one connection guarded by a lock.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = str(path)
        if self.path != ":memory:":
            Path(self.path).parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        try:
            self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
            mode = self._db.execute("PRAGMA journal_mode=WAL").fetchone()[0]
            if self.path != ":memory:" and str(mode).lower() != "wal":
                raise HistoryError(f"{self.path}: cannot enable WAL journal (got {mode!r})")
            self._db.execute("PRAGMA synchronous=FULL")
            # A small page cache keeps the daemon's memory flat however long the history grows.
            self._db.execute("PRAGMA cache_size=-512")
            version = self._db.execute("PRAGMA user_version").fetchone()[0]
            if version not in (0, 1, SCHEMA_VERSION):
                raise HistoryError(f"{self.path}: schema version {version}, this software knows {SCHEMA_VERSION}")
            if version == 1:
                self._migrate_v1()
            else:
                self._db.execute(_DDL)
                self._db.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
        except sqlite3.Error as e:
            raise HistoryError(f"cannot open history database {self.path}: {e}") from e

    def _migrate_v1(self) -> None:
        """Version 1 -> 2: add the touch record's columns; every row stays (the new columns NULL).

        One transaction: a power cut during it leaves a version-1 database that the next open
        migrates again.
        """
        db = self._db
        db.execute("BEGIN IMMEDIATE")
        try:
            have = {r[1] for r in db.execute("PRAGMA table_info(measurements)")}
            for name, kind in _V2_COLUMNS:
                if name not in have:
                    db.execute(f"ALTER TABLE measurements ADD COLUMN {name} {kind}")
            db.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
            db.execute("COMMIT")
        except sqlite3.Error:
            db.execute("ROLLBACK")
            raise

    def _conn(self) -> sqlite3.Connection:
        if self._db is None:
            raise HistoryError(f"history database {self.path} is closed")
        return self._db

    # -- writing -------------------------------------------------------------------
    def add(self, record: Mapping[str, Any]) -> int:
        """Store one measurement and commit it durably; return its id.

        ``record`` keys: ``status`` (required: 'ok', 'aborted', 'failed'),
        ``flags`` (list of str), ``result`` (JSON-able dict or None),
        ``config`` (JSON-able dict), ``touch_header`` (the touch record's
        header, :meth:`edge.estimation.record.TouchRecord.header`, a JSON-able
        dict or None), the scalar columns and the series columns (1-D float
        arrays; ``raw_T_dt_s``/``raw_q_dt_s`` as long as ``raw_t_s``) of the
        schema. Unknown keys are refused.
        """
        known = set(_SERIES) | set(_SCALARS) | {"flags", "result", "config", "touch_header"}
        unknown = set(record) - known
        if unknown:
            raise ValueError(f"record has unknown keys {sorted(unknown)}")
        status = record.get("status")
        if status not in _STATUSES:
            raise ValueError(f"status must be one of {_STATUSES}, got {status!r}")
        flags = list(record.get("flags") or [])
        if not all(isinstance(f, str) for f in flags):
            raise ValueError("flags must be a list of strings")
        blobs = {name: _blob(name, record.get(name)) for name in _SERIES}
        raw_t = blobs["raw_t_s"]
        n = 0 if raw_t is None else len(raw_t) // 8
        for name in ("raw_T_C", "raw_q_W_m2", "raw_T_dt_s", "raw_q_dt_s"):
            if blobs[name] is not None and len(blobs[name]) // 8 != n:
                raise ValueError(f"{name} has {len(blobs[name]) // 8} values, raw_t_s has {n}")
        row = {
            "created_utc": utc_now(),
            "flags": _json(flags, "flags"),
            "result": None if record.get("result") is None else _json(record["result"], "result"),
            "config": _json(record.get("config") or {}, "config"),
            "touch_header": _header_json(record.get("touch_header")),
            "n_samples": n,
            **blobs,
        }
        for name in _SCALARS:
            v = record.get(name)
            if name in ("power_W", "contact_time_s", "heater_on_s", "T0_C", "q_offset_W_m2", "sample_rate_Hz"):
                v = _finite_or_none(v)
            elif v is not None:
                v = str(v)
            row[name] = v
        cols = ", ".join(row)
        marks = ", ".join(f":{c}" for c in row)
        with self._lock:
            try:
                self._conn().execute("BEGIN IMMEDIATE")
                cur = self._conn().execute(f"INSERT INTO measurements ({cols}) VALUES ({marks})", row)
                self._conn().execute("COMMIT")
            except sqlite3.Error as e:
                try:
                    self._conn().execute("ROLLBACK")
                except sqlite3.Error:
                    pass
                raise HistoryError(f"storing a measurement failed: {e}") from e
            return int(cur.lastrowid)

    # -- reading ---------------------------------------------------------------------
    def count(self) -> int:
        """Number of stored measurements."""
        with self._lock:
            return int(self._conn().execute("SELECT COUNT(*) FROM measurements").fetchone()[0])

    _SUMMARY_COLS = ("id", "created_utc", "started_utc", "status", "reason", "error", "flags", "result",
                     "model_sha256", "power_W", "contact_time_s", "heater_on_s", "T0_C", "q_offset_W_m2",
                     "sample_rate_Hz", "n_samples")
    # Read with the series only: a summary (HISTORY, RESULT, MEASURE replies) stays as it was.
    _FULL_COLS = ("config", "touch_header") + _SERIES

    def _summary(self, row: tuple) -> dict[str, Any]:
        d = dict(zip(self._SUMMARY_COLS, row))
        d["measurement_id"] = d.pop("id")
        d["flags"] = json.loads(d["flags"])
        d["result"] = None if d["result"] is None else json.loads(d["result"])
        return d

    def get(self, measurement_id: int, *, series: bool = False) -> dict[str, Any] | None:
        """One record, or None.

        Summary fields; with ``series`` also ``config``, ``touch_header`` (a dict; None for a
        row stored before schema version 2 -- :func:`touch_header` rebuilds it) and the numpy
        series (None where not stored).
        """
        cols = ", ".join(self._SUMMARY_COLS)
        extra = (", " + ", ".join(self._FULL_COLS)) if series else ""
        with self._lock:
            row = self._conn().execute(f"SELECT {cols}{extra} FROM measurements WHERE id = ?",
                                   (int(measurement_id),)).fetchone()
        if row is None:
            return None
        d = self._summary(row[:len(self._SUMMARY_COLS)])
        if series:
            rest = row[len(self._SUMMARY_COLS):]
            d["config"] = json.loads(rest[0])
            d["touch_header"] = None if rest[1] is None else json.loads(rest[1])
            for name, b in zip(_SERIES, rest[2:]):
                d[name] = _unblob(b)
        return d

    def latest_id(self) -> int | None:
        """Id of the newest record, or None if empty."""
        with self._lock:
            row = self._conn().execute("SELECT MAX(id) FROM measurements").fetchone()
        return None if row[0] is None else int(row[0])

    def page(self, offset: int = 0, limit: int = 20) -> tuple[int, list[dict[str, Any]]]:
        """``(total, records)``: ``limit`` summaries, newest first, skipping ``offset``."""
        if isinstance(offset, bool) or not isinstance(offset, int) or offset < 0:
            raise ValueError(f"offset must be an int >= 0, got {offset!r}")
        if isinstance(limit, bool) or not isinstance(limit, int) or not 1 <= limit <= 1000:
            raise ValueError(f"limit must be an int in [1, 1000], got {limit!r}")
        cols = ", ".join(self._SUMMARY_COLS)
        with self._lock:
            total = int(self._conn().execute("SELECT COUNT(*) FROM measurements").fetchone()[0])
            rows = self._conn().execute(f"SELECT {cols} FROM measurements ORDER BY id DESC LIMIT ? OFFSET ?",
                                    (limit, offset)).fetchall()
        return total, [self._summary(r) for r in rows]

    # -- lifecycle ---------------------------------------------------------------------
    def close(self) -> None:
        """Checkpoint the WAL and close (idempotent)."""
        with self._lock:
            db, self._db = self._db, None
        if db is None:
            return
        try:
            db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        except sqlite3.Error:
            pass  # the WAL is replayed at the next open
        db.close()

    @property
    def closed(self) -> bool:
        return self._db is None

    def __enter__(self) -> History:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
