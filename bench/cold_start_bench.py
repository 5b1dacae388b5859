"""Cold start of the device daemon's code with and without bytecode compiled at install time.

The systemd unit runs with ``ProtectSystem=strict``: the installed tree is
read-only, so Python cannot cache the ``.pyc`` files it compiles and every
start compiles ``edge`` again. This bench copies ``edge/`` and the shipped
model into a temporary tree and times, in fresh interpreters, what a start
imports (``edge.service.main``, which pulls in the daemon, drivers,
estimation and NumPy) and loading the estimator on the shipped bundle:

* ``source only``: no ``.pyc`` and ``PYTHONDONTWRITEBYTECODE=1`` (a read-only
  install that was not compiled);
* ``compiled``: after ``python -m compileall`` over the tree (what
  ``pip install`` does by default, and what the README's install does).

Median [min-max] of ``--repeats`` interleaved rounds.

Run:  python bench/cold_start_bench.py [--repeats 7] [--update-readme]
Writes bench/results/cold_start.json.
"""

from __future__ import annotations

import argparse
import compileall
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import ROOT, interleaved, write_block, write_json

_CHILD = r"""
import time
t0 = time.perf_counter()
import edge.service.main
t1 = time.perf_counter()
from edge.model.bundle import load_bundle
from edge.estimation.estimate import Estimator, pipeline_golden_check
Estimator.from_bundle(load_bundle({bundle!r}, golden_check=pipeline_golden_check))
t2 = time.perf_counter()
print(t1 - t0, t2 - t0)
"""


def _run(tree: Path, env: dict) -> tuple[float, float]:
    out = subprocess.run([sys.executable, "-c", _CHILD.format(bundle=str(tree / "models" / "default"))],
                         cwd=tree, env=env, capture_output=True, text=True, timeout=120)
    if out.returncode != 0:
        raise SystemExit(out.stderr)
    a, b = out.stdout.split()
    return float(a), float(b)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--update-readme", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="cold-start-") as tmp:
        trees = {}
        for name in ("source only", "compiled"):
            tree = Path(tmp) / name.replace(" ", "_")
            shutil.copytree(ROOT / "edge", tree / "edge", ignore=shutil.ignore_patterns("__pycache__"))
            shutil.copytree(ROOT / "models", tree / "models", ignore=shutil.ignore_patterns("__pycache__"))
            trees[name] = tree
        compileall.compile_dir(trees["compiled"] / "edge", quiet=1)
        base = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONDONTWRITEBYTECODE")}
        env = dict(base, PYTHONDONTWRITEBYTECODE="1")  # read-only: nothing is cached between starts
        for name, tree in trees.items():
            env_t = dict(env, PYTHONPATH=str(tree))
            trees[name] = (tree, env_t)
        last: dict = {}
        timed = interleaved({name: (lambda t=t, e=e, name=name: last.__setitem__(name, _run(t, e)) or last[name])
                             for name, (t, e) in trees.items()}, args.repeats)
        # the wall time of the child includes interpreter start-up; the child's own split is reported too
        res = {"repeats": args.repeats, "cases": {}}
        for name, tm in timed.items():
            imp, total = tm.pop("result")
            res["cases"][name] = {"process_wall_s": tm, "last_import_s": imp, "last_import_and_model_s": total}
            print(f"{name:12s} process {tm['median_s'] * 1e3:6.0f} ms [{tm['min_s'] * 1e3:.0f}–"
                  f"{tm['max_s'] * 1e3:.0f}]  (imports {imp * 1e3:.0f} ms, + model {total * 1e3:.0f} ms, last run)")
    res["command"] = "python bench/cold_start_bench.py" + (f" --repeats {args.repeats}" if args.repeats != 7 else "")
    print(f"wrote {write_json('cold_start', res)}")
    if args.update_readme:
        c = res["cases"]
        write_block("cold-start", f"{c['source only']['process_wall_s']['median_s'] * 1e3:.0f} ms (source only) and "
                      f"{c['compiled']['process_wall_s']['median_s'] * 1e3:.0f} ms (compiled) from process start to "
                      "a loaded estimator")


if __name__ == "__main__":
    main()
