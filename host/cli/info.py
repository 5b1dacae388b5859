"""``thermotouch info``: firmware, model and board of the probe."""

from __future__ import annotations

from host.cli.args import add_device_args
from host.cli.common import device_session
from host.cli.report import dumps, info_lines


def add_parser(sub, parents):
    p = sub.add_parser("info", help="firmware, model and board of the probe", parents=parents)
    add_device_args(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def run(args) -> int:
    with device_session(args) as session:
        info = session.client.info()
        status = session.client.status()
    if args.json:
        print(dumps({"info": info, "status": status}))
    else:
        print("\n".join(info_lines(session.port, info, status)))
    return 0
