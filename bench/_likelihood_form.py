"""Is the recognition likelihood's form right? Dispersion per object, a u-dependent k, the low bin (issue #37).

The tactile as-built bench fits, per contact time and fold, a likelihood per object that is a Gaussian in
ln e with variance ``k u² + c² + spread²`` (host.recognition.fit_u_var_scale).  Three checks of that
form, on a previous run's JSON (``--answers``; nothing re-estimated, the stored per-fold fits reused):

* :func:`object_dispersion` -- per object, on the touches each fold's set *names* (the evaluation
  split): the rms z of ln e about the fitted centre against ``sqrt(k u² + c² + spread²)`` (1 when the
  width is right), the measurement's own robust z ``median(d²/(k u²))/0.455`` about the specimen, and
  the excess kurtosis of that z (0 for a Gaussian: of z, not of the raw error, which a u varying from
  touch to touch makes heavy-tailed by itself);
* :func:`u_power_profile` -- on the fitting folds, the true objects' closed-set NLL (nats, total) with
  ``k u² (u / U_REF)^(2 g)`` for a grid of ``g``, k refitted at each: a minimum away from ``g = 0``
  says k should depend on how large u is;
* :func:`bin_gap` -- accuracy minus confidence of one reliability bin, with a bootstrap interval over
  the drawn probes (touches of one probe share its calibration's level, so they are not independent).

Run:  python bench/_likelihood_form.py --answers bench/results/tactile_asbuilt.json [--contacts 0.5 1 2]
Prints the tables; writes nothing.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Sequence

import numpy as np

from edge.recognition import ObjectSet
from host.recognition import _golden_min, _mixture_nll

#: u at which the power g leaves k unchanged (a 0.5-s wood's stated u).
U_REF_LN = 0.05
POWERS = (-0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3)
#: The per-fold fitted scalars the bench stores that define a set's likelihood.
FIT_KEYS = ("bias_ln", "bias_slope", "u_var_scale", "calibration_ln", "outlier_weight", "outlier_ln")


def _excess_kurtosis(x: np.ndarray) -> float:
    d = x - x.mean()
    v = float(np.mean(d ** 2))
    return float(np.mean(d ** 4) / v ** 2 - 3.0) if v > 0 else 0.0


def object_dispersion(oset: ObjectSet, ln_e, u_ln_e, true_index, ln_e_true) -> list[dict]:
    """Per object of ``oset`` (its fitted centre and width): n, median u, rms z, the measurement's robust z, z's kurtosis."""
    x, u, ti, xt = (np.asarray(a, float) for a in (ln_e, u_ln_e, true_index, ln_e_true))
    ti = ti.astype(int)
    var = oset.u_var_scale * u ** 2 + oset.spread[ti] ** 2 + oset.calibration_ln ** 2
    z = (x - oset.ln_e[ti]) / np.sqrt(var)
    z2 = z ** 2
    # About the specimen, the bias removed: the measurement's error alone against sqrt(k) u.
    dm = x - xt - (oset.ln_e[ti] - oset.ln_e_nominal[ti])
    zm2 = dm ** 2 / (oset.u_var_scale * u ** 2)
    out = []
    for i, name in enumerate(oset.names):
        m = ti == i
        if not m.any():
            continue
        out.append(dict(object=name, n=int(m.sum()), median_u=float(np.median(u[m])),
                        rms_z=float(math.sqrt(np.mean(z2[m]))),
                        robust_z_meas=float(math.sqrt(np.median(zm2[m]) / 0.4549364)),
                        kurtosis=_excess_kurtosis(z[m])))
    return out


def u_power_profile(oset: ObjectSet, ln_e, u_ln_e, true_index, powers: Sequence[float] = POWERS,
                    bounds=(0.02, 100.0)) -> dict:
    """``{g: (total NLL - NLL at g = 0, k)}``: the closed-set NLL with variance ``k u² (u/U_REF_LN)^(2g)``, k refitted.

    The set's outlier component (weight, width), centres and additive term are kept as they are.
    """
    x, u, ti = np.asarray(ln_e, float), np.asarray(u_ln_e, float), np.asarray(true_index, int)
    base = oset.with_calibration(u_var_scale=1.0, temperature=1.0)
    res = {}
    for g in powers:
        ug = u * (u / U_REF_LN) ** g

        def nll(log_k: float) -> float:
            us = ug * math.exp(0.5 * log_k)
            q, hld, _ = base.log_terms(x, us)
            return _mixture_nll(base, q, hld, x, us, ti, 1.0, oset.outlier_weight, oset.outlier_ln, {})
        lk = _golden_min(nll, math.log(bounds[0]), math.log(bounds[1]), rounds=40)
        res[float(g)] = (nll(lk) * ti.size, math.exp(lk))
    ref = res[0.0][0] if 0.0 in res else min(v[0] for v in res.values())
    return {g: (v[0] - ref, v[1]) for g, v in res.items()}


def bin_gap(probe, confidence, correct, *, lo: float = 0.0, hi: float = 0.5, draws: int = 2000,
            seed: int = 1) -> dict | None:
    """Accuracy minus mean confidence of the answers with ``lo <= confidence < hi``; 95 % interval over probes."""
    p, c, ok = np.asarray(probe), np.asarray(confidence, float), np.asarray(correct, float)
    m = (c >= lo) & (c < hi)
    if not m.any():
        return None
    probes = np.unique(p)
    by = [np.flatnonzero(m & (p == q)) for q in probes]
    rng = np.random.default_rng(seed)
    gaps = []
    for _ in range(draws):
        idx = np.concatenate([by[k] for k in rng.integers(0, probes.size, probes.size)])
        if idx.size:
            gaps.append(float(ok[idx].mean() - c[idx].mean()))
    sd_indep = math.sqrt(float(np.sum(c[m] * (1.0 - c[m])))) / int(m.sum())
    return dict(n=int(m.sum()), confidence=float(c[m].mean()), accuracy=float(ok[m].mean()),
                gap=float(ok[m].mean() - c[m].mean()), sd_independent=sd_indep,
                interval_probes=[float(v) for v in np.percentile(gaps, [2.5, 97.5])])


def _fold_sets(oset: ObjectSet, fits: list[dict]) -> dict:
    return {f["held_out_probe"]: oset.with_calibration(**{k: f[k] for k in FIT_KEYS if f.get(k) is not None})
            for f in fits}


def report(answers_path: str, contacts: Sequence[float]) -> list[str]:
    """The three checks per contact time of the paper head of a tactile as-built run's JSON, as text lines."""
    import tactile_asbuilt_bench as B  # noqa: PLC0415 - the bench's row reader and folds, only for the CLI
    from _objects import IN_SET  # noqa: PLC0415

    head = json.loads(open(answers_path).read())["heads"]["paper"]
    objects, _ = B._objects(B.DEFAULT_OUT)
    names = [o.name for o in objects]
    oset = ObjectSet(IN_SET, label="tactile")
    probes = sorted({r["probe"] for r in head["rows"]})
    n_folds = head.get("folds") or len(probes)
    fold_of = {p: 1 + k % n_folds for k, p in enumerate(probes)} if n_folds < len(probes) else {p: p for p in probes}
    L = []
    for ct in contacts:
        R = head["recognition"]["by_contact_s"][str(float(ct))]
        rows = [r for r in head["rows"] if r["contact_s"] == ct]
        t = B.touches_of(rows, names, ct)
        fold = np.array([fold_of[r["probe"]] for r in rows])
        use = np.array([n in oset for n in np.array(names)[t.obj]]) & t.ok & ~t.poor_fit & ~t.broad
        sets = _fold_sets(oset, R["fits"])
        ti = np.array([oset.names.index(names[i]) if names[i] in oset else -1 for i in t.obj])
        disp: dict = {}
        prof: dict = {}
        for f, s in sets.items():
            ev = use & (fold == f)
            for d in object_dispersion(s, np.log(t.e[ev]), t.u_ln_e[ev], ti[ev], np.log(t.e_true[ev])):
                disp.setdefault(d["object"], []).append(d)
            fit = use & (fold != f)
            for g, (dn, k) in u_power_profile(s, np.log(t.e[fit]), t.u_ln_e[fit], ti[fit]).items():
                prof.setdefault(g, []).append((dn, k))
        L += [f"== {ct:g} s: per object on the evaluation split (pooled over folds)",
              f"{'object':24s} {'n':>5s} {'med u':>6s} {'rms z':>6s} {'z meas':>6s} {'kurt':>6s}"]
        for name, ds in disp.items():
            n = sum(d["n"] for d in ds)
            w = lambda k: sum(d[k] * d["n"] for d in ds) / n  # noqa: E731
            rms = math.sqrt(sum(d["rms_z"] ** 2 * d["n"] for d in ds) / n)
            L.append(f"{name:24s} {n:5d} {w('median_u'):6.3f} {rms:6.2f} {w('robust_z_meas'):6.2f} {w('kurtosis'):6.2f}")
        L.append("NLL (nats, total over the fitting folds, vs g = 0) with k u^2 (u/0.05)^(2g), per fold:")
        for g, v in prof.items():
            L.append(f"  g {g:+.1f}: " + " ".join(f"{dn:+7.1f} (k {k:.2f})" for dn, k in v))
        a = R["answers"]
        gap = bin_gap(a["probe"], a["confidence"], a["correct"])
        if gap:
            lo, hi = gap["interval_probes"]
            L.append(f"bin < 0.5: {gap['n']} answers at {100 * gap['confidence']:.1f} % right {100 * gap['accuracy']:.1f} %"
                     f" (gap {100 * gap['gap']:+.1f}, sd if independent {100 * gap['sd_independent']:.1f}; "
                     f"95 % over probes [{100 * lo:+.1f}, {100 * hi:+.1f}])")
    return L


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--answers", required=True, help="a tactile as-built run's JSON")
    ap.add_argument("--contacts", nargs="+", type=float, default=[0.5, 1.0, 2.0])
    args = ap.parse_args()
    for line in report(args.answers, args.contacts):
        print(line, flush=True)


if __name__ == "__main__":
    main()
