"""Speed-accuracy trade of the probe forward model.

For each scheme and resolution: the largest relative error of T_f and q_f
over a 1.95-s record (relative to the record's peak) against the exact
Laplace-domain solution, and the wall time, for the paper's Table 1 and
Table 2 materials at q_v = 7.7e7 W/m^3 on the paper's 40-mm block with a
held back.  Then the time to generate the paper's training set (67 materials
x 21 power levels = 1407 series) with each scheme, in the same run.  Every
time is a median with its min-max over rounds that run the compared cases
interleaved (bench/_common.interleaved).

Run:  python bench/forward_bench.py [--update-readme] [--repeats N]
Writes bench/results/forward.json.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from _common import fmt_ms, interleaved, rel_err, write_block, write_json
from edge.physics.forward import scale_levels, simulate, step_response
from edge.physics.probe import STACK_040, STACK_042
from edge.physics.solids import Solid
from edge.physics.materials import load_materials

MATERIALS = {
    "tempered glass": Solid(1.097, 2458.4, 809.0),
    "PMMA": Solid(0.185, 1178.35, 1429.0),
    "Al alloy": Solid(120.4, 2651.5, 873.0),
    "material I": Solid(0.1, 500.2, 2400.0),
    "material II": Solid(1.5, 2659.6, 800.0),
    "material III": Solid(12.0, 7860.0, 477.1),
}
Q_V = 7.7e7
DURATION = 1.95
LEVELS = np.arange(4.0e7, 1.4e8 + 1, 5e6)  # 21 levels

RESOLUTIONS = [
    ("paper", dict(dx_m=80e-6)),
    ("paper", dict(dx_m=40e-6)),
    ("paper", dict(dx_m=20e-6)),
    ("explicit", dict(dx_m=40e-6)),
    ("default", dict(n_probe=12, growth=1.12)),
    ("default", dict(n_probe=24, growth=1.08)),
    ("default", dict()),
    ("default", dict(n_probe=64, growth=1.03)),
]


def accuracy_table(repeats: int):
    rows = []
    for name, solid in MATERIALS.items():
        ref = simulate(solid, Q_V, DURATION, scheme="exact")
        cases, labels, refused = {"exact": lambda: simulate(solid, Q_V, DURATION, scheme="exact")}, {}, {}
        labels["exact"] = ("exact", "Talbot M=24")
        for scheme, kw in RESOLUTIONS:
            res = "dx=%g um" % round(kw["dx_m"] * 1e6) if "dx_m" in kw else (
                "n_probe=%d, growth=%g" % (kw.get("n_probe", 32), kw.get("growth", 1.06)))
            try:  # a refused run (step budget) is reported, not timed
                simulate(solid, Q_V, DURATION, scheme=scheme, **kw)
            except ValueError as exc:
                refused[(scheme, res)] = str(exc)
                continue
            key = f"{scheme} {res}"
            labels[key] = (scheme, res)
            cases[key] = (lambda scheme=scheme, kw=kw: simulate(solid, Q_V, DURATION, scheme=scheme, **kw))
        # every scheme of this material timed round-robin: medians over the same stretch of machine time
        timed = interleaved(cases, repeats, warmup=False)
        for key, tm in timed.items():
            scheme, res = labels[key]
            r = tm.pop("result")
            row = dict(material=name, scheme=scheme, resolution=res, time=tm, time_s=tm["median_s"],
                       nodes=getattr(r, "n_nodes", 0), steps=getattr(r, "n_steps", 0))
            if scheme == "exact":
                row.update(err_T=0.0, err_q=0.0, nodes=0, steps=0)
            else:
                row.update(err_T=rel_err(r.T_f_K, ref.T_f_K), err_q=rel_err(r.q_f_W_m2, ref.q_f_W_m2),
                           domain_mm=r.domain_m * 1e3)
            rows.append(row)
        for (scheme, res), why in refused.items():
            rows.append(dict(material=name, scheme=scheme, resolution=res, error=why))
        a = simulate(solid, Q_V, DURATION, stack=STACK_042, scheme="exact").T_f_K[-1]
        b = simulate(solid, Q_V, DURATION, stack=STACK_040, scheme="exact").T_f_K[-1]
        rows[-1]["stack_effect"] = (a - b) / b
    return rows


def training_set_timing(solids, repeats: int):
    """Generate len(solids) x 21 series with each scheme, interleaved; median time and worst error."""
    refs = [step_response(s, DURATION, scheme="exact") for s in solids]

    def generate(scheme):
        return [scale_levels(step_response(s, DURATION, scheme=scheme), LEVELS) for s in solids]

    timed = interleaved({"default": lambda: generate("default"), "paper": lambda: generate("paper")}, repeats,
                        warmup=False)
    out = {}
    for scheme, tm in timed.items():
        series = tm.pop("result")
        err_T = max(rel_err(T[-1], LEVELS[-1] * r.T_f_K) for (T, _), r in zip(series, refs))
        err_q = max(rel_err(q[-1], LEVELS[-1] * r.q_f_W_m2) for (_, q), r in zip(series, refs))
        out[scheme] = dict(time=tm, time_s=tm["median_s"], n_series=len(solids) * LEVELS.size,
                           worst_err_T=err_T, worst_err_q=err_q)
    # The paper computed every series separately; linearity makes that 21x the work.
    out["paper_per_series_estimate_s"] = out["paper"]["time_s"] * LEVELS.size
    return out


def paper_subset(lib, n=67):
    """n library materials evenly spread in log k (the paper used 67)."""
    order = np.argsort(lib.k)
    pick = order[np.unique(np.round(np.linspace(0, len(order) - 1, n)).astype(int))]
    return [Solid(lib.k[i], lib.rho[i], lib.c[i]) for i in pick]


def convergence_orders(solid):
    """Observed order of each scheme under halving of every cell (glass)."""
    ref = simulate(solid, 1.0, DURATION, scheme="exact").T_f_K
    out = {}
    for scheme in ("paper", "explicit"):
        errs = [rel_err(simulate(solid, 1.0, DURATION, scheme=scheme, dx_m=0.42e-3 / (5 * 2 ** i)).T_f_K, ref)
                for i in range(4)]
        out[scheme] = dict(errors=errs, orders=np.log2(np.array(errs[:-1]) / errs[1:]).tolist())
    errs = [rel_err(simulate(solid, 1.0, DURATION, n_probe=6 * 2 ** i, growth=1.2 ** (1 / 2 ** i)).T_f_K, ref)
            for i in range(4)]
    out["default"] = dict(errors=errs, orders=np.log2(np.array(errs[:-1]) / errs[1:]).tolist())
    return out


def markdown(rows, train):
    lines = ["| material | scheme | resolution | max err T_f | max err q_f | time (ms), median [min–max] | nodes | steps |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['material']} | {r['scheme']} | {r['resolution']} | refused: {r['error']} | | | | |")
            continue
        lines.append(
            f"| {r['material']} | {r['scheme']} | {r['resolution']} | {r['err_T']:.2e} | {r['err_q']:.2e} | "
            f"{fmt_ms(r['time'])} | {r['nodes']} | {r['steps']} |")
    d, p = train["default"], train["paper"]
    lines += [
        "",
        f"Training set, {d['n_series']} series (67 library materials x 21 levels, 1.95 s, 0.01-s samples; "
        f"medians [min–max] of {d['time']['n']} interleaved runs):",
        f"default {d['time_s']:.3f} s [{d['time']['min_s']:.3f}–{d['time']['max_s']:.3f}] "
        f"(worst T_f error {d['worst_err_T']:.1e}); "
        f"paper scheme {p['time_s']:.1f} s [{p['time']['min_s']:.1f}–{p['time']['max_s']:.1f}] with linearity "
        f"(worst T_f error {p['worst_err_T']:.1e}), "
        f"~{train['paper_per_series_estimate_s']:.0f} s run series by series as the paper did; "
        f"ratio {p['time_s'] / d['time_s']:.0f}x (with linearity) / "
        f"{train['paper_per_series_estimate_s'] / d['time_s']:.0f}x (series by series).",
    ]
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--update-readme", action="store_true")
    ap.add_argument("--repeats", type=int, default=5, help="interleaved rounds per case (training sets: 3)")
    args = ap.parse_args()
    rows = accuracy_table(args.repeats)
    lib = load_materials()
    train = training_set_timing(paper_subset(lib), min(args.repeats, 3))
    train_full = training_set_timing([Solid(m.k_W_mK, m.rho_kg_m3, m.c_J_kgK) for m in lib], min(args.repeats, 3))
    text = markdown(rows, train)
    text += (f"\nWhole library ({train_full['default']['n_series']} series): default "
             f"{train_full['default']['time_s']:.2f} s, paper scheme {train_full['paper']['time_s']:.1f} s.")
    orders = convergence_orders(MATERIALS["tempered glass"])
    text += "\nObserved order of convergence of T_f on glass (successive halvings of every cell): " + "; ".join(
        f"{k} " + ", ".join(f"{o:.2f}" for o in v["orders"]) for k, v in orders.items()) + "."
    # A first-order scheme costs ~dx^-3 (nodes x steps): its cost to match the default's error.
    paper40 = [r for r in rows if r.get("scheme") == "paper" and r["resolution"] == "dx=40 um" and "err_T" in r]
    dflt = {r["material"]: r for r in rows if r.get("scheme") == "default" and r["resolution"].startswith("n_probe=32")}
    ratios = [p["time_s"] * (p["err_T"] / dflt[p["material"]]["err_T"]) ** 3 / dflt[p["material"]]["time_s"]
              for p in paper40]
    text += (f"\nAt equal accuracy (paper scheme refined to the default's T_f error, cost ~dx^-3 extrapolated from "
             f"40 um): the default is {min(ratios):.1e}x to {max(ratios):.1e}x faster per series.")
    stack = {r["material"]: r["stack_effect"] for r in rows if "stack_effect" in r}
    text += "\nStacking: T_f(1.95 s) with the interface at 0.42 mm vs 0.40 mm differs by " + ", ".join(
        f"{k} {v * 100:+.1f} %" for k, v in stack.items()) + "."
    print(text)
    path = write_json("forward", dict(q_v_W_m3=Q_V, duration_s=DURATION, rows=rows, training_set=train,
                                       training_set_full_library=train_full, stack_effect=stack,
                                       convergence_orders=orders, equal_accuracy_speedup=ratios))
    print(f"\nwrote {path}")
    if args.update_readme:
        write_block("forward-bench", text)


if __name__ == "__main__":
    main()
