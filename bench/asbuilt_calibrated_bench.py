"""What the device answers CALIBRATED on drawn as-built probes, hand touches, short and long windows (issue #34).

For each probe head of :data:`HEADS` (this bench: the paper probe on the
precision board; the table is head-generic) ``--probes`` probes are drawn by
:func:`firmware_sim.asbuilt.draw_as_built` (scene key ``[as_built] draw_seed``:
every unknown of the tolerance table, the device told only the nominal probe).
Each probe is then

1. calibrated by the walk-through's references (``edge.calibration.fit.DEFAULT_REFERENCES``),
   ``--touches`` armed hand touches each (R_c uniform in [0, 1e-4] m^2K/W, object
   minus probe uniform in [-3, 3] K, heater on ``settle`` = 1 s after the
   detected contact, :data:`host.calibration.HEAT_s` of heating), through the
   code ``thermotouch calibrate`` runs: the device's own sequence on the
   emulated board records each touch, :func:`host.calibration.checked_calibration`
   fits (:func:`edge.calibration.fit.fit_calibration`), checks by
   leave-one-reference-out and re-measures the references through
   :func:`edge.estimation.seam.estimate_touch` (:func:`host.calibration.seam_remeasure`).
   The probe's reference blocks are real specimens: each differs from the
   library's value by a seeded draw of its stated uncertainty.  A refused
   calibration is counted, with its one-line reason, and the probe is then
   forced (``--force``: flagged, with its model-form floor) so its touches
   still show what the device would answer;
2. touched by hand on ``--solids`` library solids from foam to copper that are
   not references (``bench/_objects.SOLIDS``): R_c, object temperature as above,
   contact 0.5-3 s before heating (armed: heater on that long after the
   detected contact), 2 s of heating.  Each touch is answered through
   ``estimate_touch`` with the calibration at 0.5, 1 and 2 s of heating (the
   record cut at that instant: what a touch that had stopped there recorded).

Reported per head and window: e median |error| and 90th percentile where
R_c <= 3e-5, the 95 % coverage (|error| <= 1.96 u) over all touches, per
solid class (median |error| against the median attainable u of
``thermotouch design``: :func:`edge.estimation.design.attainable` at the
touch's window, power and sample interval with R_c and the object's
temperature as nuisance parameters), the calibrations refused and why, and
each probe's references re-measured after calibration (rel. error and z).

The ``--merge`` summary also tabulates what the calibrated chain's stated u(e) is made of at 1 and 2 s
(:func:`decomposition_table`): the fit's part (and within it the white-noise part, with the nuisances
T_obj0 and R_c fitted and known), the calibration's covariance and model-form floor, the contact
instant, the lateral part, against the design's bound with and without the nuisances and with the
calibration's parts added; and the median |error| beside the median |error| less each probe's median
(what one probe's calibration puts on all its touches removed: the calibration's share of the error).

``--attribute`` (ISSUE #34 item 1): on the drawn probes of ``--seeds`` (default 2 and 6) the same hand
touches of :data:`ATTRIBUTE_SOLIDS` are made again with one thing switched off at a time
(:data:`ATTRIBUTE_VARIANTS`: R_c = 0, the object near the probe's temperature, contact at heater-on,
the walk-through's calibration replaced by the probe's true as-built chain, the nominal probe, the
touch sampled at 10 Hz (the default before 50 Hz) or at 200 Hz instead of the configured 50) and the
median |error| per class and window is tabulated (bench/results/asbuilt_calibrated_attribution.json;
``--seeds 2 --tag a`` and ``--seeds 6 --tag b`` in parallel, then ``--attribute --merge a b``).

Run:  python bench/asbuilt_calibrated_bench.py [--probes 8] [--solids 20] [--touches 3] [--update-readme]
Writes bench/results/asbuilt_calibrated.json (and with --update-readme the block
``asbuilt-calibrated-bench`` in docs/results.md).  Small sizes while developing:
``--probes 2 --solids 6``.
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

from _asbuilt_touches import sensor_noise
from _common import write_block, write_json
from _objects import SOLIDS
from asbuilt_bench import scene_for, solid

import numpy as np  # noqa: E402

#: Per head: the base scene (board, heater), the walk-through's references, the reference touches'
#: heating, the windows answered and the hand touch's heating.  Another helper adds the small head.
HEADS = {
    "paper": {"references": None, "heat_s": 2.0, "windows_s": (0.5, 1.0, 2.0)},
}
RC_SPLIT = 3e-5
RC_MAX = 1e-4
OFFSET_K = 3.0
LEAD_S = (0.5, 3.0)
SPECIMEN_SEED = 7000
TOUCH_SEED = 20261127


def _hand(rng: np.random.Generator) -> dict:
    return {"R_c": float(rng.uniform(0.0, RC_MAX)), "offset_K": float(rng.uniform(-OFFSET_K, OFFSET_K)),
            "lead_s": float(rng.uniform(*LEAD_S))}


def hand_scene(head: str, obj, draw_seed: int, seed: int, *, R_c: float, offset_K: float, lead_s: float,
               heat_s: float, label: str):
    """The drawn probe's scene touching ``obj`` (a Solid) by hand: in air 1 s, then contact, armed."""
    from firmware_sim.scene.model import ObjectSpec

    sc = scene_for(head, "pmma", draw_seed, seed)
    touch = dataclasses.replace(sc.touch, start_s=1.0, length_s=lead_s + heat_s + 1.0, contact_lead_s=lead_s,
                                contact_resistance_m2K_W=R_c, object_offset_K=offset_K, press_trigger=False)
    return dataclasses.replace(sc, touch=touch, contact_resistance_m2K_W=R_c,
                               object=ObjectSpec(solid=obj, back="insulated", thickness_m=0.1, label=label))


