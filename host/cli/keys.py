"""``thermotouch keys``: make a signing key pair, list the keys of a directory.

``keys new`` writes NAME.secret.json (mode 0600, keep it on this host) and
NAME.public.json (copy it into the probe's ``security.trusted_keys_dir``);
``flash --key`` and ``deploy --key`` sign with the secret file.
"""

from __future__ import annotations

import argparse

from host.cli.errors import EXIT_BAD_INPUT, CliError


def add_parser(sub, parents):
    from host.keys import DEFAULT_NAME, KEYS_ENV  # noqa: PLC0415

    p = sub.add_parser("keys", help="make and list the keys that sign model updates", parents=parents,
                       description=__doc__.splitlines()[0])
    ksub = p.add_subparsers(dest="keys_command", required=True, metavar="ACTION", parser_class=type(p))
    n = ksub.add_parser("new", help="generate a key pair", parents=parents)
    n.add_argument("--out", metavar="DIR", default=None,
                   help=f"key directory (default ${KEYS_ENV}, else ~/.config/thermotouch/keys; created if missing)")
    n.add_argument("--name", default=DEFAULT_NAME, help=f"key name (default {DEFAULT_NAME})")
    n.add_argument("--overwrite", action="store_true", help="replace an existing key of that name (default: refuse)")
    n.set_defaults(func=run_new)
    ls = ksub.add_parser("list", help="list the keys in a directory", parents=parents)
    ls.add_argument("dir", nargs="?", default=None, help=f"key directory (default ${KEYS_ENV}, else "
                    "~/.config/thermotouch/keys)")
    ls.set_defaults(func=run_list)


def run_new(args: argparse.Namespace) -> int:
    from host.keys import default_keys_dir, key_paths, new_key  # noqa: PLC0415

    d = default_keys_dir() if args.out is None else args.out
    try:
        secret_path, public_path = key_paths(d, args.name)
    except ValueError as exc:
        raise CliError(f"argument --name: {exc}", EXIT_BAD_INPUT) from None
    key = new_key(d, args.name, overwrite=args.overwrite)
    print(f"key {key.key_id}: secret {secret_path} (mode 0600, keep it here), public {public_path} "
          "(copy it into the probe's security.trusted_keys_dir)")
    return 0


def run_list(args: argparse.Namespace) -> int:
    from edge.security.keys import SecretKey  # noqa: PLC0415
    from host.keys import default_keys_dir, list_keys  # noqa: PLC0415

    d = default_keys_dir() if args.dir is None else args.dir
    entries = list_keys(d)
    if not entries:
        print(f"no key files in {d}")
    for e in entries:
        if e.key is None:
            print(f"{e.path.name:32} unreadable: {e.error}")
        else:
            kind = "secret" if isinstance(e.key, SecretKey) else "public"
            print(f"{e.path.name:32} {kind:6} key_id {e.key.key_id}")
    return 0
