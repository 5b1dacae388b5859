"""Sequential decision: how long must a touch heat before the answer is decided, at what accuracy?

The robot's 14-object set (bench/_objects.py, shared with bench/tactile_bench.py; 5 % specimen spread),
each object touched as ``--touches`` specimens (ln e and ln α drawn with the
spread, host/recognition's specimen model), on the precision board
(ads122c04 instrument model: 90 Hz, 24-bit), q_v = 7.7e7 W/m^3, 20-mm
insulated samples, a 2 % flux-calibration error per touch. Each touch is
answered two ways on the same record:

* **fixed**: heat 1.5 s, then the full default estimate and
  ``ObjectSet.classify`` (what a plain MEASURE with a 1.5-s contact gives);
* **until-decided**: the device's :class:`edge.estimation.running.SequentialDecision`
  fed sample by sample (threshold ``--threshold``, default the device's
  0.95, after ``decide_min_s`` = 0.3 s); the heating stops at the decision,
  its answer is the decided object; a touch not decided by 1.5 s falls back
  to the fixed answer at 1.5 s (the full estimate at the end).

Reported: object accuracy of both, the median / 90th-percentile / mean
decision time, the share decided early, and accuracy among the decided.

Run:  python bench/decision_bench.py [--touches 10] [--threshold 0.95]
Writes bench/results/decision.json.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from _common import write_block, write_json
from edge.recognition import ObjectSet
from edge.estimation.running import SequentialDecision
from edge.measure.instrument import INSTRUMENTS
from host.evaluate import TouchSimulator
from host.recognition import _specimen, _specimens, library_estimator
from _objects import IN_SET

FIXED_S = 1.5
Q_V = 7.7e7
INSTRUMENT = "ads122c04"


def run(touches: int, threshold: float, min_s: float, seed: int, objects=IN_SET, oset: ObjectSet | None = None,
        instrument: str = INSTRUMENT) -> dict:
    """Fixed 1.5-s against until-decided answers for ``objects`` (default the tactile set), named among ``oset``.

    ``oset`` defaults to the objects as an uncalibrated set; the tactile
    bench passes its calibrated set (and a subset without e-overlaps), and
    runs both boards (``instrument``).
    """
    rng = np.random.default_rng(seed)
    oset = ObjectSet(objects, label="tactile_bench IN_SET") if oset is None else oset
    est = library_estimator()
    lsb = INSTRUMENTS[instrument].T_lsb_K
    rows = []
    for obj in objects:
        for _ in range(touches):
            solid = _specimen(obj, rng, est)
            t = TouchSimulator(solid, duration_s=FIXED_S).touch(Q_V, instrument, rng)
            q = np.interp(t.tT, t.tq, t.q) * (1.0 + 0.02 * rng.standard_normal())
            try:
                r = est.estimate(t.tT, t.T, q, T_resolution_K=lsb)
                fixed = oset.classify(r.effusivity_W_s05_m2K,
                                      r.effusivity_W_s05_m2K_u / r.effusivity_W_s05_m2K).object \
                    if r.effusivity_W_s05_m2K else None
            except ValueError:  # refused (the reference board on metals): no answer, counted wrong
                fixed = None
            d = SequentialDecision(oset, threshold, min_s, T_resolution_K=lsb)
            for a, b, c in zip(t.tT, t.T, q):
                d.update(a, b, c)
                if d.decided is not None:
                    break
            if d.decided is not None:
                seq_answer, seq_t, early = d.decided.object, d.decided.elapsed_s, True
            else:
                seq_answer, seq_t, early = fixed, FIXED_S, False
            rows.append(dict(object=obj.name, fixed=fixed, seq=seq_answer, t=seq_t, early=early))
    truth = np.array([r["object"] for r in rows])
    fixed_ok = np.array([r["fixed"] == r["object"] for r in rows])
    seq_ok = np.array([r["seq"] == r["object"] for r in rows])
    times = np.array([r["t"] for r in rows])
    early = np.array([r["early"] for r in rows])
    per_object = {}
    for name in dict.fromkeys(truth):
        m = truth == name
        per_object[name] = dict(median_decision_s=float(np.median(times[m])), fixed_accuracy=float(fixed_ok[m].mean()),
                                until_decided_accuracy=float(seq_ok[m].mean()), decided_early=float(early[m].mean()))
    return dict(
        objects=len(objects), touches_per_object=touches, n=len(rows), instrument=instrument, q_v_W_m3=Q_V,
        spread_rel=0.05, threshold=threshold, decide_min_s=min_s, fixed_contact_s=FIXED_S,
        fixed_accuracy=float(fixed_ok.mean()), until_decided_accuracy=float(seq_ok.mean()),
        median_decision_s=float(np.median(times)), p90_decision_s=float(np.percentile(times, 90)),
        mean_decision_s=float(times.mean()), decided_early=float(early.mean()),
        accuracy_of_decided=float(seq_ok[early].mean()) if early.any() else None,
        heating_saved=float(1.0 - times.mean() / FIXED_S), per_object=per_object,
    )


def run_faithful(touches: int, threshold: float, min_s: float, seed: int, objects=IN_SET, probe: int = 0) -> dict:
    """Until-decided on the faithful (r, z) world: the raw thick-body decision against the calibrated chain's.

    One as-built probe (``bench/_objects.PROBES[probe]``: sensitivity, sensing layer and bead
    lag off the datasheet, never told to the device) is calibrated on the calibration bench's six
    reference touches (library values), then touches ``touches`` specimens of every object: contact
    1 s before heater-on, R_c drawn in [0, 3e-5] m^2K/W, object -2..+2 K off the probe, 1.5 s of
    heating, precision board.  Each record is fed sample by sample to
    :class:`edge.estimation.running.SequentialDecision` (raw reading, as an uncalibrated device) and
    :class:`edge.estimation.running.ChainDecision` (the calibration, as a calibrated device);
    a touch not decided by 1.5 s takes the fixed answer of its own kind (the default estimate of the
    whole record, or the chain's).
    """
    from _objects import PROBES, REFERENCES, as_built
    from _recognition import bayes_ceiling

    from edge.calibration.fit import ReferenceTouch, fit_calibration
    from edge.estimation.running import ChainDecision
    from edge.estimation.result import BLOCKERS as CHAIN_BLOCKERS
    from edge.estimation.chain_estimate import estimate_from_contact
    from edge.physics.materials import load_materials
    from firmware_sim.rigs.contact_record import ContactTouch, record_touch
    from host.recognition import CONTACT_TIMES_S

    lib = load_materials()
    ab = as_built(PROBES[probe])
    refs = []
    for j, (name, rc, off) in enumerate(REFERENCES):
        r = record_touch(ContactTouch(lib.get(name).solid, rc, off, lead_s=1.0, heat_s=FIXED_S), as_built=ab,
                         seed=100 + j)
        refs.append(ReferenceTouch(name, lib.get(name).solid.effusivity_W_s05_m2K, r["t_s"], r["T_C"], r["q_W_m2"]))
    cal = fit_calibration(refs, created_utc="bench")
    rng = np.random.default_rng(seed)
    oset = ObjectSet(objects, label="tactile_bench IN_SET")
    est = library_estimator()
    rows = []
    for _, obj, solid in _specimens(objects, touches, rng, est):
        rc, off = float(rng.uniform(0.0, 3e-5)), float(rng.uniform(-2.0, 2.0))
        r = record_touch(ContactTouch(solid, rc, off, lead_s=1.0, heat_s=max(CONTACT_TIMES_S)), as_built=ab,
                         seed=int(rng.integers(1 << 31)))
        t_all, T_all, q_all = r["t_s"], r["T_C"], r["q_W_m2"]
        # Each contact time is the record's prefix (the heating is a step): the calibrated chain's answer.
        # (as the running decision, no answer where the chain flags that it does not describe the record).
        by_ct = {}
        for ct in CONTACT_TIMES_S:
            m = t_all <= ct + 1e-9
            c = estimate_from_contact(t_all[m], T_all[m], q_all[m], cal)
            rec = None if CHAIN_BLOCKERS & set(c.get("flags") or ()) else oset.classify_estimate(c)
            by_ct[str(ct)] = dict(object=rec.object if rec else None,
                                  u=(c.get("effusivity_W_s05_m2K_u") or 0.0) / c["effusivity_W_s05_m2K"]
                                  if rec else None)
        chain_fixed = by_ct[str(FIXED_S)]["object"]
        keep = t_all <= FIXED_S + 1e-9
        t, T, q = t_all[keep], T_all[keep], q_all[keep]
        base = (t > -0.5) & (t <= 0)
        T0, q0 = float(T[base].mean()), float(q[base].mean())
        heat = t > 0
        try:
            rec = oset.classify_estimate(est.estimate(t[heat], T[heat] - T0, q[heat] - q0).to_dict())
            raw_fixed = rec.object if rec else None
        except ValueError:
            raw_fixed = None
        raw = SequentialDecision(oset, threshold, min_s)
        chain = ChainDecision(oset, threshold, min_s, calibration=cal)
        ts, Ts, qs = [], [], []
        chain.attach_record(ts, Ts, qs, 0.0)
        for a, b, cq in zip(t, T, q):
            ts.append(a), Ts.append(b), qs.append(cq)
            if a > 0:
                if raw.decided is None:
                    raw.update(a, b - T0, cq - q0)
                if chain.decided is None:
                    chain.update(a, b - T0, cq - q0)
        row = dict(object=obj.name, by_contact_time=by_ct)
        for kind, dec, fixed in (("raw", raw, raw_fixed), ("chain", chain, chain_fixed)):
            early = dec.decided is not None
            row[kind] = dict(fixed=fixed, answer=dec.decided.object if early else fixed, early=early,
                             t=dec.decided.elapsed_s if early else FIXED_S)
        rows.append(row)
    out = dict(objects=len(objects), touches_per_object=touches, n=len(rows), threshold=threshold, decide_min_s=min_s,
               fixed_contact_s=FIXED_S, probe=list(PROBES[probe]), calibration_floor=cal.u_rel_floor)
    for kind in ("raw", "chain"):
        ok = np.array([r[kind]["answer"] == r["object"] for r in rows])
        fok = np.array([r[kind]["fixed"] == r["object"] for r in rows])
        early = np.array([r[kind]["early"] for r in rows])
        times = np.array([r[kind]["t"] for r in rows])
        out[kind] = dict(fixed_accuracy=float(fok.mean()), until_decided_accuracy=float(ok.mean()),
                         median_decision_s=float(np.median(times)), decided_early=float(early.mean()),
                         accuracy_of_decided=float(ok[early].mean()) if early.any() else None,
                         wrong_early=int((early & ~ok).sum()))
    # The calibrated chain per contact time against the e-only Bayes ceiling at its own u(e) (each object at
    # the median u of its answered touches), as the tactile bench does on the exact model.
    out["chain_by_contact_time"] = {}
    for ct in CONTACT_TIMES_S:
        ans = [(r["object"], r["by_contact_time"][str(ct)]) for r in rows]
        u_of = {}
        for name, a in ans:
            if a["u"] is not None:
                u_of.setdefault(name, []).append(a["u"])
        n_of = {k: len(v) for k, v in u_of.items()}
        ceiling = bayes_ceiling(oset, {k: float(np.median(v)) for k, v in u_of.items()}, n_of)[0] if u_of else None
        answered = [(name, a) for name, a in ans if a["u"] is not None]
        out["chain_by_contact_time"][str(ct)] = dict(
            accuracy=float(np.mean([a["object"] == name for name, a in answered])) if answered else None,
            ceiling=ceiling, refused=len(ans) - len(answered),
            median_u_ln_e=float(np.median([a["u"] for _, a in answered])) if answered else None)
    return out


SMALL_HEAT_S = 2.0      # the small-heater probe's standard profile
SMALL_RATE_Hz = 50.0    # its precision-board sampling (scene pmma_15V_small)


def run_faithful_small(touches: int, threshold: float, min_s: float, seed: int, objects=IN_SET,
                       fit_contact: bool = False) -> dict:
    """Until-decided on the small-heater probe in the faithful (r, z) world against its fixed 2-s answer.

    Every object's ``touches`` specimens are touched by the small-heater probe as built to its datasheet
    (scene ``glass_15V_small``: 107 mW in the 5-mm heater), contact 1 s before heater-on, R_c drawn in
    [0, 3e-5] m^2K/W, the object at the probe's temperature, 2 s of heating at 50 Hz, precision-board
    noise.  Each record is answered by the device's own estimator (:class:`AxiEstimator` on the record
    resampled as the device does) on the whole profile (fixed) and by
    :class:`edge.estimation.running.EstimatorDecision` fed sample by sample (until decided; a
    touch not decided by 2 s takes the fixed answer).  Objects are named with e and, where the touch
    measured it, alpha.  Also reported: the refits' wall time, and how often the answer determined
    k and alpha (what stopping early gives up).  ``fit_contact``: the estimator fits R_c too.
    """
    from edge.estimation.probe_estimate import AxiEstimator
    from edge.estimation.running import EstimatorDecision
    from edge.estimation.conditioning import resample_uniform
    from firmware_sim.rigs.contact_record import ContactTouch, record_touch
    from firmware_sim.rz.probe_world import geometry_for_probe
    from firmware_sim.scene.files import read_scene

    sc = read_scene("glass_15V_small")
    power_W = sc.heater.supply_voltage_V ** 2 / sc.heater.resistance_ohm
    geo = geometry_for_probe("small-heater")
    axi = AxiEstimator(library_estimator(), "small-heater", fit_contact=fit_contact)
    fit_s: list[float] = []

    def estimate_fn(t, dT, q, power_W, method):   # the device's call (edge.service.estimator.ModelEstimator)
        return axi.estimate(t, dT, q, power_W=power_W)

    def refit(*args):                          # the decision's refits, timed
        w = time.perf_counter()
        d = estimate_fn(*args)
        fit_s.append(time.perf_counter() - w)
        return d
    refit.prepare = axi.prepare

    rng = np.random.default_rng(seed)
    oset = ObjectSet(objects, label="tactile_bench IN_SET")
    est = library_estimator()
    rows = []
    for _, obj, solid in _specimens(objects, touches, rng, est):
        rc = float(rng.uniform(0.0, 3e-5))
        r = record_touch(ContactTouch(solid, rc, 0.0, lead_s=1.0, heat_s=SMALL_HEAT_S), geometry=geo,
                         scene_name="glass_15V_small", dt_s=1.0 / SMALL_RATE_Hz,
                         seed=int(rng.integers(1 << 31)))
        t, T, q = r["t_s"], r["T_C"], r["q_W_m2"]
        base = (t > -0.5) & (t <= 0)
        T0, q0 = float(T[base].mean()), float(q[base].mean())
        g = resample_uniform(t, T, q, T0, q0, SMALL_RATE_Hz, SMALL_HEAT_S)
        fixed_d = estimate_fn(*g, power_W, "default")
        rec = oset.classify_estimate(fixed_d)    # None where the estimate refused (no e)
        fixed = rec.object if rec is not None else None
        dec = EstimatorDecision(oset, threshold, min_s, estimate_fn=refit, rate_Hz=SMALL_RATE_Hz,
                                heat_s=SMALL_HEAT_S, power_W=power_W)
        ts, Ts, qs = [], [], []
        first = int(np.argmax(t > 0))
        ts.extend(t[:first]), Ts.extend(T[:first]), qs.extend(q[:first])
        dec.attach_record(ts, Ts, qs, 0.0, T0_C=T0, q0_W_m2=q0)
        for a, b, c in zip(t[first:], T[first:], q[first:]):
            ts.append(a), Ts.append(b), qs.append(c)
            dec.update(a, b - T0, c - q0)
            if dec.decided is not None:
                break
        early = dec.decided is not None
        if early:   # the result of a touch stopped there: the estimate of the record so far
            g_e = resample_uniform(np.array(ts), np.array(Ts), np.array(qs), T0, q0, SMALL_RATE_Hz,
                                   dec.decided.elapsed_s)
            early_d = estimate_fn(*g_e, power_W, "default")
        rows.append(dict(object=obj.name, fixed=fixed, answer=dec.decided.object if early else fixed,
                         early=early, t=dec.decided.elapsed_s if early else SMALL_HEAT_S,
                         alpha_fixed="alpha" in (fixed_d.get("determined") or ()),
                         alpha_answer="alpha" in ((early_d if early else fixed_d).get("determined") or ())))
    ok = np.array([r["answer"] == r["object"] for r in rows])
    fok = np.array([r["fixed"] == r["object"] for r in rows])
    early = np.array([r["early"] for r in rows])
    times = np.array([r["t"] for r in rows])
    return dict(objects=len(objects), touches_per_object=touches, n=len(rows), threshold=threshold,
                decide_min_s=min_s, fixed_contact_s=SMALL_HEAT_S, power_W=power_W, fit_contact=fit_contact,
                fixed_accuracy=float(fok.mean()), until_decided_accuracy=float(ok.mean()),
                median_decision_s=float(np.median(times)), decided_early=float(early.mean()),
                accuracy_of_decided=float(ok[early].mean()) if early.any() else None,
                wrong_early=int((early & ~ok).sum()),
                alpha_determined_fixed=float(np.mean([r["alpha_fixed"] for r in rows])),
                alpha_determined_until_decided=float(np.mean([r["alpha_answer"] for r in rows])),
                refit_ms=dict(median=float(np.median(fit_s) * 1e3), p95=float(np.percentile(fit_s, 95) * 1e3),
                              max=float(np.max(fit_s) * 1e3), n=len(fit_s)) if fit_s else None,
                refits_per_touch=len(fit_s) / len(rows), rows=rows)


def faithful_small_table(res: dict) -> str:
    """The docs/results.md block of :func:`run_faithful_small`."""
    pct = lambda x: "-" if x is None else f"{x * 100:.0f} %"  # noqa: E731
    f = res["refit_ms"]
    per_object = {}
    for r in res["rows"]:
        per_object.setdefault(r["object"], []).append(r)
    objs = " · ".join(f"{name} {sum(r['fixed'] == name for r in rs)}/{sum(r['answer'] == name for r in rs)}"
                      for name, rs in per_object.items())
    return "\n".join([
        f"{res['n']} touches ({res['touches_per_object']} specimens of each of the {res['objects']} tactile objects) "
        f"by the small-heater probe on the faithful world, precision board at {SMALL_RATE_Hz:g} Hz, threshold "
        f"{res['threshold']:g} after {res['decide_min_s']:g} s"
        + (", R_c fitted" if res.get("fit_contact") else "")
        + f" (`python bench/decision_bench.py --world faithful --probe small-heater"
        + (f" --fit-contact --touches {res['touches_per_object']}`):" if res.get("fit_contact")
           else " --update-readme`):"), "",
        "| answer | object accuracy | median heating | decided early | accuracy of early decisions "
        "| wrong early decisions | α determined |", "|---|---|---|---|---|---|---|",
        f"| fixed {res['fixed_contact_s']:g} s | {pct(res['fixed_accuracy'])} | {res['fixed_contact_s']:.2f} s | - | - "
        f"| - | {pct(res['alpha_determined_fixed'])} |",
        f"| until decided | {pct(res['until_decided_accuracy'])} | {res['median_decision_s']:.2f} s | "
        f"{pct(res['decided_early'])} | {pct(res['accuracy_of_decided'])} | {res['wrong_early']} | "
        f"{pct(res['alpha_determined_until_decided'])} |", "",
        f"A refit of the record so far took {f['median']:.1f} ms (median; p95 {f['p95']:.1f} ms, max "
        f"{f['max']:.1f} ms; {res['refits_per_touch']:.1f} per touch) on this machine. Right answers per object, "
        f"fixed/until decided: {objs}.",
    ])


def faithful_table(res: dict) -> str:
    """The docs/results.md block of :func:`run_faithful`."""
    pct = lambda x: "-" if x is None else f"{x * 100:.0f} %"  # noqa: E731
    L = [f"{res['n']} touches ({res['touches_per_object']} specimens of each of the {res['objects']} tactile "
         f"objects) by one as-built probe on the faithful world, precision board, threshold {res['threshold']:g} "
         f"after {res['decide_min_s']:g} s; a touch the chain refuses (`poor_fit` and the like) counts as wrong "
         f"(`python bench/decision_bench.py --world faithful --update-readme`):", "",
         "| running decision | fixed 1.5 s accuracy | until-decided accuracy | median decision time | decided early "
         "| accuracy of early decisions | wrong early decisions |", "|---|---|---|---|---|---|---|"]
    for kind, label in (("raw", "thick-body fit of the raw reading (uncalibrated device)"),
                        ("chain", "calibrated sensor chain (calibrated device)")):
        r = res[kind]
        L.append(f"| {label} | {pct(r['fixed_accuracy'])} | {pct(r['until_decided_accuracy'])} | "
                 f"{r['median_decision_s']:.2f} s | {pct(r['decided_early'])} | {pct(r['accuracy_of_decided'])} | "
                 f"{r['wrong_early']} |")
    ct = res.get("chain_by_contact_time")
    if ct:
        L += ["", "The calibrated chain by contact time (the same touches' prefixes; object accuracy of the answered "
              "touches, an `unknown` counts as wrong; ceiling: e-only Bayes at the chain's own median u(e) per "
              "object):", "", "| contact | object acc | Bayes ceiling | refused | median u(e) |", "|---|---|---|---|---|"]
        for k, r in ct.items():
            u = "-" if r["median_u_ln_e"] is None else f"{r['median_u_ln_e'] * 100:.1f} %"
            L.append(f"| {float(k):g} s | {pct(r['accuracy'])} | {pct(r['ceiling'])} | {r['refused']}/{res['n']} | {u} |")
    return "\n".join(L)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--touches", type=int, default=10)
    p.add_argument("--threshold", type=float, default=0.95)
    p.add_argument("--min-s", type=float, default=0.3)
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--world", choices=("model", "faithful"), default="model",
                   help="the exact probe model (default) or the faithful (r, z) world with a calibrated chain")
    p.add_argument("--probe", choices=("paper", "small-heater"), default="paper",
                   help="with --world faithful: the probe (small-heater: its own estimator's running answer)")
    p.add_argument("--fit-contact", action="store_true",
                   help="with --probe small-heater: its estimator fits the contact resistance too (not the default)")
    p.add_argument("--update-readme", action="store_true", help="with --world faithful: rewrite its block in docs/results.md")
    a = p.parse_args()
    if a.world == "faithful" and a.probe == "small-heater":
        w = time.perf_counter()
        res = run_faithful_small(a.touches, a.threshold, a.min_s, a.seed, fit_contact=a.fit_contact)
        res["wall_s"] = round(time.perf_counter() - w, 1)
        table = faithful_small_table(res)
        print(table)
        write_json("decision_faithful_small" + ("_rc" if a.fit_contact else ""), res)
        if a.update_readme and not a.fit_contact:
            write_block("decision-faithful-small-bench", table)
        return
    if a.world == "faithful":
        w = time.perf_counter()
        res = run_faithful(a.touches, a.threshold, a.min_s, a.seed)
        res["wall_s"] = round(time.perf_counter() - w, 1)
        table = faithful_table(res)
        print(table)
        write_json("decision_faithful", res)
        if a.update_readme:
            write_block("decision-faithful-bench", table)
        return
    w = time.perf_counter()
    res = run(a.touches, a.threshold, a.min_s, a.seed)
    res["wall_s"] = round(time.perf_counter() - w, 1)
    print(f"{res['n']} touches, {res['objects']} objects, {INSTRUMENT}: fixed {FIXED_S} s accuracy "
          f"{res['fixed_accuracy']:.3f}; until-decided accuracy {res['until_decided_accuracy']:.3f}, median "
          f"decision {res['median_decision_s']:.2f} s (p90 {res['p90_decision_s']:.2f} s), decided early "
          f"{res['decided_early']:.0%}")
    write_json("decision", res)


if __name__ == "__main__":
    main()
