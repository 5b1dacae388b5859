"""The probe's bias of ln e and the width of poorly fitted touches: fits host.recognition.calibrate uses.

Split from host/recognition.py (the 700-line rule); re-exported there, so callers keep importing
them from ``host.recognition``.
"""

from __future__ import annotations

import math

import numpy as np

from edge.recognition import ObjectSet
from edge.recognition.objects import BIAS_REF_E_W_s05_m2K

__all__ = ["BIAS_U_FLOOR_LN", "POOR_FIT_LN_FLOOR", "fit_bias", "fit_poor_fit_ln"]


#: Floor on a touch's u(ln e) in the bias fit's weights: a metal's 2 % or a glass's 1.6 % should not
#: let a handful of touches set the line for everything.
BIAS_U_FLOOR_LN = 0.02
#: Smallest ``poor_fit_ln`` a fit returns: a few poorly fitted touches that happen to sit on their
#: object must not make the next one look precise.
POOR_FIT_LN_FLOOR = 0.1


def fit_bias(object_set: ObjectSet, touches) -> tuple[float, float]:
    """The probe's bias of ln e, ``(bias_ln, bias_slope)``: weighted least squares of ln(e / e_true) on ln e_true.

    Against each touch's own specimen (``e_true``), so the specimen spread is not in it; weights
    ``1 / (u² + BIAS_U_FLOOR_LN²)``.  Only touches answered with their stated u (not ``poor_fit``).
    The line is about :data:`edge.recognition.objects.BIAS_REF_E_W_s05_m2K`: ``bias_ln`` is the bias there.
    """
    m = touches.ok & ~touches.poor_fit & np.isfinite(touches.u_ln_e)
    if int(m.sum()) < 3:
        return 0.0, 0.0
    x = np.log(touches.e_true[m]) - math.log(BIAS_REF_E_W_s05_m2K)
    y = np.log(touches.e[m] / touches.e_true[m])
    sw = 1.0 / np.sqrt(touches.u_ln_e[m] ** 2 + BIAS_U_FLOOR_LN ** 2)
    if np.ptp(x) < 0.5:   # one object (or a tight cluster): a level, no slope
        return float(np.sum(sw ** 2 * y) / np.sum(sw ** 2)), 0.0
    coef = np.linalg.lstsq(np.column_stack([sw, sw * x]), sw * y, rcond=None)[0]
    return float(coef[0]), float(coef[1])


def fit_poor_fit_ln(object_set: ObjectSet, touches, true_index) -> float:
    """``poor_fit_ln``: the scatter of poorly fitted chain e's about what their objects read, at the set's T.

    ``sqrt(mean(d²) / T - mean(spread²) - calibration_ln²)``, at least :data:`POOR_FIT_LN_FLOOR`, over the ``poor_fit``
    touches (d: ln e minus the true object's expected reading, its bias included), divided by
    ``sqrt(k)`` (the set's ``u_var_scale``: the device scales this width as any stated u); 0 (such
    touches name nothing) when there are none.
    """
    m = touches.poor_fit & touches.ok
    if not m.any():
        return 0.0
    ti = np.asarray(true_index, int)[m]
    d2 = (np.log(touches.e[m]) - object_set.ln_e[ti]) ** 2
    # The device's variance of such a touch is T (k w² + spread² + calibration_ln²): w from the rest.
    v = (float(np.mean(d2)) / object_set.temperature - float(np.mean(object_set.spread[ti] ** 2))
         - object_set.calibration_ln ** 2)
    return float(max(POOR_FIT_LN_FLOOR, math.sqrt(max(v, 0.0))) / math.sqrt(object_set.u_var_scale))
