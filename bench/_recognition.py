"""Recognition figures the tactile and decision benches share: ceilings, separations, scores of a set's answers.

Each takes an :class:`edge.recognition.ObjectSet` and simulated touches
(host.recognition) and returns plain numbers; the held-out groups are those
of :mod:`_objects`.
"""

from __future__ import annotations

import math

import numpy as np

from _objects import HELD_OUT, HELD_OUT_FAR, HELD_OUT_NEAR, IN_SET
from edge.recognition import UNKNOWN, ObjectSet
from host.recognition import RELIABILITY_BINS, reliability


def ideal_set(objects=IN_SET) -> ObjectSet:
    """The set with the ideal e-only test: variances as stated (T = 1), z_crit = 1.96 (95 % in-set acceptance)."""
    return ObjectSet(objects, temperature=1.0, z_crit=1.96, label="ideal")


def separations(u_ln_e: float) -> list[dict]:
    """Each held-out object's distance to the nearest in-set object, and the ideal test's design "unknown" rate."""
    ideal = ideal_set()
    rows = []
    for o in HELD_OUT:
        d = math.log(o.e_W_s05_m2K) - ideal.ln_e
        i = int(np.argmin(np.abs(d)))
        sigma = math.hypot(float(ideal.spread[i]), u_ln_e)
        sd = math.hypot(o.spread_rel, u_ln_e)
        rows.append(dict(name=o.name, cls=o.cls, e=o.e_W_s05_m2K, nearest=ideal.names[i], d_ln_e=float(d[i]),
                         in_spreads=abs(float(d[i])) / float(ideal.spread[i]), in_sigma=abs(float(d[i])) / sigma,
                         design_unknown=1.0 - ideal.acceptance_probability(math.log(o.e_W_s05_m2K), sd, u_ln_e),
                         group="distinguishable" if o in HELD_OUT_FAR else "near"))
    return rows


def non_overlapping(u_ln_e: float, objects=IN_SET) -> tuple:
    """A subset of the set without e-overlaps: walking up in e, keep an object clear of the last one kept.

    Clear: ``|Δ ln e| >= 2 sqrt(v_a + v_b)``, ``v = u² + spread²`` (not a
    confusion pair of :meth:`ObjectSet.confusion_pairs`).
    """
    kept = []
    for o in sorted(objects, key=lambda o: o.e_W_s05_m2K):
        if kept:
            last = kept[-1]
            v = u_ln_e ** 2 * 2 + last.spread_rel ** 2 + o.spread_rel ** 2
            if math.log(o.e_W_s05_m2K / last.e_W_s05_m2K) < 2.0 * math.sqrt(v):
                continue
        kept.append(o)
    return tuple(kept)


def design_unknown(oset: ObjectSet, objects, u_of: dict) -> float | None:
    """Mean design "unknown" rate of ``objects`` under ``oset``'s fitted test, each at its own median u(e).

    Each object's own u(e) (``u_of``: name -> median u of its touches), not
    the set's median: on the reference board u(e) grows steeply with e (a
    metal's rise is a few thermometer steps), which is what limits it.
    """
    rates = [1.0 - oset.acceptance_probability(math.log(o.e_W_s05_m2K), math.hypot(o.spread_rel, u_of[o.name]),
                                               u_of[o.name]) for o in objects if o.name in u_of]
    return float(np.mean(rates)) if rates else None


def bayes_ceiling(oset: ObjectSet, u_of: dict, weight_of: dict) -> tuple[float, float]:
    """Bayes-optimal object and class accuracy on e alone, each object at its own u(e) and share of touches.

    ``∫ max_i w_i p_i(x) dx`` (class: ``∫ max_c Σ_{i∈c} w_i p_i``) on a grid
    in ln e, ``p_i`` normal with variance ``u_i² + spread_i²``, over the
    objects that gave estimates (``u_of``) weighted by their answered
    touches. :meth:`ObjectSet.confusion_pairs` does the same with one u for
    all; on the reference board u(e) grows with e, so one median u would
    overstate the ceiling for stone and metal.
    """
    idx = [j for j, n in enumerate(oset.names) if n in u_of]
    if not idx:
        return math.nan, math.nan
    mu = oset.ln_e[idx]
    sd = np.sqrt(np.array([u_of[oset.names[j]] for j in idx]) ** 2 + oset.spread[idx] ** 2)
    w = np.array([weight_of[oset.names[j]] for j in idx], float)
    w = w / w.sum()
    step = float(sd.min()) / 20.0
    x = np.arange(float((mu - 8 * sd).min()), float((mu + 8 * sd).max()) + step, step)
    dens = w * np.exp(-0.5 * ((x[:, None] - mu) / sd) ** 2) / (sd * math.sqrt(2 * math.pi))
    cls = np.array([oset.class_names.index(oset.classes[j]) for j in idx])
    by_class = np.zeros((x.size, len(oset.class_names)))
    np.add.at(by_class.T, cls, dens.T)
    return float(dens.max(axis=1).sum() * step), float(by_class.max(axis=1).sum() * step)


