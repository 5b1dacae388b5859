"""Recognition: the user's own objects, and which one a touch was (open set, calibrated).

Recognition reads an estimate (e with its u, and α where the probe measured
it) and names an object; it knows nothing of how the estimate was made, so it
sits beside estimation, not inside it.

Modules
-------
:mod:`~edge.recognition.objects`
    :class:`KnownObject`, the set's CSV format and its parser (:class:`ObjectSetError`).
:mod:`~edge.recognition.object_set`
    :class:`ObjectSet`: likelihood, posteriors, the open-set test, design rates,
    confusion pairs (the model is described there).
:mod:`~edge.recognition.stats`
    chi-square tails and normal quantiles of the open-set test.
:mod:`~edge.recognition.touch`
    what a touch measured that recognition uses (:func:`measured_alpha`).
:mod:`~edge.recognition.fields`
    the recognition fields every result shares (:func:`recognition_fields`).

The names below are the package's public interface; callers import them from
``edge.recognition``.
"""

from edge.recognition.fields import LIBRARY_SET, RESULT_KEYS, recognition_fields
from edge.recognition.object_set import LIBRARY_CALIBRATION, Confusion, ConfusionPair, ObjectSet, Recognition
from edge.recognition.objects import (COLUMNS, DEFAULT_PRIOR_UNKNOWN, DEFAULT_SPREAD_REL, DEFAULT_Z_CRIT, DIRECTIVES,
                                      UNKNOWN, UNKNOWN_LN_E_SPAN, Issue, KnownObject, ObjectSetError)
from edge.recognition.stats import chi2_sf, open_set_z, p_crit_of, tail_p, z_of_p
from edge.recognition.touch import BROAD_LN, DEFAULT_ALPHA_U_GROWTH, effective_u_ln_alpha, measured_alpha

__all__ = [
    "UNKNOWN",
    "DEFAULT_SPREAD_REL",
    "DEFAULT_Z_CRIT",
    "DEFAULT_PRIOR_UNKNOWN",
    "UNKNOWN_LN_E_SPAN",
    "BROAD_LN",
    "LIBRARY_CALIBRATION",
    "COLUMNS",
    "DIRECTIVES",
    "ObjectSetError",
    "Issue",
    "KnownObject",
    "Recognition",
    "ConfusionPair",
    "Confusion",
    "ObjectSet",
    "chi2_sf",
    "p_crit_of",
    "RESULT_KEYS",
    "LIBRARY_SET",
    "recognition_fields",
    "measured_alpha",
    "effective_u_ln_alpha",
    "DEFAULT_ALPHA_U_GROWTH",
    "open_set_z",
    "tail_p",
    "z_of_p",
]
