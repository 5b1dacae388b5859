"""``thermotouch demo``: a simulated probe, a deployed model, the paper's nine touches, a table and plots."""

from __future__ import annotations

from host.cli.args import add_output
from host.cli.common import say


def add_parser(sub, parents):
    p = sub.add_parser("demo", help="simulated probe: deploy a model, touch the paper's samples, print and plot",
                       parents=parents)
    p.add_argument("--train", action="store_true", help="train a quick model and deploy it instead of the shipped one")
    add_output(p, "--out", kind="dir", default="thermotouch-demo",
               help="output directory to create (default ./thermotouch-demo; an existing one needs --overwrite)")
    p.set_defaults(func=run)


def run(args) -> int:
    from host.demo import run_demo  # noqa: PLC0415

    return run_demo(args.out, train=args.train, overwrite=args.overwrite, log=say)
