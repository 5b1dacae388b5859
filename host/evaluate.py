"""Accuracy of the estimators on simulated measurements.

Simulated touches use the exact (Laplace) probe model on a finite sample
(20 mm, insulated back, as on a table), observed through an instrument model
(edge.measure.instrument: sampling, noise, quantisation) - a different model from
the one either estimator inverts.

Heater: the paper does not give its heater's resistance; 50 ohm is assumed,
so q_v = V^2 / (50 ohm x 55 mm x 60 mm x 20 um): 8 V -> 1.94e7, 12 V ->
4.36e7, 15 V -> 6.82e7, 18 V -> 9.82e7, 20 V -> 1.21e8, 25 V -> 1.89e8 W/m^3.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from edge.estimation.estimate import Estimator
from edge.physics.forward import simulate
from edge.measure.instrument import INSTRUMENTS
from edge.physics.probe import DEFAULT_STACK
from edge.physics.solids import Solid

HEATER_RESISTANCE_OHM = 50.0
SAMPLES = {
    "tempered_glass": (Solid(1.097, 2458.4, 809.0), (12.0, 15.0, 18.0)),
    "pmma": (Solid(0.185, 1178.35, 1429.0), (8.0, 15.0, 20.0)),
    "aluminium_alloy": (Solid(120.4, 2651.5, 873.0), (15.0, 20.0, 25.0)),
}


def q_v_for_voltage(v: float) -> float:
    return DEFAULT_STACK.q_v_from_voltage(v, HEATER_RESISTANCE_OHM)


@dataclass
class Touch:
    tT: np.ndarray
    T: np.ndarray
    tq: np.ndarray
    q: np.ndarray


class TouchSimulator:
    """Noisy touches of one solid, from one exact unit response scaled per power."""

    def __init__(self, solid: Solid, duration_s: float = 2.0, thickness_m: float = 0.02, back: str = "insulated"):
        self.solid = solid
        r = simulate(solid, 1.0, duration_s, dt_s=0.002, thickness_m=thickness_m, back=back, scheme="exact")
        self.t, self.T1, self.q1 = r.t_s, r.T_f_K, r.q_f_W_m2

    def touch(self, q_v: float, instrument: str, rng: np.random.Generator, duration_s: float | None = None) -> Touch:
        inst = INSTRUMENTS[instrument]
        m = self.t <= (duration_s if duration_s else self.t[-1]) + 1e-12
        tT, T, tq, q = inst.sample(self.t[m], q_v * self.T1[m], q_v * self.q1[m], rng,
                                   t0_offset_K=rng.uniform(0, inst.T_lsb_K))
        return Touch(tT, T, tq, q)


def rel(a, b):
    return None if a is None else (a - b) / b


def paper_cases(est: Estimator, instrument: str, *, repeats: int = 5, seed: int = 1) -> list[dict]:
    """Errors of e, k, alpha for both methods on the paper's nine experiments."""
    rng = np.random.default_rng(seed)
    rows = []
    for name, (solid, volts) in SAMPLES.items():
        sim = TouchSimulator(solid)
        for v in volts:
            qv = q_v_for_voltage(v)
            for method in ("paper", "default"):
                errs = {"e": [], "k": [], "alpha": []}
                res = None
                for _ in range(repeats):
                    t = sim.touch(qv, instrument, rng)
                    res = est.estimate(t.tT, t.T, t.q, t_q_s=t.tq, T_resolution_K=INSTRUMENTS[instrument].T_lsb_K,
                                       method=method, q_v_W_m3=qv)
                    if res.k_W_mK is None:
                        continue
                    errs["e"].append(rel(res.effusivity_W_s05_m2K, solid.effusivity_W_s05_m2K))
                    errs["k"].append(rel(res.k_W_mK, solid.k_W_mK))
                    errs["alpha"].append(rel(res.alpha_m2_s, solid.alpha_m2_s))
                rows.append(dict(
                    sample=name, voltage_V=v, q_v_W_m3=qv, method=method, instrument=instrument,
                    e_err=float(np.mean(np.abs(errs["e"]))) if errs["e"] else None,
                    k_err=float(np.mean(errs["k"])) if errs["k"] else None,
                    alpha_err=float(np.mean(errs["alpha"])) if errs["alpha"] else None,
                    k_err_abs=float(np.mean(np.abs(errs["k"]))) if errs["k"] else None,
                    alpha_err_abs=float(np.mean(np.abs(errs["alpha"]))) if errs["alpha"] else None,
                    k_u_rel=(res.k_W_mK_u / res.k_W_mK) if res and res.k_W_mK else None,
                    e_u_rel=(res.effusivity_W_s05_m2K_u / res.effusivity_W_s05_m2K) if res and res.k_W_mK else None,
                    material=res.material if res else None, flags=res.flags if res else [],
                    n_ok=len(errs["e"]),
                ))
    return rows


