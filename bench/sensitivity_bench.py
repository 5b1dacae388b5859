"""Two diagnoses behind the calibration notes of docs/science.md, reproducible.

1. The small-heater probe's response to its flux sensor's scale: for PMMA, tempered glass,
   AISI 304 and aluminium, a noise-free 5-s record of the axisymmetric model at 50 Hz, the
   estimate's ``fit.flux_scale_sensitivity`` (d ln k, d ln alpha per unit relative scale error,
   linearised) and what refits of the record with the flux scaled by 0.98 and 1.02 give
   (the fit's own k and alpha).
2. The paper probe's contact-resistance bias: noise-free 1-D FaithfulWorld touches (nominal
   probe, R_c 5e-5 m^2K/W, object 1.5 K warm, contact 1 s before heating, 4 s heating) fitted
   by the sensor chain with the datasheet chain -- the probe's own -- with the thermocouple
   smoothed before the storage term (as shipped) and without; the R_c error times e^2 is
   constant (~5 J/m^2K) where a surface heat capacity explains it.  Then, from
   ``bench/results/calibration.json`` (``python bench/calibration_bench.py``), the median
   z = (R_c fit - R_c) / u(R_c) per solid of the calibrated 1-D touches; and, from both boards'
   calibration benches, each metal's mean e error and coverage on the paper geometry.
3. The real-probe demo's aluminium scenes (``host.realprobe.TEST_TOUCHES``) noise-free, the
   datasheet probe known exactly, with the object at the probe's temperature and at the scene's
   offset: e error of the chain's answer and of its 1-D fit (no lateral loss), and the alpha
   the lateral profile found, against the truth.

Run:  python bench/sensitivity_bench.py        (~1 min)
Writes bench/results/sensitivity.json.
"""

from __future__ import annotations

import json
import statistics
import sys
from collections import defaultdict

import numpy as np

from _common import RESULTS, ROOT, write_json

sys.path.insert(0, str(ROOT))

from edge.estimation.estimate import Estimator, pipeline_golden_check  # noqa: E402
from edge.estimation.probe_estimate import AxiEstimator  # noqa: E402
from edge.estimation.sensor_chain import SensorChainCalibration, fit_sensor_chain  # noqa: E402
from edge.model.bundle import load_bundle  # noqa: E402
from edge.physics.axisym import AxisymModel  # noqa: E402
from edge.physics.geometry import PROBES  # noqa: E402
from edge.physics.materials import load_materials  # noqa: E402


def flux_scale(lib) -> dict:
    from thermotouch_models import DEFAULT_BUNDLE

    axi = AxiEstimator(Estimator.from_bundle(load_bundle(DEFAULT_BUNDLE, golden_check=pipeline_golden_check)),
                       "small-heater")
    t = np.arange(251) * 0.02
    model = AxisymModel(PROBES["small-heater"], t)
    out = {}
    print("small-heater probe, 5 s: d ln x / d ln (flux scale), linearised | from refits at 0.98 / 1.02")
    for name in ("pmma", "tempered_glass", "aisi_304", "aluminium"):
        s = lib.get(name).solid
        T, q = model.signals(s.k_W_mK, s.alpha_m2_s)
        d0 = axi.estimate(t, T, q)
        lo, hi = axi.estimate(t, T, q * 0.98), axi.estimate(t, T, q * 1.02)
        refit = {x: float(np.log(hi["fit"][f"{x}_W_mK" if x == "k" else "alpha_m2_s"]
                                 / lo["fit"][f"{x}_W_mK" if x == "k" else "alpha_m2_s"]) / np.log(1.02 / 0.98))
                 for x in ("k", "alpha")}
        sens = d0["fit"]["flux_scale_sensitivity"]
        out[name] = {"linearised": sens, "refit": refit,
                     "u_rel_k": d0["k_W_mK_u"] / d0["k_W_mK"], "u_rel_alpha": d0["alpha_m2_s_u"] / d0["alpha_m2_s"]}
        print(f"  {name:16s} k {sens['k']:+6.2f} | {refit['k']:+6.2f}   alpha {sens['alpha']:+6.2f} | "
              f"{refit['alpha']:+6.2f}   stated u(k) {out[name]['u_rel_k']:.1%}, u(alpha) {out[name]['u_rel_alpha']:.1%}")
    return out