def armed_touch(scene, store, workdir: str, *, heat_s: float, settle_s: float, arm_s: float = 10.0,
                rate_Hz: float | None = None):
    """One armed touch through the device's sequence and estimate path (sequence_rig with MEASURE's arm).

    ``rate_Hz``: another sample rate than the configuration's (the attribution's finely sampled touch).
    """
    from firmware_sim.rigs.sequence_rig import sequence_run

    m = {"contact_time_s": heat_s} | ({} if rate_Hz is None else {"sample_rate_Hz": rate_Hz})
    out, _, _ = sequence_run(scene, store, workdir, {"measurement": m}, arm_s=arm_s, settle_s=settle_s)
    return out


def cut(record, window_s: float):
    """The record as a touch that stopped heating at ``window_s`` would have it (samples up to then)."""
    keep = record.t_s <= window_s + 1e-9
    sub = {k: (None if getattr(record, k) is None else getattr(record, k)[keep]) for k in ("T_dt_s", "q_dt_s")}
    return dataclasses.replace(record, t_s=record.t_s[keep], T_C=record.T_C[keep], q_W_m2=record.q_W_m2[keep],
                               heater_on_s=min(record.heater_on_s, window_s), **sub)


def calibrate_probe(head: str, draw_seed: int, n_touches: int, store, workdir: str, rng) -> dict:
    """The walk-through on one drawn probe: reference touches, fit, self-check (forced when refused)."""
    from edge.calibration.fit import DEFAULT_REFERENCES, OTHER_REFERENCE_U_REL, REFERENCE_U_REL, ReferenceTouch
    from edge.calibration.fit import fit_calibration
    from edge.calibration.model import CalibrationError
    from edge.estimation.chain_estimate import uniform_record
    from edge.physics.materials import load_materials
    from host.calibration import HEAT_s, CalibrationRefused, checked_calibration, seam_remeasure
    from host.cli.common import seam_context

    lib = load_materials()
    refs = HEADS[head]["references"] or DEFAULT_REFERENCES
    srng = np.random.default_rng(SPECIMEN_SEED + draw_seed)
    touches, records, names, conds = [], [], [], []
    for name in refs:
        s0 = lib.get(name).solid
        f = 1.0 + REFERENCE_U_REL.get(name, OTHER_REFERENCE_U_REL) * float(srng.standard_normal())
        specimen = dataclasses.replace(s0, k_W_mK=s0.k_W_mK * f, rho_kg_m3=s0.rho_kg_m3 * f)   # e x f, alpha kept
        for j in range(n_touches):
            h = _hand(rng)
            h["lead_s"] = 1.0   # the walk-through's --settle
            sc = hand_scene(head, specimen, draw_seed, 9000 + 97 * draw_seed + 11 * len(touches), R_c=h["R_c"],
                            offset_K=h["offset_K"], lead_s=h["lead_s"], heat_s=HEAT_s, label=name)
            out = armed_touch(sc, store, workdir, heat_s=HEAT_s, settle_s=h["lead_s"])
            rec = out.touch
            if rec is None or str(out.status) != "ok":
                conds.append({**h, "name": name, "status": str(out.status)})
                continue
            t, T, q = uniform_record(rec.t_s, rec.T_C, rec.q_W_m2)
            touches.append(ReferenceTouch(name, s0.effusivity_W_s05_m2K, t, T, q))
            records.append(rec)
            names.append(name)
            conds.append({**h, "name": name, "specimen_e_rel": f - 1.0, "status": "ok"})
    e_refs = [lib.get(n).solid.effusivity_W_s05_m2K for n in names]
    u_refs = [REFERENCE_U_REL.get(n, OTHER_REFERENCE_U_REL) for n in names]
    ctx = seam_context(None, method=records[0].method) if records else None
    remeasure = seam_remeasure(records, [ctx] * len(records))

    def fit(tt, k):
        return fit_calibration(tt, probe=head, min_references=k)
    out = {"touches": conds, "refused": None, "error": None, "cal": None, "check": None}
    try:
        cal, check = checked_calibration(fit, touches, names, e_refs, u_refs, remeasure, force=False)
    except CalibrationRefused as exc:
        out["refused"] = str(exc)
        try:
            cal, check = checked_calibration(fit, touches, names, e_refs, u_refs, remeasure, force=True)
        except (CalibrationError, ValueError) as exc2:
            out["error"] = str(exc2)
            return out
    except (CalibrationError, ValueError) as exc:
        out["refused"] = out["error"] = str(exc)
        return out
    out["cal"], out["check"] = cal, check
    # The references re-measured after calibration, per touch: rel. error against the library and z.
    remeasured = []
    for j, n in enumerate(names):
        got = remeasure(cal, j)
        if got is None:
            remeasured.append({"name": n, "rel": None, "z": None})
            continue
        e, u = got
        z = math.log(e / e_refs[j]) / math.hypot(u / e, u_refs[j])
        remeasured.append({"name": n, "rel": e / e_refs[j] - 1.0, "z": z})
    out["remeasured"] = remeasured
    return out