def identification(est: Estimator, instrument: str, *, touches: int = 4, q_v: float = 7.7e7,
                   seed: int = 2) -> dict:
    """Top-1 identification over every library material (default method)."""
    rng = np.random.default_rng(seed)
    names = est.library.names
    ln_e = np.log(est.library.effusivity)
    hits, total, conf = {}, {}, []
    resolvable_hits = resolvable_total = 0
    u_seen = []
    for i, name in enumerate(names):
        rc = est.library.rho_c[i]
        solid = Solid(float(est.library.k[i]), float(rc), 1.0)
        sim = TouchSimulator(solid)
        cls = est.library.classes[i]
        for _ in range(touches):
            t = sim.touch(q_v, instrument, rng)
            r = est.estimate(t.tT, t.T, t.q, t_q_s=t.tq, T_resolution_K=INSTRUMENTS[instrument].T_lsb_K)
            total[cls] = total.get(cls, 0) + 1
            ok = r.material == name
            hits[cls] = hits.get(cls, 0) + ok
            if not ok:
                conf.append((name, r.material or "(no estimate)"))
            u = r.effusivity_W_s05_m2K_u / r.effusivity_W_s05_m2K if r.effusivity_W_s05_m2K else 1.0
            u_seen.append(u)
            others = np.delete(ln_e, i)
            if np.min(np.abs(others - ln_e[i])) > 2 * u:
                resolvable_total += 1
                resolvable_hits += ok
    n = sum(total.values())
    pairs: dict = {}
    for a, b in conf:
        pairs[(a, b)] = pairs.get((a, b), 0) + 1
    top_conf = sorted(pairs.items(), key=lambda kv: -kv[1])[:10]
    return dict(
        instrument=instrument, touches=n, top1=sum(hits.values()) / n,
        resolvable_touches=resolvable_total,
        top1_resolvable=(resolvable_hits / resolvable_total) if resolvable_total else None,
        by_class={c: hits[c] / total[c] for c in sorted(total)},
        median_u_ln_e=float(np.median(u_seen)),
        confusions=[f"{a} -> {b} ({n})" for (a, b), n in top_conf],
    )


def leave_one_out_default(est: Estimator, instrument: str, *, seed: int = 3, q_v: float = 7.7e7) -> dict:
    """Default method with each material removed from the prior in turn."""
    rng = np.random.default_rng(seed)
    errs = {"e": [], "k": [], "alpha": []}
    base = dict(
        lib_effusivity=est.library.effusivity, lib_k=est.library.k, lib_rho_c=est.library.rho_c,
        lib_names=np.array(est.library.names), lib_class=np.array(est.library.classes),
    )
    for i in range(len(est.library.names)):
        keep = np.arange(len(est.library.names)) != i
        arrays = {k: v[keep] for k, v in base.items()}
        arrays["prior_coef"] = np.array([est.library.kernel_floor_ln, est.library.rho_c_intrinsic_ln, est.library.material_spread_ln,
                                        est.paper_u_ln_k])
        e_i = Estimator(arrays)
        solid = Solid(float(est.library.k[i]), float(est.library.rho_c[i]), 1.0)
        t = TouchSimulator(solid).touch(q_v, instrument, rng)
        r = e_i.estimate(t.tT, t.T, t.q, t_q_s=t.tq, T_resolution_K=INSTRUMENTS[instrument].T_lsb_K)
        if r.k_W_mK is None:
            continue
        errs["e"].append(abs(rel(r.effusivity_W_s05_m2K, solid.effusivity_W_s05_m2K)))
        errs["k"].append(abs(rel(r.k_W_mK, solid.k_W_mK)))
        errs["alpha"].append(abs(rel(r.alpha_m2_s, solid.alpha_m2_s)))
    return summarize(errs)


def summarize(errs: dict) -> dict:
    out = {}
    for key, v in errs.items():
        a = np.asarray(v)
        out[key] = dict(median=float(np.median(a)), p90=float(np.percentile(a, 90)),
                        within_10=float(np.mean(a < 0.10)), within_20=float(np.mean(a < 0.20)), n=int(a.size))
    return out


