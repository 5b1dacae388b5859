"""How the default estimate's compute scales with the record.

Cases (default method, one Estimator on the shipped bundle):

* ``touch_2s``: a 2-s simulated touch of tempered glass on the ADS122C04
  board (T and q at 90 Hz on their own time bases);
* ``touch_2s_jittered``: the same with new sample-time jitter (+-10 % of
  the period) on every call, so no resampling operator is ever reused;
* ``daemon_2s``: the same touch as the daemon hands it over, resampled on
  the 10-Hz measurement grid (edge.estimation.conditioning.resample_uniform);
* ``record_60s_100Hz``: 60 s of glass sampled at 100 Hz;
* ``record_10s_1kHz``: 10 s of glass sampled at 1 kHz;
* ``known_thickness_4s``: 0.5 mm PMMA on an insulating back, 4 s at 100 Hz,
  estimated with the thickness known (the 1-D alpha scan).

For each: median, min and max wall time of ``--repeats`` calls after one
warm-up call (caches warm, as in the daemon), the cold first call and the
peak memory of one estimate in a fresh process (peak RSS, VmHWM, of the whole
process, which includes Python, NumPy and the bundle, and the tracemalloc
peak of the estimate itself), and the estimate's relative errors.

Run:  python bench/estimate_scaling_bench.py [--repeats 21] [--update-readme]
Writes bench/results/estimate_scaling.json.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import ROOT, write_block, write_json

import numpy as np  # noqa: E402  (after _common: one BLAS thread)

from edge.physics.forward import simulate  # noqa: E402
from edge.estimation.conditioning import resample_uniform  # noqa: E402
from edge.physics.solids import Solid  # noqa: E402

GLASS = Solid(1.097, 2458.4, 809.0)
PMMA = Solid(0.185, 1178.35, 1429.0)
Q_V = 7.7e7


def make_records() -> dict[str, dict]:
    """Each case's estimate() arguments (arrays and keywords) and the true solid."""
    from host.evaluate import TouchSimulator

    rng = np.random.default_rng(9)
    touch = TouchSimulator(GLASS).touch(Q_V, "ads122c04", rng)
    g_t, g_dT, g_q = resample_uniform(touch.tT, touch.T + 20.0, touch.q, 20.0, 0.0, 10.0, 2.0)
    r60 = simulate(GLASS, Q_V, 60.0, dt_s=0.01, back="infinite", scheme="exact")
    r10 = simulate(GLASS, Q_V, 10.0, dt_s=0.001, back="infinite", scheme="exact")
    rth = simulate(PMMA, Q_V, 4.0, dt_s=0.01, thickness_m=0.5e-3, back="insulated", scheme="exact")
    return {
        "touch_2s": dict(solid=GLASS, t_s=touch.tT, dT_K=touch.T, q_W_m2=touch.q, kw=dict(t_q_s=touch.tq)),
        "touch_2s_jittered": dict(solid=GLASS, t_s=touch.tT, dT_K=touch.T, q_W_m2=touch.q,
                                  kw=dict(t_q_s=touch.tq), jitter=0.1 / 90.0),
        "daemon_2s": dict(solid=GLASS, t_s=g_t, dT_K=g_dT, q_W_m2=g_q, kw={}),
        "record_60s_100Hz": dict(solid=GLASS, t_s=r60.t_s, dT_K=r60.T_f_K, q_W_m2=r60.q_f_W_m2, kw={}),
        "record_10s_1kHz": dict(solid=GLASS, t_s=r10.t_s, dT_K=r10.T_f_K, q_W_m2=r10.q_f_W_m2, kw={}),
        "known_thickness_4s": dict(solid=PMMA, t_s=rth.t_s, dT_K=rth.T_f_K, q_W_m2=rth.q_f_W_m2,
                                   kw=dict(thickness_m=0.5e-3, back="insulated")),
    }


def load_estimator():
    from edge.model.bundle import load_bundle
    from edge.estimation.estimate import Estimator, pipeline_golden_check
    from thermotouch_models import DEFAULT_BUNDLE

    return Estimator.from_bundle(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))


# One estimate in a fresh process: cold time and peak memory.
_CHILD = r"""
import sys
sys.path.insert(0, {root!r}); sys.path.insert(0, {bench!r})
import _common  # one BLAS thread, this checkout first
import json, resource, time, tracemalloc
import numpy as np
from estimate_scaling_bench import load_estimator
est = load_estimator()
d = np.load({npz!r})
kw = json.loads(str(d["kw"]))
args = (d["t_s"], d["dT_K"], d["q_W_m2"])
if "t_q_s" in d.files:
    kw["t_q_s"] = d["t_q_s"]
def peak_rss_MB():
    # VmHWM belongs to this process image (ru_maxrss would carry the parent's peak over fork/exec).
    try:
        with open("/proc/self/status") as f:
            return next(int(l.split()[1]) for l in f if l.startswith("VmHWM:")) / 1024
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
rss0 = peak_rss_MB()
t0 = time.perf_counter()
est.estimate(*args, **kw)
cold = time.perf_counter() - t0
rss1 = peak_rss_MB()
import edge.estimation.estimate as E, edge.physics.fluxmodel as F, edge.estimation.spline as S
for mod in (E, F, S):  # empty every cache, then trace one cold estimate's allocations
    for name in dir(mod):
        f = getattr(mod, name)
        if hasattr(f, "cache_clear"):
            f.cache_clear()
tracemalloc.start()
est.estimate(*args, **kw)
peak = tracemalloc.get_traced_memory()[1]
tracemalloc.stop()
print(json.dumps(dict(cold_s=cold, peak_rss_before_MB=rss0, peak_rss_MB=rss1, traced_peak_MB=peak / 2**20)))
"""


