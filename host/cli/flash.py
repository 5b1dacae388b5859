"""``thermotouch flash``: verify a model bundle and install it on the probe."""

from __future__ import annotations

from host.cli.args import add_device_args
from host.cli.common import device_session


def add_parser(sub, parents):
    p = sub.add_parser("flash", help="verify a model bundle and install it on the probe", parents=parents)
    p.add_argument("bundle", help="bundle directory (e.g. from 'thermotouch train')")
    add_device_args(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from host.flash import flash_bundle, load_verified  # noqa: PLC0415

    load_verified(args.bundle)  # refuse a bad bundle before touching the device (exit 2)
    with device_session(args) as session:
        r = flash_bundle(session, args.bundle)
    print(f"flashed {args.bundle} ({r['bytes']} B): device runs {r['model_version']} sha256 {r['model_sha256']}")
    return 0
