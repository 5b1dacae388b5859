"""Estimating the tactile as-built bench's cached records: each drawn probe calibrated, every touch estimated.

Used by bench/tactile_asbuilt_bench.py (``--reuse``).  The probes are independent (each calibrated on
its own reference touches, its touches estimated with its own calibration), so ``jobs`` > 1 spreads
them over that many forked processes; the rows come back in the records' order whatever ``jobs`` is,
so the figures do not depend on it.
"""

from __future__ import annotations

import math
import multiprocessing
import time

import _asbuilt_touches as A
from edge.recognition import BROAD_LN, measured_alpha
from edge.recognition.fields import BROAD_FLAGS, POOR_FIT_FLAG


def widened(row: dict) -> bool:
    """Whether a row's u(ln e) was widened to BROAD_LN (a BROAD_FLAGS answer): the rule's width, not the stated u."""
    return row.get("u_ln_e_stated") is not None and row["u_ln_e"] != row["u_ln_e_stated"]


def _row(r, m, ct, ctx) -> dict:
    """One touch's estimate at contact time ``ct`` through the one estimate path, as the device names it."""
    from edge.estimation.seam import estimate_touch

    row = {**m, "contact_s": ct, "e": math.nan, "u_ln_e": math.nan, "alpha": math.nan,
           "u_ln_alpha": math.nan, "corr": math.nan, "method": None, "flags": [], "error": None}
    if r is None:
        row["error"] = "no record"
        return row
    try:
        d = estimate_touch(A.truncated(r, ct), ctx).to_dict()
        e, u = d["effusivity_W_s05_m2K"], d["effusivity_W_s05_m2K_u"]
        chain = d.get("sensor_chain") or {}
        row.update(method=d["method"], flags=list(d["flags"]), chain_flags=chain.get("flags"))
        if e is None and POOR_FIT_FLAG in d["flags"] and (chain.get("effusivity_W_s05_m2K") or 0) > 0:
            # Withheld by the seam; recognition may still name it from the chain's e (poor_fit_ln).
            row.update(e_chain=float(chain["effusivity_W_s05_m2K"]), poor_fit=True)
        if e is not None and u is not None and e > 0:
            row.update(e=float(e), u_ln_e=float(u) / float(e), u_ln_e_stated=float(u) / float(e))
            if BROAD_FLAGS & set(d["flags"]):   # named as the device names it (recognition_fields)
                row["u_ln_e"] = max(row["u_ln_e"], BROAD_LN)
            a = measured_alpha(d)
            if a is not None:
                row.update(alpha=a[0], u_ln_alpha=a[1], corr=a[2])
    except ValueError as exc:
        row["error"] = f"{type(exc).__name__}: {exc}"
    return row


def estimate_probe(task) -> tuple:
    """(probe, its calibration's summary, [(record index, contact time, row)]) for one drawn probe."""
    from edge.calibration.model import CalibrationError
    from host.cli.common import seam_context

    head, p, refs, touches, times = task
    try:
        cal, check = A.calibrate_records(head, refs)
        info = {"sha256": cal.sha256, "u_rel_floor": cal.u_rel_floor, "forced": cal.forced,
                "self_check_passed": check.get("passed"), "refused": None}
    except (CalibrationError, ValueError) as exc:
        cal = None
        info = {"refused": f"{type(exc).__name__}: {exc}"}
    print(f"{head}: probe {p} calibration {info}", flush=True)
    ctx = seam_context(None, calibration=cal)
    return p, info, [(i, ct, _row(r, m, ct, ctx)) for i, r, m in touches for ct in times]


def estimate_head(head: str, recs, meta, times, jobs: int = 1) -> dict:
    """Calibrate each probe on its references, then estimate every touch at each of ``times`` (s)."""
    t0 = time.perf_counter()
    probes = sorted({m["probe"] for m in meta})
    tasks = [(head, p, [(m["name"], r) for r, m in zip(recs, meta) if m["kind"] == "reference" and m["probe"] == p],
              [(i, r, m) for i, (r, m) in enumerate(zip(recs, meta)) if m["kind"] == "touch" and m["probe"] == p],
              sorted(times)) for p in probes]
    if jobs > 1:
        with multiprocessing.get_context("fork").Pool(jobs) as pool:
            out = pool.map(estimate_probe, tasks, chunksize=1)
    else:
        out = [estimate_probe(t) for t in tasks]
    cals = {p: info for p, info, _ in out}
    rows = [row for _, _, row in sorted((x for _, _, rs in out for x in rs), key=lambda x: (x[0], x[1]))]  # record order
    return {"calibrations": cals, "rows": rows, "estimate_s": time.perf_counter() - t0}
