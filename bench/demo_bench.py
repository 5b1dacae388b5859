"""Wall and CPU time of ``thermotouch demo``, process start to exit.

Each run is a fresh ``thermotouch demo --out DIR`` process into a new
directory (so the simulated probe starts with empty storage, as on a fresh
machine): the default demo, a drawn as-built probe calibrated by the
walk-through, then touching the paper's samples on the faithful world.
Median [min-max] of ``--repeats`` runs; CPU is user + system of the process
and its children (the plot process), which a loaded machine does not inflate
the way it does the wall time.

With ``--update-readme`` it also writes the demo's report (the calibration, its self-check and
the per-touch table, from the last timed run: the probe and the scenes are seeded, so every run
prints the same) into docs/results.md's ``demo-output`` block (the time into README.md's ``demo-bench``).

Run:  python bench/demo_bench.py [--repeats 5] [--update-readme]
Writes bench/results/demo.json.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import ROOT, interleaved, update_readme, write_block, write_json


#: CPU seconds (user + system, the demo and its children) of each run, in order.
CPU_S: list[float] = []


def _children_cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _demo() -> str:
    with tempfile.TemporaryDirectory(prefix="demo-bench-") as tmp:
        c0 = _children_cpu_s()
        out = subprocess.run([sys.executable, "-m", "host.cli.main", "demo", "--out", str(Path(tmp) / "demo")],
                             env=dict(os.environ, PYTHONPATH=str(ROOT)), capture_output=True, text=True,
                             timeout=300)
        if out.returncode != 0:
            raise SystemExit(f"thermotouch demo failed:\n{out.stderr}")
        CPU_S.append(_children_cpu_s() - c0)
        return out.stdout


def _report(stdout: str) -> str:
    """The demo's report: from the calibration's line to the line before the closing summary."""
    lines = stdout.splitlines()
    a = max(i for i, ln in enumerate(lines) if ln.startswith("calibration "))   # the report, after the progress
    b = next(i for i, ln in enumerate(lines) if ln.startswith("heater invariant held"))
    return "```\n" + "\n".join(lines[a:b]).rstrip() + "\n```"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--update-readme", action="store_true")
    args = ap.parse_args()
    tm = interleaved({"demo": _demo}, args.repeats, warmup=True)["demo"]
    report = _report(tm.pop("result"))   # the last run's output (seeded: every run prints the same)
    cpu = CPU_S[1:]   # the timed runs (the first is the warm-up)
    text = (f"in {tm['median_s']:.1f} s (median of {tm['n']} runs, {tm['min_s']:.1f}–{tm['max_s']:.1f} s; "
            f"{statistics.median(cpu):.1f} s of CPU, `python bench/demo_bench.py`).")
    print(text)
    res = {"wall": tm, "cpu_s": {"median_s": statistics.median(cpu), "min_s": min(cpu), "max_s": max(cpu),
                                 "runs": cpu},
           "load_avg_1min": os.getloadavg()[0], "command": "python bench/demo_bench.py", "target_s": 10.0}
    print(f"wrote {write_json('demo', res)}")
    if args.update_readme:
        update_readme("demo-bench", text)
        write_block("demo-output", report)


if __name__ == "__main__":
    main()
