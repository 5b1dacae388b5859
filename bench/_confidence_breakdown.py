"""Where an in-set answer's missing confidence goes: the tactile as-built bench's diagnosis of under-confidence.

An answer's printed posterior ``c`` leaves ``1 - c`` to the other hypotheses: the ``unknown``
background (prior ``prior_unknown``, flat over ``UNKNOWN_LN_E_SPAN``), the runner-up object and
the rest.  Per reliability bin of the in-set answers (evaluation split), :func:`breakdown` reports
the mean confidence, the share right, and those three masses, for all answers and for the
sub-populations the likelihood treats differently (answers with a stated u; touches named from a
poorly fitted chain at ``poor_fit_ln``).  Beside it, the *closed-set* confidence of the accepted
answers (``c / (1 - unknown)``) against the same rightness: a diagnostic of the object terms
alone, never what the device prints (the printed answer keeps the background's mass; a rejected
in-set touch still counts wrong).  ISSUE #37: in-set answers between 0.6 and 0.95 were right
5-13 points more often than they said; this splits how much of that is the background's mass.
"""

from __future__ import annotations

import numpy as np

from _recognition import in_set_answers
from host.recognition import RELIABILITY_BINS

__all__ = ["breakdown", "breakdown_lines"]


def _rows(conf, ok, unk, runner, closed, bins) -> list[dict]:
    edges = np.asarray(bins, float)
    which = np.clip(np.searchsorted(edges, conf, side="right") - 1, 0, edges.size - 2)
    rows = []
    for b in range(edges.size - 1):
        m = which == b
        n = int(m.sum())
        mean = (lambda a: float(np.mean(a[m])) if n else None)  # noqa: E731
        rows.append(dict(lo=float(edges[b]), hi=float(edges[b + 1]), n=n, confidence=mean(conf),
                         accuracy=mean(ok.astype(float)), unknown=mean(unk), runner_up=mean(runner),
                         closed_set=mean(closed)))
    return rows


def breakdown(oset, touches, recs, *, bins=RELIABILITY_BINS) -> dict:
    """Per bin of the in-set answers' confidence: n, confidence, right, unknown / runner-up mass, closed-set confidence.

    ``unknown``: the background's mass beside an object answer (0 for an ``unknown`` answer, whose
    confidence is that mass); ``runner_up``: the best object other than the answer.  Groups: ``all``, ``stated_u`` (named with the answer's stated u), ``poor_fit`` (named from a
    withheld chain e at the set's ``poor_fit_ln``).  ``unknown_share``: the mean background mass
    beside the object answers, over all answers (what an in-set-only reliability table counts as under-confidence wherever
    the objects' own terms are calibrated).
    """
    idx, conf, ok = in_set_answers(oset, touches, recs)
    accepted = np.array([recs[i].accepted for i in idx], bool)
    # The background's mass beside an object answer (a rejected answer's confidence is that mass itself).
    unk = np.where(accepted, [recs[i].unknown_posterior for i in idx], 0.0) if idx.size else np.zeros(0)
    runner = np.array([next((p for n, p in recs[i].candidates if n != recs[i].object), 0.0) for i in idx], float)
    # Accepted answers without the background's mass; a rejected one keeps its own.
    closed = np.where(accepted, conf / np.maximum(1.0 - unk, 1e-12), conf)
    poor = np.asarray(touches.poor_fit, bool)[idx] if idx.size else np.zeros(0, bool)
    groups = {"all": np.ones(idx.size, bool), "stated_u": ~poor, "poor_fit": poor}
    return {"unknown_share": float(unk.mean()) if unk.size else None,
            "groups": {g: {"n": int(m.sum()), "rows": _rows(conf[m], ok[m], unk[m], runner[m], closed[m], bins)}
                       for g, m in groups.items()}}


def _pct(x) -> str:
    return "–" if x is None else f"{100 * x:.0f}"


def breakdown_lines(by_contact: dict) -> list[str]:
    """The bench's table: per contact time and bin, conf / right / unknown / runner-up (n), and closed-set conf."""
    R = {c: r["confidence_breakdown"] for c, r in by_contact.items() if r.get("confidence_breakdown")}
    if not R:
        return []
    L = ["", "Where the in-set answers' missing confidence went (evaluation split; `bench/_confidence_breakdown.py`): "
         "per bin, printed confidence / right / mean `unknown` mass / runner-up object's mass (n), then the "
         "closed-set confidence `c / (1 - unknown)` of the same answers (a diagnostic, not printed). Mean `unknown` "
         "mass over all answers: " + ", ".join(f"{float(c):g} s {100 * R[c]['unknown_share']:.1f} %" for c in R) + ".",
         "", "| group | bin | " + " | ".join(f"{float(c):g} s" for c in R) + " |", "|---|---|" + "---|" * len(R)]
    for g in ("all", "stated_u", "poor_fit"):
        rows = {c: R[c]["groups"][g]["rows"] for c in R}
        first = next(iter(rows.values()))
        for b, row in enumerate(first):
            cells = []
            for c in R:
                x = rows[c][b]
                cells.append("." if not x["n"] else f"{_pct(x['confidence'])}/{_pct(x['accuracy'])}/"
                             f"{_pct(x['unknown'])}/{_pct(x['runner_up'])} ({x['n']}); closed {_pct(x['closed_set'])}")
            L.append(f"| {g} (n {', '.join(str(R[c]['groups'][g]['n']) for c in R)}) | {row['lo']:.2f}-{row['hi']:.2f} | "
                     + " | ".join(cells) + " |")
    return L
