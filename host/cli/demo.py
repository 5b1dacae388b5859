"""``thermotouch demo``: a simulated probe, a deployed model, the paper's nine touches, a table and plots."""

from __future__ import annotations

import os
from pathlib import Path

from host.cli.args import add_output
from host.cli.common import say


def add_parser(sub, parents):
    p = sub.add_parser("demo", help="simulated probe drawn as built: calibrate it, touch the paper's samples, print "
                                    "errors and intervals, plot", parents=parents)
    p.add_argument("--ideal", action="store_true",
                   help="instead: the ideal-world demo (the estimator's own 1-D world; nine touches on the reference "
                        "and the precision board against the paper's Table 2)")
    p.add_argument("--train", action="store_true", help="train a quick model and deploy it instead of the shipped one")
    p.add_argument("--real-probe", action="store_true",
                   help="instead: an as-built probe on the faithful world (precision board) is calibrated on three "
                        "reference specimens, then measures the paper's glass, PMMA and aluminium with contact "
                        "resistance and a temperature difference, before and after calibration (about a minute)")
    add_output(p, "--out", kind="dir", default=None,
               help=f"output directory to create (default ./{DEFAULT_OUT}, or ./{DEFAULT_OUT}-2, -3 ... when that "
                    "exists: a rerun never replaces an earlier one); an existing --out needs --overwrite")
    p.set_defaults(func=run)


#: The demo's default output directory (numbered siblings when it exists).
DEFAULT_OUT = "thermotouch-demo"


def default_out(cwd: Path | None = None) -> Path:
    """The first of ``thermotouch-demo``, ``thermotouch-demo-2``, ... that does not exist in ``cwd``."""
    base = Path.cwd() if cwd is None else Path(cwd)
    n = 1
    while True:
        p = base / (DEFAULT_OUT if n == 1 else f"{DEFAULT_OUT}-{n}")
        if not os.path.lexists(p):
            return Path(os.path.relpath(p)) if cwd is None else p
        n += 1


def run(args) -> int:
    from host.demo import run_demo  # noqa: PLC0415

    if args.out is None:
        # The README's main command runs twice in a row: the second run writes beside the first.
        args.out = default_out()
    if args.real_probe:
        if args.ideal:
            from host.cli.errors import CliError  # noqa: PLC0415

            raise CliError("--ideal and --real-probe are two different demos: give one")
        return _run_real_probe(args)

    return run_demo(args.out, train=args.train, overwrite=args.overwrite, ideal=args.ideal, log=say)


def _run_real_probe(args) -> int:
    from host.cli.errors import CliError  # noqa: PLC0415
    from host.demo import build_then_move  # noqa: PLC0415
    from host.realprobe import run_real_probe  # noqa: PLC0415

    if args.train:
        raise CliError("--real-probe uses the shipped model; --train is for the paper demo")
    out = args.out
    if out.exists() and not args.overwrite:
        raise CliError(f"--out {out} exists (use --overwrite to replace it)")
    # A fresh probe every run (reproducible numbers) in a hidden sibling; only our own entries of an
    # existing --out are replaced when it is done, and a failed run leaves nothing.
    build_then_move(out, lambda work: run_real_probe(work, say=say))
    return 0
