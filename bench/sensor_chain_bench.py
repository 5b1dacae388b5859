"""Sensor-chain estimator against the default method on FaithfulWorld records (ISSUE #10 §3).

Run:  python bench/sensor_chain_bench.py [--quick]

FaithfulWorld (axisymmetric FV probe; 1-D-limit geometry and the paper probe) over a grid of
solids (PMMA to aluminium, thick objects), contact resistance R_c in {0, 3e-5, 1e-4} m^2K/W,
object offset in {-3, 0, +3} K and contact lead {0.5, 2} s before a 10-s heating, with
precision-board noise (10 mK, 0.5 W/m^2).  Reports per geometry: e median |error| and 90th
percentile, 95 % coverage (|e - e_true| <= 2 u), R_c recovered within u, for the default
:class:`edge.estimation.estimate.Estimator` (from heater-on, baseline T0) and for
:func:`edge.estimation.sensor_chain.fit_sensor_chain` (from contact); and the compute time per
estimate (medians over interleaved repeats).  World runs are cached in bench/results/cache.
Writes bench/results/sensor_chain.json and prints a markdown table.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

from _common import RESULTS, interleaved

import numpy as np

from edge.estimation.sensor_chain import SensorChainCalibration, fit_sensor_chain
from edge.physics.materials import load_materials

SOLIDS = ("pmma", "hdpe", "borofloat_33", "pyroceram", "zirconia_3y", "stainless_440a", "inconel_x750",
          "ductile_iron", "cartridge_brass", "aluminium")
RCS = (0.0, 3e-5, 1e-4)
OFFSETS = (-3.0, 0.0, 3.0)
LEADS = (0.5, 2.0)
HEAT_s = 10.0
DT_s = 0.05
WORLD_DT_s = 0.05
NOISE_T_K, NOISE_Q = 0.01, 0.5
CACHE = RESULTS / "cache"


def _geometry(kind: str):
    from firmware_sim.rz.grid import Mesh
    from firmware_sim.rz.probe_world import Geometry, geometry_for_probe
    if kind == "1d":
        return Geometry(substrate=None, h_air_W_m2K=0.0, heater_radius_m=0.1, object_radius_m=0.15,
                        mesh=Mesh(max_dr_m=0.01))
    return geometry_for_probe("paper")


def world_record(kind: str, solid_name: str, rc: float, offset: float, lead: float) -> dict:
    """(t from contact, thermocouple, thermopile, e_true, T_amb, lead) of one FaithfulWorld touch (cached)."""
    key = f"sensor_chain_{kind}_{solid_name}_{rc:g}_{offset:+g}_{lead:g}.npz"
    path = CACHE / key
    if path.exists():
        d = np.load(path)
        return {k: d[k] for k in d.files}
    from firmware_sim.clock import VirtualClock
    from firmware_sim.rz.probe_world import FaithfulWorld
    from firmware_sim.scene.files import read_scene
    from firmware_sim.world import ScheduleDrive
    solid = load_materials().get(solid_name).solid
    sc = read_scene("glass_15V")
    env = sc.environment
    T_amb = env.ambient_temperature_C
    t_contact = 1.0
    sc = dataclasses.replace(
        sc, object=dataclasses.replace(sc.object, solid=solid, back="infinite"),
        environment=dataclasses.replace(env, initial_temperature_C=T_amb + offset),
        touch=dataclasses.replace(sc.touch, start_s=t_contact, length_s=lead + HEAT_s + 5.0),
        contact_resistance_m2K_W=rc)
    clk = VirtualClock()
    clk.advance(100.0)
    t_on = t_contact + lead
    w = FaithfulWorld(sc, clk, ScheduleDrive([t_on, t_on + HEAT_s], [1.0, 0.0]), geometry=_geometry(kind),
                      dt_s=WORLD_DT_s)
    t = t_contact + np.arange(0.0, lead + HEAT_s + 1e-9, DT_s)
    s = w.series(t)
    rec = {"t": t - t_contact, "T": s["y"], "q": s["q_sensor"], "e_true": solid.effusivity_W_s05_m2K,
           "T_amb": T_amb, "lead": lead}
    CACHE.mkdir(parents=True, exist_ok=True)
    np.savez(path, **rec)
    return rec


def noisy(rec: dict, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rec["T"] + NOISE_T_K * rng.standard_normal(rec["T"].size), rec["q"] + NOISE_Q * rng.standard_normal(rec["q"].size)


def default_estimate(est, rec: dict, T: np.ndarray, q: np.ndarray):
    """The device's default method: from heater-on, excess over the pre-heating baseline."""
    t = rec["t"]
    i_on = int(np.argmin(np.abs(t - float(rec["lead"]))))
    base = float(np.mean(T[max(0, i_on - 5):i_on + 1]))
    r = est.estimate(t[i_on:] - t[i_on], T[i_on:] - base, q[i_on:])
    return r.effusivity_W_s05_m2K, r.effusivity_W_s05_m2K_u


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="3 solids, R_c 1e-4, offsets -3/+3, lead 2 s, 1-D only")
    args = ap.parse_args()
    from edge.estimation.estimate import Estimator, pipeline_golden_check
    from edge.model.bundle import load_bundle
    from thermotouch_models import DEFAULT_BUNDLE
    est = Estimator.from_bundle(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))
    solids = ("pmma", "borofloat_33", "aluminium") if args.quick else SOLIDS
    grid = [(k, s, rc, o, ld) for k in (("1d",) if args.quick else ("1d", "paper")) for s in solids
            for rc in ((1e-4,) if args.quick else RCS) for o in ((-3.0, 3.0) if args.quick else OFFSETS)
            for ld in ((2.0,) if args.quick else LEADS)]
    t0 = time.perf_counter()
    rows = []
    timing_case = None
    for n, (kind, s, rc, o, ld) in enumerate(grid):
        rec = world_record(kind, s, rc, o, ld)
        T, q = noisy(rec, n)
        e_true = float(rec["e_true"])
        try:
            e_d, u_d = default_estimate(est, rec, T, q)
        except ValueError:
            e_d, u_d = None, None
        r = fit_sensor_chain(rec["t"], T, q, calibration=SensorChainCalibration())
        rows.append({"geometry": kind, "solid": s, "R_c": rc, "offset_K": o, "lead_s": ld, "e_true": e_true,
                     "e_default": e_d, "u_default": u_d, "e_chain": r.e_W_s05_m2K, "u_chain": r.u_e_W_s05_m2K,
                     "R_c_fit": r.R_c_m2K_W, "u_R_c": r.u_R_c_m2K_W, "T_obj0_err_K": r.T_obj0_C - (float(rec["T_amb"]) + o),
                     "normalised_residual": r.normalised_residual})
        if timing_case is None:
            timing_case = (rec, T, q)
    world_s = time.perf_counter() - t0
    rec, T, q = timing_case
    timing = interleaved({
        "default": lambda: (default_estimate(est, rec, T, q), None)[1],
        "sensor_chain": lambda: (fit_sensor_chain(rec["t"], T, q), None)[1],
    }, repeats=7)

    def summary(rs, key_e, key_u):
        ok = [x for x in rs if x[key_e] is not None and np.isfinite(x[key_e])]
        err = np.array([abs(x[key_e] / x["e_true"] - 1.0) for x in ok])
        cov = np.mean([abs(x[key_e] - x["e_true"]) <= 2.0 * x[key_u] for x in ok]) if ok else float("nan")
        return {"n": len(ok), "median_abs_err": float(np.median(err)) if ok else None,
                "p90_abs_err": float(np.percentile(err, 90)) if ok else None, "coverage_95": float(cov)}

    out = {"grid": {"solids": solids, "quick": args.quick}, "rows": rows, "timing": timing, "world_s": world_s,
           "summary": {}}
    lines = ["| geometry | method | n | median abs err e | p90 | 95 % coverage | R_c within u |",
             "|---|---|---|---|---|---|---|"]
    for kind in sorted({r["geometry"] for r in rows}):
        rs = [r for r in rows if r["geometry"] == kind]
        sd, sc = summary(rs, "e_default", "u_default"), summary(rs, "e_chain", "u_chain")
        rc_ok = float(np.mean([abs(r["R_c_fit"] - r["R_c"]) <= r["u_R_c"] for r in rs]))
        out["summary"][kind] = {"default": sd, "sensor_chain": sc, "R_c_within_u": rc_ok}
        for name, sm, rco in (("default", sd, "-"), ("sensor_chain", sc, f"{rc_ok:.0%}")):
            lines.append(f"| {kind} | {name} | {sm['n']} | {sm['median_abs_err']:.1%} | {sm['p90_abs_err']:.1%} | "
                         f"{sm['coverage_95']:.0%} | {rco} |")
    print("\n".join(lines))
    print(f"time per estimate: {json.dumps(timing)}")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "sensor_chain.json").write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