def lr_accepts(rec) -> bool:
    """The mixture's Bayes rule: accepted when an object's posterior beats the "unknown" background's."""
    return rec.candidates[0][1] > rec.unknown_posterior


def evaluate(oset: ObjectSet, touches, recs) -> dict:
    """Accuracy, acceptance, unknown rates (measured and design) and the ceiling for one board and contact time."""
    names = touches.names
    in_set = np.array([names[i] in oset for i in touches.obj])
    answered = touches.ok
    truth = [names[i] for i in touches.obj]
    cls_of = {o.name: o.recognition_class for o in oset.objects}
    far = {o.name for o in HELD_OUT_FAR}
    a_in = np.flatnonzero(in_set & answered)
    a_far = np.array([i for i in np.flatnonzero(~in_set & answered) if truth[i] in far], int)
    a_near = np.array([i for i in np.flatnonzero(~in_set & answered) if truth[i] not in far], int)
    obj_ok = np.array([recs[i].object == truth[i] for i in a_in], bool)
    # The closed-set answer (the top candidate, accepted or not): what the Bayes ceiling bounds.
    top_ok = np.array([recs[i].candidates[0][0] == truth[i] for i in a_in], bool)
    u_of = {}
    for i in np.flatnonzero(answered):
        u_of.setdefault(truth[i], []).append(float(touches.u_ln_e[i]))
    n_of = {k: len(v) for k, v in u_of.items()}
    u_of = {k: float(np.median(v)) for k, v in u_of.items()}
    ceiling, class_ceiling = bayes_ceiling(oset, u_of, n_of)
    cls_ok = np.array([recs[i].cls == cls_of[truth[i]] for i in a_in], bool)
    accepted = np.array([recs[i].accepted for i in a_in], bool)
    u_med = float(np.median(touches.u_ln_e[a_in])) if a_in.size else math.nan
    conf = oset.confusion_pairs(u_med) if a_in.size else None
    per_out = {}
    for i in np.concatenate([a_far, a_near]):
        per_out.setdefault(truth[i], []).append(not recs[i].accepted)
    mean = lambda a: float(np.mean(a)) if len(a) else None  # noqa: E731
    present_far = [o for o in HELD_OUT_FAR if o.name in names]
    present_near = [o for o in HELD_OUT_NEAR if o.name in names]
    return dict(
        touches_in=int(in_set.sum()), touches_out=int((~in_set).sum()),
        refused_in=int((in_set & ~answered).sum()), refused_out=int((~in_set & ~answered).sum()),
        object_accuracy=mean(obj_ok), class_accuracy=mean(cls_ok), in_set_acceptance=mean(accepted),
        unknown_far=mean([not recs[i].accepted for i in a_far]),
        unknown_near=mean([not recs[i].accepted for i in a_near]),
        closed_set_accuracy=mean(top_ok),
        # Ablation: the mixture's Bayes rule (a likelihood-ratio test against the flat "unknown" density
        # over ln e, prior prior_unknown) in place of the z test -- answer "unknown" when its posterior is
        # the largest.
        lr_in_set_acceptance=mean([lr_accepts(recs[i]) for i in a_in]),
        lr_object_accuracy=mean([lr_accepts(recs[i]) and recs[i].candidates[0][0] == truth[i] for i in a_in]),
        lr_unknown_far=mean([not lr_accepts(recs[i]) for i in a_far]),
        lr_unknown_near=mean([not lr_accepts(recs[i]) for i in a_near]),
        design_unknown_far=design_unknown(oset, present_far, u_of),
        design_unknown_near=design_unknown(oset, present_near, u_of),
        design_acceptance=float(np.mean([oset.acceptance_probability(float(oset.ln_e[j]), math.hypot(
            float(oset.spread[j]), u_of[n]), u_of[n]) for j, n in enumerate(oset.names) if n in u_of]))
        if a_in.size else None,
        median_u_by_object=u_of,
        unknown_rate_by_object={k: float(np.mean(v)) for k, v in per_out.items()},
        median_u_ln_e=u_med,
        bayes_object=ceiling if a_in.size else None, bayes_class=class_ceiling if a_in.size else None,
        bayes_object_median_u=conf.bayes_accuracy if conf else None,
        confusion_pairs=[[p.a, p.b] for p in conf.pairs] if conf else [],
    )


