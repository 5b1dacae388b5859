"""Window self-consistency of each drawn probe's reference touches vs its objects' short-window level error.

ISSUE #37 (CAL44).  Each drawn as-built paper probe of the tactile bench is calibrated on its own
reference touches (as the bench does: :func:`_asbuilt_touches.calibrate_records`); each reference touch
is then re-estimated through the one estimate path at short heating windows and at its full 8 s.
``delta_T = ln e(T) - ln e(8 s)`` of the SAME touch needs no true e: it is the window's own level
error on that probe.  Per probe it is interpolated in ln e (between the references) to each object's
e and compared with the probe's mean object error ln(e / e_true) at T (rows of
bench/results/tactile_asbuilt.json).  Printed: the between/within split of the object errors, how
much of the between-probe variance delta_T predicts, and (the four woods pooled per probe) how much
the calibration's own parameter error predicts: fitted theta minus the drawn probe's as-built chain
(:func:`true_theta`, known here because the bench draws the probe).

    python bench/_window_consistency.py --probes 55 --jobs 2 --out /tmp/cal44/wc.json   # ~400 CPU-s
    python bench/_window_consistency.py --analyse /tmp/cal44/wc.json                      # tables again
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _asbuilt_grow as G  # noqa: E402
import _asbuilt_touches as A  # noqa: E402
from _common import RESULTS  # noqa: E402

WINDOWS_s = (0.5, 1.0, 2.0)
#: ln e of each object (its median specimen, W s^0.5 / m^2 K): where delta_T is read between the references.
OBJ_LN_E = {"pine_shelf": math.log(323.0), "natural_rubber_mat": math.log(363.0), "mdf_board": math.log(377.0),
            "oak_worktop": math.log(450.0), "soda_lime_bottle": math.log(1372.0)}
OBJECTS = ("pine_shelf", "natural_rubber_mat", "mdf_board", "oak_worktop", "soda_lime_bottle")


def reference_windows(task) -> tuple:
    """(probe, [(name, {T: ln e}) per reference touch]) for one probe: calibrated, references re-estimated."""
    from edge.estimation.seam import estimate_touch
    from host.cli.common import seam_context

    p, refs, times = task
    cal, _ = A.calibrate_records("paper", refs)
    ctx = seam_context(None, calibration=cal)
    out = []
    for name, r in refs:
        if r is None:
            continue
        lne = {}
        for T in (*times, None):
            rec = r if T is None else A.truncated(r, T)
            try:
                d = estimate_touch(rec, ctx).to_dict()
                e = d["effusivity_W_s05_m2K"] or (d.get("sensor_chain") or {}).get("effusivity_W_s05_m2K")
                lne["full" if T is None else str(T)] = math.log(e) if e else math.nan
            except ValueError:
                lne["full" if T is None else str(T)] = math.nan
        out.append((name, lne))
    return p, {"touches": out, "theta": [float(x) for x in cal.theta], "u_theta": [float(x) for x in cal.u_theta],
               "u_rel_floor": float(cal.u_rel_floor), "forced": bool(cal.forced),
               "model_form_wood": float(cal.model_form_u_rel(380.0)),
               "misses": (cal.self_check or {}).get("misses")}


def object_errors(times, rows=None) -> dict:
    """{probe: {T: {object: [ln(e / e_true)...]}}} from ``rows`` (default: the committed bench rows)."""
    if rows is None:
        rows = json.loads((RESULTS / "tactile_asbuilt.json").read_text())["heads"]["paper"]["rows"]
    out: dict = {}
    for r in rows:
        if r.get("kind", "touch") != "touch" or r["contact_s"] not in times or not (r.get("e") or 0) > 0:
            continue
        if not math.isfinite(r["e"]):
            continue
        out.setdefault(r["probe"], {}).setdefault(r["contact_s"], {}).setdefault(r["name"], []).append(
            math.log(r["e"] / r["e_true"]))
    return out


def predicted_offsets(refs, T) -> tuple[np.ndarray, np.ndarray]:
    """(ln e at the full window, mean delta_T) per reference material of one probe, sorted by ln e."""
    by: dict = {}
    for name, lne in refs:
        full, short = lne.get("full", math.nan), lne.get(str(T), lne.get(T, math.nan))
        if math.isfinite(full) and math.isfinite(short):
            by.setdefault(name, []).append((full, short - full))
    pts = sorted((float(np.mean([a for a, _ in v])), float(np.mean([b for _, b in v]))) for v in by.values())
    return np.array([a for a, _ in pts]), np.array([b for _, b in pts])


def analyse(ref_windows: dict, times=WINDOWS_s, objects=OBJECTS, rows=None) -> dict:
    """Between / within split of the objects' errors and what the references' delta_T predicts of it."""
    errs = object_errors(set(times), rows)
    out: dict = {}
    for T in times:
        per_obj: dict = {}
        for name in objects:
            m, d, w, n = [], [], [], []
            for p, refs in ref_windows.items():
                x = errs.get(int(p), {}).get(T, {}).get(name)
                if not x:
                    continue
                le, dl = predicted_offsets(refs, T)
                if le.size == 0:
                    continue
                ln_e_true = OBJ_LN_E[name]
                d.append(float(np.interp(ln_e_true, le, dl)))   # nearest reference outside their span
                m.append(float(np.mean(x)))
                w.extend(np.asarray(x) - np.mean(x))
                n.append(len(x))
            m, d = np.array(m), np.array(d)
            within = float(np.sqrt(np.sum(np.square(w)) / max(len(w) - len(m), 1)))
            between = float(np.std(m, ddof=1))
            noise = within / math.sqrt(float(np.mean(n)))     # a probe mean's own sampling scatter
            r = float(np.corrcoef(m, d)[0, 1])
            b = float(np.polyfit(d, m, 1)[0])
            after = float(np.std(m - d, ddof=1))
            per_obj[name] = {"probes": len(m), "between": between, "within": within, "mean_noise": noise,
                             "between_excess": math.sqrt(max(between ** 2 - noise ** 2, 0.0)), "r": r, "slope": b,
                             "r2": r * r, "between_after_subtracting": after, "mean_err": float(np.mean(m)),
                             "mean_delta": float(np.mean(d))}
        out[str(T)] = per_obj
    return out


WOODS = ("pine_shelf", "natural_rubber_mat", "mdf_board", "oak_worktop")
#: Where the references' linear fit of delta_T in ln e is read for the pooled woods (their median e ~ 380).
WOOD_LN_E = math.log(380.0)


def _r2(m: np.ndarray, X: np.ndarray) -> tuple[float, np.ndarray]:
    """R^2 of the least-squares fit of m on the columns of X (plus a constant), and its coefficients."""
    A_ = np.column_stack([X, np.ones(len(m))])
    b = np.linalg.lstsq(A_, m, rcond=None)[0]
    return float(1.0 - np.var(m - A_ @ b) / np.var(m)), b[:-1]


def true_theta(probe: int) -> np.ndarray:
    """The drawn probe's own chain parameters (ln flux_scale, ln depth, bead lag, ln layer k), as-built."""
    from firmware_sim.asbuilt import draw_as_built, draw_factors

    ab, f = draw_as_built("paper", probe), draw_factors("paper", probe)
    return np.array([-math.log1p(f["flux_sensitivity_rel"]), math.log(ab.sensing_thickness_m),
                     ab.thermocouple_time_constant_s, math.log(ab.sensing_k_W_mK)])