#: --attribute: what each simplification of the hand touch / probe does to the answer (ISSUE #34 item 1).
ATTRIBUTE_SOLIDS = ("cork_board", "balsa", "hdpe", "epdm", "soda_lime_plate_glass", "aluminium", "copper")
#: Variant -> (hand-touch overrides, probe drawn?, calibration: "walk" the walk-through's, "true" the as-built truth);
#: a "rate_Hz" override samples the touch at that rate instead of the configured one (50 Hz: the
#: precision board's default; 10 Hz was the default before it).
#: An object at the probe's own temperature is never detected by the armed touch (no contact step): 0.3 K off.
ATTRIBUTE_VARIANTS = {
    "as bench": ({}, True, "walk"),
    "R_c = 0": ({"R_c": 0.0}, True, "walk"),
    "object 0.3 K off": ({"offset_K": 0.3}, True, "walk"),
    "contact at heater-on": ({"lead_s": 0.0}, True, "walk"),
    "true as-built calibration": ({}, True, "true"),
    "nominal probe, datasheet chain": ({}, False, "true"),
    "true cal., R_c = 0, object 0.3 K off": ({"R_c": 0.0, "offset_K": 0.3}, True, "true"),
    "true cal., sampled at 10 Hz": ({"rate_Hz": 10.0}, True, "true"),
    "true cal., sampled at 200 Hz": ({"rate_Hz": 200.0}, True, "true"),
}


def true_calibration(head: str, draw_seed: int | None, like, scene=None):
    """``like`` (a fitted calibration) with the chain the probe was really built with and no floor.

    The thermopile reads its square's mean sensitivity (the map's gradients are linear about its centre:
    mean 1), so the flux scale is nominal / true sensitivity.
    """
    from edge.estimation.sensor_chain import SensorChainCalibration
    from firmware_sim.asbuilt import Nominal, draw_as_built

    nom = Nominal.of(head, scene)
    base = SensorChainCalibration()
    rho_c = base.k_W_mK / base.alpha_m2_s
    if draw_seed is None:
        return dataclasses.replace(like, chain=dataclasses.replace(base, tc_tau_s=nom.thermocouple_time_constant_s),
                                   u_rel_floor=0.0)
    ab = draw_as_built(head, draw_seed, scene)
    chain = SensorChainCalibration(sensing_thickness_m=ab.sensing_thickness_m, k_W_mK=ab.sensing_k_W_mK,
                                   alpha_m2_s=ab.sensing_k_W_mK / rho_c, tc_tau_s=ab.thermocouple_time_constant_s,
                                   flux_scale=nom.flux_sensitivity_V_per_W_m2 / ab.flux_sensitivity_V_per_W_m2)
    return dataclasses.replace(like, chain=chain, u_rel_floor=0.0)