def rc_smoothing(lib) -> dict:
    from firmware_sim.rigs.contact_record import ContactTouch, one_d_geometry, record_touch

    geo, chain, rc = one_d_geometry(), SensorChainCalibration(), 5e-5
    out = {}
    print("\npaper probe, noise-free 1-D touches, R_c 5e-5: R_c error (x e^2, J/m^2K) with / without smoothing")
    for name in ("cork_board", "natural_rubber_soft", "borofloat_33", "granite", "aluminium"):
        s = lib.get(name).solid
        r = record_touch(ContactTouch(s, rc, 1.5, lead_s=1.0, heat_s=4.0), geometry=geo, seed=None, dt_s=0.01)
        m = r["t_s"] >= r["contact_t_s"] - 1e-9
        row = {}
        for label, sm in (("smoothed", None), ("raw", 0.0)):
            kw = {} if sm is None else {"smooth_s": sm}
            f = fit_sensor_chain(r["t_s"][m] - r["contact_t_s"], r["T_C"][m], r["q_W_m2"][m],
                                 T_probe0_C=r["T_probe0_C"], calibration=chain, **kw)
            row[label] = {"dR_c": f.R_c_m2K_W - rc, "e_err": f.e_W_s05_m2K / s.effusivity_W_s05_m2K - 1,
                          "dR_c_e2": (f.R_c_m2K_W - rc) * s.effusivity_W_s05_m2K ** 2}
        out[name] = row
        print(f"  {name:20s} smoothed dR_c {row['smoothed']['dR_c']:+.2e} (x e^2 {row['smoothed']['dR_c_e2']:+6.1f})"
              f"   raw {row['raw']['dR_c']:+.2e} (x e^2 {row['raw']['dR_c_e2']:+6.1f})")
    return out


def rc_z_from_calibration_bench() -> dict:
    path = RESULTS / "calibration.json"
    if not path.exists():
        print(f"\n{path} missing: run python bench/calibration_bench.py")
        return {}
    rows = [r for r in json.loads(path.read_text())["rows"]
            if r["chain"] == "calibrated" and r["e"] is not None and r["geometry"] == "1d"]
    by = defaultdict(list)
    e_of = {}
    for r in rows:
        by[r["solid"]].append((r["R_c_fit"] - r["R_c"]) / r["u_R_c"])
        e_of[r["solid"]] = r["e_true"]
    out = {s: {"e": e_of[s], "median_z": statistics.median(v), "n": len(v)} for s, v in by.items()}
    allz = [z for v in by.values() for z in v]
    print(f"\ncalibrated 1-D touches of the calibration bench: R_c inside its 95 % in "
          f"{100 * np.mean(np.abs(allz) <= 1.96):.0f} % of {len(allz)}; median z per solid, by e:")
    print("  " + ", ".join(f"{s} {d['median_z']:+.1f}" for s, d in sorted(out.items(), key=lambda x: x[1]["e"])))
    return out


def metals_from_calibration_bench() -> dict:
    """Per metal, the calibrated paper-geometry touches of both boards' calibration benches: mean e error, coverage."""
    out = {}
    for board, name in (("precision", "calibration.json"), ("reference", "calibration_reference.json")):
        path = RESULTS / name
        if not path.exists():
            print(f"\n{path} missing: run python bench/calibration_bench.py" + ("" if board == "precision" else
                                                                                 " --board reference"))
            continue
        by = defaultdict(list)
        for r in json.loads(path.read_text())["rows"]:
            if r["geometry"] == "paper" and r["chain"] == "calibrated" and r["e"] is not None and r["e_true"] > 5000:
                by[r["solid"]].append((r["e"] / r["e_true"] - 1.0, abs(r["e"] - r["e_true"]) <= 1.96 * r["u_e"],
                                       r["u_e"] / r["e"]))
        out[board] = {s: {"mean_err": statistics.mean(x[0] for x in v), "covered": sum(x[1] for x in v), "n": len(v),
                          "median_u_rel": statistics.median(x[2] for x in v)} for s, v in by.items()}
        print(f"\ncalibration bench, {board} board, paper geometry, calibrated, metals (e > 5000): mean e error, "
              "95 % interval holds e, median u(e)")
        for sname, d in sorted(out[board].items()):
            print(f"  {sname:<22} {d['mean_err']:+.1%}  {d['covered']}/{d['n']}  u {d['median_u_rel']:.1%}")
    return out


