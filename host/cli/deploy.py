"""``thermotouch deploy``: train a bundle, prove it is no worse than the probe's, flash it, check a touch.

(Formerly the separate ``train-and-deploy`` script; the flow is :func:`host.deploy.train_and_deploy`.)
Exit status 0 deployed, 1 device or self-check failure, 2 bad input (also a bundle or key the device
refuses: unsigned, untrusted, bad signature, not newer), 3 refused (nothing flashed).
"""

from __future__ import annotations

import argparse

from host.cli.args import add_device_args, add_output, check_outputs, output_dir, positive_float, seed
from host.cli.common import device_session, say
from host.cli.errors import CliError

#: Bundle directory when neither --out nor --bundle is given.
DEFAULT_OUT = "thermotouch-model"


def add_parser(sub, parents):
    from host.deploy import Thresholds  # noqa: PLC0415

    p = sub.add_parser("deploy", help="train a bundle, check it against the probe's, flash it, self-check a touch",
                       parents=parents, description=__doc__.splitlines()[0])
    add_device_args(p, sim_help="start a simulated probe on SCENE for the duration (self-check against the "
                                "scene's object; glass_15V is a good reference)")
    p.add_argument("--quick", action="store_true", help="6 power levels, no noisy copies, fewer iterations")
    add_output(p, "--out", kind="dir", default=None,
               help="bundle directory to write (default ./thermotouch-model; an existing one needs --overwrite)")
    p.add_argument("--seed", type=seed, default=0, help="random seed, 0 .. 2^32-1 (default 0)")
    p.add_argument("--bundle", help="deploy this existing bundle instead of training one")
    p.add_argument("--baseline", help="the device's current bundle directory, if not the shipped default")
    p.add_argument("--key", metavar="FILE", default=None,
                   help="secret key file to sign the deployed bundle's manifest with (thermotouch keys new)")
    p.add_argument("--reference", choices=("tempered_glass", "pmma", "aluminium_alloy"),
                   help="with --port: the reference sample the probe rests on for the self-check touch")
    for f in Thresholds.__dataclass_fields__:
        flag = f"--max-{f.replace('_', '-')}"
        p.add_argument(flag, dest=f"max_{f}", type=positive_float, default=getattr(Thresholds, f), metavar="FRACTION",
                       help=f"largest error to deploy, fraction (default {getattr(Thresholds, f)})")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from host.deploy import Thresholds, train_and_deploy  # noqa: PLC0415

    if args.reference is not None and args.sim is not None:
        raise CliError("--reference is for a probe on --port (a simulated probe checks against its scene)")
    if args.bundle is not None:
        from host.flash import load_verified  # noqa: PLC0415

        if args.out is not None:
            raise CliError("--out names the bundle to train; --bundle deploys an existing one")
        load_verified(args.bundle)  # refused before the device is touched (exit 2)
    elif args.out is None:
        try:
            args.out = output_dir(DEFAULT_OUT)
        except argparse.ArgumentTypeError as exc:
            raise CliError(f"argument --out: {exc}") from None
        check_outputs(args)
    if args.baseline is not None:
        from host.flash import load_verified  # noqa: PLC0415

        load_verified(args.baseline)
    from host.flash import load_signing_key  # noqa: PLC0415

    key = load_signing_key(args.key)  # a bad key is refused before training (exit 2)
    th = Thresholds(**{f: getattr(args, f"max_{f}") for f in Thresholds.__dataclass_fields__})
    with device_session(args) as session:
        r = train_and_deploy(session, args.out, quick=args.quick, seed=args.seed, bundle=args.bundle,
                             baseline=args.baseline, thresholds=th, reference=args.reference,
                             overwrite=args.overwrite, log=say, key=key)
    print(f"deployed {r['bundle']} (sha256 {r['model_sha256']})")
    return 0
