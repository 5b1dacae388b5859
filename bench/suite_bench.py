"""Wall time of the README's test command (``python -m pytest -n 2``) and of its fast tier, and where it goes.

Two tiers, each a fresh pytest process on a checkout with no bytecode, no
pytest cache and no Hypothesis storage (as CI's clean clone), ``--workers`` xdist workers, JUnit XML for
the per-test times:

* the full suite, what CI runs (target: at most 60 s of wall time on this
  two-core machine class when it is quiet);
* the fast tier, ``-m "not slow"``: the tests marked ``slow`` (long
  simulations, retrains, daemons killed at every step) left out, for a quick
  local loop (target: at most 20 s).

Each repeat runs both tiers back to back, so that the two share the machine's
moods. Reports per tier the wall time (process start to exit, what the
targets are about), the CPU time of the whole run (user + system of every
process: steadier than the wall time on a shared machine, and with both
cores busy the wall time is about half of it), the sum of the per-test times
(setup, call and teardown: the work the workers share) and the slowest
files, and the machine's load average when each run started (figures taken
at a load above 1 are not the quiet machine's). Median [min-max] of
``--repeats`` runs.

Run:  python bench/suite_bench.py [--repeats 3] [--workers 2] [--tier both|full|fast] [--update-readme]
Writes bench/results/suite.json (one tier: suite_TIER.json); ``--update-readme`` (both tiers only)
writes the README's ``suite-bench`` block.
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

from _common import ROOT, update_readme, write_json
from tests.support.scratch import memory_scratch_root

#: Targets of issue #33, seconds of wall time on two workers, quiet machine.
TARGET_WALL_s = {"full": 60.0, "fast": 20.0}
#: The pytest marker expression of each tier (None: everything).
TIER_MARKER = {"full": None, "fast": "not slow"}
#: The commands as a reader types them (the README's test command runs the full tier).
TIER_COMMAND = {"full": "python -m pytest -n 2", "fast": 'python -m pytest -n 2 -m "not slow"'}


def _clean_bytecode() -> None:
    """The tree as CI's clean clone has it: no bytecode, and no Hypothesis storage (``.hypothesis/``: its
    Unicode table and the project constants it collects, about 1.5 CPU-s in a process that builds them)."""
    for d in ROOT.rglob("__pycache__"):
        if ".venv" not in d.parts:
            shutil.rmtree(d, ignore_errors=True)
    shutil.rmtree(ROOT / ".hypothesis", ignore_errors=True)


def _run(workers: int, tier: str) -> dict:
    """One pytest run of ``tier`` from a tree without bytecode; its times, counts and slowest files."""
    _clean_bytecode()
    load_1min = os.getloadavg()[0]
    # On the file system tests/conftest.py gives the suite's scratch (a RAM one when there is one): on the disk,
    # a --basetemp put the suite's ~5 400 scratch files where the README's command does not (+1.7 s, one pair).
    scratch = memory_scratch_root()
    with tempfile.TemporaryDirectory(prefix="suite-bench-", dir=None if scratch is None else str(scratch)) as tmp:
        xml = Path(tmp) / "junit.xml"
        # A fresh --basetemp, as on CI's clean machine: pytest otherwise also deletes the temporary
        # directories of older runs (it keeps three; ~2000 directories each for this suite).
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--junitxml={xml}",
               f"--basetemp={Path(tmp) / 'basetemp'}"]
        if workers > 0:
            cmd += ["-n", str(workers)]
        if TIER_MARKER[tier] is not None:
            cmd += ["-m", TIER_MARKER[tier]]
        t0 = time.perf_counter()
        ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=3600)
        wall = time.perf_counter() - t0
        ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        # CPU of the whole process tree (every process is waited for by its parent): on a shared
        # machine the wall time moves with the neighbours' load, the CPU time much less.
        cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
        if out.returncode != 0:
            raise SystemExit(f"the {tier} tier failed (exit {out.returncode}):\n{out.stdout[-3000:]}")
        per_file = collections.Counter()
        n = 0
        for case in ET.parse(xml).getroot().iter("testcase"):
            n += 1
            # classname is the test's module (dotted), or module.Class for a method in a test class.
            mod = case.get("classname", "")
            parts = mod.split(".")
            if parts and parts[-1][:1].isupper():
                parts = parts[:-1]
            per_file["/".join(parts) + ".py"] += float(case.get("time", 0.0))
    m = re.search(r"(\d+) passed", out.stdout)
    return {"tier": tier, "wall_s": wall, "cpu_s": cpu, "tests_s": sum(per_file.values()), "n": n,
            "passed": int(m.group(1)) if m else None, "load_1min_at_start": load_1min,
            "files": per_file.most_common(8)}


def _median(values: list[float]) -> float:
    v = sorted(values)
    return v[len(v) // 2]


def _range(values: list[float]) -> str:
    v = sorted(values)
    return f" [{v[0]:.0f}–{v[-1]:.0f}]" if len(v) > 1 else ""


def summary(tier: str, runs: list[dict]) -> dict:
    """Median and range of one tier's runs, and whether the median meets the tier's target."""
    walls = [r["wall_s"] for r in runs]
    return {"n_tests": runs[0]["n"], "runs": len(runs), "wall_s": _median(walls),
            "wall_range_s": [min(walls), max(walls)], "cpu_s": _median([r["cpu_s"] for r in runs]),
            "tests_s": _median([r["tests_s"] for r in runs]), "target_wall_s": TARGET_WALL_s[tier],
            "meets_target": _median(walls) <= TARGET_WALL_s[tier], "command": TIER_COMMAND[tier],
            "max_load_1min_at_start": max(r["load_1min_at_start"] for r in runs)}


def tier_text(tier: str, runs: list[dict]) -> str:
    """One tier's sentence for the README."""
    walls, cpus, tests = ([r[k] for r in runs] for k in ("wall_s", "cpu_s", "tests_s"))
    what = ("Full suite (`" + TIER_COMMAND["full"] + "`, what CI runs)" if tier == "full" else
            "Fast tier (`" + TIER_COMMAND["fast"] + "`: the tests marked `slow` left out)")
    return (f"{what}: {runs[0]['n']} tests in {_median(walls):.0f} s of wall time{_range(walls)} "
            f"(target ≤ {TARGET_WALL_s[tier]:.0f} s), {_median(cpus):.0f} s of CPU{_range(cpus)} "
            f"(user + system, every process; per-test times sum to {_median(tests):.0f} s{_range(tests)}).")


