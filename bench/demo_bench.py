"""Wall time of ``thermotouch demo``, process start to exit.

Each run is a fresh ``thermotouch demo --out DIR`` process into a new
directory (so the simulated probe starts with empty storage, as on a fresh
machine). Median [min-max] of ``--repeats`` runs.

With ``--update-readme`` it also writes the demo's report (the per-touch and per-sample
tables of both boards, from the last timed run: the scenes are seeded, so every run prints the same)
into docs/results.md's ``demo-output`` block (the time into README.md's ``demo-bench``).

Run:  python bench/demo_bench.py [--repeats 5] [--update-readme]
Writes bench/results/demo.json.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import ROOT, interleaved, update_readme, write_block, write_json


def _demo() -> str:
    with tempfile.TemporaryDirectory(prefix="demo-bench-") as tmp:
        out = subprocess.run([sys.executable, "-m", "host.cli.main", "demo", "--out", str(Path(tmp) / "demo")],
                             env=dict(os.environ, PYTHONPATH=str(ROOT)), capture_output=True, text=True,
                             timeout=300)
        if out.returncode != 0:
            raise SystemExit(f"thermotouch demo failed:\n{out.stderr}")
        return out.stdout


def _report(stdout: str) -> str:
    """The demo's tables: from the first board's heading to the line before the closing summary."""
    lines = stdout.splitlines()
    a = next(i for i, ln in enumerate(lines) if ln.startswith("Reference board ("))
    b = next(i for i, ln in enumerate(lines) if ln.startswith("heater invariant held"))
    return "```\n" + "\n".join(lines[a:b]).rstrip() + "\n```"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--update-readme", action="store_true")
    args = ap.parse_args()
    tm = interleaved({"demo": _demo}, args.repeats, warmup=True)["demo"]
    report = _report(tm.pop("result"))   # the last run's output (seeded: every run prints the same)
    text = (f"in {tm['median_s']:.1f} s (median of {tm['n']} runs, {tm['min_s']:.1f}–{tm['max_s']:.1f} s, "
            "`python bench/demo_bench.py`).")
    print(text)
    print(f"wrote {write_json('demo', {'wall': tm, 'command': 'python bench/demo_bench.py', 'target_s': 4.0})}")
    if args.update_readme:
        update_readme("demo-bench", text)
        write_block("demo-output", report)


if __name__ == "__main__":
    main()
