"""The recognition fields of a result: which object an estimate names, as every output shares them."""

from __future__ import annotations

import math
from typing import Mapping

from edge.recognition.object_set import ObjectSet
from edge.recognition.touch import BROAD_LN

__all__ = ["RESULT_KEYS", "LIBRARY_SET", "BROAD_FLAGS", "POOR_FIT_FLAG", "recognition_fields"]

#: Keys :func:`recognition_fields` adds to a result (``estimate --json``, the device's records).
RESULT_KEYS = ("object_set", "object", "object_posterior", "class", "class_posterior", "unknown_posterior",
               "candidates")
#: Name of the built-in object set (every library material), the default when no set is chosen.
LIBRARY_SET = "library"
#: Flags of an answer whose stated u recognition does not trust.  ``calibration_refused``: the probe is
#: calibrated but this answer is the uncalibrated 1-D method's, which on a hand touch is off by tens
#: of percent (ten-fold on foam) with a u that does not say so (ISSUE #10, #37): named from it with
#: its own u, a posterior would be confident and wrong.  Its u(ln e) is widened to BROAD_LN (e known
#: within a factor e), so the posteriors say how little such an answer tells.
BROAD_FLAGS = frozenset({"calibration_refused"})


def _broadened(estimate: Mapping) -> dict:
    e = estimate.get("effusivity_W_s05_m2K")
    u = estimate.get("effusivity_W_s05_m2K_u")
    if e is None or not float(e) > 0:
        return dict(estimate)
    u_ln = float(u) / float(e) if u is not None and float(u) >= 0 else 0.0
    return {**estimate, "effusivity_W_s05_m2K_u": float(e) * max(u_ln, BROAD_LN)}


#: The flag of an answer whose calibrated chain fitted poorly (its e withheld by the seam, ISSUE #34).
POOR_FIT_FLAG = "poor_fit"


def _from_poor_fit_chain(object_set: ObjectSet, estimate: Mapping) -> Mapping:
    """The estimate with the poorly fitted chain's e in place of the withheld one, at the set's ``poor_fit_ln``.

    The seam withholds a poor_fit chain's e as a *number* (on hand touches of foam it reads tens of
    percent high), but it still places the object: foam's 40 read as 70 is nowhere near cardboard's
    110 or a wood's 320 (ISSUE #37).  Used only by a set that carries a fitted ``poor_fit_ln`` (the
    scatter of such answers about their objects, host.recognition.fit_poor_fit_ln); otherwise, and
    without a chain e, the estimate unchanged (it names no object).
    """
    chain = estimate.get("sensor_chain")
    if (object_set.poor_fit_ln <= 0 or estimate.get("effusivity_W_s05_m2K") is not None
            or POOR_FIT_FLAG not in set(estimate.get("flags") or ()) or not isinstance(chain, Mapping)):
        return estimate
    try:
        e = float(chain.get("effusivity_W_s05_m2K"))
    except (TypeError, ValueError):
        return estimate
    if not (math.isfinite(e) and e > 0):
        return estimate
    return {**estimate, "effusivity_W_s05_m2K": e, "effusivity_W_s05_m2K_u": e * object_set.poor_fit_ln,
            "method": "sensor_chain", "fit": None}


def recognition_fields(object_set: ObjectSet, estimate: Mapping, *, set_name: str | None = None,
                       top: int = 3, contact_time_s: float | None = None) -> dict:
    """Which object of ``object_set`` an estimate names, as the result fields every output shares.

    One definition for ``thermotouch estimate --json`` and the device's
    measurement records (so ``measure --json`` carries the same keys).

    Parameters
    ----------
    object_set : ObjectSet
    estimate : mapping
        An ``Estimate.to_dict()``: ``effusivity_W_s05_m2K`` and its standard
        uncertainty ``effusivity_W_s05_m2K_u`` are used (only e: the default
        method's k and α are functions of e and add nothing). A missing
        uncertainty counts as 0 -- the objects' spreads still set the widths.
    set_name : str, optional
        Name reported as ``object_set`` (default: the set's label).
    top : int
        Number of candidates.
    contact_time_s : float, optional
        How long the touch heated, s: the set's calibration at that contact time names it
        (:meth:`ObjectSet.at_contact`; a set without a per-contact table ignores it).

    Returns
    -------
    dict
        ``object_set``, ``object`` (a name of the set or ``"unknown"``),
        ``object_posterior``, ``class``, ``class_posterior``,
        ``unknown_posterior`` and ``candidates`` (the ``top`` objects by
        posterior, each ``{"name", "posterior"}``). Without an effusivity
        (no estimate) the names and posteriors are None and ``candidates`` empty (the seam reports
        ``object`` as ``"unknown"``).  An answer flagged with one of :data:`BROAD_FLAGS` is named
        with its u(ln e) widened to :data:`edge.recognition.touch.BROAD_LN`; one whose e the seam
        withheld for a poorly fitted chain is named from the chain's e where the set says how far
        to trust it (``poor_fit_ln``, :func:`_from_poor_fit_chain`).
    """
    out: dict = {"object_set": object_set.label if set_name is None else set_name, "object": None,
                 "object_posterior": None, "class": None, "class_posterior": None, "unknown_posterior": None,
                 "candidates": []}
    broad = bool(BROAD_FLAGS & set(estimate.get("flags") or ()))
    if broad:
        estimate = _broadened(estimate)
    named = _from_poor_fit_chain(object_set.at_contact(contact_time_s), estimate)
    # A broadened u and a poor_fit chain's width are the rule's widths, not shrunk as a stated u would be.
    r = object_set.classify_estimate(named, top=top, contact_time_s=contact_time_s,
                                     stated=named is estimate and not broad)
    if r is None:
        return out
    out.update({"object": r.object, "object_posterior": float(r.object_posterior), "class": r.cls,
                "class_posterior": float(r.class_posterior), "unknown_posterior": float(r.unknown_posterior),
                "candidates": [{"name": n, "posterior": float(p)} for n, p in r.candidates]})
    return out
