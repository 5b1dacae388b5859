"""The probe's bias of ln e and the width of poorly fitted touches: fits host.recognition.calibrate uses.

Split from host/recognition.py (the 700-line rule); re-exported there, so callers keep importing
them from ``host.recognition``.
"""

from __future__ import annotations

import math

import numpy as np

from edge.recognition import ObjectSet, effective_u_ln_alpha
from edge.recognition.objects import BIAS_REF_E_W_s05_m2K

__all__ = ["BIAS_U_FLOOR_LN", "POOR_FIT_LN_FLOOR", "SHRINK_KEYS", "U_SHRINK_RANGE", "U_SHRINK_ROUNDS", "U_SHRINK_STEP",
           "fit_bias", "fit_poor_fit_ln",
           "fit_u_typ", "fit_alpha_u_growth"]

#: The set's scalars of the shrunk u (edge.recognition.ObjectSet.likelihood_u).
SHRINK_KEYS = ("u_shrink", "u_typ_ln0", "u_typ_ln1", "u_typ_ln2")
#: The power b on the stated u (host.recognition.fit_u_var_scale(shrink=True); 1 is the stated u): searched on
#: this range by golden section (ROUNDS: the bracket narrows to 0.75 x 0.618^12 = 0.002) and kept to STEP, so a
#: set's directive reads as the fit's resolution.  Not below 0.25: there the typical u decides nearly alone,
#: and a poor_fit touch's width, shrunk like any stated u (fit_poor_fit_ln inverts u_typ^(1-b) w^b), needs a
#: w of tens in ln e to reach its scatter.
U_SHRINK_RANGE = (0.25, 1.0)
U_SHRINK_ROUNDS = 12
U_SHRINK_STEP = 0.01


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


def fit_u_typ(object_set: ObjectSet, u_ln_e, true_index) -> dict:
    """The curve of the u a touch of each object typically states: least squares of ln u on x_j and x_j².

    ``x_j = ln(e_j / e_ref)`` of the touch's true object (its nominal e); returns ``u_typ_ln0/1/2``
    (:meth:`edge.recognition.ObjectSet.typical_u`).  A U in ln e: the polymers' and the metals' u are
    large at a short touch, the glasses' and woods' small.  Fewer than three distinct objects: a level.
    """
    ti = np.asarray(true_index, int)
    y = np.log(np.asarray(u_ln_e, float))
    x = object_set.ln_e_nominal[ti] - math.log(BIAS_REF_E_W_s05_m2K)
    if np.unique(ti).size < 3:
        return {"u_typ_ln0": float(np.mean(y)), "u_typ_ln1": 0.0, "u_typ_ln2": 0.0}
    a = np.linalg.lstsq(np.column_stack([np.ones_like(x), x, x * x]), y, rcond=None)[0]
    return {"u_typ_ln0": float(a[0]), "u_typ_ln1": float(a[1]), "u_typ_ln2": float(a[2])}


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
    # The device names such a touch with this width as it is (not shrunk as a stated u: ObjectSet.likelihood_u).
    return float(max(POOR_FIT_LN_FLOOR, math.sqrt(max(v, 0.0))) / math.sqrt(object_set.u_var_scale))


def fit_alpha_u_growth(object_set: ObjectSet, touches: Touches, true_index, *, hi: float = 100.0) -> float:
    """The growth a with which measured α's scatter about their objects matches ``u (1 + a u)`` (mean z² = 1).

    Over the touches that measured α of objects with k, ρ, c (each object's
    specimen spread included): ``mean((ln α - ln α_i)² / (u_eff(a)² + spread_i²)) = 1``, solved by
    bisection (it falls monotonically with a); 0 when the stated u already
    covers the scatter. See :data:`edge.recognition.DEFAULT_ALPHA_U_GROWTH`.
    """
    ti = np.asarray(true_index, int)
    m = np.isfinite(touches.alpha) & object_set.has_props[ti]
    if not m.any():
        return float(object_set.alpha_u_growth)
    d2 = (np.log(touches.alpha[m]) - object_set.ln_alpha[ti[m]]) ** 2
    s2 = object_set.spread[ti[m]] ** 2
    u = touches.u_ln_alpha[m]

    def excess(a: float) -> float:
        ue = effective_u_ln_alpha(u, a)
        return float(np.mean(d2 / (ue ** 2 + s2))) - 1.0

    if excess(0.0) <= 0.0:
        return 0.0
    if excess(hi) > 0.0:
        return hi
    lo_a, hi_a = 0.0, hi
    for _ in range(60):
        mid = 0.5 * (lo_a + hi_a)
        lo_a, hi_a = (mid, hi_a) if excess(mid) > 0.0 else (lo_a, mid)
    return 0.5 * (lo_a + hi_a)