def in_set_answers(oset: ObjectSet, touches, recs, *, of_class: bool = False):
    """The answered in-set touches: their indices, confidences (the answer's posterior) and rightness.

    "unknown" is a wrong answer; a touch with nothing to name by (None) is left out.
    """
    names = touches.names
    cls_of = {o.name: o.recognition_class for o in oset.objects}
    idx = [i for i in range(len(recs)) if recs[i] is not None and names[touches.obj[i]] in oset]
    if of_class:
        conf = [recs[i].class_posterior for i in idx]
        ok = [recs[i].cls == cls_of[names[touches.obj[i]]] for i in idx]
    else:
        conf = [recs[i].object_posterior for i in idx]
        ok = [recs[i].object == names[touches.obj[i]] for i in idx]
    return np.array(idx, int), np.asarray(conf, float), np.asarray(ok, bool)


def in_set_reliability(oset: ObjectSet, touches, recs, *, of_class: bool = False) -> dict:
    """Reliability of the answers to in-set touches (confidence: the answer's posterior; "unknown" is wrong)."""
    _, conf, ok = in_set_answers(oset, touches, recs, of_class=of_class)
    return reliability(conf, ok)


def confusion_matrix(oset: ObjectSet, touches, recs) -> dict:
    cols = list(oset.names) + [UNKNOWN, "(refused)"]
    rows = list(touches.names)
    m = np.zeros((len(rows), len(cols)), int)
    for i, r in enumerate(recs):
        m[touches.obj[i], cols.index(r.object if r else "(refused)")] += 1
    return dict(rows=rows, cols=cols, counts=m.tolist())


def thermal_ceiling(objects=IN_SET, n: int = 20000, seed: int = 11) -> dict:
    """What any thermal probe could do on this set: e and α measured *exactly*, only the specimens vary.

    Monte Carlo (``n`` specimens per object, ln e and ln α each with the
    object's spread, as the touches are drawn): the Bayes-optimal object and
    class answers (largest density, largest class sum), and the pairs of
    objects of different classes closer than two spreads in (ln e, ln α).
    """
    rng = np.random.default_rng(seed)
    mu = np.array([[math.log(o.e_W_s05_m2K), math.log(o.alpha_m2_s)] for o in objects])
    sd = np.array([o.spread_rel for o in objects])
    classes = sorted({o.recognition_class for o in objects})
    ci = np.array([classes.index(o.recognition_class) for o in objects])
    hit = hit_c = 0
    for i in range(len(objects)):
        x = mu[i] + sd[i] * rng.standard_normal((n, 2))
        d2 = ((x[:, None, :] - mu[None]) ** 2).sum(axis=2) / sd ** 2
        dens = np.exp(-0.5 * d2) / sd ** 2
        hit += int(np.sum(dens.argmax(axis=1) == i))
        by_c = np.zeros((n, len(classes)))
        np.add.at(by_c.T, ci, dens.T)
        hit_c += int(np.sum(by_c.argmax(axis=1) == ci[i]))
    pairs = []
    for a in range(len(objects)):
        for b in range(a + 1, len(objects)):
            if objects[a].recognition_class == objects[b].recognition_class:
                continue
            dist = float(np.hypot(*(mu[a] - mu[b])) / math.hypot(sd[a], sd[b]))
            if dist < 2.0:
                pairs.append(dict(a=objects[a].name, b=objects[b].name, d_ln_e=float(mu[b, 0] - mu[a, 0]),
                                  d_ln_alpha=float(mu[b, 1] - mu[a, 1]), spreads=dist))
    return dict(object=hit / (n * len(objects)), cls=hit_c / (n * len(objects)), close_pairs=pairs, n=n)


