"""``thermotouch history``: the probe's stored measurements, newest first; CSV export."""

from __future__ import annotations

from host.cli.args import add_device_args, add_output, positive_int
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
    p.set_defaults(func=run)


def run(args) -> int:
    import csv  # noqa: PLC0415

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
