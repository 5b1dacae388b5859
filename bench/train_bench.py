"""Wall time of ``thermotouch train`` (full and ``--quick``), each run from an empty dataset cache.

Each run is a fresh ``thermotouch`` process with its own empty
``$THERMOTOUCH_CACHE`` (so the training set is generated, not read), timed
from process start to exit; full and quick runs alternate (interleaved), and
each reports the median [min-max] of ``--repeats`` runs, with the bundle's
own split (training set / fitting) from its manifest.

Run:  python bench/train_bench.py [--repeats 3] [--update-readme]
Writes bench/results/train.json.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import ROOT, interleaved, write_block, write_json


def _train(quick: bool) -> dict:
    with tempfile.TemporaryDirectory(prefix="train-bench-") as tmp:
        env = dict(os.environ, THERMOTOUCH_CACHE=str(Path(tmp) / "cache"), PYTHONPATH=str(ROOT))
        cmd = [sys.executable, "-m", "host.cli.main", "train", "--out", str(Path(tmp) / "bundle")]
        out = subprocess.run(cmd + (["--quick"] if quick else []), env=env, capture_output=True, text=True,
                             timeout=600)
        if out.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} failed:\n{out.stderr}")
        metrics = json.loads((Path(tmp) / "bundle" / "manifest.json").read_text()).get("metrics", {})
    return {k: metrics.get(k) for k in ("dataset_seconds", "train_seconds")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--update-readme", action="store_true")
    args = ap.parse_args()
    timed = interleaved({"full": lambda: _train(False), "quick": lambda: _train(True)}, args.repeats, warmup=False)
    res = {"repeats": args.repeats, "targets_s": {"full": 20.0, "quick": 4.0}, "cases": {}}
    for name, tm in timed.items():
        split = tm.pop("result")
        res["cases"][name] = {"wall": tm, "last_run_split_s": split}
    f, q = res["cases"]["full"], res["cases"]["quick"]
    text = (f"`thermotouch train` {f['wall']['median_s']:.1f} s [{f['wall']['min_s']:.1f}–{f['wall']['max_s']:.1f}], "
            f"`--quick` {q['wall']['median_s']:.1f} s [{q['wall']['min_s']:.1f}–{q['wall']['max_s']:.1f}] "
            f"(process start to exit, empty dataset cache, one BLAS thread; medians [min–max] of {args.repeats} "
            f"interleaved runs, `python bench/train_bench.py`)")
    print(text)
    res["command"] = "python bench/train_bench.py" + (f" --repeats {args.repeats}" if args.repeats != 3 else "")
    print(f"wrote {write_json('train', res)}")
    if args.update_readme:
        write_block("train-bench", text)


if __name__ == "__main__":
    main()
