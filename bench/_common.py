"""Helpers shared by the benchmark scripts."""

from __future__ import annotations

import json
import platform
import re
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(1, str(ROOT))  # this checkout's edge/ and host/, before any installed copy

from host.blas import limit_blas_threads  # noqa: E402

limit_blas_threads()  # before NumPy loads OpenBLAS: one thread (see host/blas.py)

import numpy as np  # noqa: E402

RESULTS = ROOT / "bench" / "results"


def best_time(fn, repeat: int = 3) -> tuple[float, object]:
    """Best wall time (s) of ``repeat`` calls, and the last result."""
    best = np.inf
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def rel_err(a, ref) -> float:
    """Largest deviation over the record relative to the record's peak."""
    return float(np.max(np.abs(np.asarray(a) - ref)) / np.max(np.abs(ref)))


def write_json(name: str, payload: dict) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    payload = dict(payload)
    payload["machine"] = {"python": platform.python_version(), "processor": platform.processor() or platform.machine()}
    path = RESULTS / f"{name}.json"
    path.write_text(json.dumps(payload, indent=1))
    return path


def update_readme(tag: str, text: str) -> None:
    """Replace the block between <!-- tag:begin --> and <!-- tag:end --> in README.md."""
    readme = ROOT / "README.md"
    src = readme.read_text()
    pat = re.compile(rf"(<!-- {tag}:begin -->\n).*?(<!-- {tag}:end -->)", re.S)
    if not pat.search(src):
        raise SystemExit(f"README.md has no <!-- {tag}:begin --> ... <!-- {tag}:end --> block")
    readme.write_text(pat.sub(lambda m: m.group(1) + text.rstrip() + "\n" + m.group(2), src))
