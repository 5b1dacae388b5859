"""Wall time of one 2-s touch on the axisymmetric (r, z) world model (firmware_sim/rz).

For glass, PMMA and aluminium on the default probe grid (PU foam, heater film,
sensing layer, 40 mm x 50 mm object, graded cells): build the grid, factorise
for dt = 10 ms, and march 200 steps of a touch with the probe at 25 degC on
an object at 22 degC and 5 W in the heater (thermocouple, flux sensor and
face flux every step).  Reported per case: median and min-max over
``--repeat`` runs of the whole thing and of its parts (grid, factorisation,
stepping), for TR-BDF2 (the default), Crank-Nicolson and backward Euler; plus
the superposition route (one unit-step and one free response, then any power
schedule by convolution).

Run:  python bench/rz_world_bench.py [--repeat 7]
Writes bench/results/rz_world.json.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

from _common import ROOT, write_json

sys.path.insert(0, str(ROOT))  # the repo's firmware_sim package, also when run from bench/

import numpy as np  # noqa: E402

from edge.physics.solids import Solid  # noqa: E402
from firmware_sim.rz.grid import probe_grid  # noqa: E402
from firmware_sim.rz.solver import Solver, clear_factor_cache  # noqa: E402

SOLIDS = {"glass": Solid(1.1, 2500.0, 800.0), "PMMA": Solid(0.19, 1190.0, 1470.0),
          "aluminium": Solid(160.0, 2700.0, 900.0)}
DT_S = 0.01
N_STEPS = 200
POWER_W = 5.0


def one_touch(solid: Solid, scheme: str) -> dict:
    clear_factor_cache()  # a cold start: the factorisation is timed, not the shared cache
    t0 = time.perf_counter()
    g = probe_grid(solid)
    t1 = time.perf_counter()
    s = Solver(g, DT_S, scheme)
    t2 = time.perf_counter()
    rec = s.run(s.initial_field(25.0, 22.0), N_STEPS, s.heater_source_W(), POWER_W)
    t3 = time.perf_counter()
    return {"total_s": t3 - t0, "grid_s": t1 - t0, "factor_s": t2 - t1, "steps_s": t3 - t2,
            "cells": int(g.nr * g.nz), "shape_nz_nr": [g.nz, g.nr],
            "T_tc_2s_C": float(rec.T_tc_K[-1]), "q_sensor_2s_W_m2": float(rec.q_sensor_W_m2[-1]),
            "q_face_2s_W_m2": float(rec.q_face_W_m2[-1])}


def superposed(solid: Solid) -> dict:
    clear_factor_cache()
    t0 = time.perf_counter()
    s = Solver(probe_grid(solid), DT_S)
    step = s.step_response(N_STEPS)
    free = s.free_response(N_STEPS, 25.0, 22.0)
    t1 = time.perf_counter()
    Solver.superpose(free, step, np.full(N_STEPS, POWER_W))
    t2 = time.perf_counter()
    return {"responses_s": t1 - t0, "superpose_s": t2 - t1}


def summary(runs: list[dict], key: str) -> dict:
    v = [r[key] for r in runs]
    return {"median": statistics.median(v), "min": min(v), "max": max(v)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    cases = {}
    for name, solid in SOLIDS.items():
        for scheme in ("trbdf2", "cn", "be"):
            one_touch(solid, scheme)  # warm-up (imports, allocator)
            runs = [one_touch(solid, scheme) for _ in range(args.repeat)]
            row = {k: summary(runs, k) for k in ("total_s", "grid_s", "factor_s", "steps_s")}
            row.update({k: runs[-1][k] for k in ("cells", "shape_nz_nr", "T_tc_2s_C", "q_sensor_2s_W_m2",
                                                  "q_face_2s_W_m2")})
            cases[f"{name}/{scheme}"] = row
            t = row["total_s"]
            print(f"{name:9s} {scheme:6s} {row['shape_nz_nr'][0]}x{row['shape_nz_nr'][1]} cells: "
                  f"2-s touch {t['median'] * 1e3:6.0f} ms (min {t['min'] * 1e3:.0f}, max {t['max'] * 1e3:.0f}); "
                  f"factor {row['factor_s']['median'] * 1e3:.1f} ms, steps {row['steps_s']['median'] * 1e3:.0f} ms")
        sp = [superposed(solid) for _ in range(max(3, args.repeat // 2))]
        cases[f"{name}/superposition"] = {k: summary(sp, k) for k in ("responses_s", "superpose_s")}
        r = cases[f"{name}/superposition"]
        print(f"{name:9s} superposition: step + free responses {r['responses_s']['median'] * 1e3:.0f} ms, "
              f"each further power schedule {r['superpose_s']['median'] * 1e3:.2f} ms")
    worst = max(c["total_s"]["median"] for k, c in cases.items() if k.endswith("/trbdf2"))
    print(f"worst median 2-s touch (TR-BDF2, 200 steps of 10 ms): {worst * 1e3:.0f} ms (budget 2000 ms)")
    path = write_json("rz_world", {
        "what": "wall time of one 2-s touch (200 steps of 10 ms) on the default (r, z) probe grid: "
                "grid + factorisation + stepping, median and min-max over repeats",
        "command": "python bench/rz_world_bench.py" + (f" --repeat {args.repeat}" if args.repeat != 7 else ""),
        "dt_s": DT_S, "n_steps": N_STEPS, "power_W": POWER_W, "repeat": args.repeat,
        "cases": cases, "worst_median_trbdf2_s": worst,
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
