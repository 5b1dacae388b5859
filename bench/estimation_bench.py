"""Accuracy and compute time of the two estimation methods, side by side.

* the paper's nine experiments (glass 12/15/18 V, PMMA 8/15/20 V, Al 15/20/25 V;
  50-ohm heater assumed, see host/evaluate.py), both instruments, both methods;
* leave-one-material-out: default method with the material removed from the
  prior; paper method by 7 grouped folds (retraining without the fold), both
  on noisy simulated touches of the held-out materials;
* identification from noisy touches of every library material;
* effusivity accuracy vs contact time and heater voltage (the profiles);
* compute per measurement (resampling, features, network, alpha): paper scan
  (explicit FTCS as the paper) vs default, median [min-max] time over
  interleaved rounds, and error.

Run:  python bench/estimation_bench.py [--bundle DIR] [--update-readme]
Writes bench/results/estimation.json.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from _common import interleaved, write_block, write_json
from edge.model.bundle import load_bundle
from edge.estimation.estimate import Estimator, pipeline_golden_check
from host.evaluate import (SAMPLES, TouchSimulator, contact_time_trade, identification, leave_one_out_default,
                           leave_out_paper, paper_cases, q_v_for_voltage)


def compute_timing(est_fast: Estimator, est_paper: Estimator, repeats: int = 7):
    """Compute time per measurement (median [min-max] of interleaved rounds) and errors, paper scan vs default."""
    rng = np.random.default_rng(9)
    out = {}
    for name, (solid, volts) in SAMPLES.items():
        t = TouchSimulator(solid).touch(q_v_for_voltage(volts[1]), "ads122c04", rng)
        timed = interleaved({
            "default": lambda: est_fast.estimate(t.tT, t.T, t.q, t_q_s=t.tq, method="default"),
            # the explicit paper scan on aluminium takes seconds per call: fewer rounds
            "paper_scan": lambda: est_paper.estimate(t.tT, t.T, t.q, t_q_s=t.tq, method="paper"),
        }, repeats if name != "aluminium_alloy" else 3)
        for label, tm in timed.items():
            res = tm.pop("result")
            out[f"{name}/{label}"] = dict(
                median_ms=tm["median_s"] * 1e3, min_ms=tm["min_s"] * 1e3, max_ms=tm["max_s"] * 1e3, n=tm["n"],
                e_err=float(res.effusivity_W_s05_m2K / solid.effusivity_W_s05_m2K - 1),
                k_err=float(res.k_W_mK / solid.k_W_mK - 1), alpha_err=float(res.alpha_m2_s / solid.alpha_m2_s - 1))
    return out


def pct(x):
    return "-" if x is None else f"{x * 100:+.1f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bundle", default=None)
    ap.add_argument("--update-readme", action="store_true")
    args = ap.parse_args()
    from thermotouch_models import DEFAULT_BUNDLE

    bundle = load_bundle(args.bundle or DEFAULT_BUNDLE, golden_check=pipeline_golden_check)
    est = Estimator.from_bundle(bundle)
    est_paper = Estimator.from_bundle(bundle, paper_scan_scheme="paper")
    res = {"model_sha256": bundle.sha256, "manifest_metrics": bundle.manifest.get("metrics", {})}
    t0 = time.perf_counter()
    res["paper_cases"] = {inst: paper_cases(est, inst, repeats=5) for inst in ("mcp9600", "ads122c04")}
    res["lomo_default"] = {inst: leave_one_out_default(est, inst) for inst in ("mcp9600", "ads122c04")}
    res["lomo_paper"] = {inst: leave_out_paper(inst) for inst in ("mcp9600", "ads122c04")}
    res["identification"] = {inst: identification(est, inst, touches=3) for inst in ("mcp9600", "ads122c04")}
    res["contact_time"] = {inst: contact_time_trade(est, inst) for inst in ("mcp9600", "ads122c04")}
    res["compute"] = compute_timing(est, est_paper)
    res["bench_seconds"] = time.perf_counter() - t0

    L = []
    for inst, rows in res["paper_cases"].items():
        L += [f"Paper's nine experiments, {inst} board (mean signed error over 5 noisy touches, %; e: mean |error|):", "",
              "| sample | V | q_v (W/m³) | method | e err | k err | α err | stated u(k) |", "|---|---|---|---|---|---|---|---|"]
        for r in rows:
            L.append(f"| {r['sample']} | {r['voltage_V']:.0f} | {r['q_v_W_m3']:.3g} | {r['method']} | {pct(r['e_err'])} | "
                     f"{pct(r['k_err'])} | {pct(r['alpha_err'])} | {pct(r['k_u_rel'])} |")
        L.append("")
    L.append("Leave-one-material-out (|relative error|: median / 90th percentile / share within 10 % / 20 %):")
    L.append("")
    L.append("| method | board | e | k | α |")
    L.append("|---|---|---|---|---|")
    f = lambda s: f"{s['median'] * 100:.1f} / {s['p90'] * 100:.0f} / {s['within_10'] * 100:.0f} % / {s['within_20'] * 100:.0f} %"
    for inst, s in res["lomo_default"].items():
        L.append(f"| default | {inst} | {f(s['e'])} | {f(s['k'])} | {f(s['alpha'])} |")
    for inst, s in res["lomo_paper"].items():
        L.append(f"| paper (7 grouped folds) | {inst} | {f(s['e'])} | {f(s['k'])} | {f(s['alpha'])} |")
    L.append("")
    for inst, idn in res["identification"].items():
        L.append(f"Identification, {inst}: top-1 {idn['top1'] * 100:.1f} % of {idn['touches']} touches; "
                 f"{(idn['top1_resolvable'] or 0) * 100:.1f} % of the {idn['resolvable_touches']} touches whose "
                 f"material's effusivity differs from every other by > 2 u (median u(e)/e "
                 f"{idn['median_u_ln_e'] * 100:.1f} %). By class: "
                 + ", ".join(f"{c} {v * 100:.0f} %" for c, v in idn["by_class"].items())
                 + ". Top confusions: " + "; ".join(idn["confusions"][:5]) + ".")
        L.append("")
    L.append("Effusivity RMS error / median stated u vs contact time (default method, 18 V, %); "
             "profiles (edge/measure/profiles.py): quick = 0.5 s, standard = 2 s, precise = 4 s:")
    L.append("")
    for inst, rows in res["contact_time"].items():
        L.append(f"| {inst} | " + " | ".join(f"{t:g} s" for t in (0.3, 0.5, 1, 2, 4)) + " |")
        L.append("|---|" + "---|" * 5)
        for s in SAMPLES:
            cells = []
            for t in (0.3, 0.5, 1.0, 2.0, 4.0):
                r = [x for x in rows if x["sample"] == s and x["contact_time_s"] == t and x["voltage_V"] == 18.0][0]
                cell = "-" if r["e_rms_err"] is None else f"{r['e_rms_err'] * 100:.1f} / {r['e_stated_u'] * 100:.1f}"
                if r["n"] < 10:
                    cell += f" ({10 - r['n']}/10 refused: insufficient signal)"
                cells.append(cell)
            L.append(f"| {s} | " + " | ".join(cells) + " |")
        L.append("")
    L.append("Compute per measurement (ms, median [min–max] of interleaved rounds; errors in %):")
    L.append("")
    L.append("| case | time (ms) | e err | k err | α err |")
    L.append("|---|---|---|---|---|")
    for k_, v in res["compute"].items():
        L.append(f"| {k_} | {v['median_ms']:.2f} [{v['min_ms']:.2f}–{v['max_ms']:.2f}] | {pct(v['e_err'])} | "
                 f"{pct(v['k_err'])} | {pct(v['alpha_err'])} |")
    m = res["manifest_metrics"]
    if m:
        L.append("")
        ds_s = m.get("dataset_seconds", 0)
        L.append(f"Shipped bundle: PCA p1+p2 explain {m.get('pca_explained_variance_2', 0) * 100:.1f} % of the "
                 f"variance of the (noise-augmented) training features; training set "
                 + ("from the cache" if ds_s < 1 else f"{ds_s:.0f} s") + f" + fitting {m.get('train_seconds', 0):.0f} s "
                 f"(its manifest; `thermotouch train --out DIR` with an empty $THERMOTOUCH_CACHE times both).")
    text = "\n".join(L)
    print(text)
    print(f"\nwrote {write_json('estimation', res)}")
    if args.update_readme:
        write_block("estimation-bench", text)


if __name__ == "__main__":
    main()