def pooled(data: dict, times=WINDOWS_s) -> dict:
    """Per probe, the four woods pooled (24 touches): what the references' delta_T and the calibration's
    own parameter error (fitted theta - the drawn probe's) predict of the probe's mean error at T."""
    refs, cals = data["references"], data.get("calibrations") or {}
    errs = object_errors(set(times), data.get("rows"))

    def mean_err(p, T):
        x = [v for n in WOODS for v in errs.get(int(p), {}).get(T, {}).get(n, [])]
        return float(np.mean(x)) if x else math.nan
    ps = [p for p in sorted(refs, key=int) if all(math.isfinite(mean_err(p, T)) for T in times)]
    dth = (np.array([np.array(cals[p]["theta"]) - true_theta(int(p)) for p in ps]) if cals else None)
    out: dict = {"probes": len(ps)}
    if dth is not None:
        out["theta_error_sd"] = [float(x) for x in np.std(dth, axis=0, ddof=1)]
        out["u_theta_median"] = [float(x) for x in np.median([cals[p]["u_theta"] for p in ps], axis=0)]
    for T in times:
        m = np.array([mean_err(p, T) for p in ps])
        row = {"between": float(np.std(m, ddof=1))}
        for mat in ("pmma", "pyroceram", "aisi_304"):   # the references' own window error, per probe
            d = [np.mean([l[str(T)] - l["full"] for n, l in refs[p] if n == mat]) for p in ps]
            row[f"ref_delta_sd_{mat}"] = float(np.nanstd(d, ddof=1))
        d_pm = np.array([np.mean([l[str(T)] - l["full"] for n, l in refs[p] if n == "pmma"]) for p in ps])
        lin = []
        for p in ps:   # offset + slope in ln e over the six touches, read at the woods' e
            pts = [(l["full"], l[str(T)] - l["full"]) for n, l in refs[p] if math.isfinite(l[str(T)])]
            X = np.array([[1.0, a - WOOD_LN_E] for a, _ in pts])
            lin.append(float(np.linalg.lstsq(X, np.array([b for _, b in pts]), rcond=None)[0][0]))
        lin = np.array(lin)
        for key, d in (("pmma", d_pm), ("linear", lin)):
            r2, b = _r2(m, d[:, None])
            row[key] = {"r2": r2, "slope": float(b[0]), "after_subtracting": float(np.std(m - d, ddof=1)),
                        "after_regression": float(np.std(m, ddof=1) * math.sqrt(1.0 - r2))}
        if dth is not None:
            r2, b = _r2(m, dth)
            row["theta_error"] = {"r2": r2, "coef": [float(x) for x in b],
                                  "r": [float(np.corrcoef(m, dth[:, i])[0, 1]) for i in range(dth.shape[1])]}
        out[str(T)] = row
    return out


