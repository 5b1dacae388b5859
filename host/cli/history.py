"""``thermotouch history``: the probe's stored measurements, newest first; CSV export."""

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
    add_output(p, "--export", suffixes=(".csv",), metavar="FILE.csv", help="write the records to a CSV file")
    p.add_argument("--limit", type=positive_int, default=None, help="at most this many records (default: all)")
    p.add_argument("--export-series", nargs=2, metavar=("ID", "FILE.csv"), default=None,
                   help="write measurement ID's touch record as the device recorded it (a '# key: value' header "
                        "naming the probe, power, sample clock, calibration, model and software; columns t_s from "
                        "heater-on, negative before; T_C; q_W_m2; read times when recorded) as a CSV that "
                        "`thermotouch estimate` and `calibrate --record` read")
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
        path = output_file((".csv",))(file)
    except argparse.ArgumentTypeError as exc:
        raise CliError(f"--export-series: {exc}") from None
    if os.path.lexists(path) and not args.overwrite:
        raise CliError(f"--export-series {path} exists (use --overwrite to replace it)")
    return mid, path


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
    except OSError as exc:
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


def run(args) -> int:
    import csv  # noqa: PLC0415

    if args.export_series is not None:
        if args.export is not None or args.json:
            raise CliError("--export-series writes one record; it does not combine with --export or --json")
        return _export_series(args)

    from host.atomic import atomic_path  # noqa: PLC0415

    items: list[dict] = []
    with device_session(args) as session:
        offset = 0
        while args.limit is None or len(items) < args.limit:
            want = PAGE if args.limit is None else min(PAGE, args.limit - len(items))
            page = session.client.history(offset=offset, limit=want)
            items.extend(page["items"])
            offset += len(page["items"])
            if not page["items"] or offset >= page["total"]:
                break
    items = items[:args.limit] if args.limit is not None else items
    if args.export:
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
