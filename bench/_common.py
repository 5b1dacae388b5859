"""Helpers shared by the benchmark scripts."""

from __future__ import annotations

import json
import os
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


def interleaved(cases: dict, repeats: int = 5, *, warmup: bool = True) -> dict:
    """Time every case ``repeats`` times, round-robin, so that they share the machine's moods.

    A shared machine's speed drifts over seconds; timing case A five times and
    then case B five times compares two different machines. Here each round
    runs every case once, and each case reports the median and the min-max of
    its rounds (never a best-of against a single run).

    Parameters
    ----------
    cases : dict
        name -> zero-argument callable.
    repeats : int
        Rounds.
    warmup : bool
        One untimed call of each case first (imports, caches, allocator).

    Returns
    -------
    dict
        name -> ``{"median_s", "min_s", "max_s", "n", "result"}`` (the last call's result).
    """
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    times: dict = {name: [] for name in cases}
    results: dict = {}
    if warmup:
        for name, fn in cases.items():
            results[name] = fn()
    for _ in range(repeats):
        for name, fn in cases.items():
            t0 = time.perf_counter()
            results[name] = fn()
            times[name].append(time.perf_counter() - t0)
    return {name: {"median_s": float(np.median(ts)), "min_s": float(np.min(ts)), "max_s": float(np.max(ts)),
                   "n": len(ts), "result": results[name]} for name, ts in times.items()}


def fmt_ms(t: dict, digits: int = 2) -> str:
    """``median [min-max]`` in ms of an :func:`interleaved` entry."""
    return (f"{t['median_s'] * 1e3:.{digits}f} [{t['min_s'] * 1e3:.{digits}f}–"
            f"{t['max_s'] * 1e3:.{digits}f}]")


def rel_err(a, ref) -> float:
    """Largest deviation over the record relative to the record's peak."""
    return float(np.max(np.abs(np.asarray(a) - ref)) / np.max(np.abs(ref)))


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> dict:
    """What the figures were measured on: the CPU, NumPy's SIMD level and the BLAS.

    Machines of this class differ in more than their load: without AVX-512, NumPy's float64
    ``tanh`` has no SIMD loop, and ``tanh`` is most of the network's training time there
    (``thermotouch train`` under py-spy).
    """
    import threadpoolctl

    try:
        from numpy._core._multiarray_umath import __cpu_features__ as feats
    except ImportError:  # NumPy < 2
        from numpy.core._multiarray_umath import __cpu_features__ as feats

    blas = [f"{i.get('internal_api')} {i.get('version')} ({i.get('architecture')})"
            for i in threadpoolctl.threadpool_info() if i.get("user_api") == "blas"]
    return {"python": platform.python_version(), "processor": platform.processor() or platform.machine(),
            "cpu": _cpu_model(), "cpus": os.cpu_count(), "numpy": np.__version__,
            "simd": [k for k in ("AVX512F", "AVX2", "FMA3", "ASIMD") if feats.get(k)], "blas": blas}


def write_json(name: str, payload: dict) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    payload = dict(payload)
    payload["machine"] = machine()
    path = RESULTS / f"{name}.json"
    path.write_text(json.dumps(payload, indent=1))
    return path


README = ROOT / "README.md"
#: Where the benches' generated tables live (docs/results.md); the README keeps the suite, demo and accuracy blocks.
RESULTS_MD = ROOT / "docs" / "results.md"


def write_block(tag: str, text: str, path: Path = RESULTS_MD) -> Path:
    """Replace the text between ``<!-- tag:begin -->`` and ``<!-- tag:end -->`` in ``path``; the one writer.

    Parameters
    ----------
    tag : str
        The marker's name, e.g. ``"forward-bench"``.
    text : str
        The block's new content (Markdown); a trailing newline is added.
    path : Path
        The Markdown file holding the markers (default docs/results.md).

    Returns
    -------
    Path
        The file written.
    """
    src = path.read_text()
    pat = re.compile(rf"(<!-- {re.escape(tag)}:begin -->\n).*?(<!-- {re.escape(tag)}:end -->)", re.S)
    if not pat.search(src):
        name = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
        raise SystemExit(f"{name} has no <!-- {tag}:begin --> ... <!-- {tag}:end --> block")
    path.write_text(pat.sub(lambda m: m.group(1) + text.rstrip() + "\n" + m.group(2), src))
    return path


def update_readme(tag: str, text: str) -> Path:
    """:func:`write_block` into README.md (the blocks the front page keeps: suite, demo time, accuracy)."""
    return write_block(tag, text, README)
