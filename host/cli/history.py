"""``thermotouch history``: the probe's stored measurements, newest first; CSV or Parquet export.

``--export FILE.parquet`` (and ``--export-series ID FILE.parquet``) write the same columns as the CSV,
typed (numbers as float64 with nulls, ids as integers, text as text), each column's unit in its field
metadata, and what identifies the export in the file's metadata: the device (``device_id``, ``board``),
its software, the probe head, the export's UTC time and the ± convention. Parquet needs the optional
``pyarrow`` (``pip install 'thermotouch[parquet]'``); without it the export is refused before connecting.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np

from host.cli.args import add_device_args, add_output, output_file, positive_int
from host.cli.common import device_session
from host.cli.errors import EXIT_RUNTIME, CliError
from host.cli.report import HISTORY_CSV_COLUMNS, csv_cell, dumps, history_lines, history_row

#: Records per HISTORY request.
PAGE = 100


def add_parser(sub, parents):
    p = sub.add_parser("history", help="the probe's stored measurements, newest first", parents=parents)
    add_device_args(p)
    p.add_argument("--json", action="store_true", help="print one JSON list")
    add_output(p, "--export", suffixes=(".csv", ".parquet"), metavar="FILE.csv|FILE.parquet",
               help="write the records to a CSV file, or a Parquet table (needs pyarrow)")
    p.add_argument("--limit", type=positive_int, default=None, help="at most this many records (default: all)")
    p.add_argument("--export-series", nargs=2, metavar=("ID", "FILE.csv"), default=None,
                   help="write measurement ID's touch record as the device recorded it (a '# key: value' header "
                        "naming the probe, power, sample clock, calibration, model and software; columns t_s from "
                        "heater-on, negative before; T_C; q_W_m2; read times when recorded) as a CSV (or, named "
                        "*.parquet, a Parquet table with that header as metadata) that `thermotouch estimate` "
                        "and `calibrate --record` read")
    p.set_defaults(func=run)


def _series_target(args) -> tuple[int, Path]:
    """``--export-series ID FILE.csv``, checked before any connection."""
    sid, file = args.export_series
    try:
        mid = int(sid)
    except ValueError:
        raise CliError(f"--export-series: measurement ID must be a whole number, got {sid!r}") from None
    if mid < 1:
        raise CliError(f"--export-series: measurement ID must be >= 1, got {mid}")
    try:
        path = output_file((".csv", ".parquet"))(file)
    except argparse.ArgumentTypeError as exc:
        raise CliError(f"--export-series: {exc}") from None
    if os.path.lexists(path) and not args.overwrite:
        raise CliError(f"--export-series {path} exists (use --overwrite to replace it)")
    _need_pyarrow(path, "--export-series")
    return mid, path


def _need_pyarrow(path: Path, flag: str) -> None:
    """A Parquet output without pyarrow is refused before any connection (exit 2)."""
    from host.records import RecordError, _parquet, is_parquet  # noqa: PLC0415

    if is_parquet(path):
        try:
            _parquet()
        except RecordError as exc:
            raise CliError(f"{flag} {path}: {exc}") from None


def _export_series(args) -> int:
    from host.client import DeviceError  # noqa: PLC0415
    from host.records import write_touch  # noqa: PLC0415

    mid, path = _series_target(args)
    with device_session(args) as session:
        try:
            s = session.client.series(mid, "raw")
            rec = session.client.result(mid)
        except DeviceError as exc:
            raise CliError(f"--export-series {mid}: {exc.message}", EXIT_RUNTIME) from None
        try:
            info = session.client.info()
        except DeviceError:
            info = {}
        header = s.get("header")
        if header is None and s.get("raw_t_s") is not None:
            header = _header_from_result(session.client, rec, info)
    t, T, q = s.get("raw_t_s"), s.get("raw_T_C"), s.get("raw_q_W_m2")
    if t is None or len(t) == 0:
        raise CliError(f"--export-series {mid}: the device stored no raw record for it", EXIT_RUNTIME)
    touch = _touch(mid, header, s)
    result = rec.get("result") or {}
    identity = {"measurement_id": mid, "started_utc": rec.get("started_utc"), "status": rec.get("status"),
                "reason": rec.get("reason"),
                "calibration_sha256": result.get("calibration_sha256"),
                "model_sha256": rec.get("model_sha256") or result.get("model_sha256"),
                "object_set": result.get("object_set"), "software": info.get("firmware_version"),
                # The device that holds the history took the touch (its serial, where it has one).
                "board": info.get("board"), "device_id": info.get("device_id"),
                # The running decision the device judged the answer against (one line of JSON).
                "decision": None if not isinstance(result.get("decision"), dict)
                else json.dumps(result["decision"], separators=(",", ":"), sort_keys=True)}
    try:
        write_touch(path, touch, identity)
    except (OSError, ValueError) as exc:
        raise CliError(f"cannot write {path}: {exc.strerror or exc}", EXIT_RUNTIME) from None
    dropped = int(len(t) - touch.t_s.size)
    print(f"measurement {mid}: {touch.t_s.size} samples ({dropped} unreadable dropped) written to {path}")
    return 0


def _header_from_result(client, rec: dict, info: dict) -> dict:
    """A device that sends no header (older software): the record's fields from what RESULT and the
    device's configuration say, marked as rebuilt."""
    from host.client import DeviceError  # noqa: PLC0415

    try:
        cfg = client.config_get("measurement.baseline_s", "estimation.method")
    except DeviceError:
        cfg = {}
    return {"probe": info.get("probe") or "paper", "power_W": rec.get("power_W"),
            "heater_on_s": rec.get("heater_on_s") or 0.0, "sample_rate_Hz": rec.get("sample_rate_Hz"),
            "baseline_s": cfg.get("measurement.baseline_s", 0.0), "method": cfg.get("estimation.method", "default"),
            "saturated": "saturated" in (rec.get("flags") or []), "header_rebuilt": True}