def attribute(seeds: list[int], n_touches: int, solids=ATTRIBUTE_SOLIDS, windows=(0.5, 1.0, 2.0)) -> dict:
    """Switch off one thing at a time on the same hand touches: which one makes the answer right."""
    from thermotouch_models import DEFAULT_BUNDLE

    from edge.estimation.estimate import pipeline_golden_check
    from edge.estimation.seam import estimate_touch
    from edge.model.bundle import load_bundle
    from edge.physics.materials import load_materials
    from firmware_sim.rigs.sequence_rig import OneBundleStore
    from host.cli.common import seam_context

    head, spec = "paper", HEADS["paper"]
    lib = load_materials()
    store = OneBundleStore(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))
    workdir = tempfile.mkdtemp(prefix="asbuilt-cal-attr-")
    rows = []
    t0 = time.perf_counter()
    for draw_seed in seeds:
        rng = np.random.default_rng([TOUCH_SEED, draw_seed])
        c = calibrate_probe(head, draw_seed, n_touches, store, workdir, rng)
        walk = c["cal"]
        print(f"draw {draw_seed}: calibrated ({time.perf_counter() - t0:.0f} s)", flush=True)
        for si, name in enumerate(solids):
            obj = lib.get(name)
            h0 = _hand(rng)
            for vname, (over, drawn, which) in ATTRIBUTE_VARIANTS.items():
                h = {**h0, **{k: v for k, v in over.items() if k != "rate_Hz"}}
                ds = draw_seed if drawn else None
                sc = hand_scene(head, obj.solid, draw_seed, 5000 + 131 * draw_seed + si, heat_s=spec["heat_s"],
                                label=name, **h)
                if not drawn:
                    sc = dataclasses.replace(sc, as_built=None)
                settle = max(h["lead_s"], 0.0)
                out = armed_touch(sc, store, workdir, heat_s=spec["heat_s"], settle_s=settle, rate_Hz=over.get("rate_Hz"))
                cal = walk if which == "walk" else true_calibration(head, ds, walk, sc)
                row = {"probe": draw_seed, "solid": name, "class": obj.cls, "variant": vname, **h,
                       "status": str(out.status)}
                rec = out.touch
                for w in windows:
                    if rec is None:
                        row[f"err_{w:g}"] = None
                        continue
                    ctx = seam_context(None, method=rec.method, calibration=cal)
                    try:
                        d = estimate_touch(cut(rec, w), ctx).to_dict()
                    except ValueError:
                        d = {}
                    e, u = d.get("effusivity_W_s05_m2K"), d.get("effusivity_W_s05_m2K_u")
                    row[f"err_{w:g}"] = None if e is None else e / obj.solid.effusivity_W_s05_m2K - 1.0
                    row[f"u_{w:g}"] = None if e is None or u is None else u / e
                rows.append(row)
                print(f"  {draw_seed} {name:22s} {vname:36s} " + " ".join(
                    f"{w:g}s {_pct(row.get(f'err_{w:g}'))} (u {_pct(row.get(f'u_{w:g}'), '.1f')})" for w in windows),
                    flush=True)
    return {"seeds": seeds, "solids": list(solids), "windows_s": list(windows), "rows": rows,
            "wall_s": time.perf_counter() - t0}


def attribution_table(res: dict) -> str:
    """Median |error| per variant and solid class, per window (the attribution of ISSUE #34 item 1)."""
    rows, windows = res["rows"], res["windows_s"]
    classes = sorted({r["class"] for r in rows}, key=lambda c: min(
        i for i, r in enumerate(rows) if r["class"] == c))
    head = "| variant | window | " + " | ".join(classes) + " |"
    lines = [head, "|" + "---|" * (2 + len(classes))]
    for v in ATTRIBUTE_VARIANTS:
        for w in windows:
            cells = []
            for cls in classes:
                errs = [abs(r[f"err_{w:g}"]) for r in rows if r["variant"] == v and r["class"] == cls
                        and r.get(f"err_{w:g}") is not None]
                cells.append(_pct(statistics.median(errs), ".1f") if errs else "–")
            lines.append(f"| {v} | {w:g} s | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def attainable_u(head: str, obj, window_s: float, power_W: float, dt_s: float, R_c: float, lead_s: float,
                 nuisances: bool = True, *, sigma_T_K: float, sigma_q_W_m2: float) -> float | None:
    """``thermotouch design --hand``'s attainable u(e): R_c (at the touch's) and the object's temperature unknown.

    ``nuisances=False``: both known (the touch-only bound without the hand touch's unknowns).  The
    noise is one sample's of the touch's own scene (:func:`_asbuilt_touches.sensor_noise`).
    """
    from edge.estimation.design import attainable

    d = attainable(obj, window_s, probe=head, power_W=power_W, dt_s=dt_s, fit_contact=nuisances,
                   contact_resistance_m2K_W=R_c, fit_object_temperature=nuisances, contact_lead_s=lead_s,
                   sigma_T_K=sigma_T_K, sigma_q_W_m2=sigma_q_W_m2)
    return d.u_rel_effusivity if math.isfinite(d.u_rel_effusivity) else None


def pick(n: int) -> tuple:
    """``n`` of :data:`SOLIDS` spread from foam to copper (all of them when ``n`` >= 20)."""
    if n >= len(SOLIDS):
        return tuple(SOLIDS)
    return tuple(SOLIDS[int(i)] for i in np.unique(np.round(np.linspace(0, len(SOLIDS) - 1, n))))


