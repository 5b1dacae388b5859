"""Wall time of the README's test command (``python -m pytest -n 2``) and where it goes.

Each run is a fresh pytest process on a checkout with no bytecode and no
pytest cache (as CI's clean clone): ``--workers`` xdist workers, JUnit XML
for the per-test times.  Reports the wall time (process start to exit, what
issue #13's "test time" bar is about), the CPU time of the whole run (user +
system of every process: steadier than the wall time on a shared machine, and
with both cores busy the wall time is about half of it), the sum of the
per-test times (setup, call and teardown: the work the workers share) and the
slowest files.  Median [min-max] of ``--repeats`` runs.

Run:  python bench/suite_bench.py [--repeats 1] [--workers 2] [--update-readme]
Writes bench/results/suite.json.
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


def _clean_bytecode() -> None:
    for d in ROOT.rglob("__pycache__"):
        if ".venv" not in d.parts:
            shutil.rmtree(d, ignore_errors=True)


def _run(workers: int) -> dict:
    _clean_bytecode()
    with tempfile.TemporaryDirectory(prefix="suite-bench-") as tmp:
        xml = Path(tmp) / "junit.xml"
        # A fresh --basetemp, as on CI's clean machine: pytest otherwise also deletes the temporary
        # directories of older runs (it keeps three; ~2000 directories each for this suite).
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--junitxml={xml}",
               f"--basetemp={Path(tmp) / 'basetemp'}"]
        if workers > 0:
            cmd += ["-n", str(workers)]
        t0 = time.perf_counter()
        ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=3600)
        wall = time.perf_counter() - t0
        ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        # CPU of the whole process tree (every process is waited for by its parent): on a shared
        # machine the wall time moves with the neighbours' load, the CPU time much less.
        cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
        if out.returncode != 0:
            raise SystemExit(f"the suite failed (exit {out.returncode}):\n{out.stdout[-3000:]}")
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
    return {"wall_s": wall, "cpu_s": cpu, "tests_s": sum(per_file.values()), "n": n,
            "passed": int(m.group(1)) if m else None, "files": per_file.most_common(8)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--update-readme", action="store_true")
    args = ap.parse_args()
    runs = [_run(args.workers) for _ in range(args.repeats)]
    walls = sorted(r["wall_s"] for r in runs)
    tests = sorted(r["tests_s"] for r in runs)
    cpus = sorted(r["cpu_s"] for r in runs)
    med = lambda v: v[len(v) // 2]  # noqa: E731
    rng = lambda v: f" [{v[0]:.0f}–{v[-1]:.0f}]" if len(v) > 1 else ""  # noqa: E731
    text = (f"{runs[0]['n']} tests in {med(walls):.0f} s of wall time{rng(walls)} on {args.workers} workers "
            f"and {med(cpus):.0f} s of CPU{rng(cpus)} (user + system, every process of the run; "
            f"the per-test times sum to {med(tests):.0f} s{rng(tests)}; "
            f"{'median of ' + str(len(runs)) + ' runs' if len(runs) > 1 else 'one run'} from a tree without "
            "bytecode, `python bench/suite_bench.py`).")
    print(text)
    for f, s in runs[0]["files"]:
        print(f"  {s:6.1f} s  {f}")
    os.makedirs(ROOT / "bench" / "results", exist_ok=True)
    print(f"wrote {write_json('suite', {'runs': runs, 'workers': args.workers, 'target_wall_s': 45.0, 'command': 'python bench/suite_bench.py'})}")
    if args.update_readme:
        update_readme("suite-bench", text)


if __name__ == "__main__":
    main()
