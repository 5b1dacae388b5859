"""What a touch measured that recognition uses: α where the probe measured it, and its widened u.

Only a probe that sees a length scale (the small-heater probe) measures the
diffusivity α; the default method's α is the library prior given e and adds
nothing. :func:`measured_alpha` reads it from an estimate's dict,
:func:`effective_u_ln_alpha` widens its stated uncertainty as the set's
``alpha_u_growth`` says.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

__all__ = ["BROAD_LN", "ALPHA_INFORMATIVE_U_LN", "DEFAULT_ALPHA_U_GROWTH", "effective_u_ln_alpha", "measured_alpha"]

#: Standard deviation (ln units) of the term an object without α gets for a measured α.
BROAD_LN = 1.0
#: Largest stated u(ln α) a measured α is used with: a record that pins α no better than a factor e
#: says less than an object without α is granted (BROAD_LN).
ALPHA_INFORMATIVE_U_LN = BROAD_LN
#: Growth a of a measured α's uncertainty, ``u (1 + a u)``, for a set without its own fit: the
#: small-heater fit's linearised u is honest where α is well determined and understates the scatter
#: more the less it is (the likelihood is far from Gaussian in ln α). Fitted by
#: ``python bench/tactile_bench.py`` (host.recognition.fit_alpha_u_growth on the precision board's
#: small-heater calibration touches: 2.23; 5.1 on the reference board) and reported there.
DEFAULT_ALPHA_U_GROWTH = 2.2


def effective_u_ln_alpha(u_ln_alpha, growth: float):
    """The uncertainty a measured α is used with: ``u (1 + growth u)`` (see :data:`DEFAULT_ALPHA_U_GROWTH`)."""
    u = np.asarray(u_ln_alpha, float)
    return u * (1.0 + growth * u)


def measured_alpha(estimate: Mapping) -> tuple[float, float, float] | None:
    """``(alpha, u_ln_alpha, corr_e_alpha)`` a touch measured, or None.

    Only a probe that sees a length scale measures α (the small-heater probe,
    :class:`edge.estimation.probe_estimate.AxiEstimator`). Its fit reports its
    own α with the total uncertainty (fit and flux calibration) and the
    correlation of the ln e and ln α errors in ``fit`` -- whether or not α was
    precise enough to be called determined (below 30 %): a 60 % α still tells
    objects of equal e apart. Where α is that uncertain the linearised u
    understates its scatter; the set widens it (``alpha_u_growth``,
    :func:`effective_u_ln_alpha`). None when the record pins α no better than
    :data:`ALPHA_INFORMATIVE_U_LN`, and for the default method, whose α is the
    library prior given e.
    """
    fit = estimate.get("fit")
    if estimate.get("method") != "axisym" or not isinstance(fit, Mapping):
        return None
    try:
        alpha, u, r = (float(fit[key]) for key in ("alpha_m2_s", "u_ln_alpha", "corr_e_alpha"))
    except (KeyError, TypeError, ValueError):
        return None
    if not (alpha > 0 and math.isfinite(alpha) and 0 < u <= ALPHA_INFORMATIVE_U_LN and abs(r) < 1):
        return None
    return alpha, u, r