def aluminium_offset(lib) -> dict:
    """The real-probe demo's aluminium scenes noise-free, with the object at the probe's temperature and at the scene's offset."""
    from edge.calibration.model import ProbeCalibration
    from edge.estimation.chain_estimate import estimate_from_contact
    from firmware_sim.rigs.contact_record import ContactTouch, record_touch
    from firmware_sim.rz.probe_world import geometry_for_probe
    from host.realprobe import HEAT_s, TEST_TOUCHES

    # The probe as the datasheet says, and told so exactly: what is left is the estimator's own model.
    nom = ProbeCalibration.nominal("paper")
    exact = ProbeCalibration(probe="paper", chain=nom.chain, covariance=nom.covariance * 1e-6, calibrated=True)
    geo = geometry_for_probe("paper", infinite_thickness_m=0.05)   # the demo's 50-mm block
    out = []
    print("\nreal-probe demo's aluminium scenes, noise-free, datasheet probe known exactly, 8-s heating: e error of")
    print("the answer and of the 1-D fit on the same window, and the alpha the lateral profile found")
    for tc in (t for t in TEST_TOUCHES if t.material == "aluminium_alloy"):
        solid = lib.get(tc.material).solid
        alpha_true = solid.k_W_mK / solid.rho_c_J_m3K
        for off in (0.0, tc.object_offset_K):
            r = record_touch(ContactTouch(solid, tc.contact_resistance_m2K_W, off,
                                          lead_s=tc.lead_s, heat_s=HEAT_s), geometry=geo, seed=None)
            d = estimate_from_contact(r["t_s"], r["T_C"], r["q_W_m2"], exact)
            if d["effusivity_W_s05_m2K"] is None:
                print(f"  {tc.voltage_V:3.0f} V scene, object {off:+.1f} K: no answer ({', '.join(d['flags'])})")
                out.append({"voltage_V": tc.voltage_V, "offset_K": off, "answer": None, "flags": d["flags"]})
                continue
            e = d["effusivity_W_s05_m2K"] / r["e_true"]
            e_1d = e / (1.0 + d["lateral_correction"])
            row = {"voltage_V": tc.voltage_V, "offset_K": off, "lead_s": tc.lead_s, "R_c": tc.contact_resistance_m2K_W,
                   "answer": e - 1, "one_d": e_1d - 1, "alpha_ratio": d["alpha_m2_s"] / alpha_true,
                   "alpha_u_rel": d["alpha_m2_s_u"] / d["alpha_m2_s"], "determined": d["determined"],
                   "fit_end_t_s": d["fit_end_t_s"], "u_rel": d["effusivity_W_s05_m2K_u"] / d["effusivity_W_s05_m2K"]}
            out.append(row)
            print(f"  {tc.voltage_V:3.0f} V scene, object {off:+.1f} K: answer {row['answer']:+.1%} (u {row['u_rel']:.1%})"
                  f", 1-D {row['one_d']:+.1%}; alpha {row['alpha_ratio']:.2f} x true (u {row['alpha_u_rel']:.0%}"
                  f"{', measured' if 'alpha' in row['determined'] else ', prior'}); window to {row['fit_end_t_s']:.2f} s")
    return out


def main() -> None:
    lib = load_materials()
    res = {"flux_scale": flux_scale(lib), "rc_smoothing": rc_smoothing(lib),
           "rc_z_per_solid": rc_z_from_calibration_bench(),
           "metals_paper": metals_from_calibration_bench(), "aluminium_offset": aluminium_offset(lib),
           "command": "python bench/sensitivity_bench.py"}
    print(f"wrote {write_json('sensitivity', res)}")


if __name__ == "__main__":
    main()