def run(n_probes: int, n_solids: int, n_touches: int, seeds: list[int] | None = None) -> dict:
    from thermotouch_models import DEFAULT_BUNDLE

    from edge.calibration.model import identifiability
    from edge.estimation.estimate import pipeline_golden_check
    from edge.estimation.seam import estimate_touch
    from edge.model.bundle import load_bundle
    from edge.physics.materials import load_materials
    from firmware_sim.rigs.sequence_rig import OneBundleStore
    from host.cli.common import seam_context

    lib = load_materials()
    store = OneBundleStore(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check))
    workdir = tempfile.mkdtemp(prefix="asbuilt-cal-bench-")
    rows, probes = [], []
    att_cache: dict = {}
    t0 = time.perf_counter()
    for head, spec in HEADS.items():
        for draw_seed in (seeds or range(1, n_probes + 1)):
            rng = np.random.default_rng([TOUCH_SEED, draw_seed])
            c = calibrate_probe(head, draw_seed, n_touches, store, workdir, rng)
            cal = c.pop("cal")
            check = c.pop("check")
            info = {"head": head, "draw_seed": draw_seed, **c,
                    "calibration": None if cal is None else {
                        "sha256": cal.sha256, "u_rel_floor": cal.u_rel_floor, "forced": cal.forced,
                        "theta": cal.theta.tolist(), "u_theta": cal.u_theta.tolist(),
                        "identifiability": identifiability(cal)},
                    "self_check": None if check is None else check.to_dict()}
            probes.append(info)
            zs = [r["z"] for r in c.get("remeasured", []) if r["z"] is not None]
            print(f"{head} draw {draw_seed}: {'REFUSED ' + c['refused'][:120] if c['refused'] else 'calibrated'}; "
                  f"floor {0 if cal is None else cal.u_rel_floor:.1%}; refs z {', '.join(f'{z:+.1f}' for z in zs)} "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)
            if cal is None:
                continue
            ctx = None
            for si, name in enumerate(pick(n_solids)):
                obj = lib.get(name)
                h = _hand(rng)
                sc = hand_scene(head, obj.solid, draw_seed, 5000 + 131 * draw_seed + si, heat_s=spec["heat_s"],
                                label=name, **h)
                out = armed_touch(sc, store, workdir, heat_s=spec["heat_s"], settle_s=h["lead_s"])
                rec = out.touch
                if rec is None:
                    rows.append({"head": head, "probe": draw_seed, "solid": name, "class": obj.cls, **h,
                                 "status": str(out.status), "window_s": None})
                    continue
                if ctx is None:
                    ctx = seam_context(None, method=rec.method, calibration=cal)
                e_true = obj.solid.effusivity_W_s05_m2K
                noise = dict(zip(("sigma_T_K", "sigma_q_W_m2"), sensor_noise(sc)[:2]))   # this touch's scene
                for w in spec["windows_s"]:
                    try:
                        d = estimate_touch(cut(rec, w), ctx).to_dict()
                    except ValueError as exc:
                        d = {"effusivity_W_s05_m2K": None, "flags": [f"error: {exc}"]}
                    e, u = d.get("effusivity_W_s05_m2K"), d.get("effusivity_W_s05_m2K_u")
                    key = (name, w, h["R_c"], h["lead_s"])
                    if key not in att_cache:
                        att_cache[key] = attainable_u(head, obj.solid, w, rec.power_W, 1.0 / rec.sample_rate_Hz,
                                                      h["R_c"], h["lead_s"], **noise)
                        att_cache[key + ("known",)] = attainable_u(head, obj.solid, w, rec.power_W,
                                                                   1.0 / rec.sample_rate_Hz, h["R_c"], h["lead_s"],
                                                                   nuisances=False, **noise)
                    rows.append({"head": head, "probe": draw_seed, "solid": name, "class": obj.cls, **h,
                                 "status": str(out.status), "window_s": w, "e_true": e_true, "e": e, "u_e": u,
                                 "err": None if e is None else e / e_true - 1.0, "flags": d.get("flags"),
                                 "method": d.get("method"), "calibration_sha256": d.get("calibration_sha256"),
                                 "u_e_parts": d.get("u_e_parts"), "attainable_u_rel": att_cache[key],
                                 "u_e_fit_noise": (d.get("sensor_chain") or {}).get("u_e_fit_noise"),
                                 "u_e_fit_noise_nuisance_known":
                                     (d.get("sensor_chain") or {}).get("u_e_fit_noise_nuisance_known"),
                                 "attainable_u_rel_no_nuisance": att_cache[key + ("known",)]})
                r2 = rows[-1]
                print(f"  {name:26s} Rc {h['R_c']:.1e} off {h['offset_K']:+.1f} lead {h['lead_s']:.1f}: "
                      + " ".join(f"{r['window_s']:g}s {_pct(r.get('err'))}" for r in rows[-len(spec['windows_s']):])
                      + f" flags {r2.get('flags')}", flush=True)
    return {"heads": {h: {k: v for k, v in s.items() if k != "references"} for h, s in HEADS.items()},
            "probes_per_head": n_probes, "solids": list(pick(n_solids)), "touches_per_reference": n_touches,
            "conditions": f"hand touches: R_c U[0, {RC_MAX:g}] m^2K/W, object - probe U[-{OFFSET_K:g}, {OFFSET_K:g}] K, "
                          f"contact U[{LEAD_S[0]:g}, {LEAD_S[1]:g}] s before heating (references: 1 s, the walk-through's "
                          "settle); precision board; objects 0.1 m thick, insulated back",
            "wall_s": time.perf_counter() - t0, "load_avg_1min": os.getloadavg()[0],
            "summary": summarise(rows, probes), "probes": probes, "rows": rows}


def _pct(x, fmt="+.1f") -> str:
    return "–" if x is None else f"{100 * x:{fmt}} %"