def print_pooled(a: dict) -> None:
    print(f"four woods pooled per probe ({a['probes']} probes)")
    if "theta_error_sd" in a:
        print("  calibration's theta error (fitted - as built) sd: " + ", ".join(
            f"{n} {x:.4f} (stated u median {u:.4f})" for n, x, u in
            zip(("ln_flux", "ln_depth", "tau_s", "ln_k"), a["theta_error_sd"], a["u_theta_median"])))
    for T in WINDOWS_s:
        v = a[str(T)]
        line = (f"  T {T} s: between {100 * v['between']:.2f} %; references' own delta_T spread over probes "
                f"pmma {100 * v['ref_delta_sd_pmma']:.2f} / pyroceram {100 * v['ref_delta_sd_pyroceram']:.2f} / "
                f"aisi_304 {100 * v['ref_delta_sd_aisi_304']:.2f} %")
        for key in ("pmma", "linear"):
            x = v[key]
            line += (f"\n    delta_T {key}: R2 {x['r2']:.2f} slope {x['slope']:.2f}; between after subtracting "
                     f"{100 * x['after_subtracting']:.2f} %, after the regression {100 * x['after_regression']:.2f} %")
        if "theta_error" in v:
            x = v["theta_error"]
            line += (f"\n    theta error (4 regressors): R2 {x['r2']:.2f}; r " +
                     " ".join(f"{n} {r:+.2f}" for n, r in zip(("ln_flux", "ln_depth", "tau", "ln_k"), x["r"])) +
                     "; d ln e / d theta " + " ".join(f"{c:+.2f}" for c in x["coef"]))
        print(line)


def print_table(a: dict) -> None:
    for T, per in a.items():
        print(f"T = {T} s: object  probes  between / within  (mean noise)  mean err  mean delta  r  slope  R2  "
              "between after m - delta")
        for name, v in per.items():
            print(f"  {name:20s} {v['probes']:3d}  {100 * v['between']:.1f} / {100 * v['within']:.1f} %  "
                  f"({100 * v['mean_noise']:.1f})  {100 * v['mean_err']:+.1f}  {100 * v['mean_delta']:+.1f}  "
                  f"{v['r']:+.2f}  {v['slope']:.2f}  {v['r2']:.2f}  {100 * v['between_after_subtracting']:.1f} %")


# -- the six reference touches ----------------------------------------------------------------------
#: Where --extra-reference keeps the extra material's simulated touches (outside bench/results/cache).
EXTRA_CACHE = Path(tempfile.gettempdir()) / "thermotouch-window-consistency"


