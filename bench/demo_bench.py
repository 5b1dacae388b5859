"""Wall time of ``thermotouch demo``, process start to exit.

Each run is a fresh ``thermotouch demo --out DIR`` process into a new
directory (so the simulated probe starts with empty storage, as on a fresh
machine). Median [min-max] of ``--repeats`` runs.

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

from _common import ROOT, interleaved, update_readme, write_json


def _demo() -> None:
    with tempfile.TemporaryDirectory(prefix="demo-bench-") as tmp:
        out = subprocess.run([sys.executable, "-m", "host.cli.main", "demo", "--out", str(Path(tmp) / "demo")],
                             env=dict(os.environ, PYTHONPATH=str(ROOT)), capture_output=True, text=True,
                             timeout=300)
        if out.returncode != 0:
            raise SystemExit(f"thermotouch demo failed:\n{out.stderr}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--update-readme", action="store_true")
    args = ap.parse_args()
    tm = interleaved({"demo": _demo}, args.repeats, warmup=True)["demo"]
    tm.pop("result")
    text = (f"in {tm['median_s']:.1f} s (median of {tm['n']} runs, {tm['min_s']:.1f}–{tm['max_s']:.1f} s, "
            "`python bench/demo_bench.py`).")
    print(text)
    print(f"wrote {write_json('demo', {'wall': tm, 'command': 'python bench/demo_bench.py', 'target_s': 4.0})}")
    if args.update_readme:
        update_readme("demo-bench", text)


if __name__ == "__main__":
    main()
