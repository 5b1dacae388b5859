"""``thermotouch history``: the probe's stored measurements, newest first; CSV export."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from host.cli.args import add_device_args, add_output, output_file, positive_int
from host.cli.common import device_session
from host.cli.errors import EXIT_RUNTIME, CliError
from host.cli.report import HISTORY_CSV_COLUMNS, dumps, history_lines, history_row

#: Records per HISTORY request.
PAGE = 100


def add_parser(sub, parents):
    p = sub.add_parser("history", help="the probe's stored measurements, newest first", parents=parents)
    add_device_args(p)
    p.add_argument("--json", action="store_true", help="print one JSON list")
    add_output(p, "--export", suffixes=(".csv",), metavar="FILE.csv", help="write the records to a CSV file")
    p.add_argument("--limit", type=positive_int, default=None, help="at most this many records (default: all)")
    p.add_argument("--export-series", nargs=2, metavar=("ID", "FILE.csv"), default=None,
                   help="write measurement ID's raw record (t_s from heater-on, negative before; T_K; q_W_m2) "
                        "as a CSV that `thermotouch estimate` and `calibrate --record` read")
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
    from host.records import write_series  # noqa: PLC0415

    mid, path = _series_target(args)
    with device_session(args) as session:
        try:
            s = session.client.series(mid, "raw")
        except DeviceError as exc:
            raise CliError(f"--export-series {mid}: {exc.message}", EXIT_RUNTIME) from None
        probe = None
        try:
            info = session.client.info()
            probe = info.get("probe")
        except DeviceError:
            pass
    t, T, q = s.get("raw_t_s"), s.get("raw_T_C"), s.get("raw_q_W_m2")
    if t is None or len(t) == 0:
        raise CliError(f"--export-series {mid}: the device stored no raw record for it", EXIT_RUNTIME)
    keep = np.isfinite(t) & np.isfinite(T) & np.isfinite(q)
    try:
        write_series(path, t[keep], T[keep] + 273.15, q[keep], probe=probe)
    except OSError as exc:
        raise CliError(f"cannot write {path}: {exc.strerror or exc}", EXIT_RUNTIME) from None
    print(f"measurement {mid}: {int(keep.sum())} samples ({int((~keep).sum())} unreadable dropped) written to {path}")
    return 0


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
                    w.writerow(history_row(it))
        except OSError as exc:
            raise CliError(f"cannot write {args.export}: {exc.strerror or exc}", EXIT_RUNTIME) from None
    if args.json:
        print(dumps(items))
    else:
        print("\n".join(history_lines(items, str(args.export) if args.export else None)))
    return 0