def _touch(mid: int, header: dict, s: dict):
    """The device's touch record from its header and raw columns (unreadable samples dropped)."""
    from edge.estimation.record import RecordError, TouchRecord  # noqa: PLC0415

    t, T, q = s["raw_t_s"], s["raw_T_C"], s["raw_q_W_m2"]
    dts = [s.get("raw_T_dt_s"), s.get("raw_q_dt_s")]
    keep = np.isfinite(t) & np.isfinite(T) & np.isfinite(q)
    for a in dts:
        if a is not None:
            keep &= np.isfinite(a)
    try:
        return TouchRecord.from_header(header, t[keep], T[keep], q[keep],
                                       *(None if a is None else a[keep] for a in dts))
    except RecordError as exc:
        raise CliError(f"--export-series {mid}: the device's record is not usable: {exc}", EXIT_RUNTIME) from None


#: Units of the history columns that have one (Parquet field metadata; the CSV's names say them).
HISTORY_UNITS = {"power_W": "W", "contact_time_s": "s", "heater_on_s": "s", "T0_C": "degC",
                 "effusivity_W_s05_m2K": "W s^0.5/(m^2 K)", "effusivity_W_s05_m2K_u": "W s^0.5/(m^2 K)",
                 "k_W_mK": "W/(m K)", "k_W_mK_u": "W/(m K)", "alpha_m2_s": "m^2/s", "alpha_m2_s_u": "m^2/s"}
_HISTORY_FLOATS = ("power_W", "contact_time_s", "heater_on_s", "T0_C", "effusivity_W_s05_m2K",
                   "effusivity_W_s05_m2K_u", "k_W_mK", "k_W_mK_u", "alpha_m2_s", "alpha_m2_s_u",
                   "material_confidence", "object_posterior", "class_posterior")