def diagnosis(oset: ObjectSet, touches, recs) -> dict:
    """Per object: why its touches were (mis)named -- the estimate's bias, its z-scores, the answers.

    ``bias``: median ln(e / e_true) of the answers with a stated u (against each touch's own
    specimen, so the 5 % spread is not in it); ``rms_z``: rms of that error over the stated u (1
    when the u is honest and there is no bias); ``z_object``: median distance of ln e from the
    object's own ln e in the likelihood's units ``sqrt(u² + spread²)`` before any fitted bias (a
    value near ±1 moves a touch into its neighbour's territory on a set spaced one spread
    apart); ``answers``: what the touches were named (``(refused)``: nothing to name by).
    """
    out = {}
    for i, name in enumerate(touches.names):
        if name not in oset:
            continue
        j = oset.names.index(name)
        ks = [k for k in range(touches.e.size) if touches.obj[k] == i]
        stated = [k for k in ks if math.isfinite(touches.e[k]) and math.isfinite(touches.u_ln_e[k])
                  and not touches.poor_fit[k]]
        err = np.array([math.log(touches.e[k] / touches.e_true[k]) for k in stated])
        u = np.array([touches.u_ln_e[k] for k in stated])
        z_obj = (np.log(touches.e[stated]) - oset.ln_e_nominal[j]) / np.sqrt(u ** 2 + oset.spread[j] ** 2) \
            if stated else np.array([])
        answers: dict = {}
        for k in ks:
            a = recs[k].object if recs[k] is not None else "(refused)"
            answers[a] = answers.get(a, 0) + 1
        wrong = sorted(((n, c) for n, c in answers.items() if n != name), key=lambda x: -x[1])
        out[name] = dict(n=len(ks), stated=len(stated), poor_fit=int(sum(bool(touches.poor_fit[k]) for k in ks)),
                         bias=float(np.median(err)) if err.size else None,
                         u=float(np.median(u)) if u.size else None,
                         rms_z=float(np.sqrt(np.mean((err / u) ** 2))) if err.size else None,
                         z_object=float(np.median(z_obj)) if z_obj.size else None,
                         accuracy=answers.get(name, 0) / max(1, len(ks)), answers=answers,
                         confused_with=wrong[0] if wrong else None)
    return out


def ece_floor(rel: dict, draws: int = 2000, seed: int = 5) -> dict | None:
    """The ECE a perfectly calibrated answerer would show on these touches: its sampling noise.

    Each touch right with probability equal to its confidence (the bin's mean confidence, for
    each of its ``n`` touches), binned as :func:`host.recognition.reliability` bins; the median and
    the 90th percentile over ``draws``.  An ECE bar below this floor cannot be judged on so few touches.
    """
    rows = [r for r in rel["rows"] if r["n"]]
    if not rows:
        return None
    n_all = sum(r["n"] for r in rows)
    rng = np.random.default_rng(seed)
    eces = np.zeros(draws)
    for r in rows:
        acc = rng.binomial(r["n"], r["confidence"], size=draws) / r["n"]
        eces += r["n"] / n_all * np.abs(acc - r["confidence"])
    return {"median": float(np.median(eces)), "p90": float(np.quantile(eces, 0.9)), "n": n_all}


