"""The recognition fields of a result: which object an estimate names, as every output shares them."""

from __future__ import annotations

from typing import Mapping

from edge.recognition.object_set import ObjectSet

__all__ = ["RESULT_KEYS", "LIBRARY_SET", "recognition_fields"]

#: Keys :func:`recognition_fields` adds to a result (``estimate --json``, the device's records).
RESULT_KEYS = ("object_set", "object", "object_posterior", "class", "class_posterior", "unknown_posterior",
               "candidates")
#: Name of the built-in object set (every library material), the default when no set is chosen.
LIBRARY_SET = "library"


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
        (no estimate) the names and posteriors are None and ``candidates`` empty.
    """
    out: dict = {"object_set": object_set.label if set_name is None else set_name, "object": None,
                 "object_posterior": None, "class": None, "class_posterior": None, "unknown_posterior": None,
                 "candidates": []}
    r = object_set.classify_estimate(estimate, top=top, contact_time_s=contact_time_s)
    if r is None:
        return out
    out.update({"object": r.object, "object_posterior": float(r.object_posterior), "class": r.cls,
                "class_posterior": float(r.class_posterior), "unknown_posterior": float(r.unknown_posterior),
                "candidates": [{"name": n, "posterior": float(p)} for n, p in r.candidates]})
    return out
