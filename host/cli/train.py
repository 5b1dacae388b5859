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
    p.set_defaults(func=run)


def run(args) -> int:
    import warnings  # noqa: PLC0415

    from host.progress import ProgressBar, Ticker  # noqa: PLC0415
    from host.train import train_bundle  # noqa: PLC0415

    with warnings.catch_warnings(), ProgressBar("training set", "material") as bar:
        warnings.simplefilter("ignore")  # sklearn convergence chatter; the metrics tell the truth
        train_bundle(args.out, quick=args.quick, seed=args.seed, progress=bar, overwrite=args.overwrite,
                     log=note, step=Ticker)
    return 0