def six_references(p: int, refs: list) -> list:
    """The probe's six reference touches of :data:`_objects.REFERENCES`, as the cache holds them.

    An older merge kept one touch per material; ``python bench/tactile_asbuilt_bench.py --heads paper
    --fill-references`` touches the dropped ones again (what this module first did into a scratch
    directory: one place now, :func:`_asbuilt_grow.fill_references`).
    """
    from _objects import REFERENCES

    if len(refs) != len(REFERENCES):
        raise SystemExit(f"probe {p}: {len(refs)} reference touches cached, not {len(REFERENCES)}: run "
                         "python bench/tactile_asbuilt_bench.py --heads paper --fill-references")
    return refs


#: An extra reference's two touches (R_c, object - probe), as the walk-through's pairs.
EXTRA_HANDS = ((0.0, 1.0), (1e-5, -1.0))


def extra_references(p: int, name: str) -> list:
    """Two hand touches of library material ``name`` on probe ``p`` (kept in :data:`EXTRA_CACHE`)."""
    from asbuilt_bench import solid
    from host.calibration import HEAT_s

    path = EXTRA_CACHE / f"refs_{name}" / f"probe{p}.npz"
    if path.exists():
        recs, meta, _ = A.load_records(path)
        return [(m["name"], r) for r, m in zip(recs, meta)]
    store, wd = G._store(), tempfile.mkdtemp(prefix="cal44-extra-")
    out = [(name, A.simulate(A.hand_scene("paper", solid(name), p, 9000 + 13 * p + j, rc_m2K_W=rc, offset_K=off,
                                           lead_s=1.0, heat_s=HEAT_s, label=name), store, wd, HEAT_s))
           for j, (rc, off) in enumerate(EXTRA_HANDS)]
    A.save_records(path, [r for _, r in out], [{"kind": "reference", "probe": p, "name": n} for n, _ in out], {})
    return out


def six_probe(task) -> tuple:
    """One probe calibrated on its six reference touches (and an extra reference's two, if named): its
    references' windows and its objects' rows."""
    from edge.estimation.seam import estimate_touch
    from host.cli.common import seam_context

    p, refs, touches, times, *extra = task
    refs6 = six_references(p, refs) + (extra_references(p, extra[0]) if extra and extra[0] else [])
    _, ref_out = reference_windows((p, refs6, times))
    cal, _ = A.calibrate_records("paper", refs6)
    ctx = seam_context(None, calibration=cal)
    rows = []
    for r, m in touches:
        for T in times:
            row = {"probe": p, "name": m["name"], "e_true": m["e_true"], "contact_s": T, "e": math.nan}
            try:
                d = estimate_touch(A.truncated(r, T), ctx).to_dict()
                if d["effusivity_W_s05_m2K"]:
                    row.update(e=d["effusivity_W_s05_m2K"], u_ln_e=d["effusivity_W_s05_m2K_u"] / d["effusivity_W_s05_m2K"])
            except ValueError:
                pass
            rows.append(row)
    return p, ref_out, rows


def six_data(probes, res) -> dict:
    """The --six run's output in the shape :func:`analyse` and :func:`pooled` read (``rows``: its own)."""
    return {"probes": probes, "references": {str(p): v["touches"] for p, v, _ in res},
            "calibrations": {str(p): {k: x for k, x in v.items() if k != "touches"} for p, v, _ in res},
            "rows": [x for *_, rs in res for x in rs]}


def split(rows, probes, T, name) -> dict:
    """Between / within of ln(e / e_true) and rms z (stated u) of one object at T over ``probes``."""
    by: dict = {}
    z = []
    for r in rows:
        if r["probe"] in probes and r["contact_s"] == T and r["name"] == name and (r.get("e") or 0) > 0 \
                and math.isfinite(r["e"]):
            x = math.log(r["e"] / r["e_true"])
            by.setdefault(r["probe"], []).append(x)
            if r.get("u_ln_e") and math.isfinite(r["u_ln_e"]):
                z.append(x / r["u_ln_e"])
    means = np.array([np.mean(v) for v in by.values()])
    w = [x - np.mean(v) for v in by.values() for x in v]
    return {"between": float(np.std(means, ddof=1)), "within": float(np.sqrt(np.sum(np.square(w)) /
            max(len(w) - len(means), 1))), "bias": float(np.mean([x for v in by.values() for x in v])),
            "rms_z": float(np.sqrt(np.mean(np.square(z)))) if z else math.nan, "n": len(w)}


