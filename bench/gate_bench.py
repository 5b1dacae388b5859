"""The deploy gate on candidate bundles against the shipped one, on both boards.

Run:  python bench/gate_bench.py [--workdir DIR] [--update-readme]
    python bench/gate_bench.py --seeds 1 2 3 [--workdir DIR]

Trains the shipped recipe (seed 0) and the --quick recipe (seed 0) with an empty
dataset cache, builds the two deliberately broken copies of the shipped bundle
(names permuted, network output negated; fresh hashes and golden vectors), and
prints host.gate's report and the verdict for each against the shipped bundle,
through the reference board's MCP9600 and the precision board's ADS122C04.  It
also checks the two claims about reproducibility: a second full retrain gives
bit-identical arrays, and the shipped bundle's arrays are not among them.

With ``--seeds`` it instead trains the full recipe with each seed and prints the
paired differences against the shipped bundle: the spread of equally good fits,
from which host.gate.MARGINS are set.

``--update-readme`` writes the reference board's reports into README.md's
gate-bench block.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import warnings
from pathlib import Path

import _common  # noqa: F401  (one BLAS thread, this checkout first)
import numpy as np

from edge.estimation.estimate import pipeline_golden_check
from edge.model.bundle import load_bundle
from host.deploy import judge
from host.gate import compare, describe_set, evaluate, format_report
from host.train import train_bundle
from tests.support.bundles import broken_copy
from thermotouch_models import DEFAULT_BUNDLE


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", help="where to write the bundles (default: a temporary directory)")
    ap.add_argument("--seeds", type=int, nargs="+", help="only the seed study: full-recipe retrains with these seeds")
    ap.add_argument("--update-readme", action="store_true", help="write the reference board's reports into README.md")
    args = ap.parse_args(argv)
    work = Path(args.workdir or tempfile.mkdtemp(prefix="gate-bench-"))
    work.mkdir(parents=True, exist_ok=True)
    if args.seeds:
        return seed_study(work, args.seeds)
    os.environ["THERMOTOUCH_CACHE"] = str(work / "cache-1")  # empty: the training set is generated
    shipped = load_bundle(DEFAULT_BUNDLE, pipeline_golden_check)
    cands = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cands["retrain (shipped recipe, seed 0)"] = train_bundle(work / "full", seed=0, overwrite=True,
                                                                 log=lambda s: None)
        cands["--quick (seed 0)"] = train_bundle(work / "quick", quick=True, seed=0, overwrite=True,
                                                 log=lambda s: None)
        os.environ["THERMOTOUCH_CACHE"] = str(work / "cache-2")
        again, _ = train_bundle(work / "full2", seed=0, overwrite=True, log=lambda s: None)
    full = cands["retrain (shipped recipe, seed 0)"][0]
    same = all(np.array_equal(full.arrays[k], again.arrays[k]) for k in full.arrays)
    differ = sorted(k for k in shipped.arrays if not np.array_equal(full.arrays[k], shipped.arrays[k]))
    print(f"second full retrain (training set regenerated): arrays bit-identical: {same}")
    print(f"retrain vs shipped bundle: {len(differ)} arrays differ ({', '.join(differ)})")
    for how in ("permuted_names", "negated_output"):
        b = broken_copy(DEFAULT_BUNDLE, work / how, how) if not (work / how).exists() else \
            load_bundle(work / how, pipeline_golden_check)
        cands[f"broken: {how}"] = (b, dict(shipped.manifest["metrics"]))
    reference: list[str] = []
    for inst in ("mcp9600", "ads122c04"):
        print(f"\n### {describe_set(inst)}")
        old = evaluate(shipped, inst)
        for name, (b, metrics) in cands.items():
            new = evaluate(b, inst)
            cmp = compare(new, old)
            why = judge(metrics, new["means"], cmp)
            report = [f"{name} vs shipped:", format_report(cmp),
                      "  thresholded (paper samples, mean |error|): " + ", ".join(
                          f"{k} {v * 100:.1f} % (shipped {old['means'][k] * 100:.1f} %)"
                          for k, v in new["means"].items()),
                      "  -> " + ("DEPLOY" if not why else "REFUSE: " + "; ".join(why))]
            print("\n" + "\n".join(report))
            if inst == "mcp9600":
                reference += report
    if args.update_readme:
        _common.write_block("gate-bench", "```\n" + "\n".join(reference) + "\n```")
    return 0


def seed_study(work: Path, seeds) -> int:
    os.environ["THERMOTOUCH_CACHE"] = str(work / "cache-seeds")
    shipped = load_bundle(DEFAULT_BUNDLE, pipeline_golden_check)
    olds = {inst: evaluate(shipped, inst) for inst in ("mcp9600", "ads122c04")}
    for seed in seeds:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            b, _ = train_bundle(work / f"seed{seed}", seed=seed, overwrite=True, log=lambda s: None)
        for inst, old in olds.items():
            for c in compare(evaluate(b, inst), old):
                print(f"seed {seed} {inst:9s} {c.quantity:17s} {c.diff:+.4f} [{c.lo:+.4f}, {c.hi:+.4f}] {c.verdict}",
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