def _mean_abs_normal(d: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """``E|X|`` for ``X ~ N(d, sd²)`` (folded normal mean; ``|d|`` where ``sd`` is 0)."""
    d, sd = np.asarray(d, float), np.asarray(sd, float)
    out = np.abs(d).astype(float)
    m = sd > 0
    z = d[m] / sd[m]
    erf = np.vectorize(math.erf)
    out[m] = sd[m] * math.sqrt(2.0 / math.pi) * np.exp(-0.5 * z ** 2) + d[m] * erf(z / math.sqrt(2.0))
    return out


def _signed_root(x: float) -> float:
    return math.copysign(math.sqrt(abs(x)), x)


def debiased_ece(confidence, correct, bins=RELIABILITY_BINS) -> dict:
    """Binned calibration error with its sampling bias removed (Kumar, Liang & Ma 2019, "Verified
    uncertainty calibration").

    The plug-in ``Σ w_b |ȳ_b − c̄_b|`` is biased upward: a bin's accuracy ``ȳ_b`` carries binomial
    noise of variance ``σ_b² = c̄_b (1 − c̄_b) / n_b`` and ``|·|`` turns noise into gap.  Kumar et
    al.'s ℓ2 estimator ``Σ w_b ((ȳ_b − c̄_b)² − σ_b²)`` is unbiased for the squared calibration
    error; ``debiased`` is its signed square root (a root-mean-square gap, ≥ the ℓ1 ECE for the
    same bins, so ``debiased ≤ 0.03`` judges the bar conservatively; negative when the touches
    scatter less than a calibrated answerer's would).  Their ℓ1 correction, subtracting each bin's
    expected excess ``E|N(ȳ_b − c̄_b, σ_b²)| − |ȳ_b − c̄_b|``, removes only part of the bias (about
    half at a few hundred touches: the excess is evaluated at the noisy gap): ``debiased_l1``.
    ``σ_b²`` uses the bin's mean confidence, the variance under the hypothesis being tested (a
    calibrated bin), so a bin all right or all wrong is still corrected.

    Returns
    -------
    dict
        ``plug_in`` (the ECE as :func:`host.recognition.reliability` computes it), ``debiased``,
        ``debiased_l1`` and ``n``.
    """
    conf = np.asarray(confidence, float)
    ok = np.asarray(correct, float)
    if conf.size == 0:
        return {"plug_in": None, "debiased": None, "debiased_sq": None, "debiased_l1": None, "n": 0}
    edges = np.asarray(bins, float)
    which = np.clip(np.searchsorted(edges, conf, side="right") - 1, 0, edges.size - 2)
    n_b = np.bincount(which, minlength=edges.size - 1).astype(float)
    used = n_b > 0
    c_b = np.bincount(which, conf, minlength=edges.size - 1)[used] / n_b[used]
    y_b = np.bincount(which, ok, minlength=edges.size - 1)[used] / n_b[used]
    w_b = n_b[used] / conf.size
    gap = y_b - c_b
    var_b = c_b * (1.0 - c_b) / n_b[used]
    l2 = float(np.sum(w_b * (gap ** 2 - var_b)))
    return {"plug_in": float(np.sum(w_b * np.abs(gap))),
            "debiased": _signed_root(l2), "debiased_sq": l2,
            "debiased_l1": float(np.sum(w_b * (2.0 * np.abs(gap) - _mean_abs_normal(gap, np.sqrt(var_b))))),
            "n": int(conf.size)}


def ece_interval(confidence, correct, group=None, *, draws: int = 1000, seed: int = 7, level: float = 0.95,
                 bins=RELIABILITY_BINS) -> dict:
    """Bootstrap interval of the plug-in and the debiased ECE over touches (and over groups: probes).

    Each draw resamples the groups (``group``: the drawn probe of each touch; None: one group) with
    replacement, then the touches within each drawn group with replacement, and recomputes
    :func:`debiased_ece`.  The plug-in's interval is the percentile one.  The debiased estimate's is
    taken on its square (``debiased_sq``) and centred on the estimate: a resample's bins carry the
    resampling noise on top of the data's, so its debiased square sits about one ``σ_b²`` too high
    and the percentile interval would be shifted up by that bias; the draws give the spread only
    (``debiased_sq + q − mean``), then the signed root.  With three probes the group level is
    coarse, so the touch-only interval is returned beside it.
    """
    conf = np.asarray(confidence, float)
    ok = np.asarray(correct, bool)
    g = np.zeros(conf.size, int) if group is None else np.unique(np.asarray(group), return_inverse=True)[1]
    members = [np.flatnonzero(g == k) for k in range(int(g.max()) + 1 if g.size else 0)]
    rng = np.random.default_rng(seed)
    point = debiased_ece(conf, ok, bins)
    out = {}
    for label, by_group in (("touches", False), ("probes_and_touches", True)):
        plug, deb = np.empty(draws), np.empty(draws)
        for d in range(draws):
            gs = rng.integers(0, len(members), len(members)) if by_group else np.arange(len(members))
            idx = np.concatenate([rng.choice(members[k], members[k].size) for k in gs])
            r = debiased_ece(conf[idx], ok[idx], bins)
            plug[d], deb[d] = r["plug_in"], r["debiased_sq"]
        q = [(1.0 - level) / 2.0, (1.0 + level) / 2.0]
        out[label] = {"plug_in": [float(x) for x in np.quantile(plug, q)],
                      "debiased": [_signed_root(point["debiased_sq"] + float(x) - float(deb.mean()))
                                   for x in np.quantile(deb, q)]}
    return {**point, "interval": out, "level": level, "draws": draws}


#: The reliability bar of issue #37: every bin with at least RELIABILITY_MIN_N touches within ±RELIABILITY_TOL.
RELIABILITY_MIN_N = 20
RELIABILITY_TOL = 0.05


def reliability_sampling(confidence, correct, bins=RELIABILITY_BINS, *, min_n: int = RELIABILITY_MIN_N,
                         tol: float = RELIABILITY_TOL, draws: int = 4000, seed: int = 13) -> dict:
    """How far a perfectly calibrated answerer's bins land from its confidences on these touches.

    The reliability bar asks every bin of ``min_n`` or more touches to be within ``tol`` of its
    confidence, but a bin's accuracy is a sum of Bernoulli draws: on 175 touches near 0.5 its sd is
    3.8 points, so even an answerer whose every confidence is exact misses ±5 about one time in
    six.  Each draw makes touch i right with probability ``confidence[i]`` (exactly calibrated, the
    same touches in the same bins) and bins the answers as :func:`host.recognition.reliability`.

    Returns
    -------
    dict
        ``bins``: per bin with ``n >= min_n``, ``lo``, ``hi``, ``n``, ``confidence``, ``accuracy``,
        ``gap`` (accuracy - confidence), ``sd`` (the calibrated gap's sd, sqrt(Σ c(1-c)) / n),
        ``p_off`` (share of draws with ``|gap| > tol``) and ``p_as_far`` (share with a gap at least
        as large as the observed one: the two-sided p-value of "this bin is calibrated");
        ``p_all_within`` (share of draws with every such bin within ``tol``: how often a calibrated
        answerer meets the bar as written on these touches); ``draws``, ``seed``.
    """
    conf = np.asarray(confidence, float)
    ok = np.asarray(correct, bool)
    edges = np.asarray(bins, float)
    which = np.clip(np.searchsorted(edges, conf, side="right") - 1, 0, edges.size - 2)
    rng = np.random.default_rng(seed)
    out, all_within = [], np.ones(draws, bool)
    for b in range(edges.size - 1):
        c = conf[which == b]
        n = c.size
        if n < min_n:
            continue
        # Draws of the number right: the touches' Bernoulli trials, summed (a Poisson-binomial).
        right = (rng.random((draws, n)) < c).sum(axis=1)
        gaps = right / n - c.mean()
        gap = float(ok[which == b].mean() - c.mean())
        within = np.abs(gaps) <= tol
        all_within &= within
        out.append(dict(lo=float(edges[b]), hi=float(edges[b + 1]), n=int(n), confidence=float(c.mean()),
                        accuracy=float(ok[which == b].mean()), gap=gap,
                        sd=float(math.sqrt(np.sum(c * (1.0 - c))) / n), p_off=float(np.mean(~within)),
                        p_as_far=float(np.mean(np.abs(gaps) >= abs(gap) - 1e-12))))
    return {"bins": out, "p_all_within": float(np.mean(all_within)), "draws": draws, "seed": seed,
            "min_n": min_n, "tol": tol}


def reliability_judged(s: dict, level: float = 0.05) -> str:
    """The bar's verdict on :func:`reliability_sampling`'s figures, with what a calibrated answerer would show.

    "met": every bin within ``tol``.  Otherwise each bin outside is named with its sd and p-value; the
    verdict is "NOT met" when some bin is further off than a calibrated answerer is in ``level`` of
    draws (its miscalibration is shown), else "NOT met as written, consistent with calibration" (the
    gap is of the size a calibrated answerer shows on as many touches).
    """
    off = [b for b in s["bins"] if abs(b["gap"]) > s["tol"]]
    tail = (f"; a perfectly calibrated answerer on these touches meets it in {100 * s['p_all_within']:.0f} % of "
            f"{s['draws']} draws ({len(s['bins'])} such bins)")
    if not off:
        return "met" + tail
    shown = [b for b in off if b["p_as_far"] < level]
    parts = ", ".join(f"{b['lo']:.2f}-{b['hi']:.2f}: confidence {100 * b['confidence']:.1f} %, right "
                      f"{100 * b['accuracy']:.1f} % of {b['n']} (sd {100 * b['sd']:.1f} points; a calibrated "
                      f"answerer is this far off in {100 * b['p_as_far']:.0f} % of draws, beyond ±"
                      f"{100 * s['tol']:.0f} in {100 * b['p_off']:.0f} %)" for b in off)
    verdict = "NOT met" if shown else "NOT met as written, consistent with calibration"
    return f"{verdict} ({parts})" + tail
