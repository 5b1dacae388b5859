"""Tactile recognition of everyday objects: accuracy, ceiling, open set, calibration.

A robot's object set of 14 everyday objects, none of them a library entry
(checked by name), and 4 more objects that are *not* in the set (held out:
the right answer for them is "unknown"). Each object is touched as
``--touches`` specimens drawn from a 5 % spread (ln e and ln α independent),
every specimen on both boards (edge.measure.instrument.INSTRUMENTS) at contact
times 0.5 / 1 / 1.5 / 2 s, with a per-touch flux-sensor calibration error
(2 %, the estimator's budget), through host/evaluate.py's TouchSimulator
(exact probe model, 20 mm insulated sample, q_v = 7.7e7 W/m^3) and the
default estimator (e only). Per board, the set's temperature and z_crit are
fitted (host/recognition.calibrate) on separately seeded touches of the set's
own objects; the test touches are then recognised by the uncalibrated
(T = 1, z_crit = 2.5) and the calibrated set.

Reported per board and contact time: object and class accuracy of the
touches that gave an estimate, the Bayes-optimal ceiling on e alone (at the
median u(e) of those touches), in-set acceptance, the "unknown" rate of
held-out objects, refusals; per board the reliability table (binned
confidence vs accuracy, in-set touches, all contact times); the confusion
matrix at 2 s on the precision board (ads122c04); and, for comparison with
the issue, what the library naming does with these objects (none is in it).

Run:  python bench/tactile_bench.py [--touches 20] [--cal-touches 10]
Writes bench/results/tactile.json.

Property sources (values near 300 K; handbook ranges are wide, the values
below are one representative point, not a measurement of a real specimen):
  [ISO]  EN ISO 10456:2007, Building materials -- hygrothermal properties,
         Table 3 (design values: λ, ρ, c_p) -- timber 500 / 700 kg/m³,
         fibreboard incl. MDF 600 kg/m³, natural rubber, polypropylene,
         soda-lime glass, ceramic/porcelain, crystalline rock (granite),
         stainless steel, aluminium alloys, copper, cast iron, silicone,
         gypsum plasterboard 900 kg/m³.
  [ETB]  The Engineering ToolBox, "Thermal conductivity of selected
         materials" / "Specific heat of solids" (flexible polyurethane foam,
         expanded polystyrene, corrugated cardboard, ABS).
  ABS values are the middle of typical datasheet ranges (k 0.14-0.21 W/(m K),
  ρ 1040-1060 kg/m³, c 1300-1500 J/(kg K)).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from _common import write_json
from edge.estimation.objects import UNKNOWN, KnownObject, ObjectSet
from edge.measure.instrument import INSTRUMENTS
from edge.physics.materials import load_materials
from host.recognition import CONTACT_TIMES_S, calibrate, classify_touches, library_estimator, reliability, \
    simulate_touches

SPREAD = 0.05
P = KnownObject.from_properties
#: The robot's object set (name, class, k W/(m K), ρ kg/m³, c J/(kg K), source).
IN_SET = (
    P("pu_foam_cushion", "foam", 0.035, 30, 1400, SPREAD, source="ETB flexible PU foam"),
    P("corrugated_cardboard", "other", 0.065, 150, 1400, SPREAD, source="ETB corrugated board"),
    P("pine_shelf", "wood", 0.13, 500, 1600, SPREAD, source="ISO timber 500 kg/m3"),
    P("natural_rubber_mat", "rubber", 0.13, 910, 1100, SPREAD, source="ISO natural rubber"),
    P("mdf_board", "wood", 0.14, 600, 1700, SPREAD, source="ISO fibreboard incl. MDF 600 kg/m3"),
    P("oak_worktop", "wood", 0.18, 700, 1600, SPREAD, source="ISO timber 700 kg/m3"),
    P("abs_toy_brick", "polymer", 0.17, 1050, 1400, SPREAD, source="ETB / datasheet ranges, ABS"),
    P("polypropylene_box", "polymer", 0.22, 910, 1800, SPREAD, source="ISO polypropylene"),
    P("soda_lime_bottle", "glass", 1.0, 2500, 750, SPREAD, source="ISO soda-lime glass"),
    P("porcelain_mug", "ceramic", 1.3, 2300, 840, SPREAD, source="ISO ceramic/porcelain"),
    P("granite_countertop", "stone", 2.8, 2800, 1000, SPREAD, source="ISO crystalline rock"),
    P("stainless_304_pan", "alloy", 17.0, 7900, 500, SPREAD, source="ISO stainless steel"),
    P("al_6061_laptop_case", "alloy", 160.0, 2800, 880, SPREAD, source="ISO aluminium alloys"),
    P("copper_pipe", "metal", 380.0, 8900, 380, SPREAD, source="ISO copper"),
)
#: Touched but not in the set: the right answer is "unknown".
HELD_OUT = (
    P("eps_foam_cup", "foam", 0.035, 50, 1300, SPREAD, source="ETB expanded polystyrene"),
    P("plasterboard_wall", "other", 0.25, 900, 1000, SPREAD, source="ISO gypsum plasterboard 900 kg/m3"),
    P("silicone_rubber_mat", "rubber", 0.35, 1200, 1000, SPREAD, source="ISO silicone"),
    P("cast_iron_pan", "alloy", 50.0, 7500, 450, SPREAD, source="ISO cast iron"),
)


def evaluate(oset: ObjectSet, touches, recs) -> dict:
    """Accuracy, acceptance, unknown rate and the ceiling for one board and contact time."""
    names = touches.names
    in_set = np.array([names[i] in oset for i in touches.obj])
    answered = touches.ok
    truth = [names[i] for i in touches.obj]
    cls_of = {o.name: o.cls for o in oset.objects}
    a_in = np.flatnonzero(in_set & answered)
    a_out = np.flatnonzero(~in_set & answered)
    pred = [r.object if r else None for r in recs]
    obj_ok = np.array([pred[i] == truth[i] for i in a_in], bool)
    cls_ok = np.array([recs[i].cls == cls_of[truth[i]] for i in a_in], bool)
    accepted = np.array([recs[i].accepted for i in a_in], bool)
    unknown_out = np.array([not recs[i].accepted for i in a_out], bool)
    u_med = float(np.median(touches.u_ln_e[a_in])) if a_in.size else math.nan
    conf = oset.confusion_pairs(u_med) if a_in.size else None
    per_out = {}
    for i in a_out:
        per_out.setdefault(truth[i], []).append(not recs[i].accepted)
    return dict(
        touches_in=int(in_set.sum()), touches_out=int((~in_set).sum()),
        refused_in=int((in_set & ~answered).sum()), refused_out=int((~in_set & ~answered).sum()),
        object_accuracy=float(obj_ok.mean()) if a_in.size else None,
        class_accuracy=float(cls_ok.mean()) if a_in.size else None,
        in_set_acceptance=float(accepted.mean()) if a_in.size else None,
        unknown_rate_held_out=float(unknown_out.mean()) if a_out.size else None,
        unknown_rate_by_object={k: float(np.mean(v)) for k, v in per_out.items()},
        median_u_ln_e=u_med,
        bayes_object=conf.bayes_accuracy if conf else None, bayes_class=conf.bayes_class_accuracy if conf else None,
        confusion_pairs=[[p.a, p.b] for p in conf.pairs] if conf else [],
    )


def in_set_reliability(oset: ObjectSet, touches, recs) -> dict:
    names = touches.names
    idx = [i for i in range(len(recs)) if recs[i] is not None and names[touches.obj[i]] in oset]
    return reliability([recs[i].object_posterior for i in idx], [recs[i].object == names[touches.obj[i]] for i in idx])


def confusion_matrix(oset: ObjectSet, touches, recs) -> dict:
    cols = list(oset.names) + [UNKNOWN, "(refused)"]
    rows = list(touches.names)
    m = np.zeros((len(rows), len(cols)), int)
    for i, r in enumerate(recs):
        m[touches.obj[i], cols.index(r.object if r else "(refused)")] += 1
    return dict(rows=rows, cols=cols, counts=m.tolist())


def library_naming(touches) -> dict:
    """What the library (old naming and the new default set) says about objects that are not in it."""
    est = library_estimator()
    lib_set = ObjectSet.from_library()
    ok = np.flatnonzero(touches.ok)
    old_conf, new_unknown, new_conf = [], [], []
    for i in ok:
        e, u = float(touches.e[i]), float(touches.u_ln_e[i])
        old_conf.append(est.library.identify(e, u)[0][1])
        r = lib_set.classify(e, u)
        new_unknown.append(not r.accepted)
        new_conf.append(r.object_posterior if r.accepted else 0.0)
    old_conf, new_conf = np.array(old_conf), np.array(new_conf)
    return dict(touches=int(ok.size), old_named_at_0_9=float(np.mean(old_conf >= 0.9)),
                old_median_confidence=float(np.median(old_conf)), new_unknown_rate=float(np.mean(new_unknown)),
                new_named_at_0_9=float(np.mean(new_conf >= 0.9)), new_median_confidence_when_named=float(
                    np.median(new_conf[new_conf > 0])) if np.any(new_conf > 0) else None)


def pct(x):
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x * 100:.0f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--touches", type=int, default=20, help="specimens per object (test), each on every board/time")
    ap.add_argument("--cal-touches", type=int, default=10, help="specimens per object for the calibration fit")
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args()

    lib_names = set(load_materials().names)
    everyday = IN_SET + HELD_OUT
    clash = sorted(o.name for o in everyday if o.name in lib_names)
    assert not clash, f"benchmark objects must not be library entries: {clash}"
    oset = ObjectSet(IN_SET, label="tactile_bench")
    t0 = time.perf_counter()
    test = simulate_touches(everyday, touches=args.touches, seed=args.seed)
    res = dict(objects=[dict(name=o.name, cls=o.cls, e=o.e_W_s05_m2K, source=o.source) for o in IN_SET],
               held_out=[dict(name=o.name, cls=o.cls, e=o.e_W_s05_m2K, source=o.source) for o in HELD_OUT],
               spread_rel=SPREAD, touches_per_object=args.touches, cal_touches_per_object=args.cal_touches,
               contact_times_s=list(CONTACT_TIMES_S), seed=args.seed, boards={})
    L = []
    for bi, inst in enumerate(INSTRUMENTS):
        cal_set, cal_rep = calibrate(oset, inst, touches=args.cal_touches, seed=args.seed + 1000 + bi)
        board = dict(calibration=cal_rep, sets={})
        for label, s in (("uncalibrated", oset), ("calibrated", cal_set)):
            by_ct, pooled_recs, pooled_idx = {}, [], []
            for ct in CONTACT_TIMES_S:
                m = (test.instrument == inst) & (test.contact_time_s == ct)
                sub = test.select(m)
                recs = classify_touches(s, sub)
                by_ct[str(ct)] = evaluate(s, sub, recs)
                if ct == 2.0 and inst == "ads122c04" and label == "calibrated":
                    res["confusion_matrix_ads122c04_2s"] = confusion_matrix(s, sub, recs)
                pooled_recs += recs
                pooled_idx.append(np.flatnonzero(m))
            sub = test.select(np.concatenate(pooled_idx))
            board["sets"][label] = dict(temperature=s.temperature, z_crit=s.z_crit, by_contact_time=by_ct,
                                        reliability=in_set_reliability(s, sub, pooled_recs))
        res["boards"][inst] = board
    lib_touches = test.select(test.instrument == "ads122c04")
    res["library_naming_ads122c04"] = {str(ct): library_naming(lib_touches.select(lib_touches.contact_time_s == ct))
                                       for ct in (0.5, 2.0)}
    res["bench_seconds"] = time.perf_counter() - t0

    # -- tables ---------------------------------------------------------------------------
    L.append(f"Tactile recognition: {len(IN_SET)} everyday objects in the set + {len(HELD_OUT)} held out "
             f"(answer should be 'unknown'); {args.touches} specimens each (5 % spread), per board and contact time.")
    L.append("")
    for inst, board in res["boards"].items():
        c = board["calibration"]
        L.append(f"{inst}: fitted on {c['touches']} held-out in-set touches: temperature {c['temperature']:.3g}, "
                 f"z_crit {c['z_crit']:.3g} (closed-set ECE {c['reliability_before']['ece'] * 100:.1f} % -> "
                 f"{c['reliability_after']['ece'] * 100:.1f} %)")
        L.append("")
        L.append("| set | contact | object acc | Bayes ceiling | class acc | class ceiling | in-set accepted | "
                 "held-out 'unknown' | refused | median u(e) |")
        L.append("|---|---|---|---|---|---|---|---|---|---|")
        for label, sr in board["sets"].items():
            for ct, r in sr["by_contact_time"].items():
                L.append(f"| {label} | {float(ct):g} s | {pct(r['object_accuracy'])} % | {pct(r['bayes_object'])} % | "
                         f"{pct(r['class_accuracy'])} % | {pct(r['bayes_class'])} % | "
                         f"{pct(r['in_set_acceptance'])} % | "
                         f"{pct(r['unknown_rate_held_out'])} % | {r['refused_in'] + r['refused_out']}/"
                         f"{r['touches_in'] + r['touches_out']} | {r['median_u_ln_e'] * 100:.1f} % |")
        L.append("")
        L.append(f"Reliability, {inst}, in-set touches, all contact times (confidence = posterior of the answer):")
        L.append("")
        L.append("| bin | uncalibrated n | conf | acc | calibrated n | conf | acc |")
        L.append("|---|---|---|---|---|---|---|")
        ru, rc = board["sets"]["uncalibrated"]["reliability"], board["sets"]["calibrated"]["reliability"]
        for a, b in zip(ru["rows"], rc["rows"]):
            L.append(f"| {a['lo']:.2f}-{a['hi']:.2f} | {a['n']} | {pct(a['confidence'])} | {pct(a['accuracy'])} | "
                     f"{b['n']} | {pct(b['confidence'])} | {pct(b['accuracy'])} |")
        L.append(f"| ECE | | {ru['ece'] * 100:.1f} % | | | {rc['ece'] * 100:.1f} % | |")
        L.append("")
    cm = res["confusion_matrix_ads122c04_2s"]
    L.append("Confusion matrix, ads122c04, 2 s, calibrated (rows: touched; columns: answer, numbered as the rows; "
             "u = unknown, r = refused):")
    L.append("")
    short = [str(i + 1) for i in range(len(cm["cols"]) - 2)] + ["u", "r"]
    L.append("| touched | " + " | ".join(short) + " |")
    L.append("|---|" + "---|" * len(short))
    for i, (name, row) in enumerate(zip(cm["rows"], cm["counts"])):
        tag = f"{i + 1} {name}" if i < len(IN_SET) else f"(held out) {name}"
        L.append(f"| {tag} | " + " | ".join(str(x) if x else "." for x in row) + " |")
    L.append("")
    for ct, r in res["library_naming_ads122c04"].items():
        L.append(f"Library naming of these (non-library) objects, ads122c04, {float(ct):g} s, {r['touches']} touches: "
                 f"old Library.identify names {r['old_named_at_0_9'] * 100:.0f} % at confidence >= 0.9 "
                 f"(median {r['old_median_confidence']:.2f}); default ObjectSet says 'unknown' for "
                 f"{r['new_unknown_rate'] * 100:.0f} %, names {r['new_named_at_0_9'] * 100:.0f} % at >= 0.9.")
    L.append("")
    L.append(f"({res['bench_seconds']:.0f} s)")
    print("\n".join(L))
    print(f"\nwrote {write_json('tactile', res)}")


if __name__ == "__main__":
    main()