def write_history_parquet(path: Path, items: list[dict], info: dict) -> None:
    """The history rows (:func:`host.cli.report.history_row`) as a typed Parquet table with the export's identity."""
    import pyarrow as pa  # noqa: PLC0415

    from host.cli.report import UNCERTAINTY_NOTE  # noqa: PLC0415
    from host.records import write_parquet  # noqa: PLC0415

    rows = [history_row(it) for it in items]
    cols = {}
    for name in HISTORY_CSV_COLUMNS:
        values = [r[name] for r in rows]
        if name in _HISTORY_FLOATS:
            cols[name] = pa.array([None if v is None else float(v) for v in values], type=pa.float64())
        elif name == "measurement_id":
            cols[name] = pa.array(values, type=pa.int64())
        else:
            cols[name] = pa.array([None if v is None else str(v) for v in values], type=pa.string())
    probes = sorted({str((it.get("result") or {}).get("probe")) for it in items
                     if (it.get("result") or {}).get("probe")})
    meta = {"device_id": info.get("device_id"), "board": info.get("board"), "software": info.get("firmware_version"),
            "probe": info.get("probe") or (probes[0] if len(probes) == 1 else " ".join(probes) or None),
            "exported_utc": _utc_now(), "records": len(rows), "uncertainty": UNCERTAINTY_NOTE}
    write_parquet(path, cols, meta, HISTORY_UNITS, "history")


def read_history_parquet(path) -> tuple[list[dict], dict[str, str]]:
    """``(rows, metadata)`` of a ``history --export FILE.parquet`` table (rows as :func:`history_row` gives them)."""
    from host.records import read_parquet  # noqa: PLC0415

    cols, meta = read_parquet(path, "history")
    names = list(cols)
    n = len(cols[names[0]]) if names else 0
    return [{k: (None if isinstance(cols[k], np.ndarray) and np.isnan(cols[k][i]) else
                 (float(cols[k][i]) if isinstance(cols[k], np.ndarray) else cols[k][i])) for k in names}
            for i in range(n)], meta


def _utc_now() -> str:
    from datetime import datetime, timezone  # noqa: PLC0415

    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def run(args) -> int:
    import csv  # noqa: PLC0415

    if args.export_series is not None:
        if args.export is not None or args.json:
            raise CliError("--export-series writes one record; it does not combine with --export or --json")
        return _export_series(args)

    from host.atomic import atomic_path  # noqa: PLC0415
    from host.records import is_parquet  # noqa: PLC0415

    parquet = args.export is not None and is_parquet(args.export)
    if parquet:
        _need_pyarrow(args.export, "--export")
    items: list[dict] = []
    info: dict = {}
    with device_session(args) as session:
        if parquet:
            info = session.client.info()
        offset = 0
        while args.limit is None or len(items) < args.limit:
            want = PAGE if args.limit is None else min(PAGE, args.limit - len(items))
            page = session.client.history(offset=offset, limit=want)
            items.extend(page["items"])
            offset += len(page["items"])
            if not page["items"] or offset >= page["total"]:
                break
    items = items[:args.limit] if args.limit is not None else items
    if parquet:
        try:
            write_history_parquet(args.export, items, info)
        except OSError as exc:
            raise CliError(f"cannot write {args.export}: {exc.strerror or exc}", EXIT_RUNTIME) from None
    elif args.export:
        try:
            with atomic_path(args.export) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
                w = csv.DictWriter(fh, fieldnames=HISTORY_CSV_COLUMNS)
                w.writeheader()
                for it in items:
                    w.writerow({k: csv_cell(v) for k, v in history_row(it).items()})
        except OSError as exc:
            raise CliError(f"cannot write {args.export}: {exc.strerror or exc}", EXIT_RUNTIME) from None
    if args.json:
        print(dumps(items))
    else:
        print("\n".join(history_lines(items, str(args.export) if args.export else None)))
    return 0
