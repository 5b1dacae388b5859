"""``thermotouch evaluate``: accuracy tables of a bundle on simulated measurements."""

from __future__ import annotations

from host.cli.common import load_estimator
from host.cli.report import dumps, evaluate_lines


def add_parser(sub, parents):
    p = sub.add_parser("evaluate", help="accuracy tables of a bundle on simulated measurements", parents=parents)
    p.add_argument("bundle", nargs="?", default=None, help="bundle directory (default: the shipped one)")
    p.add_argument("--instrument", choices=("mcp9600", "ads122c04"), default="ads122c04",
                   help="instrument model the simulated touches go through (default ads122c04)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def run(args) -> int:
    from host.evaluate import identification, paper_cases  # noqa: PLC0415
    from host.progress import Ticker  # noqa: PLC0415

    est, bundle = load_estimator(args.bundle)
    with Ticker("paper cases"):
        rows = paper_cases(est, args.instrument, repeats=3)
    with Ticker("identification"):
        ident = identification(est, args.instrument, touches=2)
    if args.json:
        print(dumps({"paper_cases": rows, "identification": ident, "model_sha256": bundle.sha256}))
    else:
        print("\n".join(evaluate_lines(rows, ident, bundle.sha256, args.instrument)))
    return 0