def _stats(rs: list[dict]) -> dict:
    ans = [r for r in rs if r.get("e") is not None and r.get("u_e") is not None]
    err = [abs(r["err"]) for r in ans]
    cover = [abs(r["e"] - r["e_true"]) <= 1.96 * r["u_e"] for r in ans]
    att = [r["attainable_u_rel"] for r in rs if r.get("attainable_u_rel") is not None]
    # Answers the calibrated chain made (the rest: the calibrated path refused, flagged, the 1-D method answered).
    chain = [r for r in ans if r.get("method") == "sensor_chain"]
    cover_chain = [abs(r["e"] - r["e_true"]) <= 1.96 * r["u_e"] for r in chain]
    return {"n": len(rs), "answered": len(ans), "through_calibration": len(chain),
            "calibration_refused": sum("calibration_refused" in (r.get("flags") or []) for r in rs),
            "cov95_through_calibration": sum(cover_chain) / len(cover_chain) if cover_chain else None,
            "median_abs_err_through_calibration": statistics.median(abs(r["err"]) for r in chain) if chain else None,
            "median_abs_err": statistics.median(err) if err else None,
            "p90_abs_err": float(np.percentile(err, 90)) if err else None,
            "cov95": sum(cover) / len(cover) if cover else None,
            "median_u_rel": statistics.median(r["u_e"] / r["e"] for r in ans) if ans else None,
            "median_attainable_u_rel": statistics.median(att) if att else None,
            "median_attainable_with_calibration_u_rel": _median(_with_calibration(r) for r in chain),
            "u_parts": _u_parts(chain)}


def _median(xs) -> float | None:
    got = [float(x) for x in xs if x is not None and math.isfinite(x)]
    return statistics.median(got) if got else None


def _with_calibration(r: dict) -> float | None:
    """The touch-only attainable u(e) with the calibration's parts added (its covariance and its model-form
    floor): a touch cannot beat the calibration it is answered through."""
    p, att = r.get("u_e_parts") or {}, r.get("attainable_u_rel")
    if att is None or "calibration" not in p:
        return None
    return math.sqrt(att ** 2 + p["calibration"] ** 2 + p.get("floor", 0.0) ** 2)


#: The stated u(e)'s parts tabulated by :func:`decomposition_table`: key in the row -> its meaning.
U_PARTS = {"error": "median \\|error\\|", "error_within_probe": "\\|error\\| less the probe's median",
           "stated": "stated u(e)", "fit": "fit (as stated)", "noise": "noise alone, nuisances fitted",
           "noise_known": "noise alone, nuisances known", "residual_factor": "fit / noise alone",
           "calibration": "calibration covariance", "floor": "calibration model-form floor",
           "contact": "contact instant", "lateral": "lateral (disk, window)",
           "attainable": "attainable (design, R_c and T_obj unknown)",
           "attainable_known": "attainable, R_c and T_obj known",
           "attainable_with_calibration": "attainable with the calibration's parts"}


def _u_parts(chain: list[dict]) -> dict:
    """Medians over the calibrated chain's answers of the parts of their stated u(e) (relative) and of their errors."""
    def part(r, k):
        p = r.get("u_e_parts") or {}
        if k == "stated":
            return r["u_e"] / r["e"]
        if k == "error":
            return abs(r["err"])
        if k == "error_within_probe":
            x = r.get("err_within_probe")
            return None if x is None else abs(x)
        if k == "noise":
            return r.get("u_e_fit_noise")
        if k == "noise_known":
            return r.get("u_e_fit_noise_nuisance_known")
        if k == "residual_factor":
            n = r.get("u_e_fit_noise")
            return p["fit"] / n if n and "fit" in p else None
        if k == "attainable":
            return r.get("attainable_u_rel")
        if k == "attainable_known":
            return r.get("attainable_u_rel_no_nuisance")
        if k == "attainable_with_calibration":
            return _with_calibration(r)
        return p.get(k)
    return {k: _median(part(r, k) for r in chain) for k in U_PARTS}