def child_run(rec: dict) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        npz = str(Path(tmp) / "rec.npz")
        kw = {k: v for k, v in rec["kw"].items() if k != "t_q_s"}
        extra = {"t_q_s": rec["kw"]["t_q_s"]} if "t_q_s" in rec["kw"] else {}
        np.savez(npz, t_s=rec["t_s"], dT_K=rec["dT_K"], q_W_m2=rec["q_W_m2"], kw=json.dumps(kw), **extra)
        code = _CHILD.format(root=str(ROOT), bench=str(ROOT / "bench"), npz=npz)
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    if out.returncode != 0:
        raise SystemExit(out.stderr)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=21)
    ap.add_argument("--cases", nargs="*", default=None, help="run only these cases")
    ap.add_argument("--update-readme", action="store_true")
    args = ap.parse_args()
    est = load_estimator()
    records = make_records()
    res = {"repeats": args.repeats, "cases": {}}
    for name, rec in records.items():
        if args.cases and name not in args.cases:
            continue
        jit = rec.get("jitter", 0.0)
        jrng = np.random.default_rng(1)
        times = []
        for j in range(args.repeats + 1):  # the first call warms up
            t_s, kw = rec["t_s"], dict(rec["kw"])
            if jit:
                t_s = t_s + np.concatenate(([0.0], jrng.uniform(-jit, jit, t_s.size - 1)))
                kw["t_q_s"] = t_s
            t0 = time.perf_counter()
            r = est.estimate(t_s, rec["dT_K"], rec["q_W_m2"], **kw)
            if j:
                times.append(time.perf_counter() - t0)
        s = rec["solid"]
        row = dict(
            n_samples=int(np.asarray(rec["t_s"]).size),
            median_ms=float(np.median(times) * 1e3), min_ms=float(np.min(times) * 1e3),
            max_ms=float(np.max(times) * 1e3),
            e=r.effusivity_W_s05_m2K, k=r.k_W_mK, alpha=r.alpha_m2_s,
            e_err=float(r.effusivity_W_s05_m2K / s.effusivity_W_s05_m2K - 1),
            alpha_err=float(r.alpha_m2_s / s.alpha_m2_s - 1) if "thickness_m" in rec["kw"] else None,
        )
        row.update(child_run(rec))
        res["cases"][name] = row
        print(f"{name:20s} n={row['n_samples']:6d}  median {row['median_ms']:9.3f} ms "
              f"(min {row['min_ms']:.3f} - max {row['max_ms']:.3f})  cold {row['cold_s'] * 1e3:9.1f} ms  "
              f"peak RSS {row['peak_rss_MB']:7.1f} MB (before {row['peak_rss_before_MB']:.1f})  "
              f"traced {row['traced_peak_MB']:8.2f} MB  e err {row['e_err'] * 100:+.3f} %"
              + (f"  alpha err {row['alpha_err'] * 100:+.2f} %" if row["alpha_err"] is not None else ""),
              flush=True)
    print(f"\nwrote {write_json('estimate_scaling', res)}")
    if args.update_readme:
        if args.cases:
            raise SystemExit("--update-readme needs every case (no --cases)")
        write_block("estimate-scaling-bench", markdown(res))


#: The issue's targets (ms, MB) for its table in docs/results.md.
TARGETS = {"touch_2s": "≤ 0.5 ms", "record_60s_100Hz": "≤ 20 ms, ≤ 80 MB", "record_10s_1kHz": "≤ 50 ms",
           "known_thickness_4s": "≤ 20 ms"}


def markdown(res: dict) -> str:
    L = [f"| case | samples | warm estimate (ms), median [min–max] of {res['repeats']} | cold (ms) | "
         "peak RSS of the process (MB) | target |", "|---|---|---|---|---|---|"]
    for name, r in res["cases"].items():
        L.append(f"| {name} | {r['n_samples']} | {r['median_ms']:.3f} [{r['min_ms']:.3f}–{r['max_ms']:.3f}] | "
                 f"{r['cold_s'] * 1e3:.1f} | {r['peak_rss_MB']:.1f} | {TARGETS.get(name, '')} |")
    return "\n".join(L)


if __name__ == "__main__":
    main()