def print_six(six: dict, times=WINDOWS_s, objects=OBJECTS, baseline: dict | None = None) -> None:
    """The objects' split on the same probes: calibrated on three reference touches (the committed rows,
    or ``baseline``: an earlier --six run's) and on this run's references (re-estimated)."""
    if baseline is None:
        d = json.loads((RESULTS / "tactile_asbuilt.json").read_text())
        rows3 = [r for r in d["heads"]["paper"]["rows"] if r["kind"] == "touch"]
    else:
        rows3 = baseline["rows"]
    probes = {int(p) for p in six["probes"]}
    print(f"{'three' if baseline is None else 'baseline'} vs this run's reference touches, same {len(probes)} "
          "probes: between / within %, bias %, rms z")
    for T in times:
        for name in objects:
            a, b = split(rows3, probes, T, name), split(six["rows"], probes, T, name)
            print(f"  {T} s {name:20s} {'3 refs' if baseline is None else 'base'} {100 * a['between']:.1f} / "
                  f"{100 * a['within']:.1f}, {100 * a['bias']:+.1f}, z {a['rms_z']:.2f}   this {100 * b['between']:.1f} / "
                  f"{100 * b['within']:.1f}, {100 * b['bias']:+.1f}, z {b['rms_z']:.2f}   (n {a['n']}, {b['n']})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--probes", type=int, default=20)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default=None)
    ap.add_argument("--analyse", default=None, help="analyse a saved --out JSON (no re-estimation)")
    ap.add_argument("--six", action="store_true",
                    help="calibrate on all six cached reference touches and re-estimate the objects' touches (against "
                         "the bench JSON's rows, made before --fill-references: the split on 3 vs 6 touches)")
    ap.add_argument("--extra-reference", default=None,
                    help="with --six: also two touches of this library material (e.g. cork_board) in the calibration")
    ap.add_argument("--baseline", default=None, help="with --six: compare with this earlier --six --out JSON")
    ap.add_argument("--first", type=int, default=0, help="skip this many probes (with --probes: a slice)")
    args = ap.parse_args()
    if args.analyse and args.six:
        six = json.loads(Path(args.analyse).read_text())
        print_six(six, baseline=json.loads(Path(args.baseline).read_text()) if args.baseline else None)
        print_table(analyse(six["references"], rows=six["rows"]))
        print_pooled(pooled(six))
        return
    if args.analyse:
        data = json.loads(Path(args.analyse).read_text())
        print_table(analyse(data["references"]))
        print_pooled(pooled(data))
        return
    t0 = time.process_time()
    recs, meta, _ = G.load_all(A.CACHE / "tactile_asbuilt_paper.npz", [], extension=False, probes=True)
    probes = sorted({m["probe"] for m in meta if m["kind"] == "reference"})[args.first:args.first + args.probes]
    if args.six:
        tasks = [(p, [(m["name"], r) for r, m in zip(recs, meta) if m["kind"] == "reference" and m["probe"] == p],
                  [(r, m) for r, m in zip(recs, meta) if m["kind"] == "touch" and m["probe"] == p
                   and m["name"] in OBJECTS and r is not None], WINDOWS_s, args.extra_reference) for p in probes]
        with multiprocessing.get_context("fork").Pool(max(args.jobs, 1)) as pool:
            res = pool.map(six_probe, tasks, chunksize=1)
        six = six_data(probes, res)
        if args.out:
            Path(args.out).write_text(json.dumps(six, indent=1))
        print_six(six, baseline=json.loads(Path(args.baseline).read_text()) if args.baseline else None)
        print_table(analyse(six["references"], rows=six["rows"]))
        print_pooled(pooled(six))
        print(f"{len(probes)} probes, {time.process_time() - t0:.0f} CPU-s (parent)")
        return
    tasks = [(p, [(m["name"], r) for r, m in zip(recs, meta) if m["kind"] == "reference" and m["probe"] == p],
              WINDOWS_s) for p in probes]
    if args.jobs > 1:
        with multiprocessing.get_context("fork").Pool(args.jobs) as pool:
            res = dict(pool.map(reference_windows, tasks, chunksize=1))
    else:
        res = dict(reference_windows(t) for t in tasks)
    out = {"probes": probes, "references": {str(p): v["touches"] for p, v in res.items()},
           "calibrations": {str(p): {k: x for k, x in v.items() if k != "touches"} for p, v in res.items()}}
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1))
    print_table(analyse(out["references"]))
    print_pooled(pooled(out))
    print(f"{len(probes)} probes, {time.process_time() - t0:.0f} CPU-s (parent)")


if __name__ == "__main__":
    main()
