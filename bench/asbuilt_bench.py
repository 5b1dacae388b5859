"""What the device answers UNCALIBRATED on drawn as-built probes (issue #34, item 4).

For each probe head (``paper``, ``small-heater``) ``--probes`` probes (default
8) are drawn by :func:`firmware_sim.asbuilt.draw_as_built` (scene key
``[as_built] draw_seed``; the tolerances are the module's table), plus the
nominal probe for reference.  Each probe touches four solids -- tempered
glass, PMMA, AISI 304 steel, copper (the project's material library) -- with a
2-s heating through the device's own code on the emulated chips
(:func:`firmware_sim.rigs.sequence_rig.sequence_touch`: sequence, drivers and
the daemon's estimator on the shipped bundle).  The device is told only the
nominal probe and has NO calibration: this is the uncalibrated baseline the
calibration work (#34 items 1-3) must beat.

Conditions: ideal contact (R_c = 0, object at the probe's temperature, contact
from heater-on) so that only the probe's unknowns act; the precision board
(ADS122C04) and the scenes' noise; objects 0.1 m thick, insulated back.
Paper head: ``alu_20V_faithful``'s board and heater (20 V on 50 ohm);
small head: ``glass_15V_small``'s (15 V on 2100.8 ohm).

``--bounds`` adds the measured bounds of the world's remaining approximations
(see :mod:`firmware_sim.asbuilt`): the paper's 55 x 60 mm rectangle between its
inscribed (27.5 mm) and circumscribed (40.7 mm) disks at the same power
density, and the paper head's square vs equal-area disk read-out.

``--one-at-a-time HEAD SEED SOLID`` prints, for one drawn probe and solid,
the answer with each group of its deviations alone (which unknown matters).

Run:  python bench/asbuilt_bench.py [--probes 8] [--bounds]   (about 2 min + 1 min for --bounds)
Writes bench/results/asbuilt.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import statistics
import sys
import tempfile
import time

from _common import write_json

import numpy as np  # noqa: E402

from edge.physics.solids import Solid  # noqa: E402
from firmware_sim.asbuilt import draw_factors  # noqa: E402
from firmware_sim.scene.files import read_scene  # noqa: E402
from firmware_sim.scene.model import AsBuiltSpec, ObjectSpec  # noqa: E402
from firmware_sim.scene.parser import library_material  # noqa: E402

BASE_SCENES = {"paper": "alu_20V_faithful", "small-heater": "glass_15V_small"}
SOLIDS = ("tempered_glass", "pmma", "aisi_304", "copper")
HEAT_S = 2.0


def solid(name: str) -> Solid:
    k, rho, c = library_material(name)
    return Solid(k_W_mK=k, rho_kg_m3=rho, c_J_kgK=c)


def scene_for(head: str, name: str, draw_seed: int | None, seed: int):
    """The head's base scene with the solid, an ideal 2-s touch and the drawn probe (None: nominal)."""
    sc = read_scene(BASE_SCENES[head])
    env = dataclasses.replace(sc.environment, initial_temperature_C=sc.environment.ambient_temperature_C)
    touch = dataclasses.replace(sc.touch, start_s=0.5, length_s=HEAT_S + 0.8, contact_lead_s=0.0,
                                contact_resistance_m2K_W=None, object_temperature_C=None, object_offset_K=None,
                                repeat=False)
    obj = ObjectSpec(solid=solid(name), back="insulated", thickness_m=0.1, label=name)
    ab = None if draw_seed is None else AsBuiltSpec(draw_seed=draw_seed)
    return dataclasses.replace(sc, environment=env, touch=touch, object=obj, contact_resistance_m2K_W=0.0,
                               seed=seed, as_built=ab, name=f"{head}:{name}:{draw_seed}")


def touch(sc, store, workdir: str) -> dict:
    from firmware_sim.rigs.sequence_rig import sequence_touch
    out, _, _ = sequence_touch(sc, store, workdir, {"measurement": {"contact_time_s": HEAT_S}})
    return {"status": str(out.status), "flags": [str(f) for f in out.flags], "result": out.result or {}}


def row_of(head: str, probe: str, name: str, d: dict) -> dict:
    s = solid(name)
    r = d["result"]
    out = {"head": head, "probe": probe, "solid": name, "status": d["status"], "flags": d["flags"],
           "determined": r.get("determined"), "method": r.get("method")}
    for key, true in (("effusivity_W_s05_m2K", s.effusivity_W_s05_m2K), ("k_W_mK", s.k_W_mK),
                      ("alpha_m2_s", s.alpha_m2_s)):
        v, u = r.get(key), r.get(f"{key}_u")
        out[key] = v
        out[f"err_{key}"] = None if v is None else v / true - 1
        out[f"u_rel_{key}"] = None if v is None or u is None else u / v
    return out