def contact_time_trade(est: Estimator, instrument: str, *, times=(0.3, 0.5, 1.0, 2.0, 4.0),
                       voltages=(12.0, 18.0, 25.0), repeats: int = 10, seed: int = 4) -> list[dict]:
    """Effusivity error and stated uncertainty vs contact time and heater voltage (default method)."""
    rng = np.random.default_rng(seed)
    rows = []
    sims = {name: TouchSimulator(s, duration_s=max(times)) for name, (s, _) in SAMPLES.items()}
    for ct in times:
        for v in voltages:
            qv = q_v_for_voltage(v)
            for name, sim in sims.items():
                e_err, e_u = [], []
                for _ in range(repeats):
                    t = sim.touch(qv, instrument, rng, duration_s=ct)
                    try:
                        r = est.estimate(t.tT, t.T, t.q, t_q_s=t.tq, T_resolution_K=INSTRUMENTS[instrument].T_lsb_K)
                    except ValueError:
                        continue
                    if r.effusivity_W_s05_m2K is None:
                        continue
                    e_err.append(rel(r.effusivity_W_s05_m2K, sim.solid.effusivity_W_s05_m2K))
                    e_u.append(r.effusivity_W_s05_m2K_u / r.effusivity_W_s05_m2K)
                rows.append(dict(contact_time_s=ct, voltage_V=v, sample=name, instrument=instrument,
                                 e_rms_err=float(np.sqrt(np.mean(np.square(e_err)))) if e_err else None,
                                 e_stated_u=float(np.median(e_u)) if e_u else None, n=len(e_err)))
    return rows


def leave_out_paper(instrument: str, *, folds: int = 7, seed: int = 5, q_v: float = 7.7e7) -> dict:
    """Paper method, materials held out in grouped folds: e, k, alpha errors on noisy touches.

    Each fold's network is trained (quick settings: 6 power levels, no noise
    copies) without the fold's materials, which are then touched and
    estimated with the paper method (alpha scan by Duhamel, which equals the
    explicit scan on thick objects - see the compute table).
    """
    import warnings

    from edge.estimation.features import FEATURE_VERSION
    from host.dataset import Dataset, DatasetSpec, generate
    from host.export import mlp_arrays_from_sklearn, pca_arrays_from_sklearn
    from edge.physics.materials import load_materials
    from host.train import fit_paper_model

    lib = load_materials()
    ds = generate(DatasetSpec(noisy_copies=0, levels_W_m3=DatasetSpec.levels_W_m3[::4]), lib)
    rng = np.random.default_rng(seed)
    idx = np.arange(len(lib))
    errs = {"e": [], "k": [], "alpha": []}
    for f in range(folds):
        held = idx[f::folds]
        tr = ~np.isin(ds.material_index, held)
        sub = Dataset(ds.features[tr], ds.k_W_mK[tr], ds.rho_c_J_m3K[tr], ds.q_v_W_m3[tr],
                      ds.material_index[tr], ds.noisy[tr], ds.names, ds.sha256)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            pm = fit_paper_model(sub, seed=seed, max_iter=300)
        keep = ~np.isin(idx, held)
        arrays = {"feature_version": np.int64(FEATURE_VERSION), "x_log_offset": pm.floor,
                  "x_mean": pm.scaler.mean_, "x_scale": pm.scaler.scale_, "y_transform": np.int64(1),
                  "lib_effusivity": lib.effusivity[keep], "lib_k": lib.k[keep], "lib_rho_c": lib.rho_c[keep],
                  "lib_names": np.array(lib.names)[keep], "lib_class": np.array(lib.classes)[keep]}
        arrays.update(pca_arrays_from_sklearn(pm.pca))
        arrays.update(mlp_arrays_from_sklearn(pm.mlp))
        est = Estimator(arrays)
        for i in held:
            m = list(lib)[i]
            solid = m.solid
            t = TouchSimulator(solid).touch(q_v, instrument, rng)
            r = est.estimate(t.tT, t.T, t.q, t_q_s=t.tq, T_resolution_K=INSTRUMENTS[instrument].T_lsb_K,
                             method="paper")
            if r.k_W_mK is None:
                continue
            errs["e"].append(abs(rel(r.effusivity_W_s05_m2K, solid.effusivity_W_s05_m2K)))
            errs["k"].append(abs(rel(r.k_W_mK, solid.k_W_mK)))
            errs["alpha"].append(abs(rel(r.alpha_m2_s, solid.alpha_m2_s)))
    return summarize(errs)
