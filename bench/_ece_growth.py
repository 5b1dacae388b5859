"""How the ECE bar's bootstrap interval narrows with the number of drawn probes and touches (issue #37).

The debiased ECE (:func:`_recognition.debiased_ece`, Kumar et al.'s ℓ2 estimator) is judged by its
95 % bootstrap interval (:func:`_recognition.ece_interval`): met when the top is ≤ 3 %, NOT met when
the bottom is above.  Whether a larger bench could decide is read off the measured widths: the
evaluation split's answers are subsampled to nested sets of ``k`` drawn probes (all their touches;
several random choices of the ``k`` probes), the interval is bootstrapped at each size, and the
half-widths *on the squared scale* (where the estimator is unbiased and the interval is centred on
the estimate) are fitted as ``h(N) = h0 (N / N0)^(-a)`` in the number ``N`` of answered in-set
touches.  The rule decides at the ``N`` where ``d² + h_top(N) ≤ 0.03²`` (met) or ``d² - h_bottom(N)
> 0.03²`` (NOT met), ``d²`` the full bench's estimate taken as the truth (so the extrapolated ``N``
is as uncertain as ``d²`` is).
"""

from __future__ import annotations

import math

import numpy as np

from _recognition import ece_interval

BAR = 0.03


def _sq(x: float) -> float:
    """The signed root's square back: the interval bound on the ℓ2 (squared) scale."""
    return math.copysign(x * x, x)


def half_widths(conf, ok, probe, *, draws: int) -> dict:
    """The debiased ECE on the squared scale and its interval's half-widths (top, bottom), both intervals."""
    ce = ece_interval(conf, ok, probe, draws=draws)
    out = {"n": int(ce["n"]), "d_sq": ce["debiased_sq"]}
    for label, iv in ce["interval"].items():
        lo, hi = (_sq(x) for x in iv["debiased"])
        out[label] = {"top": hi - ce["debiased_sq"], "bottom": ce["debiased_sq"] - lo}
    return out


def growth(probe, conf, ok, *, sizes=None, choices: int = 3, draws: int = 400, seed: int = 41) -> dict:
    """Interval half-widths at nested numbers of drawn probes, the fitted power law and the deciding ``N``.

    Parameters
    ----------
    probe, conf, ok : array_like
        Per answered in-set touch: its drawn probe, the answer's posterior, whether it was right.
    sizes : sequence of int, optional
        Numbers of probes to subsample (default 3, 6, 9, ... and all).
    choices : int
        Random choices of the probes at each size below all (their half-widths averaged).
    draws : int
        Bootstrap draws per interval.
    """
    probe, conf, ok = np.asarray(probe), np.asarray(conf, float), np.asarray(ok, bool)
    ps = np.unique(probe)
    sizes = sizes or sorted({*range(3, ps.size, 3), ps.size})
    rng = np.random.default_rng(seed)
    rows = []
    for k in sizes:
        picks = [ps] if k >= ps.size else [rng.choice(ps, k, replace=False) for _ in range(choices)]
        hw = [half_widths(conf[m], ok[m], probe[m], draws=draws) for m in (np.isin(probe, p) for p in picks)]
        rows.append({"probes": int(k), "n": float(np.mean([h["n"] for h in hw])),
                     **{lab: {s: float(np.mean([h[lab][s] for h in hw])) for s in ("top", "bottom")}
                        for lab in ("touches", "probes_and_touches")}})
    full = half_widths(conf, ok, probe, draws=1000)
    out = {"rows": rows, "d_sq": full["d_sq"], "n": full["n"], "fits": {}}
    for lab in ("touches", "probes_and_touches"):
        n = np.array([r["n"] for r in rows])
        h = np.array([0.5 * (r[lab]["top"] + r[lab]["bottom"]) for r in rows])
        ok_ = (h > 0) & (n > 0)
        a = float(-np.polyfit(np.log(n[ok_]), np.log(h[ok_]), 1)[0]) if ok_.sum() >= 2 else math.nan
        out["fits"][lab] = {"exponent": a, **decide_n(full["d_sq"], full[lab], full["n"], a)}
    return out


def decide_n(d_sq: float, hw: dict, n0: int, a: float) -> dict:
    """The ``N`` at which the interval would clear the bar, half-widths scaling as ``(N / n0)^(-a)``.

    ``met_if_zero``: the ``N`` at which a bench whose true ECE is 0 would be judged met (the top
    alone below 0.03², at the half-width measured here: a calibrated bench's is a little narrower).
    """
    bar = BAR ** 2
    if not (a > 0):
        return {"verdict_side": None, "n_decide": None, "met_if_zero": None}
    grow = lambda h, room: n0 * (h / room) ** (1.0 / a) if room > 0 else math.inf  # noqa: E731
    if d_sq < bar:
        side, n = "met", grow(hw["top"], bar - d_sq)
    else:
        side, n = "NOT met", grow(hw["bottom"], d_sq - bar)
    return {"verdict_side": side, "n_decide": None if math.isinf(n) else float(max(n, n0)),
            "met_if_zero": float(max(n0, grow(hw["top"], bar)))}


def growth_lines(R: dict) -> list[str]:
    """The README lines: half-widths per size and contact time, the exponent, the deciding N."""
    have = {c: r["ece_growth"] for c, r in R.items() if r.get("ece_growth")}
    if not have:
        return []
    fmt = lambda x: "–" if x is None else f"{x:,.0f}"  # noqa: E731
    L = ["", "ECE interval against the bench's size (`_ece_growth.growth`: the evaluation split's answers "
         "subsampled to k drawn probes, 3 random choices each, 400 bootstrap draws; half-width = mean of the 95 % "
         "interval's top and bottom distance from the debiased estimate on the squared scale, ×10⁴):", "",
         "| contact | " + " | ".join(f"{r['probes']} probes (N {r['n']:.0f}): touches / probes+touches"
                                     for r in next(iter(have.values()))["rows"]) + " |",
         "|---|" + "---|" * len(next(iter(have.values()))["rows"])]
    for c, g in have.items():
        L.append(f"| {float(c):g} s | " + " | ".join(
            f"{1e4 * 0.5 * (r['touches']['top'] + r['touches']['bottom']):.1f} / "
            f"{1e4 * 0.5 * (r['probes_and_touches']['top'] + r['probes_and_touches']['bottom']):.1f}"
            for r in g["rows"]) + " |")
    L += ["", "Fitted half-width ∝ N^(−a) and the N (answered in-set touches per contact time) at which the rule "
          "would decide, the debiased estimate d² taken as the truth (bar 0.03² = 9 ×10⁻⁴); and the N at which a "
          "bench with a true ECE of 0 would be judged met:", ""]
    for c, g in have.items():
        L.append(f"* {float(c):g} s (N {g['n']}, d² {1e4 * g['d_sq']:+.1f} ×10⁻⁴): " + "; ".join(
            f"{lab.replace('_', ' ')}: a = {f['exponent']:.2f}, decides {f['verdict_side'] or '–'} at N ≈ "
            f"{fmt(f['n_decide'])} (a true ECE of 0: N ≈ {fmt(f['met_if_zero'])})"
            for lab, f in g["fits"].items()))
    return L