def summarise(rows: list[dict]) -> dict:
    """Per head and solid: over the drawn probes, median and extremes of the errors; the nominal probe's."""
    out: dict = {}
    for head in BASE_SCENES:
        out[head] = {}
        for name in SOLIDS:
            rs = [r for r in rows if r["head"] == head and r["solid"] == name]
            drawn = [r for r in rs if r["probe"] != "nominal"]
            nom = next((r for r in rs if r["probe"] == "nominal"), None)
            s = {"n_drawn": len(drawn)}
            for q in ("effusivity_W_s05_m2K", "k_W_mK", "alpha_m2_s"):
                errs = [100 * r[f"err_{q}"] for r in drawn if r[f"err_{q}"] is not None]
                cover = [abs(r[f"err_{q}"]) <= 1.96 * r[f"u_rel_{q}"] for r in drawn
                         if r[f"err_{q}"] is not None and r[f"u_rel_{q}"] is not None]
                s[q] = {"median_abs_err_pct": statistics.median(map(abs, errs)) if errs else None,
                        "min_err_pct": min(errs) if errs else None, "max_err_pct": max(errs) if errs else None,
                        "cov95_pct": 100 * sum(cover) / len(cover) if cover else None,
                        "nominal_err_pct": None if nom is None or nom[f"err_{q}"] is None else 100 * nom[f"err_{q}"]}
            s["determined_k_alpha_pct"] = 100 * sum({"k", "alpha"} <= set(r["determined"] or []) for r in drawn) / max(
                1, len(drawn))
            out[head][name] = s
    return out


def bounds() -> dict:
    """Measured bounds of the approximations the world keeps (paper head, 2 s of heating)."""
    from firmware_sim.clock import VirtualClock
    from firmware_sim.rz.configs import geometry_for_probe
    from firmware_sim.rz.footprint import SquareSensor
    from firmware_sim.rz.probe_world import AsBuilt, FaithfulWorld
    from firmware_sim.world import ScheduleDrive

    a_in = 0.0275                                   # the 55 x 60 mm rectangle's inscribed disk
    a_out = math.hypot(0.0275, 0.030)               # and its circumscribed one
    t = np.array([0.5 + HEAT_S])

    def read(name: str, ab=AsBuilt(), **geo) -> dict:
        sc = scene_for("paper", name, None, 1)
        sc = dataclasses.replace(sc, as_built=None)
        clk = VirtualClock()
        clk.advance(0.5 + HEAT_S)
        w = FaithfulWorld(sc, clk, ScheduleDrive([0.5, 0.5 + HEAT_S], [1.0, 0.0]), as_built=ab,
                          geometry=geometry_for_probe("paper", **geo), dt_s=0.02)
        s = w.series(t)
        rise = float(s["T_tc"][0] - sc.environment.ambient_temperature_C)
        return {"q_sensor_W_m2": float(s["q_sensor"][0]), "rise_K": rise, "q_over_rise": float(s["q_sensor"][0]) / rise}

    out: dict = {"heater_bound": {}, "paper_square_vs_disk": {}}
    for name in ("pmma", "tempered_glass", "copper"):
        same_density = {"heater_area_m2": 0.055 * 0.060, "probe_radius_m": a_out}
        lo = read(name, heater_radius_m=a_in, **same_density)
        hi = read(name, heater_radius_m=a_out, **same_density)
        mid = read(name)
        out["heater_bound"][name] = {
            "inscribed": lo, "circumscribed": hi, "equal_area_disk": mid,
            "spread_rel": {k: abs(hi[k] - lo[k]) / abs(mid[k]) for k in mid}}
        if name == "copper":
            out["rectangle_vs_disk"] = rectangle_vs_disk(read, a_in, a_out, same_density)
        sq = read(name, AsBuilt(sensor=SquareSensor()))
        off = read(name, AsBuilt(sensor=SquareSensor(offset_x_m=0.5e-3, offset_y_m=0.5e-3, gradient_x=0.05)))
        out["paper_square_vs_disk"][name] = {
            "centred_rel": sq["q_sensor_W_m2"] / mid["q_sensor_W_m2"] - 1,
            "offset_0.5mm_gradient_5pct_rel": off["q_sensor_W_m2"] / mid["q_sensor_W_m2"] - 1}
        print(f"bounds {name:15s} heater spread q {out['heater_bound'][name]['spread_rel']['q_sensor_W_m2']:.2e} "
              f"rise {out['heater_bound'][name]['spread_rel']['rise_K']:.2e} "
              f"q/rise {out['heater_bound'][name]['spread_rel']['q_over_rise']:.2e}; square-disk "
              f"{out['paper_square_vs_disk'][name]['centred_rel']:.1e}, offset "
              f"{out['paper_square_vs_disk'][name]['offset_0.5mm_gradient_5pct_rel']:.1e}", flush=True)
    return out


