"""``thermotouch train``: training set, the paper's network, a bundle."""

from __future__ import annotations

from host.cli.args import add_output, seed
from host.cli.common import note


def add_parser(sub, parents):
    p = sub.add_parser("train", help="generate the training set, train the paper network, write a bundle",
                       parents=parents)
    add_output(p, "--out", kind="dir", required=True, help="bundle directory to create")
    p.add_argument("--quick", action="store_true", help="6 power levels, no noisy copies, fewer iterations")
    p.add_argument("--seed", type=seed, default=0, help="random seed, 0 .. 2^32-1 (default 0)")
    p.add_argument("--reprior", metavar="BUNDLE",
                   help="do not train: copy BUNDLE with its prior's ln(rho c) spread re-fitted on its own "
                        "library (leave-one-out); the network is unchanged")
    p.set_defaults(func=run)


def run(args) -> int:
    import warnings  # noqa: PLC0415

    if args.reprior is not None:
        return _reprior(args)

    from host.progress import ProgressBar, Ticker  # noqa: PLC0415
    from host.train import train_bundle  # noqa: PLC0415

    with warnings.catch_warnings(), ProgressBar("training set", "material") as bar:
        warnings.simplefilter("ignore")  # sklearn convergence chatter; the metrics tell the truth
        train_bundle(args.out, quick=args.quick, seed=args.seed, progress=bar, overwrite=args.overwrite,
                     log=note, step=Ticker)
    return 0


def _reprior(args) -> int:
    from edge.model.bundle import BundleError  # noqa: PLC0415
    from host.cli.errors import EXIT_BAD_INPUT, CliError  # noqa: PLC0415
    from host.train import reprior_bundle  # noqa: PLC0415

    if args.quick or args.seed != 0:
        raise CliError("--reprior copies a trained bundle: --quick and --seed do not apply", EXIT_BAD_INPUT)
    try:
        b = reprior_bundle(args.reprior, args.out, overwrite=args.overwrite, log=note)
    except (BundleError, OSError, ValueError) as e:
        raise CliError(f"--reprior {args.reprior}: {e}", EXIT_BAD_INPUT) from None
    note(f"wrote {args.out} ({b.model_version}, sha256 {b.sha256[:12]})")
    return 0

