"""``thermotouch flash``: verify a model bundle and install it on the probe."""

from __future__ import annotations

from host.cli.args import add_device_args
from host.cli.common import device_session
from host.cli.errors import CliError


def add_parser(sub, parents):
    p = sub.add_parser("flash", help="verify a model bundle and install it on the probe", parents=parents)
    p.add_argument("bundle", help="bundle directory (e.g. from 'thermotouch train')")
    add_device_args(p)
    p.add_argument("--key", metavar="FILE", default=None,
                   help="secret key file (thermotouch keys new) to sign the bundle's manifest with; "
                        "without it the upload is unsigned (a real probe refuses it)")
    p.add_argument("--force", action="store_true",
                   help="a deliberate rollback: install even if the bundle is not newer than the probe's model, "
                        "with an authorisation signed by --key for exactly this bundle over the model it runs")
    p.set_defaults(func=run)


def run(args) -> int:
    from host.flash import flash_bundle, load_signing_key, load_verified  # noqa: PLC0415

    if args.force and args.key is None:
        raise CliError("--force needs --key: a rollback is authorised by a signature, not by a flag")
    load_verified(args.bundle)  # refuse a bad bundle before touching the device (exit 2)
    key = load_signing_key(args.key)  # and a bad key
    with device_session(args) as session:
        r = flash_bundle(session, args.bundle, key=key, force=args.force)
    signed = f", signed by key {r['key_id']}" if r["key_id"] else ""
    print(f"flashed {args.bundle} ({r['bytes']} B{signed}): device runs {r['model_version']} "
          f"sha256 {r['model_sha256']}")
    return 0