def rectangle_vs_disk(read, a_in: float, a_out: float, same_density: dict, n: int = 12) -> dict:
    """The 55 x 60 mm rectangle's read-outs against its equal-area disk's, on copper, by superposition.

    Every read-out is linear in the heater's power density; a heated disk of radius ``a`` gives ``D(a)``
    and the annulus [a, a + da] adds ``D'(a) da``.  The rectangle heats the fraction ``f(r)`` of each
    annulus (its exact ring weights over the ring's area, :class:`SquareSensor` with the heater's
    sides), so ``rect = D(a_in) + sum_k (D(a_k+1) - D(a_k)) f_k`` over ``n`` rings from the inscribed
    to the circumscribed radius.  (The TCR is off: the world is then exactly linear.)
    """
    from firmware_sim.rz.footprint import SquareSensor

    radii = np.linspace(a_in, a_out, n + 1)
    rect = SquareSensor(side_x_m=0.055, side_y_m=0.060)
    frac = rect.ring_weights(radii) / (np.pi * np.diff(radii ** 2))
    D = [read("copper", heater_radius_m=float(a), **same_density) for a in radii]
    disk = read("copper", heater_radius_m=math.sqrt(0.055 * 0.060 / math.pi), **same_density)
    out = {}
    for key in ("q_sensor_W_m2", "rise_K"):
        v = D[0][key] + sum((D[k + 1][key] - D[k][key]) * frac[k] for k in range(n))
        out[key] = {"rectangle": v, "equal_area_disk": disk[key], "rel": v / disk[key] - 1}
    r_q = out["q_sensor_W_m2"]["rectangle"] / out["rise_K"]["rectangle"]
    out["q_over_rise"] = {"rel": r_q / (disk["q_sensor_W_m2"] / disk["rise_K"]) - 1}
    print(f"rectangle vs equal-area disk, copper, {HEAT_S:g} s: q {out['q_sensor_W_m2']['rel']:+.2e}, "
          f"rise {out['rise_K']['rel']:+.2e}, q/rise {out['q_over_rise']['rel']:+.2e}", flush=True)
    return out


def _f(x, fmt="+.1f") -> str:
    return "–" if x is None else f"{x:{fmt}}"


def table(summary: dict) -> str:
    lines = ["| head | solid | e: nominal probe | e: drawn, median abs (min … max) "
             "| k: drawn median abs (min … max) | α: drawn median abs (min … max) | k, α determined |",
             "|---|---|---|---|---|---|---|"]
    for head, per in summary.items():
        for name, s in per.items():
            e, k, a = s["effusivity_W_s05_m2K"], s["k_W_mK"], s["alpha_m2_s"]
            lines.append(
                f"| {head} | {name} | {_f(e['nominal_err_pct'])} % | {_f(e['median_abs_err_pct'], '.1f')} % "
                f"({_f(e['min_err_pct'])} … {_f(e['max_err_pct'])}) | {_f(k['median_abs_err_pct'], '.1f')} % "
                f"({_f(k['min_err_pct'])} … {_f(k['max_err_pct'])}) | {_f(a['median_abs_err_pct'], '.1f')} % "
                f"({_f(a['min_err_pct'])} … {_f(a['max_err_pct'])}) | {s['determined_k_alpha_pct']:.0f} % |")
    return "\n".join(lines)