def readme_text(by_tier: dict[str, list[dict]], workers: int) -> str:
    """The README's ``suite-bench`` block: one sentence per tier, then how it was measured."""
    runs = [r for rs in by_tier.values() for r in rs]
    n = len(next(iter(by_tier.values())))
    load = max(r["load_1min_at_start"] for r in runs)
    return "\n".join(tier_text(t, rs) for t, rs in by_tier.items()) + (
        f"\n{'Median of ' + str(n) + ' runs' if n > 1 else 'One run'} per tier on {workers} workers from a tree "
        f"without bytecode or Hypothesis storage, load average ≤ {load:.1f} at their start (`python bench/suite_bench.py`).")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--tier", choices=("both", "full", "fast"), default="both")
    ap.add_argument("--update-readme", action="store_true")
    args = ap.parse_args()
    if args.repeats < 1:
        ap.error("--repeats must be >= 1")
    if args.update_readme and args.tier != "both":
        ap.error("--update-readme writes both tiers' figures: use --tier both")
    tiers = ("full", "fast") if args.tier == "both" else (args.tier,)
    by_tier: dict[str, list[dict]] = {t: [] for t in tiers}
    for _ in range(args.repeats):
        for t in tiers:  # interleaved: each repeat measures every tier on the same machine mood
            by_tier[t].append(_run(args.workers, t))
    text = readme_text(by_tier, args.workers)
    print(text)
    for t, runs in by_tier.items():
        print(f"{t}: slowest files (first run)")
        for f, s in runs[0]["files"]:
            print(f"  {s:6.1f} s  {f}")
    payload = {"tiers": {t: summary(t, runs) for t, runs in by_tier.items()},
               "runs": [r for runs in by_tier.values() for r in runs], "workers": args.workers,
               "command": "python bench/suite_bench.py"}
    # A one-tier run (a quick look) does not overwrite the figures of both.
    print(f"wrote {write_json('suite' if args.tier == 'both' else f'suite_{args.tier}', payload)}")
    if args.update_readme:
        update_readme("suite-bench", text)


if __name__ == "__main__":
    main()