def decomposition_table(summary: dict, windows=("1", "2")) -> str:
    """What the calibrated chain's stated u(e) is made of at ``windows`` (s), per class, against the design's bound.

    Medians over the chain's answers; parts are relative standard uncertainties summed in quadrature
    in the stated u (fit, calibration, floor, contact, lateral); "noise alone" is the fit's u on the
    air-measured thermocouple noise without the residual's excess (with T_obj0 and R_c fitted, and
    known), "fit / noise alone" the residual's excess (model error and flux noise the fit absorbs).
    """
    cols = list(U_PARTS)
    lines = ["| head | window | class | " + " | ".join(U_PARTS[c] for c in cols) + " |",
             "|---|---|---|" + "---|" * len(cols)]
    for head, s in summary.items():
        for w in windows:
            ws = s["windows"].get(w)
            if ws is None:
                continue
            for cls, c in [("all", ws["all"])] + list(ws["classes"].items()):
                up = c.get("u_parts") or {}
                cells = [("–" if up.get(k) is None else f"{up[k]:.1f}×") if k == "residual_factor"
                         else _pct(up.get(k), ".2f") for k in cols]
                lines.append(f"| {head} | {w} s | {cls} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _within_probe(rows: list[dict]) -> list[dict]:
    """``rows`` (one window) each with ``err_within_probe``: its ln error less its probe's median over the
    calibrated chain's answers.  What one probe's calibration puts on all its touches is then gone: the
    calibration's share of the error is the difference between the two medians."""
    offset = {}
    for p in {r["probe"] for r in rows}:
        got = [math.log1p(r["err"]) for r in rows if r["probe"] == p and r.get("err") is not None
               and r.get("method") == "sensor_chain"]
        offset[p] = statistics.median(got) if got else None
    return [r | {"err_within_probe": None if r.get("err") is None or offset[r["probe"]] is None
                 else math.log1p(r["err"]) - offset[r["probe"]]} for r in rows]


def summarise(rows: list[dict], probes: list[dict]) -> dict:
    out: dict = {}
    for head, spec in HEADS.items():
        hp = [p for p in probes if p["head"] == head]
        ref_z = [r["z"] for p in hp for r in p.get("remeasured", []) if r["z"] is not None]
        s: dict = {"probes": len(hp), "refused": sum(p["refused"] is not None for p in hp),
                   "refusals": [p["refused"] for p in hp if p["refused"]],
                   "references_within_u_pct": 100 * sum(abs(z) <= 1.96 for z in ref_z) / len(ref_z) if ref_z else None,
                   "references_max_abs_z": max(map(abs, ref_z)) if ref_z else None,
                   "hand_touches_aborted": sum(1 for r in rows if r["head"] == head and r["window_s"] is None),
                   "floors": [None if p["calibration"] is None else p["calibration"]["u_rel_floor"] for p in hp],
                   "windows": {}}
        for w in spec["windows_s"]:
            rw = _within_probe([r for r in rows if r["head"] == head and r["window_s"] == w])
            ws = {"low_Rc": _stats([r for r in rw if r["R_c"] <= RC_SPLIT]), "all": _stats(rw), "classes": {}}
            for cls in sorted({r["class"] for r in rw}):
                ws["classes"][cls] = _stats([r for r in rw if r["class"] == cls])
            s["windows"][f"{w:g}"] = ws
        out[head] = s
    return out


def table(summary: dict) -> str:
    lines = ["| head | window | e median \\|error\\|, R_c ≤ 3e-5 | 90th pct, R_c ≤ 3e-5 | 95 % coverage, all | "
             "coverage, calibrated answers | answered / through calibration / touches | median stated u | "
             "median attainable u |", "|---|---|---|---|---|---|---|---|---|"]
    for head, s in summary.items():
        for w, ws in s["windows"].items():
            lo, al = ws["low_Rc"], ws["all"]
            lines.append(f"| {head} | {w} s | {_pct(lo['median_abs_err'], '.1f')} | {_pct(lo['p90_abs_err'], '.1f')} | "
                         f"{_pct(al['cov95'], '.0f')} | {_pct(al['cov95_through_calibration'], '.0f')} | "
                         f"{al['answered']} / {al['through_calibration']} / {al['n']} | {_pct(al['median_u_rel'], '.1f')} | "
                         f"{_pct(al['median_attainable_u_rel'], '.1f')} |")
    lines += ["", "| head | window | class | touches (calibration refused) | median \\|error\\| | 95 % coverage | "
              "median stated u | median attainable u | error / attainable | attainable with calibration | "
              "error / that |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for head, s in summary.items():
        for w, ws in s["windows"].items():
            for cls, c in ws["classes"].items():
                ratio = (None if c["median_abs_err"] is None or not c["median_attainable_u_rel"]
                         else c["median_abs_err"] / c["median_attainable_u_rel"])
                awc = c.get("median_attainable_with_calibration_u_rel")
                ratio_c = None if c["median_abs_err"] is None or not awc else c["median_abs_err"] / awc
                lines.append(f"| {head} | {w} s | {cls} | {c['n']} ({c['calibration_refused']}) | "
                             f"{_pct(c['median_abs_err'], '.1f')} | "
                             f"{_pct(c['cov95'], '.0f')} | {_pct(c['median_u_rel'], '.1f')} | "
                             f"{_pct(c['median_attainable_u_rel'], '.1f')} | {'–' if ratio is None else f'{ratio:.1f}'} | "
                             f"{_pct(awc, '.1f')} | {'–' if ratio_c is None else f'{ratio_c:.1f}'} |")
    lines += ["", "What the calibrated chain's stated u(e) is made of (medians over its answers; "
              "`decomposition_table`):", "", decomposition_table(summary), ""]
    for head, s in summary.items():
        floors = [f for f in s["floors"] if f is not None]
        lines.append(f"{head}: {s['refused']} of {s['probes']} calibrations refused by their self-check"
                     + (" (" + "; ".join(r.split(': ', 1)[-1][:160] for r in s["refusals"]) + ")" if s["refusals"] else "")
                     + f"; references re-measured after calibration within 1.96 u: "
                       f"{'–' if s['references_within_u_pct'] is None else format(s['references_within_u_pct'], '.0f')} %"
                     + f" (max |z| {'–' if s['references_max_abs_z'] is None else format(s['references_max_abs_z'], '.1f')})"
                     + (f"; model-form floors {min(floors):.1%} … {max(floors):.1%}" if floors else "")
                     + f"; {s['hand_touches_aborted']} hand touches aborted by the device (no contact found: an object "
                       "near the probe's temperature).")
    return "\n".join(lines)


def merge(parts: list[str]) -> dict:
    """One result from the JSON files of runs over disjoint probe seeds (``--part``; each probe is seeded alone)."""
    import json

    from _common import RESULTS

    got = [json.loads((RESULTS / f"asbuilt_calibrated_{p}.json").read_text()) for p in parts]
    out = {k: v for k, v in got[0].items() if k not in ("rows", "probes", "summary", "machine")}
    out["rows"] = [r for g in got for r in g["rows"]]
    out["probes"] = sorted((p for g in got for p in g["probes"]), key=lambda p: (p["head"], p["draw_seed"]))
    out["probes_per_head"] = len({p["draw_seed"] for p in out["probes"]})
    out["wall_s"] = max(g["wall_s"] for g in got)
    out["parts"] = {p: {"wall_s": g["wall_s"], "load_avg_1min": g["load_avg_1min"]} for p, g in zip(parts, got)}
    out["summary"] = summarise(out["rows"], out["probes"])
    return out


def _attribution_block() -> str:
    """The last ``--attribute`` run's table (bench/results/asbuilt_calibrated_attribution.json), if there is one."""
    import json

    from _common import RESULTS

    path = RESULTS / "asbuilt_calibrated_attribution.json"
    if not path.exists():
        return ""
    res = json.loads(path.read_text())
    return ("\n\nAttribution (`python bench/asbuilt_calibrated_bench.py --attribute --seeds "
            + " ".join(map(str, res["seeds"])) + "`; drawn probes " + ", ".join(map(str, res["seeds"]))
            + ", the same hand touches with one thing switched off; median |error| of e):\n\n" + attribution_table(res))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--probes", type=int, default=8, help="drawn probes per head (default 8)")
    ap.add_argument("--solids", type=int, default=len(SOLIDS), help=f"N of the {len(SOLIDS)} solids, spread foam to copper")
    ap.add_argument("--touches", type=int, default=3, help="touches per reference (default 3)")
    ap.add_argument("--update-readme", action="store_true", help="write the block in docs/results.md")
    ap.add_argument("--tag", default="", help="suffix of the results file (a development run beside the shipped one)")
    ap.add_argument("--seeds", type=int, nargs="+", default=None,
                    help="only these drawn probes (a part of a run split over processes; see --merge)")
    ap.add_argument("--merge", nargs="+", default=None, metavar="TAG",
                    help="combine the results of runs with these --tag's (disjoint --seeds) into one")
    ap.add_argument("--attribute", action="store_true",
                    help="the attribution table: one simplification at a time on the same hand touches")
    args = ap.parse_args()
    if args.attribute:
        if args.merge:   # parts over disjoint --seeds: their rows, one table
            import json

            from _common import RESULTS

            got = [json.loads((RESULTS / f"asbuilt_calibrated_attribution_{p}.json").read_text()) for p in args.merge]
            res = {**got[0], "seeds": [s for g in got for s in g["seeds"]], "rows": [r for g in got for r in g["rows"]],
                   "wall_s": max(g["wall_s"] for g in got)}
        else:
            res = attribute(args.seeds or [1, 2], args.touches)
        print(attribution_table(res))
        print("wrote", write_json("asbuilt_calibrated_attribution" + (f"_{args.tag}" if args.tag else ""), res))
        return
    if min(args.probes, args.solids, args.touches) < 1:
        sys.exit("--probes, --solids and --touches must be >= 1")
    if args.merge:
        res = merge(args.merge)
        args.probes = res["probes_per_head"]
        args.solids, args.touches = len(res["solids"]), res["touches_per_reference"]
    else:
        res = run(args.probes, args.solids, args.touches, args.seeds)
    text = table(res["summary"])
    print(text)
    print(f"wall {res['wall_s']:.0f} s, load {res['load_avg_1min']:.1f}")
    print("wrote", write_json("asbuilt_calibrated" + (f"_{args.tag}" if args.tag else ""), res))
    if args.update_readme:
        write_block("asbuilt-calibrated-bench",
                    f"{args.probes} drawn probes per head x {args.solids} solids, {args.touches} touches per reference, "
                    f"{res['wall_s']:.0f} s wall at a load of {res['load_avg_1min']:.1f} "
                    "(`python bench/asbuilt_calibrated_bench.py --update-readme`; "
                    "run here as two processes over seeds 1-4 and 5-8, `--seeds ... --tag ...`, then "
                    "`--merge TAG TAG --update-readme`). "
                    f"{res['conditions']}; attainable u at one sample's noise of the touch's own scene "
                    "(`_asbuilt_touches.sensor_noise`).\n\n" + text + _attribution_block())


if __name__ == "__main__":
    main()
