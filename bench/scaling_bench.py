"""Scaling curves: how compute grows with record length, sample rate, object-set size and session length.

* record length: the default estimate on glass records sampled at 100 Hz,
  2-60 s long;
* sample rate: the default estimate on a 10-s glass record sampled at
  10 Hz-1 kHz;
* object-set size: recognition (open-set classify with class posteriors and
  top-3 candidates) against sets of 16-8192 objects (the library's 128
  materials, and synthetic sets spread over the same effusivity range);
* touches per session: wall time per simulated touch over a session of
  ``--touches`` touches on the 1-D world and chip models (binned).

Each point: median [min-max] of ``--repeats`` rounds in which every point of
the curve is timed once (interleaved), after one warm-up call. The slope is
the least-squares exponent b of time ~ size^b over the curve's points
(0: flat, 1: linear).

Run:  python bench/scaling_bench.py [--repeats 11] [--touches 400] [--update-readme]
Writes bench/results/scaling.json.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

from _common import interleaved, write_block, write_json
from edge.physics.forward import simulate
from edge.physics.solids import Solid
from edge.recognition import KnownObject, ObjectSet

GLASS = Solid(1.097, 2458.4, 809.0)
Q_V = 7.7e7
LENGTHS_s = (2.0, 5.0, 10.0, 20.0, 60.0)
RATES_Hz = (10.0, 50.0, 100.0, 200.0, 500.0, 1000.0)
SET_SIZES = (16, 128, 512, 2048, 8192)


def _record(duration_s: float, rate_Hz: float, rng: np.random.Generator):
    r = simulate(GLASS, Q_V, duration_s, dt_s=1.0 / rate_Hz, back="infinite", scheme="exact")
    # 10 mK / 0.5 W/m^2 noise: the estimate must work for its answer, not read a clean curve
    return (r.t_s, r.T_f_K + rng.normal(0, 0.01, r.t_s.size), r.q_f_W_m2 + rng.normal(0, 0.5, r.t_s.size))


def _slope(sizes, medians) -> float:
    return float(np.polyfit(np.log(sizes), np.log(medians), 1)[0])


def estimate_curves(repeats: int) -> dict:
    from estimate_scaling_bench import load_estimator

    est = load_estimator()
    rng = np.random.default_rng(5)
    out = {}
    for name, points in (("record_length_s", [(d, 100.0) for d in LENGTHS_s]),
                         ("sample_rate_Hz", [(10.0, f) for f in RATES_Hz])):
        recs = {p: _record(*p, rng) for p in points}
        timed = interleaved({p: (lambda r=r: est.estimate(*r)) for p, r in recs.items()}, repeats)
        xs = [p[0] if name == "record_length_s" else p[1] for p in points]
        rows = []
        for x, p in zip(xs, points):
            tm = timed[p]
            res = tm.pop("result")
            rows.append({"x": x, "n_samples": int(recs[p][0].size), **tm,
                         "e_rel_err": float(res.effusivity_W_s05_m2K / GLASS.effusivity_W_s05_m2K - 1)})
        out[name] = {"points": rows, "slope": _slope([r["n_samples"] for r in rows], [r["median_s"] for r in rows])}
    return out


def _synthetic_set(n: int, rng: np.random.Generator) -> ObjectSet:
    from edge.physics.materials import load_materials

    lib = list(load_materials())
    objs = [KnownObject.from_properties(m.name, m.cls, m.k_W_mK, m.rho_kg_m3, m.c_J_kgK) for m in lib][:n]
    lo, hi = math.log(min(o.e_W_s05_m2K for o in objs)), math.log(max(o.e_W_s05_m2K for o in objs))
    classes = sorted({o.cls for o in objs})
    while len(objs) < n:
        i = len(objs)
        objs.append(KnownObject(f"synthetic-{i}", classes[i % len(classes)], math.exp(rng.uniform(lo, hi))))
    return ObjectSet(objs, label=f"{n} objects")


def set_size_curve(repeats: int) -> dict:
    rng = np.random.default_rng(6)
    sets = {n: _synthetic_set(n, rng) for n in SET_SIZES}
    timed = interleaved({n: (lambda s=s: s.classify(1478.0, 0.02)) for n, s in sets.items()}, repeats)
    rows = []
    for n in SET_SIZES:
        tm = timed[n]
        tm.pop("result")
        rows.append({"x": n, **tm})
    return {"points": rows, "slope": _slope(SET_SIZES, [r["median_s"] for r in rows])}


def session_curve(touches: int) -> dict:
    import sim_session_bench

    walls = sim_session_bench.run(touches, "glass_15V")["per_touch_wall_s"]
    bins = 8
    edges = np.linspace(0, touches, bins + 1).astype(int)
    rows = []
    for a, b in zip(edges[:-1], edges[1:]):
        w = walls[a:b]
        rows.append({"x": int(b), "from": int(a) + 1, "median_s": statistics.median(w), "min_s": min(w),
                     "max_s": max(w), "n": len(w)})
    return {"points": rows, "slope": _slope([r["x"] for r in rows], [r["median_s"] for r in rows])}


def _row(label: str, p: dict, extra: str = "") -> str:
    ms = lambda v: f"{v * 1e3:.3g}"  # noqa: E731
    return f"| {label} | {ms(p['median_s'])} [{ms(p['min_s'])}–{ms(p['max_s'])}] |{extra}"


def markdown(res: dict) -> str:
    est = res["estimate"]
    L = [f"Medians [min–max] in ms of {res['repeats']} interleaved rounds; slope b of time ∝ size^b "
         "(`python bench/scaling_bench.py --update-readme`).", ""]
    for key, head, unit in (("record_length_s", "record length at 100 Hz", "s"),
                            ("sample_rate_Hz", "sample rate, 10-s record", "Hz")):
        c = est[key]
        L += [f"| {head} | estimate (ms) | samples | e error |", "|---|---|---|---|"]
        L += [_row(f"{p['x']:g} {unit}", p, f" {p['n_samples']} | {p['e_rel_err'] * 100:+.2f} % |") for p in c["points"]]
        L += [f"| slope (per sample) | {c['slope']:.2f} | | |", ""]
    c = res["object_set"]
    L += ["| objects in the set | recognise one touch (ms) |", "|---|---|"]
    L += [_row(f"{p['x']}", p) for p in c["points"]]
    L += [f"| slope | {c['slope']:.2f} |", ""]
    c = res["session"]
    L += [f"| touches {c['points'][0]['from']}… of a {res['touches']}-touch session | per touch (ms) |", "|---|---|"]
    L += [_row(f"{p['from']}–{p['x']}", p) for p in c["points"]]
    L += [f"| slope | {c['slope']:.2f} |"]
    return "\n".join(L)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=11)
    ap.add_argument("--touches", type=int, default=400)
    ap.add_argument("--update-readme", action="store_true")
    args = ap.parse_args()
    if args.touches < 200:
        ap.error("--touches must be >= 200 (the session curve bins them)")
    t0 = time.perf_counter()
    res = {"repeats": args.repeats, "touches": args.touches, "estimate": estimate_curves(args.repeats),
           "object_set": set_size_curve(args.repeats), "session": session_curve(args.touches)}
    res["bench_seconds"] = time.perf_counter() - t0
    text = markdown(res)
    print(text)
    res["command"] = "python bench/scaling_bench.py" + (f" --repeats {args.repeats}" if args.repeats != 11 else "") \
        + (f" --touches {args.touches}" if args.touches != 400 else "")
    print(f"\nwrote {write_json('scaling', res)}")
    if args.update_readme:
        write_block("scaling-bench", text)


if __name__ == "__main__":
    main()