def run(n_probes: int) -> dict:
    from thermotouch_models import DEFAULT_BUNDLE

    from edge.estimation.estimate import pipeline_golden_check
    from edge.model.bundle import load_bundle
    from firmware_sim.rigs.sequence_rig import OneBundleStore

    store = OneBundleStore(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))
    workdir = tempfile.mkdtemp(prefix="asbuilt-bench-")
    rows, draws = [], {}
    t0 = time.perf_counter()
    for head in BASE_SCENES:
        seeds = list(range(1, n_probes + 1))
        draws[head] = {str(s): draw_factors(head, s) for s in seeds}
        for n, draw_seed in enumerate([None] + seeds):
            probe = "nominal" if draw_seed is None else f"draw {draw_seed}"
            for j, name in enumerate(SOLIDS):
                sc = scene_for(head, name, draw_seed, seed=4000 + 31 * n + j)
                t1 = time.perf_counter()
                r = row_of(head, probe, name, touch(sc, store, workdir))
                r["wall_s"] = time.perf_counter() - t1
                rows.append(r)
                pct = {q: None if r[f"err_{q}"] is None else 100 * r[f"err_{q}"]
                       for q in ("effusivity_W_s05_m2K", "k_W_mK", "alpha_m2_s")}
                print(f"{head:12s} {probe:8s} {name:15s} e {_f(pct['effusivity_W_s05_m2K'])} % "
                      f"k {_f(pct['k_W_mK'])} % alpha {_f(pct['alpha_m2_s'])} % "
                      f"det={r['determined']} {r['flags']} {r['wall_s']:.1f} s", flush=True)
    return {"heads": list(BASE_SCENES), "base_scenes": BASE_SCENES, "solids": list(SOLIDS), "heat_s": HEAT_S,
            "probes_per_head": n_probes, "calibration": "none (uncalibrated device)",
            "conditions": "ideal contact: R_c = 0, object at the probe's temperature, contact from heater-on; "
                          "precision board; objects 0.1 m thick, insulated back",
            "wall_s": time.perf_counter() - t0, "load_avg_1min": os.getloadavg()[0],
            "summary": summarise(rows), "draws": draws, "rows": rows}


def one_at_a_time(head: str, seed: int, name: str) -> dict:
    """Which unknown moves the answer: the drawn probe, then each group of its deviations alone (printed only)."""
    import firmware_sim.rz.probe_world as pw
    from thermotouch_models import DEFAULT_BUNDLE

    from edge.estimation.estimate import pipeline_golden_check
    from edge.model.bundle import load_bundle
    from firmware_sim.asbuilt import draw_as_built
    from firmware_sim.rigs.sequence_rig import OneBundleStore
    from firmware_sim.rz.configs import AsBuilt

    store = OneBundleStore(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))
    sc = scene_for(head, name, seed, 4000)
    full = draw_as_built(head, seed, sc)
    groups = {"all": tuple(f.name for f in dataclasses.fields(AsBuilt)), "none": (),
              "sensing layer": ("sensing_thickness_m", "sensing_k_W_mK"),
              "flux sensitivity": ("flux_sensitivity_V_per_W_m2",),
              "thermocouple lag": ("thermocouple_time_constant_s",), "thermocouple radius": ("thermocouple_r_m",),
              "heater R": ("heater_resistance_ohm",), "heater TCR": ("heater_tcr_per_K",),
              "leads": ("heater_lead_resistance_ohm",), "sensor footprint": ("sensor",),
              "substrate": ("substrate_k_W_mK", "substrate_rho_c_J_m3K", "substrate_thickness_m")}
    real = pw.as_built_for_scene
    out = {}
    try:
        for g, names in groups.items():
            ab = dataclasses.replace(AsBuilt(), **{n: getattr(full, n) for n in names})
            pw.as_built_for_scene = lambda scene, ab=ab: ab   # the world of this touch gets exactly ab
            r = row_of(head, g, name, touch(sc, store, tempfile.mkdtemp(prefix="asbuilt-oat-")))
            out[g] = {q: r[f"err_{q}"] for q in ("effusivity_W_s05_m2K", "k_W_mK", "alpha_m2_s")}
            e = r["err_effusivity_W_s05_m2K"]
            print(f"{head} draw {seed} {name}: {g:20s} e {_f(None if e is None else 100 * e)} %", flush=True)
    finally:
        pw.as_built_for_scene = real
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--probes", type=int, default=8, help="drawn probes per head (default 8)")
    ap.add_argument("--bounds", action="store_true", help="also measure the world's remaining approximations")
    ap.add_argument("--one-at-a-time", nargs=3, metavar=("HEAD", "SEED", "SOLID"),
                    help="only print which of a drawn probe's deviations moves its answer (writes nothing)")
    args = ap.parse_args()
    if args.one_at_a_time:
        head, seed, name = args.one_at_a_time
        one_at_a_time(head, int(seed), name)
        return
    if args.probes < 1:
        sys.exit("--probes must be >= 1")
    res = run(args.probes)
    if args.bounds:
        res["bounds"] = bounds()
    print(table(res["summary"]))
    print(f"wall {res['wall_s']:.0f} s, load {res['load_avg_1min']:.1f}")
    print("wrote", write_json("asbuilt", res))


if __name__ == "__main__":
    main()
